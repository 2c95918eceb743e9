"""Actuator-chain and controller components as SymbolicModels.

Each factory returns a :class:`fmugen.codegen.model.SymbolicModel`; the
fidelity is a keyword (what it leaves out is absent from the model).
:func:`assemble` connects components Modelica-style into one model;
:func:`load_assembly` reads an assembly TOML file.  See README.md here.
"""
from .base import TIME
from .amplifier import amplifier
from .current_driver import current_driver
from .servo_valve import servo_valve
from .hydraulic_actuator import hydraulic_actuator
from .joint import joint_inertia
from .connect import assemble
from .dc_motor import dc_motor
from .controller import controller
from .trajectory import ptp_trajectory, quintic_trajectory, table_trajectory
from .chains import single_joint
from .assembly import load_assembly
from .numeric import NumericModel, linearise, stable_step
from .parameters import load_parameter_set, available_sets

__all__ = ["TIME", "amplifier", "current_driver", "servo_valve", "hydraulic_actuator", "joint_inertia",
           "assemble", "dc_motor", "controller", "ptp_trajectory", "quintic_trajectory",
           "table_trajectory", "single_joint", "load_assembly", "NumericModel", "linearise", "stable_step", "load_parameter_set", "available_sets"]
