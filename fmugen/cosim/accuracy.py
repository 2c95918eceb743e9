"""How accurate a co-simulation can be and is: the coupling tolerance the FMUs' own accuracy allows.

**Coupling tolerance** (``coupling_tol`` of the iterated schemes).  An iteration of the macro step stops when
the residual R = G(V) - V is below ``coupling_tol`` relative to the coupled signals.  G is what the FMUs
compute over the step with their internal solvers, so it carries their local errors, ~ rtol relative to the
signals, and changes by that much whenever a guess moves the solvers' adaptive step sequence: a residual
below that level cannot be reached (Newton at 1e-8 on FMUs integrating at rtol 1e-8 stalled at 2.3x the
tolerance on the PUMA at rest).  The default is therefore ``COUPLING_TOL_FACTOR`` x the largest internal
rtol of the FMUs that integrate adaptively (their ``solver.rtol``, else the FMU's default experiment
tolerance); FMUs that integrate with fixed steps (fmugen's RK4) or declare no tolerance leave the old
default, 1e-8.
"""
from __future__ import annotations

import math

import numpy as np

COUPLING_TOL_FACTOR = 10.0  # the residual sits at a few x rtol (2.3x measured): a decade above it
COUPLING_TOL_FIXED = 1e-8  # without a stated internal tolerance
FIXED_STEP_METHODS = {3}  # fmugen's solver.method of fixed-step solvers (RK4): no rtol applies


def _number(x):
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if v > 0 else None


def internal_rtol(unit):
    """The relative tolerance an FMU integrates to (None: fixed steps, or not stated)."""
    if unit.kind == "me":  # integrated by the master's own Radau block (rtol 1e-10)
        from .me_block import ME_RTOL

        return ME_RTOL
    sv = unit.unit.start_values
    var = unit.variables
    method = sv.get("solver.method", getattr(var.get("solver.method"), "start", None))
    if _number(method) is not None and int(float(method)) in FIXED_STEP_METHODS:
        return None
    rtol = _number(sv.get("solver.rtol", getattr(var.get("solver.rtol"), "start", None)))
    if rtol is None:
        de = getattr(unit.md, "defaultExperiment", None)
        rtol = _number(getattr(de, "tolerance", None)) if de is not None else None
    return rtol


def coupling_tolerance(units) -> tuple:
    """(default coupling tolerance, the sentence that says where it comes from)."""
    rtols = {u.name: internal_rtol(u) for u in units}
    known = {k: v for k, v in rtols.items() if v is not None}
    if not known:
        return COUPLING_TOL_FIXED, f"{COUPLING_TOL_FIXED:g} (no FMU states an adaptive internal tolerance)"
    name = max(known, key=known.get)
    tol = COUPLING_TOL_FACTOR * known[name]
    return tol, (f"{tol:.3g} = {COUPLING_TOL_FACTOR:g} x the largest internal rtol of the FMUs "
                 f"({known[name]:.3g}, FMU {name!r})")


# -- the a-posteriori estimate of the coupling error -----------------------------------------------------
#
# Step halving (Richardson) over windows on a sample of communication points.  Every ``every`` macro steps
# the master saves the FMUs at t_n, runs the same scheme and extrapolation over the next ``window`` macro
# steps with H/2 from there (a *shadow* with its own input history), notes the recorded outputs at the
# window's end, restores the FMUs (and its buffers) and goes on: the run itself is bit for bit the run
# without the estimate.  When the run reaches the window's end, (y_H - y_H/2) 2^p / (2^p - 1) (p: the
# scheme's order) estimates the coupling error the run gathered over the window, and each window stands for
# the steps since the previous one.  The estimate of a column's coupling error is the sum over the run's
# windows: the error the run would have if those errors added up without decaying (for integrated signals,
# joint angles, within 0.07-9x of the measured error on the split rig; for fast, self-correcting signals,
# pressures and velocities, an overestimate).  A window, not one step: a coupling error in a velocity
# becomes an error in the angle only as it is integrated, which a single step does not see (single-step
# doubling underestimated the angle's error 70-500x).  Halving, not doubling: a shadow at 2H crosses the
# stability limit of a scheme run near it.  The trend is the growth of the window errors over the last half
# of the run (a least-squares exponential fit): a coupling that slowly destabilises the system makes them
# grow without bound, long before the interface defect looks like a divergence.

