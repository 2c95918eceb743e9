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
from ..errors import FmugenError
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
    ("stroke", "rad", "largest |theta| (|s| in m, linear kind) the joint reaches; two-chamber form: "
                      "V_t/2 - D*stroke must stay > 0 (checked, not a model parameter)"),
)


def _supply_pressure(pset) -> float | None:
    """P_s of the parameter set's [servo_valve] table (the validity range of
    the pressures), or None when the set has none."""
    return pset.sections.get("servo_valve", {}).get("P_s")


def chamber_stroke_limit(V_t: float, D: float) -> float:
    """|theta| [rad] (|s| [m]) at which a chamber volume V_t/2 - D |theta| reaches zero."""
    return V_t / (2 * D)


def hydraulic_actuator(form: str = "load_pressure", kind: str = "rotary", P_s: float = None,
                       parameter_set="default", overrides=None, name: str = "hydraulic_actuator") -> SymbolicModel:
    """Hydraulic actuator as a SymbolicModel (see module docstring).

    ``P_s`` (two-chamber form only) sets the start pressures P_A = P_B = P_s/2;
    by default the supply pressure of the same parameter set.
    """
    if form not in ("load_pressure", "two_chamber"):
        raise FmugenError(f"hydraulic_actuator: form must be 'load_pressure' or 'two_chamber', not {form!r}")
    if kind not in ("rotary", "linear"):
        raise FmugenError(f"hydraulic_actuator: kind must be 'rotary' or 'linear', not {kind!r}")
    D_name = "D_m" if kind == "rotary" else "A_p"
    used = [D_name, "V_t", "beta_e"] + (["C_tm"] if form == "load_pressure" else ["C_im", "C_em", "P_cav", "eps_P"])
    p = parameters("hydraulic_actuator", SPECS, used, parameter_set, overrides)
    pset = parameter_set if isinstance(parameter_set, ParameterSet) else load_parameter_set(parameter_set)
    s = {k: v.symbol for k, v in p.items()}
    D = s[D_name]
    P_supply = P_s if P_s is not None else _supply_pressure(pset)
    pos_range = (None, None)
    if form == "two_chamber":
        # the chamber volumes V_t/2 -+ D theta must stay positive over the joint's range
        V_t, D_val = p["V_t"].start, p[D_name].start
        limit = chamber_stroke_limit(V_t, D_val)
        stroke = (overrides or {}).get("stroke", pset.sections.get("hydraulic_actuator", {}).get("stroke"))
        unit = "rad" if kind == "rotary" else "m"
        if stroke is not None and stroke >= limit:
            raise FmugenError(
                f"hydraulic_actuator {name!r}: stroke = {stroke!r} {unit} is not compatible with the chamber "
                f"volumes: V_t/2 - {D_name}*stroke = {V_t / 2 - D_val * stroke:.4g} m3 <= 0 (V_t = {V_t!r} m3, "
                f"{D_name} = {D_val!r}); the volumes allow |position| < {limit:.6g} {unit}: reduce the stroke "
                f"or enlarge V_t")
        bound = stroke if stroke is not None else limit
        pos_range = (-bound, bound)
    if kind == "rotary":
        pos = var("theta", "rad", "joint angle", start=0.0, min=pos_range[0], max=pos_range[1])
        speed = var("w", "rad/s", "joint speed", start=0.0)
        effort = var("tau", "N.m", "actuator torque on the joint")
    else:
        pos = var("s", "m", "piston position", start=0.0, min=pos_range[0], max=pos_range[1])
        speed = var("v", "m/s", "piston speed", start=0.0)
        effort = var("F", "N", "actuator force on the joint")
    w = speed.symbol
    if form == "load_pressure":
        Q_L = var("Q_L", "m3/s", "load flow from the valve", start=0.0)
        # |P_L| <= P_s: an ideal valve cannot make more; beyond it the model is outside its range
        P_L = var("P_L", "Pa", "load pressure P_A - P_B", start=0.0, output=True, nominal=1e6,
                  min=None if P_supply is None else -P_supply, max=P_supply)
        der = 4 * s["beta_e"] / s["V_t"] * (Q_L.symbol - D * w - s["C_tm"] * P_L.symbol)
        return SymbolicModel.from_equations(
            name, [P_L], [Q_L, speed], list(p.values()), [der], [effort], [D * P_L.symbol],
            description=f"hydraulic {kind} actuator, load-pressure form",
            provenance="actuator-chain.md eqs. 5-6 (Merritt 1967 sec. 6.2)")
    if P_s is None:
        P_s = pset.value("servo_valve", "P_s")
    Q_A = var("Q_A", "m3/s", "flow into chamber A", start=0.0)
    Q_B = var("Q_B", "m3/s", "flow out of chamber B", start=0.0)
    # valid between the vapour pressure (cavitation floor) and the supply
    P_cav = p["P_cav"].start
    P_A = var("P_A", "Pa", "pressure state of chamber A", start=P_s / 2, nominal=1e7, min=P_cav, max=P_s)
    P_B = var("P_B", "Pa", "pressure state of chamber B", start=P_s / 2, nominal=1e7, min=P_cav, max=P_s)
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
