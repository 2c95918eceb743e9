"""The divergence monitor: is the coupling itself amplifying errors?

The master hands it every accepted macro step's interface defect d = U_{n+1} - P(t_{n+1}) (what the
FMUs were told their inputs would be against what they were) and the coupled values U_{n+1}.  On
blocks of ``WINDOW`` steps it looks for the signatures of an unstable coupling, before any value
overflows: growth of the defect by >= 30x while it is as large as the signal, jumps larger than a
coupling's own recent peak, a bounded limit cycle that does not decay, geometric growth step to step,
values beyond 1e8 x their scale.  What it cannot see: a coupling error that drives the system off
smoothly, without a growing oscillation at the interface (see the reliability estimate).
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from .results import FailureReport

WINDOW = 5  # macro steps per block of the monitor

PEAK_DECAY = 0.995  # per macro step: the peak magnitude forgets over ~200 steps
REST = 1e-6  # coupled signals below this fraction of their nominal scale count as at rest (no growth from noise)
GROWN = 1e3  # coupled values this many times their initial scale (or nominal) count as grown
SUSTAINED = 20  # windows (100 macro steps) of a defect that neither decays nor shrinks against the signal
ENVELOPE = 6  # windows (of 5 macro steps) in the defect's envelope: longer than an oscillation period


class _Window:
    """One window of win_len macro steps, with what the criteria need kept incrementally (O(1) per window)."""

    __slots__ = ("d", "s", "rel", "env", "run", "first_moving", "n_moving", "sustained", "jumps")

    def __getitem__(self, i):  # (defect, signal, relative defect), as a tuple
        return (self.d, self.s, self.rel)[i]


def _push_window(windows, d, s, rel) -> None:
    w = _Window()
    w.d, w.s, w.rel = d, s, rel
    # envelope: the largest defect of the last ENVELOPE windows (longer than an oscillation period)
    w.env = max([d] + [x.d for x in windows[-(ENVELOPE - 1):]]) if ENVELOPE > 1 else d
    # moving: the defect itself is above rest (1e-3 of the coupling's scale); at rest it is round-off,
    # and growth measured from round-off means nothing
    moving = d >= 1e3 * REST
    if windows and w.env >= windows[-1].env:
        p = windows[-1]
        w.run = p.run + 1
        w.first_moving = p.first_moving if p.first_moving is not None else (w if moving else None)
        w.n_moving = p.n_moving + (1 if moving else 0)
    else:
        w.run = 0
        w.first_moving = w if moving else None
        w.n_moving = 1 if moving else 0
    ok = rel >= 0.1 and moving
    w.sustained = (windows[-1].sustained + 1 if windows else 1) if ok else 0
    w.jumps = (windows[-1].jumps + 1 if windows else 1) if (rel >= 1.0 and moving) else 0
    windows.append(w)
    if len(windows) > 4 * SUSTAINED:  # keep the list short; the criteria look back at most SUSTAINED
        del windows[: len(windows) - 2 * SUSTAINED]


def _run_length(windows) -> int:
    """Number of windows over which the defect's envelope has not decreased, ending now."""
    return windows[-1].run if windows else 0


def _diverging(windows) -> float:
    """Growth factor if the coupling diverges, else 0.

    Growth: over a run of windows in which the defect's envelope never decreased (>= 6 of them with the
    signals above rest), the defect grew >= 30x and stays >= 0.2 of its coupling's recent peak (and that
    relative size is not shrinking -- a stable scheme on a ramp from rest also grows, but its defect falls
    behind the signal).  Sustained: a growth that a nonlinearity (valve flow, rails) has bounded, a limit
    cycle whose relative defect stays >= 0.1 over SUSTAINED windows without the envelope halving.
    """
    last = windows[-1]
    first = last.first_moving
    if first is not None and last.n_moving >= 6:
        growth = max(last.d, windows[-2].d) / first.d
        if growth >= 30.0 and last.rel >= 0.2 and last.rel >= 0.5 * first.rel:
            return growth
    # jumps: in 3 windows running, with the envelope not falling, an interface value moved by more than
    # its own recent peak within one macro step (a motion from rest does so in its first window at most)
    if last.jumps >= 3 and last.run >= 2:
        return last.env / max(windows[-1 - min(last.run, len(windows) - 1)].env, REST)
    if last.sustained >= SUSTAINED and len(windows) > SUSTAINED:
        then = windows[-1 - SUSTAINED].env
        if last.env >= 0.5 * then:
            return last.env / max(then, REST)
    return 0.0


def _growing(windows) -> bool:
    return bool(windows) and windows[-1].run >= 2 and windows[-1].rel >= 0.1


def _halves(recent):
    r = list(recent)
    h = len(r) // 2
    return r[:h], r[h:]


def _growing_steps(recent) -> bool:
    """The defect of the latest macro steps is >= 10x that of the ones before and a sizeable part of the signal."""
    if len(recent) < 4:
        return False
    a, b = _halves(recent)
    top = max(b, key=lambda x: x[0])
    return top[0] >= 10 * max(max(x[0] for x in a), 1e-300) and top[2] >= 0.1


def _explosive(recent) -> bool:
    """The coupled signals grew >= 4x on each of the last 4 macro steps, with a defect as large as half the
    signal: geometric growth that no polynomial ramp from rest shows (t^5 grows 3.05x from its 4th to 5th
    step), so the coupling itself amplifies.  (A physically unstable system would be flagged too: switch
    detection off for it.)"""
    if len(recent) < 5:
        return False
    r = list(recent)[-5:]
    return (r[0][1] > 0 and all(b[1] >= 4 * a[1] for a, b in zip(r, r[1:])) and r[-1][2] >= 0.5
            and r[-1][1] >= 1e-3)  # above round-off: signals are scaled by their nominal values


