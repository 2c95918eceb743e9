"""Current-controlled DC motor with gear, as in Modelica's RobotR3 axis.

Anchor: Modelica.Mechanics.MultiBody.Examples.Systems.RobotR3.Components
(Motor, GearType1/GearType2), default numbers of axis 1: motor inertia J_m =
0.0013 kg.m2, motor gain k_t = 1.1616 N.m/A, current loop w = 4590 rad/s and
D = 0.6, gear ratio -105, bearing friction Rv0 = 0.4 N.m, Rv1 = 0.13/160
N.m.s/rad, gear elasticity c = 43 N.m/rad, d = 0.005 N.m.s/rad (motor side).

RobotR3's Motor is an op-amp circuit (PI current controller, power stage,
armature L/R, EMF) whose component values are set from w and D; here the
closed current loop is reduced to the second-order low-pass those values
were chosen for (a modelling simplification, stated as such):

* current_loop="ideal":         i = i_ref                       (no state)
* current_loop="second_order":  d2i/dt2 + 2 zeta_c omega_c di/dt
                                + omega_c^2 i = omega_c^2 i_ref (states i, i_d)

Motor side (phi_m, w_m = ratio * joint angle / speed when rigid), torque
tau_m = k_t i, bearing friction tau_f = R_v0 sgn_s(w_m) + R_v1 w_m with the
C-infinity sign w/sqrt(w^2 + w_fric^2) (RobotR3 uses an ideal stick-slip
element; a regularised Coulomb term keeps the model an explicit ODE):

* elasticity=False (GearType2, rigid gear): the motor drives the load
  directly; the component contains the load (J, B_m of [joint_inertia]):
  (J + ratio^2 J_m) dw/dt = ratio (tau_m - tau_f) - B_m w - tau_load,
  dtheta/dt = w; inputs i_ref, tau_load; states theta, w (outputs);
  outputs phi_m = ratio theta, w_m = ratio w (what the controller measures).
* elasticity=True (GearType1): spring/damper between motor and gear input,
  tau_s = c (phi_m - ratio theta) + d (w_m - ratio w),
  J_m dw_m/dt = tau_m - tau_f - tau_s; inputs i_ref, theta, w (joint
  motion); states phi_m, w_m (outputs); output tau = ratio tau_s, the torque
  on the joint (connect to joint_inertia.tau).
"""
from __future__ import annotations

from ..codegen.model import SymbolicModel
from .base import parameters, var
from .joint import SPECS as JOINT_SPECS
from .smooth import smooth_sign

SPECS = (
    ("J_m", "kg.m2", "motor inertia"),
    ("k_t", "N.m/A", "motor torque constant"),
    ("omega_c", "rad/s", "natural frequency of the closed current loop"),
    ("zeta_c", "1", "damping ratio of the closed current loop"),
    ("ratio", "1", "gear ratio (motor angle / joint angle)"),
    ("R_v0", "N.m", "Coulomb friction torque, motor side"),
    ("R_v1", "N.m.s/rad", "viscous friction, motor side"),
    ("w_fric", "rad/s", "regularisation speed of the Coulomb friction"),
    ("c", "N.m/rad", "gear elasticity, motor side"),
    ("d", "N.m.s/rad", "gear damping, motor side"),
)


def dc_motor(current_loop: str = "second_order", elasticity: bool = False, parameter_set="default",
             overrides=None, load_overrides=None, name: str = "motor") -> SymbolicModel:
    """Current-controlled DC motor with gear (see module docstring)."""
    if current_loop not in ("ideal", "second_order"):
        raise ValueError(f"dc_motor: current_loop must be 'ideal' or 'second_order', not {current_loop!r}")
    used = ["J_m", "k_t", "ratio", "R_v0", "R_v1", "w_fric"]
    used += ["omega_c", "zeta_c"] if current_loop == "second_order" else []
    used += ["c", "d"] if elasticity else []
    p = parameters("dc_motor", SPECS, used, parameter_set, overrides)
    params = list(p.values())
    s = {k: v.symbol for k, v in p.items()}
    i_ref = var("i_ref", "A", "motor current reference", start=0.0)
    states, ders = [], []
    if current_loop == "ideal":
        i = i_ref.symbol
    else:
        iv = var("i", "A", "motor current", start=0.0, output=True)
        idv = var("i_d", "A/s", "rate of the motor current", start=0.0, nominal=1e3)
        states += [iv, idv]
        ders += [idv.symbol, s["omega_c"] ** 2 * (i_ref.symbol - iv.symbol)
                 - 2 * s["zeta_c"] * s["omega_c"] * idv.symbol]
        i = iv.symbol
    tau_m = s["k_t"] * i

    def friction(w_m):
        return s["R_v0"] * smooth_sign(w_m, s["w_fric"]) + s["R_v1"] * w_m

    if not elasticity:
        lp = parameters("joint_inertia", JOINT_SPECS, ["J", "B_m"], parameter_set, load_overrides)
        params += list(lp.values())
        J, B = lp["J"].symbol, lp["B_m"].symbol
        th = var("theta", "rad", "joint angle", start=0.0, output=True)
        w = var("w", "rad/s", "joint speed", start=0.0, output=True)
        tau_load = var("tau_load", "N.m", "load torque on the joint", start=0.0)
        w_m = s["ratio"] * w.symbol
        states = [th, w] + states
        ders = [w.symbol, (s["ratio"] * (tau_m - friction(w_m)) - B * w.symbol - tau_load.symbol)
                / (J + s["ratio"] ** 2 * s["J_m"])] + ders
        outs = [var("phi_m", "rad", "motor angle"), var("w_m", "rad/s", "motor speed")]
        return SymbolicModel.from_equations(
            name, states, [i_ref, tau_load], params, ders, outs, [s["ratio"] * th.symbol, w_m],
            description=f"current-controlled DC motor, rigid gear, driving its load ({current_loop} current loop)",
            provenance="Modelica RobotR3 Components.Motor and GearType2 (reduced current loop)")
    phi_m = var("phi_m", "rad", "motor angle", start=0.0, output=True)
    w_m = var("w_m", "rad/s", "motor speed", start=0.0, output=True, nominal=100.0)
    th = var("theta", "rad", "joint angle", start=0.0)
    w = var("w", "rad/s", "joint speed", start=0.0)
    tau_s = s["c"] * (phi_m.symbol - s["ratio"] * th.symbol) + s["d"] * (w_m.symbol - s["ratio"] * w.symbol)
    states = [phi_m, w_m] + states
    ders = [w_m.symbol, (tau_m - friction(w_m.symbol) - tau_s) / s["J_m"]] + ders
    return SymbolicModel.from_equations(
        name, states, [i_ref, th, w], params, ders, [var("tau", "N.m", "torque on the joint")],
        [s["ratio"] * tau_s],
        description=f"current-controlled DC motor with elastic gear ({current_loop} current loop)",
        provenance="Modelica RobotR3 Components.Motor and GearType1 (reduced current loop)")
