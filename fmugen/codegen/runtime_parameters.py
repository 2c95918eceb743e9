"""The variables the C runtime adds to every FMU (c_runtime/fmugen_model.h).

Their offsets are read from the header, their start values are the defaults
of ``fmugen_set_defaults`` (c_runtime/runtime_support.c).  Both the C printer
(``rt_start`` of model.c) and the modelDescription.xml writer take them from
here; they lived in fmugen.fmi.model_description, so the C printer imported
the XML writer, which imports the models the printer prints.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..errors import FmugenError


@dataclass(frozen=True)
class RuntimeParameter:
    """A variable the runtime adds to every FMU (offset: from its block start)."""

    name: str
    offset: int
    type: str  # "Real" or "Integer"
    causality: str
    variability: str
    initial: Optional[str]
    start: Optional[float]
    unit: str
    description: str
    min: Optional[float] = None
    max: Optional[float] = None


def header_defines() -> dict:
    """``#define FMUGEN_* <int>`` of c_runtime/fmugen_model.h (the contract)."""
    path = Path(__file__).resolve().parents[2] / "c_runtime" / "fmugen_model.h"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: the C model interface is missing (fmugen must be used from its "
                                f"source tree)")
    defs = {}
    for m in re.finditer(r"^#define\s+(FMUGEN_\w+)\s+(-?\d+)\b", path.read_text(), re.M):
        defs[m.group(1)] = int(m.group(2))
    return defs


def runtime_parameters() -> tuple:
    """The runtime's own variables, offsets read from fmugen_model.h.

    Start values are the defaults of ``fmugen_set_defaults``
    (c_runtime/runtime_support.c); tests/test_fmi_build.py checks both.
    """
    d = header_defines()
    solvers = (f"{d['FMUGEN_SOLVER_DOPRI5']} Dormand-Prince 5(4) adaptive, "
               f"{d['FMUGEN_SOLVER_IMPLICIT']} implicit (stiff, uses the Jacobian), "
               f"{d['FMUGEN_SOLVER_RK4']} classical Runge-Kutta 4 fixed step")
    return (
        RuntimeParameter("solver.rtol", d["FMUGEN_RT_RTOL"], "Real", "parameter", "fixed", "exact", 1e-6, "",
                         "relative tolerance of the Co-Simulation solver", min=0.0),
        RuntimeParameter("solver.atol", d["FMUGEN_RT_ATOL"], "Real", "parameter", "fixed", "exact", 1e-6, "",
                         "absolute tolerance of the Co-Simulation solver, relative to each state's nominal value",
                         min=0.0),
        RuntimeParameter("solver.max_step", d["FMUGEN_RT_MAX_STEP"], "Real", "parameter", "fixed", "exact", 0.0,
                         "s", "largest internal step of the Co-Simulation solver, 0 = no limit", min=0.0),
        RuntimeParameter("solver.fixed_step", d["FMUGEN_RT_FIXED_STEP"], "Real", "parameter", "fixed", "exact",
                         0.0, "s", "step of the fixed-step method, 0 = one step per communication step", min=0.0),
        RuntimeParameter("solver.method", d["FMUGEN_INT_SOLVER"], "Integer", "parameter", "fixed", "exact",
                         d["FMUGEN_SOLVER_DOPRI5"], "", f"Co-Simulation solver: {solvers}",
                         min=min(d["FMUGEN_SOLVER_DOPRI5"], d["FMUGEN_SOLVER_IMPLICIT"], d["FMUGEN_SOLVER_RK4"]),
                         max=max(d["FMUGEN_SOLVER_DOPRI5"], d["FMUGEN_SOLVER_IMPLICIT"], d["FMUGEN_SOLVER_RK4"])),
        RuntimeParameter("solver.n_steps", d["FMUGEN_INT_N_STEPS"], "Integer", "local", "discrete", "calculated",
                         None, "", "accepted internal steps of the Co-Simulation solver so far"),
        RuntimeParameter("solver.n_rejected", d["FMUGEN_INT_N_REJECTED"], "Integer", "local", "discrete",
                         "calculated", None, "", "rejected internal steps so far"),
        RuntimeParameter("solver.n_rhs", d["FMUGEN_INT_N_RHS"], "Integer", "local", "discrete", "calculated",
                         None, "", "evaluations of the derivatives by the solver so far"),
        RuntimeParameter("solver.n_jac", d["FMUGEN_INT_N_JAC"], "Integer", "local", "discrete", "calculated",
                         None, "", "evaluations of the Jacobian by the solver so far"),
        RuntimeParameter("solver.stiffness_detected", d["FMUGEN_INT_STIFFNESS_DETECTED"], "Integer", "local",
                         "discrete", "calculated", None, "",
                         "times Dormand-Prince found the problem stiff so far (use solver.method = 2 then)"),
        RuntimeParameter("solver.range_check", d["FMUGEN_INT_RANGE_CHECK"], "Integer", "parameter", "fixed",
                         "exact", d["FMUGEN_RANGE_WARN"], "",
                         "a state, input or output outside its validity range [min, max]: 0 ignored, "
                         "1 fmi2Warning (default), 2 fmi2Discard",
                         min=d["FMUGEN_RANGE_IGNORE"], max=d["FMUGEN_RANGE_ERROR"]),
        # listed only by FMUs of hybrid models (variable_layout)
        RuntimeParameter("solver.n_events", d["FMUGEN_INT_N_EVENTS"], "Integer", "local", "discrete", "calculated",
                         None, "", "events handled so far (Co-Simulation: state events located inside "
                         "communication steps, not sample instants; Model Exchange: event iterations)"),
    )


#: runtime parameters whose start value a build may set (the scene's internal solver and tolerances)
SETTABLE_RUNTIME_STARTS = ("solver.method", "solver.rtol", "solver.atol", "solver.max_step", "solver.fixed_step")


def runtime_starts(values: dict) -> dict:
    """Start values of the settable runtime parameters: ``values`` checked and completed with the defaults.

    The FMU's C defaults (``rt_start``, ``solver_start`` of the model struct)
    and the XML start values both come from this one dict, so an importer that
    sets nothing gets what the XML says.
    """
    out = {r.name: r.start for r in runtime_parameters() if r.name in SETTABLE_RUNTIME_STARTS}
    bounds = {r.name: (r.min, r.max) for r in runtime_parameters()}
    for name, v in dict(values or {}).items():
        if name not in out:
            raise FmugenError(f"runtime start value {name!r}: only {', '.join(SETTABLE_RUNTIME_STARTS)} can be set")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or v != v or v in (float("inf"), float("-inf")):
            raise FmugenError(f"runtime start value {name} = {v!r} must be a finite number")
        lo, hi = bounds[name]
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise FmugenError(f"runtime start value {name} = {v!r} is outside [{lo}, {hi}]")
        if name == "solver.method":
            if int(v) != v:
                raise FmugenError(f"runtime start value solver.method = {v!r} must be an integer")
            v = int(v)
        elif name == "solver.rtol" and not 0 < v < 1:
            raise FmugenError(f"runtime start value solver.rtol = {v!r} must lie in (0, 1)")
        out[name] = v if name == "solver.method" else float(v)
    return out
