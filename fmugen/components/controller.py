"""Cascaded P-position / PI-speed controller of one axis (RobotR3).

Anchor: Modelica.Mechanics.MultiBody.Examples.Systems.RobotR3.Components.
Controller (kp = 10, ks = 1, Ts = 0.01 s).  References are joint-side,
measurements motor-side, hence the gear ratio:

  w_ref = ratio qd_ref + k_p (ratio q_ref - phi_m)        (P position loop)
  e_w   = w_ref - w_m
  i_ref = k_s (x + e_w),   dx/dt = e_w / T_s               (PI speed loop,
                                           as Modelica.Blocks.Continuous.PI)

Inputs q_ref [rad], qd_ref [rad/s], phi_m [rad], w_m [rad/s]; state x
[rad/s]; output i_ref [A].  ``speed_loop="P"`` leaves out the integrator.
"""
from __future__ import annotations

from ..codegen.model import SymbolicModel
from .base import parameters, var

SPECS = (
    ("k_p", "1/s", "gain of the position controller"),
    ("k_s", "A.s/rad", "gain of the speed controller"),
    ("T_s", "s", "integral time of the speed controller"),
    ("ratio", "1", "gear ratio (motor angle / joint angle)"),
)


def controller(speed_loop: str = "PI", parameter_set="default", overrides=None,
               name: str = "controller") -> SymbolicModel:
    """RobotR3-style cascade controller as a SymbolicModel."""
    if speed_loop not in ("P", "PI"):
        raise ValueError(f"controller: speed_loop must be 'P' or 'PI', not {speed_loop!r}")
    used = ["k_p", "k_s", "ratio"] + (["T_s"] if speed_loop == "PI" else [])
    p = parameters("controller", SPECS, used, parameter_set, overrides)
    s = {k: v.symbol for k, v in p.items()}
    q_ref = var("q_ref", "rad", "joint angle reference", start=0.0)
    qd_ref = var("qd_ref", "rad/s", "joint speed reference", start=0.0)
    phi_m = var("phi_m", "rad", "measured motor angle", start=0.0)
    w_m = var("w_m", "rad/s", "measured motor speed", start=0.0)
    w_ref = s["ratio"] * qd_ref.symbol + s["k_p"] * (s["ratio"] * q_ref.symbol - phi_m.symbol)
    e_w = w_ref - w_m.symbol
    states, ders = [], []
    if speed_loop == "PI":
        x = var("x", "rad/s", "state of the speed integrator", start=0.0)
        states, ders = [x], [e_w / s["T_s"]]
        i_ref = s["k_s"] * (x.symbol + e_w)
    else:
        i_ref = s["k_s"] * e_w
    return SymbolicModel.from_equations(
        name, states, [q_ref, qd_ref, phi_m, w_m], list(p.values()), ders,
        [var("i_ref", "A", "motor current reference")], [i_ref],
        description=f"cascade controller, P position / {speed_loop} speed",
        provenance="Modelica RobotR3 Components.Controller")
