"""Hydraulic actuator: chamber pressures and output torque/force.

Rotary motor (``kind="rotary"``, displacement D_m [m3/rad], inputs
theta/w, output torque ``tau`` [N.m]) or linear cylinder (``kind="linear"``,
piston area A_p [m2], inputs s/v, output force ``F`` [N]); below, D and the
speed input stand for D_m, w or A_p, v.  Equations (actuator-chain.md, eqs.
5-6):

* form="load_pressure" (input Q_L; state P_L):
  (V_t/(4 beta_e)) dP_L/dt = Q_L - D w - C_tm P_L,      tau = D P_L
* form="two_chamber" (inputs Q_A, Q_B, position; states P_A, P_B):
  V_A = V_t/2 + D theta,  V_B = V_t/2 - D theta,
  (V_A/beta_e) dP_A/dt =  Q_A - D w - C_im (P_A - P_B) - C_em P_A,
  (V_B/beta_e) dP_B/dt = -Q_B + D w + C_im (P_A - P_B) - C_em P_B,
  tau = D (P_A* - P_B*)  with P* = smooth_lower_bound(P, P_cav, eps_P):
  below the cavitation floor a chamber pushes with P_cav, so the torque
  cannot follow a state that has dropped under vapour pressure.  Outputs
  P_A*, P_B* (what the valve's orifices see) and P_L = P_A* - P_B*.
"""
from __future__ import annotations

from ..codegen.model import SymbolicModel
from .base import parameters, var
from .parameters import ParameterSet, load_parameter_set
from .smooth import smooth_lower_bound

SPECS = (
    ("D_m", "m3/rad", "displacement of the rotary actuator"),
    ("A_p", "m2", "piston area of the linear cylinder"),
    ("V_t", "m3", "total trapped volume of both chambers"),
    ("beta_e", "Pa", "effective bulk modulus of the oil"),
    ("C_tm", "m3/(s.Pa)", "total leakage coefficient (load-pressure form)"),
    ("C_im", "m3/(s.Pa)", "internal (cross-port) leakage coefficient"),
    ("C_em", "m3/(s.Pa)", "external leakage coefficient"),
    ("P_cav", "Pa", "cavitation floor of the chamber pressures"),
    ("eps_P", "Pa", "width of the smooth band at the cavitation floor"),
)


def hydraulic_actuator(form: str = "load_pressure", kind: str = "rotary", P_s: float = None,
                       parameter_set="default", overrides=None, name: str = "hydraulic_actuator") -> SymbolicModel:
    """Hydraulic actuator as a SymbolicModel (see module docstring).

    ``P_s`` (two-chamber form only) sets the start pressures P_A = P_B = P_s/2;
    by default the supply pressure of the same parameter set.
    """
    if form not in ("load_pressure", "two_chamber"):
        raise ValueError(f"hydraulic_actuator: form must be 'load_pressure' or 'two_chamber', not {form!r}")
    if kind not in ("rotary", "linear"):
        raise ValueError(f"hydraulic_actuator: kind must be 'rotary' or 'linear', not {kind!r}")
    D_name = "D_m" if kind == "rotary" else "A_p"
    used = [D_name, "V_t", "beta_e"] + (["C_tm"] if form == "load_pressure" else ["C_im", "C_em", "P_cav", "eps_P"])
    p = parameters("hydraulic_actuator", SPECS, used, parameter_set, overrides)
    s = {k: v.symbol for k, v in p.items()}
    D = s[D_name]
    if kind == "rotary":
        pos = var("theta", "rad", "joint angle", start=0.0)
        speed = var("w", "rad/s", "joint speed", start=0.0)
        effort = var("tau", "N.m", "actuator torque on the joint")
    else:
        pos = var("s", "m", "piston position", start=0.0)
        speed = var("v", "m/s", "piston speed", start=0.0)
        effort = var("F", "N", "actuator force on the joint")
    w = speed.symbol
    if form == "load_pressure":
        Q_L = var("Q_L", "m3/s", "load flow from the valve", start=0.0)
        P_L = var("P_L", "Pa", "load pressure P_A - P_B", start=0.0, output=True, nominal=1e6)
        der = 4 * s["beta_e"] / s["V_t"] * (Q_L.symbol - D * w - s["C_tm"] * P_L.symbol)
        return SymbolicModel.from_equations(
            name, [P_L], [Q_L, speed], list(p.values()), [der], [effort], [D * P_L.symbol],
            description=f"hydraulic {kind} actuator, load-pressure form",
            provenance="actuator-chain.md eqs. 5-6 (Merritt 1967 sec. 6.2)")
    if P_s is None:
        pset = parameter_set if isinstance(parameter_set, ParameterSet) else load_parameter_set(parameter_set)
        P_s = pset.value("servo_valve", "P_s")
    Q_A = var("Q_A", "m3/s", "flow into chamber A", start=0.0)
    Q_B = var("Q_B", "m3/s", "flow out of chamber B", start=0.0)
    P_A = var("P_A", "Pa", "pressure state of chamber A", start=P_s / 2, nominal=1e7)
    P_B = var("P_B", "Pa", "pressure state of chamber B", start=P_s / 2, nominal=1e7)
    V_A = s["V_t"] / 2 + D * pos.symbol
    V_B = s["V_t"] / 2 - D * pos.symbol
    leak = s["C_im"] * (P_A.symbol - P_B.symbol)
    dPA = s["beta_e"] / V_A * (Q_A.symbol - D * w - leak - s["C_em"] * P_A.symbol)
    dPB = s["beta_e"] / V_B * (-Q_B.symbol + D * w + leak - s["C_em"] * P_B.symbol)
    PAe = smooth_lower_bound(P_A.symbol, s["P_cav"], s["eps_P"])
    PBe = smooth_lower_bound(P_B.symbol, s["P_cav"], s["eps_P"])
    outs = [effort, var("P_A_eff", "Pa", "pressure of chamber A above the cavitation floor"),
            var("P_B_eff", "Pa", "pressure of chamber B above the cavitation floor"),
            var("P_L", "Pa", "load pressure P_A - P_B")]
    return SymbolicModel.from_equations(
        name, [P_A, P_B], [Q_A, Q_B, pos, speed], list(p.values()), [dPA, dPB], outs,
        [D * (PAe - PBe), PAe, PBe, PAe - PBe],
        description=f"hydraulic {kind} actuator, two-chamber form",
        provenance="actuator-chain.md eq. 5 (Jelali & Kroll 2003 sec. 4.3; Manring 2005)")
