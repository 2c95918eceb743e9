"""Reference solutions of hybrid scenes: the monolithic model solved with located events and restarts.

A scene with events (stick-slip friction, backlash, end stops: ``SymbolicModel.events``) is piecewise smooth:
between events an ODE in the current mode, at an event the clauses' event iteration.  Each smooth piece is
solved with scipy's Radau IIA (exact Jacobian of the mode) whose event functions are the indicators; at a
located crossing the state is moved just past it along the flow (where the indicator has changed its
domain, the rule of ``c_runtime/events.c``), the event iteration runs, and the next piece starts there.

The solve is confirmed by a tenfold tighter one; the error estimate per column is the largest difference
between the two at the requested times, except within 1e-6 of the run's length of an event of either solve
(a jump's position, not its size, differs there: those differences are reported as the event times'
difference, ``settings["event_time_difference"]``).  Hybrid references are not cached.
"""
from __future__ import annotations

import time as _time
from typing import Optional, Sequence

import numpy as np

from .errors import CosimError

MAX_EVENTS = 100_000
STORM_GAP = 1e-9  # consecutive events closer than this (times max(1, |t|)) ...
STORM_RUN = 100  # ... this many times: an event storm


def _domains(z) -> np.ndarray:
    return np.asarray(z) > 0


def _crossed(ref, z) -> np.ndarray:
    """Strictly past a crossing from the sides ``ref`` (c_runtime/events.c's rule: from z > 0 to z < 0,
    from z <= 0 to z > 0; exactly 0 after a positive value is not yet past it)."""
    z = np.asarray(z)
    return np.where(ref, z < 0, z > 0)


class _Piecewise:
    """x(t) and the mode d(t) over the pieces of a hybrid solve (the right-hand value at an event time)."""

    def __init__(self):
        self.pieces = []  # (t_start, t_end, OdeSolution or None, state at the end, discrete states)

    def add(self, t0, t1, sol, x_end, d):
        self.pieces.append((t0, t1, sol, np.array(x_end, dtype=float), np.array(d, dtype=float)))

    def _piece(self, times):
        starts = np.array([p[0] for p in self.pieces])
        return np.clip(np.searchsorted(starts, times, side="right") - 1, 0, len(self.pieces) - 1)

    def __call__(self, times) -> tuple:
        """(states (nx, n), the index of each time's piece)"""
        times = np.asarray(times, dtype=float)
        k = self._piece(times)
        out = np.empty((len(self.pieces[0][3]), len(times)))
        for j in np.unique(k):
            sel = k == j
            t0, t1, sol, x_end, _ = self.pieces[j]
            if sol is None or t1 <= t0:
                out[:, sel] = x_end[:, None]
            else:
                out[:, sel] = sol(np.clip(times[sel], t0, t1))
        return out, k

    def mode(self, j) -> np.ndarray:
        return self.pieces[j][4]


def solve_hybrid(ev, t0: float, t1: float, x0, u, rtol: float, atol, use_jac: bool = True) -> tuple:
    """(piecewise dense output, event times, steps) of the hybrid model of ``ev`` (a ModelEvaluator, whose
    discrete states it changes) from (t0, x0) with constant inputs ``u``."""
    from scipy.integrate import solve_ivp

    tick, at = ev.next_tick(t0)
    x = ev.tick_iteration(t0, np.asarray(x0, dtype=float), u, at)
    t = float(t0)
    dense, events, steps, run, last = _Piecewise(), [], 0, 0, None
    nz = len(ev.indicators(t, x, u))
    while t < t1:
        # the domains the trajectory enters here (c_runtime/events.c: a moment later along the flow)
        delta = 1e-10 * max(1.0, abs(t))
        ref = _domains(ev.indicators(t + delta, x + delta * ev.f(t, x, u), u))
        # an indicator at its zero on the wrong side right after an event (the ball re-initialised upwards
        # at h = -1e-13): start the piece a moment later along the flow, on the side it enters, so that the
        # solver's event function does not see that as a crossing
        d = 1e-13 * max(1.0, abs(t))
        for _ in range(60):
            if not np.any(_crossed(ref, ev.indicators(t, x, u))) or d > delta:
                break
            f_here = ev.f(t, x, u)
            t, x = t + d, x + d * f_here
            d *= 2.0
        funcs = []
        for i in range(nz):
            def g(tt, xx, i=i):
                # exactly 0 stays on the side the piece started on: an indicator resting at 0 (a stuck
                # shaft's mode*w) is no root at every step, and a crossing is strictly past 0
                z = ev.indicators(tt, xx, u)[i]
                return z if z != 0.0 else (1e-300 if ref[i] else -1e-300)
            g.terminal = True
            funcs.append(g)
        kw = {"jac": lambda tt, xx: ev.jacobians(tt, xx, u)[0]} if use_jac and ev.model.jacobian is not None else {}
        tick, _ = ev.next_tick(t)
        t_end = min(t1, tick)  # a sample instant is a time event: the piece ends there
        sol = solve_ivp(lambda tt, xx: ev.f(tt, xx, u), (t, t_end), x, method="Radau", rtol=rtol, atol=atol,
                        dense_output=True, events=funcs or None, **kw)
        if sol.status == -1:
            raise CosimError(f"hybrid reference of {ev.model.name}: the solve from t = {t:g} failed: {sol.message}")
        steps += sol.t.size - 1
        if sol.status == 0:  # reached the end of the piece: the stop time, or a sample instant
            dense.add(t, t_end, sol.sol, sol.y[:, -1], ev.discrete)
            _, clocks = ev.next_tick(t_end)
            if t_end >= t1 and not clocks:
                break
            # a sample instant: known beforehand, not a located event (the error estimate masks neither it
            # nor its neighbourhood, and the event count leaves it out)
            x = ev.tick_iteration(t_end, sol.y[:, -1], u, clocks)
            dense.add(t_end, t_end, None, x, ev.discrete)
            t = t_end
            if t_end >= t1:  # a sample instant at the stop time is taken, as an FMU's last step takes it
                break
            continue
        hit = [i for i in range(nz) if len(sol.t_events[i])]
        te = float(min(sol.t_events[i][0] for i in hit))
        xe = np.array(sol.sol(te))
        dense.add(t, te, sol.sol, xe, ev.discrete)
        # just past the crossing, where the indicator has changed its domain
        d = 1e-13 * max(1.0, abs(te))
        f_e = ev.f(te, xe, u)
        for _ in range(60):
            xp = xe + d * f_e
            if np.any(_crossed(ref, ev.indicators(te + d, xp, u))):
                break
            d *= 2.0
        te, xe = te + d, xp
        run = run + 1 if last is not None and te - last <= STORM_GAP * max(1.0, abs(te)) else 0
        if run >= STORM_RUN or len(events) >= MAX_EVENTS:
            raise CosimError(f"hybrid reference of {ev.model.name}: event storm at t = {te:.17g} (Zeno behaviour or "
                             f"chattering), the last on indicator {ev.indicator_names[hit[0]]}")
        last = te
        d_before = ev.discrete
        x = ev.event_iteration(te, xe, u)
        # an event is a discontinuity only when the iteration changed something (a crossing whose clauses
        # all stay false, a solver's graze of an indicator, restarts the solve and is not counted)
        if np.any(x != xe) or np.any(ev.discrete != d_before):
            events.append(te)
        dense.add(te, te, None, x, ev.discrete)
        t = te
    return dense, np.array(events), steps


