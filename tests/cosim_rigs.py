"""The split one-joint rigs of the co-simulation tests, built once per test process.

FMU "chain" = amplifier + current driver + servo valve + actuator chambers
(inputs ``amp.theta``, ``actuator.w``; output ``actuator.tau``), FMU "joint" =
the joint inertia (input ``tau``; outputs ``theta``, ``w``) -- the split the
scenes build from ``examples/scenes/single_joint_split*.toml``.  Two
excitations:

* ``"step"``: ``amp.theta_ref`` = 0.1 rad from t = 0 (a step), for stability
  limits (it excites every mode);
* ``"smooth"``: a quintic rest-to-rest move 0 -> 0.5 rad in 2 s inside the
  chain FMU, for accuracy at large macro steps.

The monolithic reference is the same components assembled into one model.
"""
from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import numpy as np

import fmugen
from fmugen.components import (amplifier, assemble, current_driver, hydraulic_actuator, joint_inertia,
                               quintic_trajectory, servo_valve)
from fmugen.cosim.system import CosimSystem, Coupling, Recorded, ReferenceProblem, Unit

CHAIN_LINKS = [("amp.u", "driver.u"), ("driver.i", "valve.i"), ("actuator.P_L", "valve.P_L"),
               ("valve.Q_L", "actuator.Q_L")]
JOINT_LINKS = [("joint.theta", "amp.theta"), ("joint.w", "actuator.w"), ("actuator.tau", "joint.tau")]
MOVE = {"q_begin": 0.0, "q_end": 0.5, "t_start": 0.0, "T_move": 2.0}
THETA_STEP = 0.1
# internal solver of both FMUs: far (>= 100x) below every coupling error the tests measure
INTERNAL = {"solver.method": 1, "solver.rtol": 1e-10, "solver.atol": 1e-10}


def _components(ps, excitation, with_joint):
    c = {}
    if excitation == "smooth":
        c["traj"] = quintic_trajectory(overrides=MOVE, name="traj")
    c.update({"amp": amplifier(parameter_set=ps, name="amp"),
              "driver": current_driver(parameter_set=ps, name="driver"),
              "valve": servo_valve(parameter_set=ps, name="valve"),
              "actuator": hydraulic_actuator(parameter_set=ps, name="actuator")})
    if with_joint:
        c["joint"] = joint_inertia(parameter_set=ps, name="joint")
    links = list(CHAIN_LINKS) + ([("traj.q_ref", "amp.theta_ref")] if excitation == "smooth" else [])
    return c, links


@functools.lru_cache(maxsize=None)
def fmu_dir(ps: str, excitation: str) -> Path:
    d = Path(tempfile.mkdtemp(prefix=f"cosim_rig_{ps}_{excitation}_"))
    comps, links = _components(ps, excitation, False)
    chain = assemble("chain", comps, links, outputs=["actuator.tau"])
    fmugen.build_fmu(chain, d / "chain.fmu", fmi_type="both")
    fmugen.build_fmu(joint_inertia(parameter_set=ps, name="joint"), d / "joint.fmu", fmi_type="both")
    return d


def split_system(ps="default", excitation="step", stop=1.0, step=1e-3, internal=None,
                 order=("joint", "chain")) -> CosimSystem:
    d = fmu_dir(ps, excitation)
    sv = dict(INTERNAL if internal is None else internal)
    chain_sv = dict(sv, **({"amp.theta_ref": THETA_STEP} if excitation == "step" else {}))
    units = (Unit("chain", d / "chain.fmu", "cs", chain_sv, members=("amp", "driver", "valve", "actuator")),
             Unit("joint", d / "joint.fmu", "cs", sv, members=("joint",)))
    couplings = (Coupling(("joint", "theta"), ("chain", "amp.theta"), unit="rad"),
                 Coupling(("joint", "w"), ("chain", "actuator.w"), unit="rad/s"),
                 Coupling(("chain", "actuator.tau"), ("joint", "tau"), unit="N.m"))
    recorded = (Recorded("joint.theta", "joint", "theta", "rad"), Recorded("joint.w", "joint", "w", "rad/s"),
                Recorded("actuator.P_L", "chain", "actuator.P_L", "Pa"))
    return CosimSystem(f"split_{ps}_{excitation}", units, couplings, recorded, 0.0, stop, step, order=order)


@functools.lru_cache(maxsize=None)
def _amp_fmu_dir(ps: str) -> Path:
    d = Path(tempfile.mkdtemp(prefix=f"cosim_rig_amp_{ps}_"))
    amp = assemble("amp", {"amp": amplifier(parameter_set=ps, name="amp")}, [], outputs=["amp.u"])
    fmugen.build_fmu(amp, d / "amp.fmu", fmi_type="cs")
    comps = {"driver": current_driver(parameter_set=ps, name="driver"),
             "valve": servo_valve(parameter_set=ps, name="valve"),
             "actuator": hydraulic_actuator(parameter_set=ps, name="actuator")}
    chain = assemble("chain", comps, CHAIN_LINKS[1:], outputs=["actuator.tau"])
    fmugen.build_fmu(chain, d / "chain.fmu", fmi_type="cs")
    fmugen.build_fmu(joint_inertia(parameter_set=ps, name="joint"), d / "joint.fmu", fmi_type="cs")
    return d


def amp_split_system(ps="default", stop=1.0, step=1e-3) -> CosimSystem:
    """The step rig in three FMUs: the amplifier alone (no states: its outputs are functions of its inputs
    now), driver + valve + actuator, and the joint -- the same equations as ``split_system(ps, "step")``."""
    d = _amp_fmu_dir(ps)
    units = (Unit("amp", d / "amp.fmu", "cs", {"amp.theta_ref": THETA_STEP}, members=("amp",)),
             Unit("chain", d / "chain.fmu", "cs", dict(INTERNAL), members=("driver", "valve", "actuator")),
             Unit("joint", d / "joint.fmu", "cs", dict(INTERNAL), members=("joint",)))
    couplings = (Coupling(("joint", "theta"), ("amp", "amp.theta"), unit="rad"),
                 Coupling(("amp", "amp.u"), ("chain", "driver.u"), unit="V"),
                 Coupling(("joint", "w"), ("chain", "actuator.w"), unit="rad/s"),
                 Coupling(("chain", "actuator.tau"), ("joint", "tau"), unit="N.m"))
    recorded = (Recorded("joint.theta", "joint", "theta", "rad"),)
    return CosimSystem(f"amp_split_{ps}", units, couplings, recorded, 0.0, stop, step)


def reference_problem(ps="default", excitation="step", stop=1.0) -> ReferenceProblem:
    comps, links = _components(ps, excitation, True)
    m = assemble("single_joint", comps, links + JOINT_LINKS,
                 inputs=(["amp.theta_ref"] if excitation == "step" else []) + ["joint.tau_load"])
    x0 = np.array([v.start or 0.0 for v in m.states])
    u = np.array([THETA_STEP if v.name == "amp.theta_ref" else 0.0 for v in m.inputs])
    return ReferenceProblem(m, x0, u, ("joint.theta", "joint.w", "actuator.P_L"), 0.0, stop)


# first unstable macro steps of the shared actuator-chain note [s]
LIMITS = {"default": {("jacobi", "hold"): 4.0e-3, ("jacobi", "linear"): 11.7e-3, ("gauss-seidel", "hold"): 36.6e-3},
          "stiff": {("jacobi", "hold"): 1.38e-3, ("jacobi", "linear"): 2.08e-3, ("gauss-seidel", "hold"): 5.6e-3}}
