"""The thesis's own integrator and why its simulation diverged (McGalliard
1984, sec. III.C): the acceleration a(q, v) is held over the step and never
iterated,

    q <- q + h v + h^2 a / 2,     v <- v + h a.

On x'' = -w^2 x - 2 zeta w x' the step is linear, (x, v) <- G (x, v), with

    G = [[1 - (hw)^2/2,  h (1 - zeta hw)],
         [-h w^2,        1 - 2 zeta hw]].

Undamped: det G = 1 + (hw)^2/2 and the eigenvalues are a complex pair for
hw < 4, so the spectral radius is sqrt(1 + (hw)^2/2) > 1 for every h: the
amplitude grows whatever the step.  With damping, det G = 1 + (hw)^2/2 -
2 zeta hw < 1 exactly when hw < 4 zeta: the scheme is stable only below that
step.  This module checks both against the closed forms, with the spectral
radius measured from the scheme itself, and runs the scheme on the free PUMA
next to the FMU's error-controlled solvers.
"""
from __future__ import annotations

import numpy as np


def thesis_step(a, q, v, h):
    """One step of the thesis scheme for q'' = a(q, v) (any shapes)."""
    acc = a(q, v)
    return q + h * v + 0.5 * h * h * acc, v + h * acc


def amplification_matrix(w: float, zeta: float, h: float) -> np.ndarray:
    """G of the scheme on the oscillator, measured by stepping the unit vectors
    (not the closed form above)."""
    a = lambda q, v: -w * w * q - 2 * zeta * w * v  # noqa: E731
    cols = [thesis_step(a, *e, h) for e in ((1.0, 0.0), (0.0, 1.0))]
    return np.array(cols).T


def spectral_radius(w: float, zeta: float, h: float) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(amplification_matrix(w, zeta, h)))))


def growth_per_step(w: float, zeta: float, h: float, steps: int = 4000) -> float:
    """Observed amplitude growth per step over many steps (the spectral radius
    as the scheme shows it: (|z_n| / |z_0|)^(1/n), energy norm)."""
    a = lambda q, v: -w * w * q - 2 * zeta * w * v  # noqa: E731
    q, v = 1.0 / w, 0.0  # unit energy norm
    log_growth = 0.0
    for _ in range(steps):  # renormalised every step: no overflow at large h w
        q, v = thesis_step(a, q, v, h)
        e = np.hypot(w * q, v)
        log_growth += np.log(e)
        q, v = q / e, v / e
    return float(np.exp(log_growth / steps))


def undamped_radius(hw: float) -> float:
    """Closed form: sqrt(1 + (hw)^2/2)."""
    return float(np.sqrt(1 + hw * hw / 2))


def damped_stability_limit(zeta: float) -> float:
    """Closed form: the scheme is stable on a damped mode only for hw < 4 zeta."""
    return 4.0 * zeta


def oscillator_checks(w: float = 10.0) -> list:
    """(what, measured, closed form, relative tolerance) rows: the undamped
    growth and the damped limit.  The growth observed over a finite run
    differs from the spectral radius by O(1/steps) (the amplitude oscillates
    within a period), hence its looser tolerance."""
    rows = []
    for hw in (0.05, 0.2, 1.0):
        h = hw / w
        rows.append((f"undamped hw={hw:g} radius", spectral_radius(w, 0.0, h), undamped_radius(hw), 1e-12))
        rows.append((f"undamped hw={hw:g} growth/step", growth_per_step(w, 0.0, h), undamped_radius(hw), 1e-4))
    for zeta in (0.05, 0.2):
        lim = damped_stability_limit(zeta)
        for f in (0.9, 1.1):
            h = f * lim / w
            rho = spectral_radius(w, zeta, h)
            rows.append((f"zeta={zeta:g} hw={f:g}x4zeta radius {'<' if rho < 1 else '>'} 1", rho,
                         float(np.sqrt(1 + (h * w) ** 2 / 2 - 2 * zeta * h * w)), 1e-12))
    return rows


def run_on_arm(arm, q0, qd0, h: float, stop: float):
    """The scheme on the free arm (tau = 0); returns times, q, qd (stops at a blow-up)."""
    n = arm.n
    tau = np.zeros(n)
    a = lambda q, v: arm.forward_dynamics(q, v, tau)  # noqa: E731
    q, v = np.array(q0, float), np.array(qd0, float)
    ts, qs, vs = [0.0], [q.copy()], [v.copy()]
    for k in range(int(round(stop / h))):
        q, v = thesis_step(a, q, v, h)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            break
        ts.append((k + 1) * h)
        qs.append(q.copy())
        vs.append(v.copy())
    return np.array(ts), np.array(qs), np.array(vs)
