"""What a run returns: the recorded values (:class:`CosimResult`), the work and outcome
(:class:`Summary`) and, when it stopped early, why and where (:class:`FailureReport`)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np


@dataclass
class FailureReport:
    """Why and where a run stopped early."""

    time: float  # last accepted communication point [s]
    cause: str  # "fmu-failure", "diverged", "tolerance", "not-converged", "non-finite", "terminated" (an FMU
    # asked to end the simulation: terminateSimulation = true)
    message: str
    unit: Optional[str] = None  # the FMU that failed
    coupling: Optional[str] = None  # "src.var -> dst.var"
    fmu_messages: list = field(default_factory=list)

    def __str__(self) -> str:
        where = []
        if self.unit:
            where.append(f"FMU {self.unit!r}")
        if self.coupling:
            where.append(f"coupling {self.coupling}")
        lines = [f"co-simulation stopped at t = {self.time:.9g} s ({self.cause})"
                 + (f" [{'; '.join(where)}]" if where else "") + f": {self.message}"]
        lines += [f"  {m}" for m in self.fmu_messages[-5:]]
        return "\n".join(lines)


@dataclass
class Summary:
    """Work and outcome of one run."""

    system: str
    scheme: str
    extrapolation: str
    adaptive: bool
    status: str = "ok"  # "ok", "unreliable" (estimate above tol, or growing) or "failed"
    macro_steps: int = 0  # accepted
    rollbacks: int = 0  # rejected (restored) macro steps
    iterations: int = 0  # coupling iterations beyond the first (iterative/newton)
    jacobians: int = 0  # interface Jacobians by finite differences
    events: int = 0  # events the FMUs reported inside macro steps (fmugen FMUs' solver.n_events)
    discontinuities: int = 0  # macro steps after which the input history restarted because of them
    do_steps: int = 0  # fmi2DoStep calls (all FMUs, also rolled-back ones)
    fmu_calls: int = 0  # all fmi2* calls of the master
    wall_time: float = 0.0  # [s]
    simulated_time: float = 0.0  # [s]
    step_min: float = math.inf
    step_max: float = 0.0
    threads: int = 1  # threads that stepped the FMUs (workers > 1 and macro steps costly enough)
    coupling_tol: float = 0.0  # iterated schemes: the residual tolerance of the coupling iteration
    coupling_tol_source: str = ""  # where it came from ("given", or derived from the FMUs' tolerances)
    # the a-posteriori estimate of the coupling error (accuracy.py: step doubling on a sample of steps)
    error_estimate: float = math.nan  # the largest column's estimate relative to its range
    error_estimates: dict = field(default_factory=dict)  # column -> estimated coupling error (its unit)
    error_trend: str = "unknown"  # "decaying", "steady", "growing" (local error over the run's last half)
    error_growth: float = math.nan  # factor of that growth
    estimate_samples: int = 0  # shadow steps the estimate rests on
    reliability: str = ""  # why the status is "unreliable"
    physics: str = ""  # the system's state of rest is unstable (its linearisation's growing mode)
    # what the run did without because an FMU lacks a capability (no error estimate without FMU states, the ME
    # block's Jacobian by differences, ...): sentences, also in str() and as_dict()
    warnings: list = field(default_factory=list)
    failure: Optional[FailureReport] = None

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.simulated_time / self.wall_time if self.wall_time > 0 else math.inf

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("system", "scheme", "extrapolation", "adaptive", "status",
                                           "macro_steps", "rollbacks", "iterations", "jacobians",
                                           "events", "discontinuities",
                                           "do_steps", "fmu_calls", "wall_time", "simulated_time",
                                           "step_min", "step_max", "threads", "coupling_tol",
                                           "coupling_tol_source", "error_estimate", "error_estimates",
                                           "error_trend", "error_growth", "estimate_samples", "reliability",
                                           "physics", "warnings")}
        d["real_time_factor"] = self.real_time_factor
        d["failure"] = str(self.failure) if self.failure else ""
        return d

    def __str__(self) -> str:
        s = (f"{self.system}: {self.scheme}/{self.extrapolation}{' adaptive' if self.adaptive else ''}: "
             f"{self.status}; {self.macro_steps} macro steps (H {self.step_min:.4g}..{self.step_max:.4g} s), "
             f"{self.rollbacks} rollbacks, {self.iterations} iterations, {self.jacobians} Jacobians, "
             f"{self.do_steps} doStep, {self.fmu_calls} FMU calls, wall {self.wall_time:.4g} s "
             f"({self.real_time_factor:.3g}x real time)" + (f", {self.threads} threads" if self.threads > 1 else "")
             + (f"; {self.events} events in {self.discontinuities} macro steps (input history restarted "
                f"there)" if self.events else ""))
        if self.estimate_samples:
            s += (f"\nestimated coupling error {self.error_estimate:.3g} of the largest column's range "
                  f"({self.estimate_samples} step-doubling samples), trend {self.error_trend}")
        if self.physics:
            s += f"\nwarning: the system is unstable at rest ({self.physics}); its runaway is physics, not coupling"
        for w in self.warnings:
            s += f"\nwarning: {w}"
        if self.reliability:
            s += f"\nunreliable: {self.reliability}"
        if self.coupling_tol:
            s += f"\ncoupling tolerance {self.coupling_tol_source if self.coupling_tol_source != 'given' else f'{self.coupling_tol:.3g} (given)'}"
        if self.failure:
            s += "\n" + str(self.failure)
        return s


@dataclass
class CosimResult:
    """Recorded values at every accepted communication point (t_0 included)."""

    time: np.ndarray  # (n,)
    values: np.ndarray  # (n, len(columns))
    columns: tuple
    summary: Summary
    slopes: Optional[np.ndarray] = None  # (n, len(columns)) d/dt at each point (run(dense=True)), NaN: none

    @property
    def ok(self) -> bool:
        return self.summary.status == "ok"

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(column)]
        except ValueError:
            raise KeyError(f"no recorded column {column!r}; columns: {', '.join(self.columns)}") from None

    def structured(self) -> np.ndarray:
        """A structured array with fields ``time`` and every column (fmpy's result layout)."""
        dt = np.dtype([("time", float)] + [(c, float) for c in self.columns])
        out = np.empty(len(self.time), dtype=dt)
        out["time"] = self.time
        for i, c in enumerate(self.columns):
            out[c] = self.values[:, i]
        return out
