"""What a co-simulation runs: FMUs, the couplings between them, what to record.

A :class:`CosimSystem` is the scene (:mod:`fmugen.scene`) after its build:
every group of instances has become one FMU (a :class:`Unit`), every
connection between groups a :class:`Coupling` between FMU variables.  The
master (:mod:`fmugen.cosim.master`) reads nothing else, so a system can also
be written by hand around FMUs that fmugen did not build.

A :class:`ReferenceProblem` is the same scene assembled as one ODE from the
same symbolic components (``Scene.monolithic_model()``): the independent
solution every co-simulation result is measured against.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np


@dataclass(frozen=True)
class Unit:
    """One FMU of the system.

    ``start_values`` (FMI variable name -> number) are set after
    instantiation, before ``fmi2EnterInitializationMode``: parameters the
    scene changed, consistent initial states, values of inputs that nothing
    drives and internal-solver settings (``solver.method`` is an Integer).
    """

    name: str  # group name in the scene, e.g. "arm", "joint1"
    path: Path  # the .fmu
    fmi_type: str  # "cs" or "me"
    start_values: Mapping[str, float] = field(default_factory=dict)
    provides_directional_derivative: bool = True
    members: tuple = ()  # the scene instances inside (for messages)


@dataclass(frozen=True)
class Coupling:
    """``target = factor * source`` between two FMUs' variables."""

    source: tuple  # (unit name, FMI variable name of an output)
    target: tuple  # (unit name, FMI variable name of an input)
    factor: float = 1.0  # a unit conversion the scene stated (1: same unit)
    unit: str = ""  # the physical unit on the target side, for reports


@dataclass(frozen=True)
class Recorded:
    """One recorded signal: column ``column`` is ``variable`` of FMU ``unit``."""

    column: str  # scene name "instance.variable", e.g. "arm.q[2]", "valve1.x_v"
    unit: str  # FMU (unit) name
    variable: str  # FMI variable name inside that FMU
    physical_unit: str = ""


@dataclass(frozen=True)
class CosimSystem:
    name: str
    units: tuple  # of Unit, in scene order
    couplings: tuple  # of Coupling
    recorded: tuple  # of Recorded
    start_time: float = 0.0
    stop_time: float = 1.0
    step: float = 1e-3  # communication (macro) step
    # Gauss-Seidel order derived from the scene's dependency graph (units that
    # only integrate their inputs -- the arm -- first); None: scene order
    order: Optional[tuple] = None
    settings: Mapping[str, object] = field(default_factory=dict)  # the scene's [cosim] table
    # the scene's state of rest is unstable (its linearisation's growing modes, as sentences): a divergence
    # of the co-simulation is then the physics', not the coupling's
    rest_unstable: tuple = ()

    def unit(self, name: str) -> Unit:
        for u in self.units:
            if u.name == name:
                return u
        raise KeyError(f"{self.name}: no FMU named {name!r}; FMUs: {', '.join(u.name for u in self.units)}")


@dataclass(frozen=True)
class ReferenceProblem:
    """The whole scene as one ODE x' = f(t, x, u, p), y = g(t, x, u, p).

    ``model`` is a :class:`fmugen.codegen.model.SymbolicModel` whose state and
    output names are the scene's column names (``"arm.q[2]"``); parameters
    carry the scene's values as their start values; ``u`` holds the values of
    its free inputs (constant over the run).
    """

    model: object  # SymbolicModel
    x0: np.ndarray
    u: np.ndarray
    columns: Sequence[str]
    start_time: float
    stop_time: float
    nominals: Optional[np.ndarray] = None  # per-state magnitude for atol scaling
