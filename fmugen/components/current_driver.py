"""Valve current driver (voltage command u [V] -> coil current i [A]).

Equations (actuator-chain.md, eq. 2):

* static:  i = G_i u                                    (no state)
* lag:     di/dt = omega_i (G_i u - i)                  (state i)
* coil:    L di/dt = A_pa (u - R_s i) - (R_c + R_s) i   (state i): a power
  amplifier of gain A_pa driving the coil (L, R_c) with current feedback
  through the sense resistor R_s.  Its static gain is
  A_pa/(A_pa R_s + R_c + R_s) and its bandwidth (A_pa R_s + R_c + R_s)/L;
  the shipped sets choose A_pa, R_s so both equal G_i and omega_i.
"""
from __future__ import annotations

from ..codegen.model import SymbolicModel
from .base import parameters, var

SPECS = (
    ("G_i", "A/V", "transconductance of the current driver"),
    ("omega_i", "rad/s", "bandwidth of the current loop"),
    ("L", "H", "coil inductance"),
    ("R_c", "Ohm", "coil resistance"),
    ("R_s", "Ohm", "current-sense resistance"),
    ("A_pa", "1", "voltage gain of the power amplifier"),
)


def current_driver(kind: str = "lag", parameter_set="default", overrides=None,
                   name: str = "current_driver") -> SymbolicModel:
    """Valve current driver as a SymbolicModel (kind: static | lag | coil)."""
    used = {"static": ["G_i"], "lag": ["G_i", "omega_i"], "coil": ["L", "R_c", "R_s", "A_pa"]}
    if kind not in used:
        raise ValueError(f"current_driver: kind must be one of {', '.join(used)}, not {kind!r}")
    p = parameters("current_driver", SPECS, used[kind], parameter_set, overrides)
    s = {k: v.symbol for k, v in p.items()}
    u = var("u", "V", "command voltage", start=0.0)
    if kind == "static":
        i = var("i", "A", "coil current")
        return SymbolicModel.from_equations(name, [], [u], list(p.values()), [], [i], [s["G_i"] * u.symbol],
                                            description="current driver, static gain",
                                            provenance="actuator-chain.md eq. 2")
    i = var("i", "A", "coil current", start=0.0, output=True, nominal=0.01)
    if kind == "lag":
        der = s["omega_i"] * (s["G_i"] * u.symbol - i.symbol)
    else:
        der = (s["A_pa"] * (u.symbol - s["R_s"] * i.symbol) - (s["R_c"] + s["R_s"]) * i.symbol) / s["L"]
    return SymbolicModel.from_equations(name, [i], [u], list(p.values()), [der],
                                        description=f"current driver, {kind}",
                                        provenance="actuator-chain.md eq. 2")
