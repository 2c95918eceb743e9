"""Joint inertia: the rigid load a single actuator drives.

* revolute:  dtheta/dt = w,  J dw/dt = tau - B_m w - tau_load
* prismatic: ds/dt = v,      M dv/dt = F - B_p v - F_load

States theta, w (or s, v) are also outputs (no direct feedthrough), as the
arm exposes q, qd.  On the arm, tau is the joint input and tau_load comes
from the arm's dynamics (actuator-chain.md eq. 6).
"""
from __future__ import annotations

from ..codegen.model import SymbolicModel
from .base import parameters, var

SPECS = (
    ("J", "kg.m2", "inertia of joint and load"),
    ("B_m", "N.m.s/rad", "viscous friction of the revolute joint"),
    ("M", "kg", "moving mass of the prismatic joint"),
    ("B_p", "N.s/m", "viscous friction of the prismatic joint"),
)


def joint_inertia(kind: str = "revolute", parameter_set="default", overrides=None,
                  name: str = "joint") -> SymbolicModel:
    """Rigid one-axis load as a SymbolicModel."""
    if kind == "revolute":
        p = parameters("joint_inertia", SPECS, ["J", "B_m"], parameter_set, overrides)
        q = var("theta", "rad", "joint angle", start=0.0, output=True, nominal=1.0)
        qd = var("w", "rad/s", "joint speed", start=0.0, output=True, nominal=1.0)
        f = var("tau", "N.m", "actuator torque", start=0.0)
        fl = var("tau_load", "N.m", "load torque (gravity, arm coupling)", start=0.0)
        m, b = p["J"].symbol, p["B_m"].symbol
    elif kind == "prismatic":
        p = parameters("joint_inertia", SPECS, ["M", "B_p"], parameter_set, overrides)
        q = var("s", "m", "joint position", start=0.0, output=True, nominal=0.1)
        qd = var("v", "m/s", "joint speed", start=0.0, output=True, nominal=0.1)
        f = var("F", "N", "actuator force", start=0.0)
        fl = var("F_load", "N", "load force", start=0.0)
        m, b = p["M"].symbol, p["B_p"].symbol
    else:
        raise ValueError(f"joint_inertia: kind must be 'revolute' or 'prismatic', not {kind!r}")
    return SymbolicModel.from_equations(
        name, [q, qd], [f, fl], list(p.values()),
        [qd.symbol, (f.symbol - b * qd.symbol - fl.symbol) / m],
        description=f"{kind} joint inertia", provenance="actuator-chain.md eq. 6")
