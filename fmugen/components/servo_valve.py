"""Two-stage servo valve: spool dynamics and the orifice flow law.

Input: coil current ``i`` [A] and the pressure(s) the valve meters into;
output: flow(s) and the normalised spool stroke ``x_v`` = x_v/x_v,max [1].
Equations (actuator-chain.md, eqs. 3-4), K_sv = 1/i_rated:

* order 0 (static):   x_v = K_sv i                                  (no state)
* order 1:            dx_v/dt = omega_v (K_sv i - x_v)               (x_v)
* order 2:            dx_v/dt = v_v,
                      dv_v/dt = omega_v^2 (K_sv i - x_v) - 2 zeta_v omega_v v_v
* stroke limit (option): the opening used by the flow law is
  smooth_clip(x_v, 1, eps_x) (C^1; exact for |x_v| <= 1 - eps_x).

Flow of a matched, critical-centre 4-way valve with tank pressure P_T = 0,
K_q0 = Q_N sqrt(P_s/dp_N), x+ = (x + |x|)/2, x- = (x - |x|)/2:

* flow="load_pressure" (input P_L, output Q_L [m3/s]):
  Q_L = K_q0/sqrt(P_s) [x+ r(P_s - P_L) + x- r(P_s + P_L)] - K_c0 P_L,
  i.e. K_q0 x sqrt(1 - sgn(x) P_L/P_s) - K_c0 P_L written without sgn, with
  r = :func:`~fmugen.components.smooth.regroot` (width dp_reg) so the
  Jacobian stays finite when |P_L| -> P_s.
* flow="chambers" (inputs P_A, P_B, outputs Q_A into chamber A and Q_B out of
  chamber B), per-edge coefficient k = K_q0 sqrt(2/P_s):
  Q_A = k [x+ r(P_s - P_A) + x- r(P_A - P_T)] - K_c0 (P_A - P_B),
  Q_B = k [x+ r(P_B - P_T) + x- r(P_s - P_B)] - K_c0 (P_A - P_B);
  with P_A + P_B = P_s and P_T = 0 the mean (Q_A + Q_B)/2 is the Q_L above.
"""
from __future__ import annotations

import sympy as sp

from ..codegen.model import SymbolicModel
from .base import parameters, var
from .smooth import regroot, smooth_clip

SPECS = (
    ("omega_v", "rad/s", "natural frequency of the spool"),
    ("zeta_v", "1", "damping ratio of the spool"),
    ("i_rated", "A", "rated current (full stroke)"),
    ("P_s", "Pa", "supply pressure"),
    ("P_T", "Pa", "tank pressure"),
    ("Q_N", "m3/s", "rated flow at the rated pressure drop"),
    ("dp_N", "Pa", "pressure drop at which Q_N is rated"),
    ("K_c0", "m3/(s.Pa)", "flow-pressure coefficient at null (leakage)"),
    ("dp_reg", "Pa", "regularisation band of the orifice square root"),
    ("eps_x", "1", "width of the smooth band at the stroke limit"),
)


def servo_valve(order: int = 2, stroke_limit: bool = False, flow: str = "load_pressure",
                parameter_set="default", overrides=None, name: str = "servo_valve") -> SymbolicModel:
    """Servo valve as a SymbolicModel (see module docstring)."""
    if order not in (0, 1, 2):
        raise ValueError(f"servo_valve: order must be 0, 1 or 2, not {order!r}")
    if flow not in ("load_pressure", "chambers"):
        raise ValueError(f"servo_valve: flow must be 'load_pressure' or 'chambers', not {flow!r}")
    used = ["i_rated", "P_s", "Q_N", "dp_N", "K_c0", "dp_reg"]
    used += ["omega_v"] if order >= 1 else []
    used += ["zeta_v"] if order == 2 else []
    used += ["eps_x"] if stroke_limit else []
    used += ["P_T"] if flow == "chambers" else []
    p = parameters("servo_valve", SPECS, used, parameter_set, overrides)
    s = {k: v.symbol for k, v in p.items()}
    i = var("i", "A", "coil current", start=0.0)
    K_sv = 1 / s["i_rated"]
    states, ders, outs, out_exprs = [], [], [], []
    if order == 0:
        x = K_sv * i.symbol
        # |x_v| <= 1: the spool cannot move beyond its stroke (validity range)
        outs.append(var("x_v", "1", "normalised spool stroke", min=-1.0, max=1.0))
        out_exprs.append(x)
    else:
        xv = var("x_v", "1", "normalised spool stroke", start=0.0, output=True, nominal=0.1, min=-1.0, max=1.0)
        states.append(xv)
        x = xv.symbol
        if order == 1:
            ders.append(s["omega_v"] * (K_sv * i.symbol - x))
        else:
            vv = var("v_v", "1/s", "normalised spool velocity", start=0.0, nominal=100.0)
            states.append(vv)
            ders += [vv.symbol,
                     s["omega_v"] ** 2 * (K_sv * i.symbol - x) - 2 * s["zeta_v"] * s["omega_v"] * vv.symbol]
    if stroke_limit:
        x = smooth_clip(x, 1, s["eps_x"])
    x_pos = (x + sp.Abs(x)) / 2
    x_neg = (x - sp.Abs(x)) / 2
    K_q0 = s["Q_N"] * sp.sqrt(s["P_s"] / s["dp_N"])
    r = lambda dp: regroot(dp, s["dp_reg"])  # noqa: E731
    if flow == "load_pressure":
        P_L = var("P_L", "Pa", "load pressure P_A - P_B", start=0.0)
        inputs = [i, P_L]
        Q = K_q0 / sp.sqrt(s["P_s"]) * (x_pos * r(s["P_s"] - P_L.symbol) + x_neg * r(s["P_s"] + P_L.symbol)) \
            - s["K_c0"] * P_L.symbol
        outs.append(var("Q_L", "m3/s", "load flow"))
        out_exprs.append(Q)
    else:
        P_A = var("P_A", "Pa", "pressure of chamber A", start=p["P_s"].start / 2)
        P_B = var("P_B", "Pa", "pressure of chamber B", start=p["P_s"].start / 2)
        inputs = [i, P_A, P_B]
        k = K_q0 * sp.sqrt(2 / s["P_s"])
        leak = s["K_c0"] * (P_A.symbol - P_B.symbol)
        QA = k * (x_pos * r(s["P_s"] - P_A.symbol) + x_neg * r(P_A.symbol - s["P_T"])) - leak
        QB = k * (x_pos * r(P_B.symbol - s["P_T"]) + x_neg * r(s["P_s"] - P_B.symbol)) - leak
        outs += [var("Q_A", "m3/s", "flow into chamber A"), var("Q_B", "m3/s", "flow out of chamber B")]
        out_exprs += [QA, QB]
    return SymbolicModel.from_equations(
        name, states, inputs, list(p.values()), ders, outs, out_exprs,
        description=f"servo valve, spool order {order}, {flow} flow{', stroke limit' if stroke_limit else ''}",
        provenance="actuator-chain.md eqs. 3-4 (Merritt 1967 ch. 5; Thayer, Moog TB 103)")
