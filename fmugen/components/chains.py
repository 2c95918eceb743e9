"""Ready-made assemblies: the one-joint hydraulic test rig of docs/actuator-chain.md.

amplifier -> current driver -> servo valve -> actuator -> joint inertia
(actuator-chain.md, "Equations (one joint)"), closed by the position
feedback joint.theta -> amplifier.theta.  Inputs: ``amp.theta_ref`` and
``joint.tau_load``.
"""
from __future__ import annotations

from ..codegen.model import SymbolicModel
from .amplifier import amplifier
from .connect import assemble
from .current_driver import current_driver
from .hydraulic_actuator import hydraulic_actuator
from .joint import joint_inertia
from .servo_valve import servo_valve

#: causal connections of the one-joint rig (source, target)
SINGLE_JOINT_CONNECTIONS = (
    ("joint.theta", "amp.theta"),
    ("amp.u", "driver.u"),
    ("driver.i", "valve.i"),
    ("actuator.P_L", "valve.P_L"),
    ("valve.Q_L", "actuator.Q_L"),
    ("joint.w", "actuator.w"),
    ("actuator.tau", "joint.tau"),
)


def single_joint_components(parameter_set="default", control: str = "P", opamp: str = "ideal",
                            rails: bool = False, driver: str = "lag", valve_order: int = 2,
                            stroke_limit: bool = False) -> dict:
    """The rig's component instances (name -> SymbolicModel)."""
    return {
        "amp": amplifier(kind=opamp, control=control, rails=rails, parameter_set=parameter_set, name="amp"),
        "driver": current_driver(kind=driver, parameter_set=parameter_set, name="driver"),
        "valve": servo_valve(order=valve_order, stroke_limit=stroke_limit, parameter_set=parameter_set,
                             name="valve"),
        "actuator": hydraulic_actuator(form="load_pressure", parameter_set=parameter_set, name="actuator"),
        "joint": joint_inertia(parameter_set=parameter_set, name="joint"),
    }


def single_joint(parameter_set="default", control: str = "P", opamp: str = "ideal", rails: bool = False,
                 driver: str = "lag", valve_order: int = 2, stroke_limit: bool = False,
                 name: str = "single_joint") -> SymbolicModel:
    """The assembled one-joint rig as one SymbolicModel.

    States (full fidelity, PI, real op-amp): amp.z, amp.v, driver.i,
    valve.x_v, valve.v_v, actuator.P_L, joint.theta, joint.w.
    """
    comps = single_joint_components(parameter_set, control, opamp, rails, driver, valve_order, stroke_limit)
    return assemble(name, comps, SINGLE_JOINT_CONNECTIONS,
                    inputs=["amp.theta_ref", "joint.tau_load"],
                    description=f"one hydraulic joint ({parameter_set if isinstance(parameter_set, str) else 'custom'} "
                                f"set; {opamp} op-amp, {control}; driver {driver}; valve order {valve_order})")
