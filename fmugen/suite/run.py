"""Running the suite: build each case's FMU once, compute its reference, run
every method, classify, and write the table (printed, ``suite.csv``), a plot
per case and the summary figures (cheapest method meeting 1e-6, RODAS3
against scipy Radau at equal error).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from . import classify as cl
from .cases import CASES, RK4, Case, Method, get_case
from .fmu_run import Unpacked, run
from .reference import reference, sensitivity, setup

GOAL = 1e-6  # rad (or m): the accuracy a user asks of a joint angle


@dataclass
class SuiteRow:
    case: str
    method: str
    outcome: str  # accurate / detected / SILENT / reproduced (thesis rows)
    error: float  # max |y - y_ref| over the compared variables (energy cases: relative energy drift)
    allowed: float  # the promise the error is judged against
    message: str
    steps: int = 0
    rejected: int = 0
    f_evals: int = 0
    jac_evals: int = 0
    stiffness_detected: int = 0
    wall: float = 0.0  # s inside fmi2DoStep
    extra: dict = field(default_factory=dict)


class Context:
    """Where FMUs and outputs go; FMUs built once per model key."""

    def __init__(self, out: Path, log: Callable, repeats: int = 1):
        self.out = out
        self.log = log
        self.repeats = repeats
        self.fmus = {}
        (out / "fmus").mkdir(parents=True, exist_ok=True)

    def fmu(self, case: Case, model) -> Unpacked:
        from ..fmi.build import build_fmu

        key = case.model_key or case.name
        if key not in self.fmus:
            path = build_fmu(model, self.out / "fmus" / f"{key}.fmu", fmi_type="cs").path
            self.fmus[key] = Unpacked(path, self.out / "fmus" / key)
        return self.fmus[key]


def rk4_limit(s) -> float:
    """RK4's stability limit from the eigenvalues of df/dx at the start (numpy).

    Growing modes (Re lambda > 0.05 |lambda|, e.g. an arm falling from an
    unstable pose) have no stable step and are left out; nearly undamped
    ones get the imaginary-axis limit 2 sqrt 2 / |lambda| -- as the runtime
    does."""
    from ..components.numeric import stable_step

    A = s.ev.jacobians(0.0, s.x0, s.u)[0]
    h = np.inf
    for lam in np.linalg.eigvals(A):
        if lam == 0 or lam.real > 0.05 * abs(lam):
            continue
        h = min(h, stable_step([lam], "rk4") if lam.real < -0.05 * abs(lam) else 2 * np.sqrt(2) / abs(lam))
    return h


def rk4_step(case: Case, m: Method, h_lim: float) -> float:
    """The RK4 step of a method, as the FMU will take it (H / ceil(H / h))."""
    h = m.rk4_step or m.rk4_factor * h_lim
    cap = case.rk4_max_step or case.H
    h = min(h, cap)
    return case.H / np.ceil(case.H / h * (1 - 1e-12))


def _trajectory_case(ctx: Context, case: Case, methods, plots: bool) -> list:
    model = case.make_model()
    s = setup(model, case.start)
    fmu = ctx.fmu(case, model)
    t = np.arange(int(round(case.stop / case.H)) + 1) * case.H
    ref = reference(s, t, case.stiff)
    cols = [s.column(c) for c in case.compare]
    y_ref = ref.values[:, cols]
    scale = float(np.max(np.abs(y_ref)))
    unc = float(np.max(ref.uncertainty[cols]))
    G = sensitivity(s, t, cols, ref, case.stiff)
    checks = list(case.validity)
    record = list(case.compare) + [c.variable for c in checks if c.variable not in case.compare]
    h_lim = rk4_limit(s)
    rows, runs = [], []
    for m in methods:
        h = rk4_step(case, m, h_lim) if m.solver == RK4 else 0.0
        r = run(fmu, m, case.start, case.stop, case.H, record, rk4_h=h)
        r.wall = _median_wall(r, ctx.repeats, lambda: run(fmu, m, case.start, case.stop, case.H, record, rk4_h=h))
        n = len(r.t)
        err = float(np.max(np.abs(r.values[:, :len(cols)] - y_ref[:n]))) if n else np.inf
        if not np.isfinite(err):
            err = np.inf
        allowed = cl.promise(m, scale, unc, G)
        outcome, msg = cl.classify(r.completed, r.failure_message(), r.warnings(), err, allowed,
                                   cl.violations(r.values, record, checks))
        if outcome == cl.ACCURATE and G > 10 and not msg:
            msg = f"sensitivity of the motion G = {G:.3g} (error amplification), promise scaled by it"
        rows.append(SuiteRow(case.name, m.label(h or None, h_lim), outcome, err, allowed, msg, r.steps,
                             r.rejected, r.f_evals, r.jac_evals, r.stiffness_detected, r.wall,
                             {"ref_uncertainty": unc, "rk4_limit": h_lim, "sensitivity": G,
                              "t_end": float(r.t[-1]) if n else 0.0}))
        runs.append((rows[-1].method, r))
    if plots:
        from .report import plot_trajectories

        plot_trajectories(ctx.out / f"{case.name}.png", case, ref.t, y_ref, runs)
    return rows


def _median_wall(first, repeats: int, again: Callable) -> float:
    """Median wall time over ``repeats`` runs (the first one included)."""
    walls = [first.wall] + [again().wall for _ in range(max(0, repeats - 1))]
    return float(np.median(walls))


def _energy(arm, q, qd) -> np.ndarray:
    return np.array([sum(arm.energy(a, b)) for a, b in zip(q, qd)])


def _energy_case(ctx: Context, case: Case, methods, plots: bool) -> list:
    from .cases import puma_arm

    arm = puma_arm()
    model = case.make_model()
    s = setup(model, case.start)
    fmu = ctx.fmu(case, model)
    n = arm.n
    names = [f"q[{i}]" for i in range(1, n + 1)] + [f"qd[{i}]" for i in range(1, n + 1)]
    x0 = s.x0
    E0 = float(sum(arm.energy(x0[:n], x0[n:])))
    KE0, PE0 = arm.energy(x0[:n], x0[n:])
    scale = abs(KE0) + abs(PE0)
    h_lim = rk4_limit(s)
    rows, curves = [], []
    for m in methods:
        h = rk4_step(case, m, h_lim) if m.solver == RK4 else 0.0
        r = run(fmu, m, case.start, case.stop, case.H, names, rk4_h=h)
        E = _energy(arm, r.values[:, :n], r.values[:, n:])
        drift = float(np.max(np.abs(E - E0)) / scale) if len(E) else np.inf
        # energy drift over 60 s of a chaotic motion: promised 1e3 x tol (RK4: 1e-3)
        allowed = 1e-3 if m.solver == RK4 else 1e3 * m.tol
        outcome, msg = cl.classify(r.completed, r.failure_message(), r.warnings(), drift, allowed, [])
        label = m.label(h or None, h_lim)
        rows.append(SuiteRow(case.name, label, outcome, drift, allowed, msg, r.steps, r.rejected, r.f_evals,
                             r.jac_evals, r.stiffness_detected, r.wall,
                             {"drift_over_tol": drift / m.tol if m.tol else float("nan"), "E0": E0}))
        curves.append((label, r.t, (E - E0) / scale))
    if plots:
        from .report import plot_energy

        plot_energy(ctx.out / f"{case.name}.png", case, curves)
    return rows


def _thesis_case(ctx: Context, case: Case, methods, plots: bool) -> list:
    from .cases import puma_arm
    from .thesis import oscillator_checks, run_on_arm

    rows = []
    for what, measured, closed, rtol in oscillator_checks():
        rel = abs(measured - closed) / closed
        rows.append(SuiteRow(case.name, "thesis: " + what, "reproduced" if rel <= rtol else "MISMATCH",
                             rel, rtol, f"measured {measured:.10f}, closed form {closed:.10f}"))
    arm = puma_arm()
    model = case.make_model()
    s = setup(model, case.start)
    n = arm.n
    E0 = float(sum(arm.energy(s.x0[:n], s.x0[n:])))
    scale = sum(abs(e) for e in arm.energy(s.x0[:n], s.x0[n:]))
    curves = []
    for h in (1e-2, 1e-3):
        ts, qs, vs = run_on_arm(arm, s.x0[:n], s.x0[n:], h, case.stop)
        E = _energy(arm, qs, vs)
        drift = float(np.max(np.abs(E - E0)) / scale)
        grows = len(ts) < round(case.stop / h) + 1 or E[-1] - E0 > 0
        rows.append(SuiteRow(case.name, f"thesis: h {h:g} on the free PUMA",
                             "reproduced" if grows else "MISMATCH", drift, 0.0,
                             f"energy {'grows' if grows else 'does not grow'}: E(T) - E0 = {E[-1] - E0:.3g} J "
                             f"(relative drift {drift:.2e}) -- the divergence the thesis saw"))
        curves.append((f"thesis h {h:g}", ts, (E - E0) / scale))
    fmu = ctx.fmu(case, model)
    names = [f"q[{i}]" for i in range(1, n + 1)] + [f"qd[{i}]" for i in range(1, n + 1)]
    for m in methods:
        r = run(fmu, m, case.start, case.stop, case.H, names)
        E = _energy(arm, r.values[:, :n], r.values[:, n:])
        drift = float(np.max(np.abs(E - E0)) / scale)
        allowed = 1e3 * m.tol
        outcome, msg = cl.classify(r.completed, r.failure_message(), r.warnings(), drift, allowed, [])
        rows.append(SuiteRow(case.name, m.label(), outcome, drift, allowed,
                             msg or f"relative energy drift {drift:.2e}: the growth is gone", r.steps, r.rejected,
                             r.f_evals, r.jac_evals, r.stiffness_detected, r.wall))
        curves.append((m.label(), r.t, (E - E0) / scale))
    if plots:
        from .report import plot_energy

        plot_energy(ctx.out / f"{case.name}.png", case, curves)
    return rows


RUNNERS = {"trajectory": _trajectory_case, "energy": _energy_case, "thesis": _thesis_case}


def run_suite(names: Optional[Sequence[str]] = None, quick: bool = False, out="suite_out", plots: bool = True,
              log: Callable = print, cases: Optional[Sequence[Case]] = None, repeats: int = 1) -> list:
    """Run the named cases (default: all, or the quick subset) and write
    ``out/suite.csv`` and ``out/<case>.png``; returns the rows.

    ``quick`` also runs each case with its shorter list of methods;
    ``repeats``: runs per trajectory-case setting, the median wall time is
    reported (the outcome is that of the first, runs are deterministic).
    """
    from .report import print_table, summary, write_csv

    out = Path(out).resolve()  # fmpy hands the FMUs a file: URI of their folder, which must be absolute
    ctx = Context(out, log, repeats)
    if cases is None:
        chosen = [get_case(n) for n in names] if names else [c for c in CASES if c.quick or not quick]
    else:
        chosen = list(cases)
    rows = []
    for case in chosen:
        log(f"case {case.name}: {case.title}")
        methods = case.quick_methods if quick else case.methods
        rows += RUNNERS[case.kind](ctx, case, methods, plots)
    write_csv(out / "suite.csv", rows)
    print_table(rows, log)
    summary(rows, log, GOAL)
    return rows
