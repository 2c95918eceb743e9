"""The named cases of the suite: what is simulated, how, and what is compared.

A case is a model (a SymbolicModel factory), start values by FMI name
(parameters, inputs held constant, state start values), a horizon and a
communication step, the variables compared with the reference, and the
solver settings (:class:`Method`) to run.  Figures quoted in the
descriptions (eigenvalues, stall torque, RK4 limits) are those of the
actuator-chain parameter sets in ``fmugen/components/data`` and are
recomputed by the suite, not assumed.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable, Optional

DOPRI5, RODAS3, RK4 = 1, 2, 3
SOLVER_NAMES = {DOPRI5: "DOPRI5", RODAS3: "RODAS3", RK4: "RK4"}


@dataclass(frozen=True)
class Method:
    """One Co-Simulation solver setting.

    ``tol``: rtol = atol of solvers 1 and 2.  RK4: ``rk4_factor`` times the
    stability limit found from the eigenvalues of df/dx at the start (the
    suite computes it), or an absolute ``rk4_step`` [s].
    """

    solver: int
    tol: float = 0.0
    rk4_factor: float = 0.0
    rk4_step: float = 0.0

    def label(self, h: Optional[float] = None, h_limit: Optional[float] = None) -> str:
        name = SOLVER_NAMES[self.solver]
        if self.solver != RK4:
            return f"{name} tol {self.tol:.0e}"
        if h is None:
            return f"{name} {self.rk4_factor:g} h_lim" if self.rk4_factor else f"{name} h {self.rk4_step:.3g}"
        ratio = f" ({h / h_limit:.2g} h_lim)" if h_limit and h_limit < float("inf") else ""
        return f"{name} h {h:.3g}{ratio}"


TOLERANCE_METHODS = (Method(DOPRI5, 1e-6), Method(DOPRI5, 1e-9), Method(RODAS3, 1e-6), Method(RODAS3, 1e-9))
RK4_METHODS = (Method(RK4, rk4_factor=0.5), Method(RK4, rk4_factor=1.2))
QUICK_METHODS = (Method(DOPRI5, 1e-6), Method(RODAS3, 1e-6), Method(RK4, rk4_factor=0.5),
                 Method(RK4, rk4_factor=1.2))


@dataclass(frozen=True)
class Validity:
    """A physical range a variable must stay in for the model to hold."""

    variable: str
    low: float
    high: float
    why: str


@dataclass(frozen=True)
class Case:
    """A named simulation of the suite (see the module docstring).

    ``kind``: "trajectory" (compare ``compare`` with the reference on the
    communication grid), "energy" (free undamped motion: report the drift of
    the total energy, not trajectories) or "thesis" (the thesis's integrator,
    analysed in :mod:`fmugen.suite.thesis`).
    """

    name: str
    title: str
    make_model: Callable = None
    start: dict = field(default_factory=dict)
    stop: float = 0.2
    H: float = 0.01
    compare: tuple = ("joint.theta",)
    methods: tuple = TOLERANCE_METHODS + RK4_METHODS
    quick_methods: tuple = QUICK_METHODS
    quick: bool = False
    stiff: bool = True
    kind: str = "trajectory"
    validity: tuple = ()
    model_key: str = ""
    rk4_max_step: float = 0.0  # cap of RK4 steps (non-stiff cases: accuracy, not stability, binds)


# ---------------------------------------------------------------- models
@lru_cache(maxsize=None)
def rig(parameter_set="stiff", control="P", opamp="ideal", rails=False, stroke_limit=False):
    from ..components import single_joint

    return single_joint(parameter_set, control=control, opamp=opamp, rails=rails, stroke_limit=stroke_limit)


@lru_cache(maxsize=None)
def rig_two_chamber(parameter_set="stiff"):
    """The one-joint rig with the valve's two flows and the actuator's two chambers
    (V_A,B = V_t/2 +- D_m theta, a cavitation floor on each pressure)."""
    from ..components import (amplifier, assemble, current_driver, hydraulic_actuator, joint_inertia,
                              servo_valve)

    comps = {"amp": amplifier(parameter_set=parameter_set, name="amp"),
             "driver": current_driver(parameter_set=parameter_set, name="driver"),
             "valve": servo_valve(flow="chambers", parameter_set=parameter_set, name="valve"),
             "actuator": hydraulic_actuator(form="two_chamber", parameter_set=parameter_set, name="actuator"),
             "joint": joint_inertia(parameter_set=parameter_set, name="joint")}
    conns = [("joint.theta", "amp.theta"), ("amp.u", "driver.u"), ("driver.i", "valve.i"),
             ("actuator.P_A_eff", "valve.P_A"), ("actuator.P_B_eff", "valve.P_B"),
             ("valve.Q_A", "actuator.Q_A"), ("valve.Q_B", "actuator.Q_B"),
             ("joint.theta", "actuator.theta"), ("joint.w", "actuator.w"), ("actuator.tau", "joint.tau")]
    return assemble("single_joint_two_chamber", comps, conns, inputs=["amp.theta_ref", "joint.tau_load"])


@lru_cache(maxsize=None)
def puma_arm():
    import fmugen
    from pathlib import Path

    return fmugen.load_robot(Path(__file__).resolve().parents[2] / "robots" / "puma_thesis_com.toml")


@lru_cache(maxsize=None)
def puma():
    return puma_arm().state_space_model(outputs=("p_ee",))


Q = tuple(f"q[{i}]" for i in range(1, 7))
P_EE = ("p_ee[1]", "p_ee[2]", "p_ee[3]")
# a pose away from singularities: elbow bent, wrist pitched
PUMA_POSE = {"q[2]": -0.5, "q[3]": 0.5, "q[4]": 0.3, "q[5]": 0.8, "q[6]": 0.2}
P_S = 14e6  # Pa, supply pressure of both parameter sets
STALL = P_S * 1.5e-5  # N.m, P_s D_m = 210 N.m

PUMA_METHODS = (Method(DOPRI5, 1e-6), Method(DOPRI5, 1e-9), Method(RODAS3, 1e-6), Method(RODAS3, 1e-9),
                Method(RK4, rk4_step=1e-3), Method(RK4, rk4_step=1e-4))
PUMA_QUICK = (Method(DOPRI5, 1e-6), Method(RODAS3, 1e-6), Method(RK4, rk4_step=1e-4))
ENERGY_METHODS = (Method(DOPRI5, 1e-6), Method(DOPRI5, 1e-8), Method(DOPRI5, 1e-10), Method(RODAS3, 1e-6),
                  Method(RODAS3, 1e-8), Method(RK4, rk4_step=1e-3), Method(RK4, rk4_step=2e-4))
PRESSURE_RANGE = Validity("actuator.P_L", -P_S, P_S, "the load-pressure form of the valve holds for |P_L| <= P_s")

CASES = (
    Case("stiff_P", "stiff actuator set, P control (stiffness ratio 4.9e3, driver pole -5e4 1/s)",
         lambda: rig("stiff"), {"amp.theta_ref": 0.1}, 0.2, 0.01, quick=True, model_key="rig_stiff_P"),
    Case("stiff_PI", "stiff actuator set, PI control (stiffness ratio 1.8e4)",
         lambda: rig("stiff", "PI"), {"amp.theta_ref": 0.1}, 0.3, 0.01, model_key="rig_stiff_PI"),
    Case("stiff_PI_opamp", "stiff set, PI, real op-amp (GBW 1 MHz, pole -3.95e5 1/s, ratio 1.4e5)",
         lambda: rig("stiff", "PI", "real"), {"amp.theta_ref": 0.1}, 0.2, 0.01, quick=True,
         model_key="rig_stiff_PI_real"),
    Case("default_P_opamp", "default (PUMA shoulder) set, P, real op-amp",
         lambda: rig("default", "P", "real"), {"amp.theta_ref": 0.1}, 0.5, 0.01, model_key="rig_default_P_real"),
    Case("rails_stroke", "stiff set, 2 rad step: amplifier rails (10 V) and valve stroke saturate",
         lambda: rig("stiff", rails=True, stroke_limit=True), {"amp.theta_ref": 2.0}, 0.5, 0.01,
         model_key="rig_stiff_P_rails_stroke"),
    Case("load_near_stall", "stiff set, constant load 190 N.m (0.9 of the stall torque P_s D_m = 210 N.m)",
         lambda: rig("stiff"), {"joint.tau_load": 0.9 * STALL}, 0.3, 0.01, validity=(PRESSURE_RANGE,),
         model_key="rig_stiff_P"),
    Case("load_above_stall", "stiff set, constant load 5000 N.m (24x the stall torque): the load-pressure "
         "model leaves its range", lambda: rig("stiff"), {"joint.tau_load": 5000.0}, 0.1, 0.01,
         validity=(PRESSURE_RANGE,), quick=True, model_key="rig_stiff_P",
         quick_methods=(Method(DOPRI5, 1e-6), Method(RODAS3, 1e-6))),
    Case("trapped_volume", "two-chamber actuator driven to theta = -0.33 rad, where V_A = V_t/2 + D_m theta "
         "-> 2 % of V_t/2 (hydraulic stiffness grows as 1/V_A)",
         lambda: rig_two_chamber(), {"amp.theta_ref": -0.327}, 1.0, 0.01, model_key="rig_two_chamber",
         validity=(Validity("actuator.P_A", -1e5, 2 * P_S, "chamber pressure between vacuum and 2 P_s"),
                   Validity("actuator.P_B", -1e5, 2 * P_S, "chamber pressure between vacuum and 2 P_s"))),
    Case("cavitation", "two-chamber actuator overrun by a 400 N.m load (above stall): a chamber is drained to "
         "the cavitation floor", lambda: rig_two_chamber(), {"joint.tau_load": 400.0, "amp.theta_ref": 0.0},
         0.05, 0.001, model_key="rig_two_chamber"),
    Case("damping_x1e6", "stiff set with joint damping B_m x 1e6 (1e6 N.m.s/rad: a mode at -1e6 1/s)",
         lambda: rig("stiff"), {"amp.theta_ref": 0.1, "joint.B_m": 1e6}, 0.2, 0.01, model_key="rig_stiff_P"),
    Case("inertia_1e-6", "stiff set with joint inertia 1e-6 kg.m2", lambda: rig("stiff"),
         {"amp.theta_ref": 0.1, "joint.J": 1e-6}, 0.1, 0.01, model_key="rig_stiff_P"),
    Case("inertia_1e3", "stiff set with joint inertia 1e3 kg.m2", lambda: rig("stiff"),
         {"amp.theta_ref": 0.1, "joint.J": 1e3}, 2.0, 0.05, model_key="rig_stiff_P"),
    Case("comm_step_large", "stiff set, one communication step over the whole 0.5 s", lambda: rig("stiff"),
         {"amp.theta_ref": 0.1}, 0.5, 0.5, quick=True, model_key="rig_stiff_P",
         quick_methods=(Method(DOPRI5, 1e-6), Method(RODAS3, 1e-6), Method(RK4, rk4_factor=1.2))),
    Case("comm_step_small", "stiff set, communication steps of 1 us (2000 steps)", lambda: rig("stiff"),
         {"amp.theta_ref": 0.1}, 2e-3, 1e-6, model_key="rig_stiff_P",
         methods=(Method(DOPRI5, 1e-6), Method(RODAS3, 1e-6), Method(RK4, rk4_factor=0.5))),
    Case("puma_light_wrist", "thesis PUMA falling from rest, wrist spinning (flange axial inertia 9.1e-5 kg.m2, "
         "cond M ~ 4.5e5)", puma, dict(PUMA_POSE, **{"qd[6]": 20.0}), 1.0, 0.01, compare=Q + P_EE,
         methods=PUMA_METHODS, quick_methods=PUMA_QUICK, quick=True, stiff=False, model_key="puma"),
    Case("puma_wrist_singularity", "thesis PUMA, wrist swept through q5 = 0 at 20 rad/s (end-effector outputs)",
         puma, dict(PUMA_POSE, **{"q[5]": 0.4, "qd[5]": -20.0, "qd[4]": 5.0}), 0.1, 0.002, compare=Q + P_EE,
         methods=PUMA_METHODS, quick_methods=PUMA_QUICK, stiff=False, model_key="puma"),
    Case("puma_shoulder_singularity", "thesis PUMA, arm upright, swept at 5 rad/s through the shoulder "
         "singularity (wrist centre at distance d_3 from the base axis, p_ee[1] = 0)", puma,
         {"q[2]": -1.5707963267948966 + 0.2, "q[3]": 1.5707963267948966, "q[5]": 0.5, "qd[2]": -5.0}, 0.1, 0.002,
         compare=Q + P_EE, methods=PUMA_METHODS, quick_methods=PUMA_QUICK, stiff=False, model_key="puma"),
    Case("puma_gravity_x10", "thesis PUMA falling under 10 g", puma, dict(PUMA_POSE, **{"g_z": -98.1}), 1.0,
         0.01, compare=Q + P_EE, methods=PUMA_METHODS, stiff=False, model_key="puma"),
    Case("puma_mass_extremes", "thesis PUMA with the flange mass 1e-6 kg (inertias 1e-6 x k^2) and the upper "
         "arm 1e3 kg", puma, dict(PUMA_POSE, **{"m_6": 1e-6, "m_2": 1e3, "qd[6]": 5.0}), 0.5, 0.01,
         compare=Q + P_EE, methods=PUMA_METHODS, stiff=False, model_key="puma"),
    Case("puma_energy_60s", "free undamped thesis PUMA (tau = 0) for 60 s: energy drift per solver and tolerance",
         puma, dict(PUMA_POSE, **{"qd[1]": 1.0, "qd[6]": 5.0}), 60.0, 0.05, compare=Q,
         methods=ENERGY_METHODS, stiff=False, kind="energy", model_key="puma"),
    Case("thesis_integrator", "the thesis's integrator (acceleration held over the step, no iteration): growth "
         "sqrt(1 + (h w)^2/2) undamped, stable only for h w < 4 zeta; on the free PUMA against our solvers",
         puma, dict(PUMA_POSE, **{"qd[6]": 5.0}), 2.0, 0.01, compare=Q, kind="thesis", quick=True, stiff=False,
         methods=(Method(DOPRI5, 1e-6), Method(RODAS3, 1e-6)), quick_methods=(Method(DOPRI5, 1e-6),),
         model_key="puma"),
)


def case_names(quick: bool = False) -> list:
    return [c.name for c in CASES if c.quick or not quick]


def get_case(name: str) -> Case:
    for c in CASES:
        if c.name == name:
            return c
    raise KeyError(f"unknown suite case {name!r}; the cases are: {', '.join(c.name for c in CASES)}")
