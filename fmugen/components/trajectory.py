"""Reference trajectories: explicit functions of the model time ``t``.

Sources have no states and no inputs; their outputs are closed forms in
:data:`fmugen.components.base.TIME` (the ``t`` argument of the generated C
functions).  Phases are sympy ``Piecewise`` in t (printed as C ternaries --
fine for sources, which nothing differentiates with respect to a state).

* :func:`ptp_trajectory` -- point to point with speed and acceleration
  limits, as Modelica RobotR3's KinematicPTP2 for one axis: accelerate with
  qdd_max until qd_max (or half way), cruise, decelerate, hold.  With
  dq = q_end - q_begin: v_p = min(qd_max, sqrt(|dq| qdd_max)),
  T_a = v_p/qdd_max, T_c = |dq|/v_p - T_a, T_e = 2 T_a + T_c.
* :func:`quintic_trajectory` -- q = q_begin + dq (10 s^3 - 15 s^4 + 6 s^5),
  s = (t - t_start)/T_move clamped to [0, 1] (zero speed and acceleration at
  both ends).
* :func:`table_trajectory` -- knots (t_k, y_k): piecewise linear or a
  natural cubic spline, held constant outside the knots; the knots are data
  baked into the model (the thesis fed torques and trajectories as knots).

Outputs q_ref [rad], qd_ref [rad/s], qdd_ref [rad/s2] (names configurable for
tables, e.g. tau_ref [N.m]).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import sympy as sp

from ..codegen.model import SymbolicModel
from .base import TIME, parameters, var

SPECS = (
    ("q_begin", "rad", "start position"),
    ("q_end", "rad", "end position"),
    ("qd_max", "rad/s", "speed limit"),
    ("qdd_max", "rad/s2", "acceleration limit"),
    ("t_start", "s", "start time of the motion"),
    ("T_move", "s", "duration of the quintic motion"),
)

_TINY = sp.Float(1e-300)  # keeps 0/0 out of a zero-length move


def _outs(name="q_ref", unit="rad", desc="joint angle reference"):
    return [var(name, unit, desc), var(f"{name[:-4] if name.endswith('_ref') else name}d_ref"
                                       if name.endswith("_ref") else f"{name}_d", f"{unit}/s",
                                       "first time derivative of " + name),
            var(f"{name[:-4]}dd_ref" if name.endswith("_ref") else f"{name}_dd", f"{unit}/s2",
                "second time derivative of " + name)]


def ptp_trajectory(parameter_set="default", overrides=None, name: str = "trajectory") -> SymbolicModel:
    """Speed- and acceleration-limited point-to-point motion (KinematicPTP2)."""
    p = parameters("trajectory", SPECS, ["q_begin", "q_end", "qd_max", "qdd_max", "t_start"],
                   parameter_set, overrides)
    s = {k: v.symbol for k, v in p.items()}
    dq = s["q_end"] - s["q_begin"]
    adq = sp.Abs(dq)
    sgn = dq / (adq + _TINY)
    vlim = sp.sqrt(adq * s["qdd_max"])
    v_p = (s["qd_max"] + vlim - sp.Abs(s["qd_max"] - vlim)) / 2  # min(qd_max, vlim), branch-free
    T_a = v_p / s["qdd_max"]
    T_c = adq / (v_p + _TINY) - T_a
    T_e = 2 * T_a + T_c
    tau = TIME - s["t_start"]
    a = s["qdd_max"]
    q = sp.Piecewise((s["q_begin"], tau < 0),
                     (s["q_begin"] + sgn * a * tau**2 / 2, tau < T_a),
                     (s["q_begin"] + sgn * v_p * (tau - T_a / 2), tau < T_a + T_c),
                     (s["q_end"] - sgn * a * (T_e - tau) ** 2 / 2, tau < T_e),
                     (s["q_end"], True))
    qd = sp.Piecewise((0, tau < 0), (sgn * a * tau, tau < T_a), (sgn * v_p, tau < T_a + T_c),
                      (sgn * a * (T_e - tau), tau < T_e), (0, True))
    qdd = sp.Piecewise((0, tau < 0), (sgn * a, tau < T_a), (0, tau < T_a + T_c), (-sgn * a, tau < T_e),
                       (0, True))
    return SymbolicModel.from_equations(
        name, [], [], list(p.values()), [], _outs(), [q, qd, qdd],
        description="point-to-point trajectory with speed and acceleration limits",
        provenance="Modelica RobotR3 PathPlanning1 / Blocks.Sources.KinematicPTP2 (one axis)")


def quintic_trajectory(parameter_set="default", overrides=None, name: str = "trajectory") -> SymbolicModel:
    """Quintic (minimum-jerk) rest-to-rest polynomial of duration T_move."""
    p = parameters("trajectory", SPECS, ["q_begin", "q_end", "t_start", "T_move"], parameter_set, overrides)
    s = {k: v.symbol for k, v in p.items()}
    dq = s["q_end"] - s["q_begin"]
    T = s["T_move"]
    sig = (TIME - s["t_start"]) / T
    inside = sp.And(sig >= 0, sig < 1)
    q = sp.Piecewise((s["q_begin"], sig < 0),
                     (s["q_begin"] + dq * (10 * sig**3 - 15 * sig**4 + 6 * sig**5), sig < 1),
                     (s["q_end"], True))
    qd = sp.Piecewise((dq * (30 * sig**2 - 60 * sig**3 + 30 * sig**4) / T, inside), (0, True))
    qdd = sp.Piecewise((dq * (60 * sig - 180 * sig**2 + 120 * sig**3) / T**2, inside), (0, True))
    return SymbolicModel.from_equations(
        name, [], [], list(p.values()), [], _outs(), [q, qd, qdd],
        description="quintic rest-to-rest trajectory", provenance="minimum-jerk polynomial")


def table_trajectory(times: Sequence[float], values: Sequence[float], kind: str = "linear",
                     output: str = "q_ref", unit: str = "rad", name: str = "table") -> SymbolicModel:
    """Knot table as a source (held constant outside [t_0, t_n]).

    ``kind="linear"`` gives the value and its (piecewise constant) first
    derivative; ``kind="cubic"`` a natural cubic spline with first and second
    derivatives.  Outputs ``output`` and its derivatives (``qd_ref``,
    ``qdd_ref`` for ``q_ref``; ``<output>_d``, ``<output>_dd`` otherwise).
    """
    t = np.asarray(times, dtype=float)
    y = np.asarray(values, dtype=float)
    if t.ndim != 1 or t.shape != y.shape or len(t) < 2:
        raise ValueError(f"{name}: need at least two knots, times and values of equal length "
                         f"(got {t.shape} and {y.shape})")
    if not np.all(np.isfinite(t)) or not np.all(np.isfinite(y)):
        raise ValueError(f"{name}: knot times and values must be finite")
    if np.any(np.diff(t) <= 0):
        raise ValueError(f"{name}: knot times must increase strictly")
    if kind not in ("linear", "cubic"):
        raise ValueError(f"{name}: kind must be 'linear' or 'cubic', not {kind!r}")
    T = TIME
    F = lambda v: sp.Float(float(v))  # noqa: E731
    pieces_y, pieces_d, pieces_dd = [(F(y[0]), T < F(t[0]))], [(0, T < F(t[0]))], [(0, T < F(t[0]))]
    if kind == "linear":
        for k in range(len(t) - 1):
            slope = (y[k + 1] - y[k]) / (t[k + 1] - t[k])
            cond = T < F(t[k + 1])
            pieces_y.append((F(y[k]) + F(slope) * (T - F(t[k])), cond))
            pieces_d.append((F(slope), cond))
    else:
        from scipy.interpolate import CubicSpline

        cs = CubicSpline(t, y, bc_type="natural")
        for k in range(len(t) - 1):
            c3, c2, c1, c0 = (F(c) for c in cs.c[:, k])
            d = T - F(t[k])
            cond = T < F(t[k + 1])
            pieces_y.append((c0 + d * (c1 + d * (c2 + d * c3)), cond))
            pieces_d.append((c1 + d * (2 * c2 + 3 * c3 * d), cond))
            pieces_dd.append((2 * c2 + 6 * c3 * d, cond))
    pieces_y.append((F(y[-1]), True))
    pieces_d.append((0, True))
    pieces_dd.append((0, True))
    outs = _outs(output, unit, f"tabulated {output}")
    exprs = [sp.Piecewise(*pieces_y), sp.Piecewise(*pieces_d)]
    if kind == "cubic":
        exprs.append(sp.Piecewise(*pieces_dd))
    else:
        outs = outs[:2]
    return SymbolicModel.from_equations(
        name, [], [], [], [], outs, exprs,
        description=f"{kind} knot table of {output} ({len(t)} knots)",
        provenance="knot tables as fed to the McGalliard (1984) simulation")