WINDOW_STEPS = 10  # macro steps a shadow window spans (at most)
SAMPLES = 6  # windows per run at least (short runs)
RISE = 2.0  # a window also when the interface defect has risen this much since the last one
COST = 60  # the shadow windows cost about 1/COST of the run (plus a save and restore per window)
GROWTH = 4.0  # the local error grew this much over the last half of the run: "growing"
NOISE = 100.0  # local errors below NOISE x the FMUs' internal rtol (relative) are solver noise: no trend
# Without a tolerance from the user a run is still not "ok" when the coupling error of one shadow window
# reaches this fraction of the signal's largest value: no digit of the answer is known.  (Jacobi/held on the PUMA at 0.15
# and 0.2 ms diverges early and then levels off -- no growing trend -- with estimates of 26 and 131 rad for
# errors of 1.9 and 4.4 rad; stable runs of the main job's grid stay below 1e-2 of their range.)
NO_DIGIT = 0.5


# the scheme's order of accuracy (local error O(H^(p+1))): held inputs 1, the line 2, the parabola 3
ORDERS = {"hold": 1, "linear": 2, "quadratic": 3, "cubic": 3}


class ErrorEstimate:
    """Accumulates the shadow samples of one run; ``finish`` gives the estimate, the trend and the verdict."""

    def __init__(self, scheme, extrapolation, n_steps, columns, rtol, nominal=None):
        p = ORDERS[extrapolation]
        if scheme == "gauss-seidel" and p > 2:
            p = 2  # a later FMU gets the line to its source's new value
        self.p = p
        # macro steps a shadow window spans (2 x window steps of H/2): fewer in short runs
        self.window = int(max(2, min(WINDOW_STEPS, n_steps // 100)))
        # windows every 2 x COST x window steps (the shadows cost 1/COST of a long run), but at least
        # SAMPLES per run: a drift that starts mid-run must be seen (a short run pays more, up to ~15 %)
        self.every = int(min(COST * 2 * self.window, max(n_steps // SAMPLES, 4 * self.window)))
        # over a window the errors are global: Richardson, e(H) = (y_H - y_H/2) 2^p / (2^p - 1)
        self.div = (2.0 ** p - 1.0) / 2.0 ** p
        self.columns = columns
        # a column's scale is its largest value, but at least its nominal: a signal at rest (a joint
        # without gravity load, 1e-14 N.m) would otherwise make round-off "the whole signal"
        self.nominal = np.ones(len(columns)) if nominal is None else np.asarray(nominal, dtype=float)
        self.rtol = rtol or 0.0
        self.pending = None  # (t, H, shadow outputs, steps still to go)
        self.t, self.local = [], []  # sample times, local error per column (absolute)
        self.gathers = []  # per sample and column: the error grew over the window (True) or settled
        self.mid = None
        self.at = []  # the run's accepted-step count at each sample (each stands for the steps since the last)
        self.next_at = max(1, min(self.every, n_steps // 10))  # the first window early in the run
        self.shadow_steps = 0
        self.level = self.trigger = 0.0  # defect at the last window, and the rise that calls the next

    # (the master calls only ``due`` when its step count reaches ``next_at``, and ``accepted`` while a
    # comparison is pending: nothing per ordinary step)
    def due(self, t, H, stop) -> bool:
        """A shadow window from t now? (two full windows' room left)."""
        return self.pending is None and t + self.window * H < stop - 1e-9 * H

    def active(self, level, n) -> None:
        """The interface defect of the last block (the divergence monitor's): a window now when it rose
        RISE-fold since the last window -- the coupling is at work (a motion starts), which sparse windows
        at fixed intervals would miss."""
        if self.pending is None and level > self.trigger:
            self.next_at = min(self.next_at, n)
            self.level = level

    def started(self, t, H, Ys, n) -> None:
        self.trigger = RISE * self.level
        self.pending = (t, H, Ys, self.window)
        self.shadow_steps += 1
        self.next_at = n + self.every

    def skipped(self, n) -> None:
        """No window now (a failed shadow, or too close to the end)."""
        self.next_at = n + self.every

    def accepted(self, H, Y, n) -> None:
        """After an accepted macro step (n so far) with its recorded outputs, while a comparison is pending."""
        t, Hs, Ys, left = self.pending
        if H != Hs:  # the step changed (adaptive, or the last step): no longer the window's comparison
            self.pending = None
            return
        if left == self.window - self.window // 2 + 1:  # the (window // 2)-th step of the window
            self.mid = np.abs(Ys[0] - Y)  # halfway through the window
        if left > 1:
            self.pending = (t, Hs, Ys, left - 1)
            return
        self.pending = None
        self.t.append(t)
        end = np.abs(Ys[1] - Y)
        self.local.append(end / self.div)
        # does the error gather over the window (integrated signals: it doubles or more from the middle to the
        # end) or settle (fast, self-correcting ones: a pressure behind a stiff spring)?
        self.gathers.append(end >= 1.5 * self.mid)
        self.at.append(n)

    def discard(self) -> None:
        """A step was rolled back: the pending comparison no longer compares the same start."""
        self.pending = None

    def finish(self, values, tol, n):
        """(estimate per column, relative estimate, trend, growth factor, verdict sentence or None)."""
        cols = self.columns
        if not self.local:
            return {}, math.nan, "unknown", math.nan, None
        L = np.array(self.local)  # (samples, columns)
        w = np.diff(np.array([0] + self.at, dtype=float))
        w[-1] += n - self.at[-1]  # the steps after the last sample count with it
        self.est_sum = (L * w[:, None]).sum(axis=0) / self.window
        self.est_max = L.max(axis=0)
        # a column whose error gathered over most windows adds up over the run; one whose error settles
        # within a window is as large as its largest window's
        gathers = np.mean(np.array(self.gathers, dtype=float), axis=0) >= 0.5
        est = np.where(gathers, self.est_sum, self.est_max)
        scale = np.max(np.abs(values), axis=0) if len(values) else np.ones(len(cols))
        scale = np.maximum(scale, self.nominal)
        rel_est = est / scale
        j = int(np.argmax(rel_est))
        estimate = {c: float(e) for c, e in zip(cols, est)}
        rel_local = (L / scale).max(axis=1)
        trend, growth = _trend(np.array(self.t), rel_local, NOISE * self.rtol)
        verdict = None
        if tol is not None and rel_est[j] > tol:
            verdict = (f"estimated coupling error {est[j]:.3g} in {cols[j]} ({rel_est[j]:.3g} of its range) exceeds "
                       f"the tolerance {tol:.3g}")
        elif tol is None and np.max(self.est_max / scale) > NO_DIGIT:
            # judged on the largest error of one window, not on the run's sum: the sum overestimates fast,
            # self-correcting signals (pressures: up to 1000x) and would cry wolf
            k = int(np.argmax(self.est_max / scale))
            verdict = (f"the coupling error over one window reached {self.est_max[k]:.3g} in {cols[k]}, "
                       f"{self.est_max[k] / scale[k]:.3g} of the signal's largest value: no digit of the answer is "
                       f"known (give --tol for a stricter limit)")
        elif trend == "growing":
            verdict = (f"the coupling error grows: its local estimate grew {growth:.3g}x over the last half of the "
                       f"run (a slow instability of the coupled system, or of the coupling)")
        return estimate, float(rel_est[j]), trend, growth, verdict


def _trend(t, e, floor):
    """('growing' | 'steady' | 'decaying' | 'unknown', growth factor) of the local errors e at times t over
    the last half of the run."""
    if len(t) < 6:
        return "unknown", math.nan
    half = t >= t[0] + 0.5 * (t[-1] - t[0])
    tt, ee = t[half], e[half]
    if len(tt) < 4 or tt[-1] <= tt[0]:
        return "unknown", math.nan
    y = np.log(np.maximum(ee, 1e-300))
    slope = np.polyfit(tt, y, 1)[0]
    growth = float(math.exp(min(slope * (tt[-1] - tt[0]), 700.0)))
    if growth >= GROWTH and ee[-1] > floor:
        return "growing", growth
    return ("decaying" if growth < 1.0 / GROWTH else "steady"), growth
