"""Co-simulation of scenes: the master, reference solutions, reports."""