class DivergenceMonitor:
    """Watches the interface of one run (see the module docstring).  ``observe`` per accepted step;
    ``growing()`` tells whether the defect was growing when an FMU failed."""

    def __init__(self, labels, scale0, U0, advice, physics=()):
        nu = len(labels)
        self.labels = labels
        self.scale0 = scale0  # each coupling's initial magnitude or nominal
        self.advice = advice  # what to do about a coupling above its stability limit (depends on the scheme)
        self.physics = tuple(physics)  # the system's own unstable modes at rest (a runaway no step cures)
        self.what = "the system diverges" if self.physics else "the coupling diverges"
        self.windows = []
        self.count = 0
        self.D = np.zeros((WINDOW, nu))  # the block's defects, one row per macro step
        self.U = np.zeros((WINDOW, nu))  # ... and coupled values
        self.recent = deque(maxlen=8)  # (defect, signal, relative defect) of the last macro steps
        self.peak = np.abs(U0).copy()  # slowly forgetting peak |U| per coupling
        self.flat = np.arange(WINDOW) * nu  # row starts in a flattened block
        self.nu = nu
        self.level = 0.0
        self.decay = PEAK_DECAY ** WINDOW  # the peak's forgetting over one block
        self.rest = REST * scale0  # below this a coupling counts as at rest

    def observe(self, t, H, d, U):
        """One accepted macro step (defect d, values U); a FailureReport once the coupling diverges."""
        self.D[self.count] = d
        self.U[self.count] = U
        self.count += 1
        if self.count < WINDOW:
            return None
        self.count = 0
        return self._check(t, H, self.D, self.U)

    def growing(self) -> bool:
        return _growing(self.windows) or _growing_steps(self.recent)

    def _stability_limit(self, H) -> str:
        if self.physics:
            return (f"physically unstable, not a coupling error: {self.physics[0].split(': the system')[0]}; "
                    f"it runs away from rest whatever the macro step or scheme")
        return f"H = {H:.4g} s is above this scheme's stability limit: {self.advice}"

    def _check(self, t, H, D, U):
        """Divergence check on a block of accepted macro steps (defects D, values U: (WINDOW, nu))."""
        scale0, peak, windows, recent = self.scale0, self.peak, self.windows, self.recent
        # numpy reductions cost microseconds each and this runs every WINDOW steps of every run (it was a third
        # of the master's overhead): few of them, the per-row figures as Python floats
        A = np.abs(U)
        R = np.abs(D)
        Amax = A.max(axis=0)
        A /= scale0
        sn = A.max(axis=1).tolist()  # each step's largest value, in units of its coupling's scale
        Rs = R / scale0
        jd = Rs.argmax(axis=1)  # each step's coupling with the largest defect
        flat = self.flat + jd
        dn = Rs.ravel().take(flat).tolist()  # ... and that defect, scaled
        if not all(map(math.isfinite, sn + dn)):  # row maxima propagate inf and nan
            j = int(np.argmax(~np.isfinite(U).all(axis=0) | ~np.isfinite(D).all(axis=0)))
            return FailureReport(t, "non-finite", "a coupled value is not finite", coupling=self.labels[j])
        if sn[-1] > 1e8:
            j = int(np.argmax(A[-1]))
            return FailureReport(t, "diverged", f"coupled value grew to {sn[-1]:.3g} x its initial scale",
                                 coupling=self.labels[j])
        # the defect against the same coupling's recent peak magnitude (not its value now, which crosses
        # zero): ~1 when the coupling error is the signal, ~H*omega for a resolved motion
        np.maximum(peak * self.decay, Amax, out=peak)
        rel = (R.ravel().take(flat) / np.maximum(peak.take(jd), self.rest.take(jd))).tolist()
        recent.extend(zip(dn, sn, rel))
        # grown a thousandfold past its scale while the coupling error is as large as the signal: the
        # coupling has pumped energy in (a PUMA under Jacobi/held at 8 ms spins at 1e5 rad/s within 0.1 s
        # and then wanders, bounded, with defects small against those values)
        rel_max = max(rel)
        if sn[-1] > GROWN and rel_max >= 0.5:
            j = int(jd[rel.index(rel_max)])
            return FailureReport(
                t, "diverged",
                f"{self.what}: coupled values grew to {sn[-1]:.3g} x their initial scale with an "
                f"interface defect {rel_max:.2g} x the signal ({self._stability_limit(H)})",
                coupling=self.labels[j])
        if _explosive(recent):
            return FailureReport(
                t, "diverged",
                f"{self.what}: the coupled values grew more than 4x on each of 4 macro steps with a "
                f"defect as large as the signal ({self._stability_limit(H)})",
                coupling=self.labels[int(jd[-1])])
        self.level = max(dn)  # the block's largest scaled defect (the error estimate samples when it rises)
        k = dn.index(max(dn))  # the first largest, as argmax
        _push_window(windows, dn[k], max(sn), rel[k])
        div = _diverging(windows)
        if div:
            return FailureReport(
                t, "diverged",
                f"{self.what}: the interface defect (changed {div:.3g}x over the last "
                f"{len(D) * max(_run_length(windows), min(len(windows), SUSTAINED))} macro steps) "
                f"does not decay and is as large as the signal ({self._stability_limit(H)})",
                coupling=self.labels[int(jd[k])])
        return None
