"""Write a new component in a few lines and get its FMUs.

A component is a SymbolicModel: states, inputs, parameters (each a Variable
with unit, description and default), the derivative expressions and the
outputs.  This one is a pressure transducer with a first-order lag (time
constant T_p) and a gain K_p [V/Pa]:

    dp_m/dt = (P - p_m)/T_p,     v_s = K_p p_m

It is exported on its own (ME and CS in one FMU), then connected to the
actuator of the one-joint rig to measure the load pressure, and the assembly
exported as one FMU.

Run:  python examples/custom_component.py [output_dir]
"""
import argparse
from pathlib import Path

import sympy as sp
from fmpy import simulate_fmu

from fmugen.codegen.model import SymbolicModel, Variable
from fmugen.components import assemble
from fmugen.components.chains import SINGLE_JOINT_CONNECTIONS, single_joint_components
from fmugen.fmi.build import build_fmu


def pressure_sensor(T_p=2e-3, K_p=1e-6, name="sensor"):
    P, p_m, T, K = sp.symbols("P p_m T_p K_p", real=True)
    return SymbolicModel.from_equations(
        name,
        states=[Variable("p_m", p_m, "Pa", "filtered pressure", start=0.0)],
        inputs=[Variable("P", P, "Pa", "measured pressure", start=0.0)],
        parameters=[Variable("T_p", T, "s", "time constant of the transducer", start=T_p),
                    Variable("K_p", K, "V/Pa", "transducer gain", start=K_p)],
        derivatives=[(P - p_m) / T],
        outputs=[Variable("v_s", sp.Symbol("v_s", real=True), "V", "sensor voltage")],
        output_exprs=[K * p_m],
        description="pressure transducer with first-order lag")


def main(out_dir="build"):
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # 1. the component on its own
    sensor = pressure_sensor()
    fmu = build_fmu(sensor, out / "sensor.fmu", fmi_type="both").path
    r = simulate_fmu(str(fmu), fmi_type="CoSimulation", start_values={"P": 7e6}, stop_time=0.01,
                     output=["v_s"])
    print(f"sensor step, v_s(10 ms) = {r['v_s'][-1]:.4f} V (expected {7.0 * (1 - 2.718281828 ** -5):.4f})")
    # 2. the component connected into the one-joint rig, exported as one FMU
    comps = single_joint_components("default")
    comps["sensor"] = sensor
    rig = assemble("rig_with_sensor", comps, list(SINGLE_JOINT_CONNECTIONS) + [("actuator.P_L", "sensor.P")],
                   inputs=["amp.theta_ref", "joint.tau_load"])
    fmu2 = build_fmu(rig, out / "rig_with_sensor.fmu", fmi_type="both").path
    r = simulate_fmu(str(fmu2), fmi_type="CoSimulation", stop_time=1.0,
                     start_values={"amp.theta_ref": 0.1, "joint.tau_load": 50.0, "solver.method": 2},
                     output=["joint.theta", "sensor.v_s"])
    print(f"rig with sensor: theta(1 s) = {r['joint.theta'][-1]:.5f} rad, "
          f"v_s(1 s) = {r['sensor.v_s'][-1]:.4f} V (holding 50 N.m needs P_L = {50 / 1.5e-5 / 1e6:.3f} MPa)")
    return r


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("output_dir", nargs="?", default="build", help="where the FMUs go (default: build)")
    main(ap.parse_args().output_dir)
