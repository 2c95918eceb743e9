"""Error amplifier (operational amplifier) of the position loop.

Inputs ``theta_ref``, ``theta`` [rad]; output ``u`` [V]; error
e = theta_ref - theta.  Equations (actuator-chain.md, eq. 1):

* ideal, P:   u = K_a e
* ideal, PI:  u = K_a (e + z/T_I),  dz/dt = e            (state z [rad.s])
* real op-amp (single pole, omega_p = 2 pi GBW/A0) wired for closed-loop
  gain K_a:  dv/dt = omega_p (A0 (e_in - v/K_a) - v),  u = v  (state v [V]),
  e_in = e (P) or e + z/T_I (PI)
* rails (option): u -> smooth_clip(u, U_max, eps_U) (C^1, exact below
  U_max - eps_U; see :mod:`fmugen.components.smooth`).

Fidelity options leave out what they do not model: the ideal amplifier has no
state v and no A0/GBW parameters; the P amplifier has no z and no T_I.
"""
from __future__ import annotations

import math

import sympy as sp

from ..codegen.model import SymbolicModel
from .base import parameters, var
from .smooth import smooth_clip

SPECS = (
    ("K_a", "V/rad", "closed-loop gain of the error amplifier"),
    ("T_I", "s", "integral time of the PI amplifier"),
    ("U_max", "V", "output rail of the amplifier"),
    ("eps_U", "V", "width of the smooth band at the rail"),
    ("A0", "1", "open-loop DC gain of the op-amp"),
    ("GBW", "Hz", "gain-bandwidth product of the op-amp"),
)


def amplifier(kind: str = "ideal", control: str = "P", rails: bool = False,
              parameter_set="default", overrides=None, name: str = "amplifier") -> SymbolicModel:
    """Error amplifier as a SymbolicModel (see module docstring).

    >>> m = amplifier(control="PI")
    >>> [v.name for v in m.states], [v.name for v in m.inputs], m.outputs[0].name
    (['z'], ['theta_ref', 'theta'], 'u')
    """
    if kind not in ("ideal", "real"):
        raise ValueError(f"amplifier: kind must be 'ideal' or 'real', not {kind!r}")
    if control not in ("P", "PI"):
        raise ValueError(f"amplifier: control must be 'P' or 'PI', not {control!r}")
    used = ["K_a"] + (["T_I"] if control == "PI" else []) + (["U_max", "eps_U"] if rails else []) \
        + (["A0", "GBW"] if kind == "real" else [])
    p = parameters("amplifier", SPECS, used, parameter_set, overrides)
    s = {k: v.symbol for k, v in p.items()}
    theta_ref = var("theta_ref", "rad", "reference joint angle", start=0.0)
    theta = var("theta", "rad", "measured joint angle", start=0.0)
    e = theta_ref.symbol - theta.symbol
    states, ders = [], []
    e_in = e
    if control == "PI":
        z = var("z", "rad.s", "integral of the position error", start=0.0)
        states.append(z)
        ders.append(e)
        e_in = e + z.symbol / s["T_I"]
    if kind == "real":
        v = var("v", "V", "op-amp output voltage", start=0.0, nominal=1.0)
        states.append(v)
        # 2*pi as a number: strict C99 has no M_PI (sympy prints pi as M_PI)
        omega_p = sp.Float(2 * math.pi) * s["GBW"] / s["A0"]
        ders.append(omega_p * (s["A0"] * (e_in - v.symbol / s["K_a"]) - v.symbol))
        u = v.symbol
    else:
        u = s["K_a"] * e_in
    if rails:
        u = smooth_clip(u, s["U_max"], s["eps_U"])
    out = var("u", "V", "amplifier output (command voltage of the current driver)")
    return SymbolicModel.from_equations(
        name, states, [theta_ref, theta], list(p.values()), ders, [out], [u],
        description=f"error amplifier ({kind} op-amp, {control}{', rails' if rails else ''})",
        provenance="actuator-chain.md eq. 1; op-amp single-pole model as Modelica.Electrical.Analog.Basic.OpAmpDetailed",
    )
