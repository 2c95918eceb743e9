"""fmugen: FMI 2.0 components for robot manipulators and their actuator chains."""
__version__ = "0.1.0"