def _values(ev, dense, times, cols, u) -> np.ndarray:
    """The columns at ``times``: states from the pieces, computed outputs in each time's mode."""
    X, k = dense(times)
    out = np.empty((len(times), len(cols)))
    need_y = any(kind == "y" for kind, _ in cols)
    Y = np.empty((len(times), ev.model.ny)) if need_y else None
    if need_y:
        for j in np.unique(k):
            ev.discrete = dense.mode(j)
            for i in np.flatnonzero(k == j):
                Y[i] = ev.g(times[i], X[:, i], u)
    for c, (kind, i) in enumerate(cols):
        out[:, c] = X[i] if kind == "x" else Y[:, i]
    return out


def solve_hybrid_reference(problem, times, rtol: float, parameter_values: Optional[dict], cols,
                           nominal: np.ndarray) -> tuple:
    """The hybrid counterpart of :func:`fmugen.cosim.reference.solve_reference` (see the module doc):
    (values at ``times``, per-column error estimate, settings)."""
    from ..codegen.evaluate import ModelEvaluator

    m = problem.model
    t0, t1 = float(problem.start_time), float(problem.stop_time)
    x0 = np.asarray(problem.x0, dtype=float).ravel()
    u = np.asarray(problem.u, dtype=float).ravel()
    times = np.asarray(times, dtype=float)
    runs = []
    for rt, at in ((rtol, rtol), (max(rtol / 10, 2.3e-14), rtol / 10)):
        ev = ModelEvaluator(m, parameter_values)
        w = _time.perf_counter()
        dense, events, steps = solve_hybrid(ev, t0, t1, x0, u, rt, at * nominal)
        runs.append((_values(ev, dense, times, cols, u), events, steps, _time.perf_counter() - w))
    (v1, ev1, s1, w1), (v2, ev2, s2, w2) = runs
    tight = max(rtol / 10, 2.3e-14)
    if len(ev1) != len(ev2):
        raise CosimError(f"hybrid reference of {m.name}: the confirming solve (rtol {tight:g}) found {len(ev2)} "
                         f"events, the main one {len(ev1)}; no reference is stated")
    near = np.zeros(len(times), dtype=bool)
    for te in np.concatenate([ev1, ev2]):
        near |= np.abs(times - te) <= 1e-6 * (t1 - t0)
    diff = np.abs(v1 - v2)
    err = np.max(diff[~near], axis=0) if np.any(~near) else np.max(diff, axis=0)
    settings = {"method": "Radau with located events and restarts", "rtol": rtol, "atol": f"{rtol:g} x nominal",
                "steps": int(s1), "wall_time": w1, "events": int(len(ev1)),
                "event_times": [float(t) for t in ev1[:1000]],
                "event_time_difference": float(np.max(np.abs(ev1 - ev2))) if len(ev1) else 0.0,
                "confirm": [f"Radau rtol {tight:g}: {s2} steps, {len(ev2)} events, {w2:.3g} s"]}
    return v1, err, settings
