"""Per-macro-step overhead of the co-simulation master against a bare loop of fmpy calls.

Both loops run the split one-joint rig (FMU "chain" = amplifier, driver, valve,
chambers; FMU "joint" = the inertia) with Jacobi and held inputs, and do the
same exchanges per macro step: set the coupled inputs of each FMU, fmi2DoStep,
read the coupled and recorded outputs.  The FMUs integrate with one RK4 step
per macro step (``solver.method = 3``), so their own work is small and the
loop around them shows.

* bare loop: ``fmpy.fmi2.FMU2Slave.setReal / doStep / getReal`` with Python
  lists, recording into a preallocated array -- the least a user writes;
* master: :func:`fmugen.cosim.run` (value references resolved once, raw C
  entry points on preallocated numpy buffers, divergence monitor, recording, the coupling error estimate;
  also timed without the estimate, for its cost).

Prints the median time per macro step of each over ``--repeats`` runs (after a
warm-up run) and their ratio, measured in the same process (goal: master <=
1.5x the bare loop), as CPU time of the process (what the loop costs, whatever
else the machine runs: both loops are single-threaded) and as wall time (which
on a shared machine also counts the time the process waited for a core).  Both
must give the same trajectory bit for bit, which is checked.

    python examples/bench_cosim_overhead.py [--steps 20000] [--repeats 5] [--set stiff]
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import fmugen
from fmugen.components import (amplifier, assemble, current_driver, hydraulic_actuator, joint_inertia,
                               servo_valve)
from fmugen.cosim import CosimSystem, Coupling, Master, Recorded, Unit, run

H = 1e-4  # RK4 on the stiff chain needs < 56 us per internal step; 100 us on the default set is stable


def build(out: Path, ps: str) -> tuple:
    chain = assemble("chain", {"amp": amplifier(parameter_set=ps, name="amp"),
                               "driver": current_driver(parameter_set=ps, name="driver"),
                               "valve": servo_valve(parameter_set=ps, name="valve"),
                               "actuator": hydraulic_actuator(parameter_set=ps, name="actuator")},
                     [("amp.u", "driver.u"), ("driver.i", "valve.i"), ("actuator.P_L", "valve.P_L"),
                      ("valve.Q_L", "actuator.Q_L")], outputs=["actuator.tau"])
    fmugen.build_fmu(chain, out / "chain.fmu", fmi_type="cs")
    fmugen.build_fmu(joint_inertia(parameter_set=ps, name="joint"), out / "joint.fmu", fmi_type="cs")
    return out / "chain.fmu", out / "joint.fmu"


START = {"chain": {"solver.method": 3, "amp.theta_ref": 0.1}, "joint": {"solver.method": 3}}


def system(chain, joint, n) -> CosimSystem:
    return CosimSystem("bench", (Unit("chain", chain, "cs", START["chain"]), Unit("joint", joint, "cs", START["joint"])),
                       (Coupling(("joint", "theta"), ("chain", "amp.theta")), Coupling(("joint", "w"), ("chain", "actuator.w")),
                        Coupling(("chain", "actuator.tau"), ("joint", "tau"))),
                       (Recorded("joint.theta", "joint", "theta"), Recorded("joint.w", "joint", "w"),
                        Recorded("actuator.tau", "chain", "actuator.tau")),
                       0.0, n * H, H)


def bare_loop(chain, joint, n) -> tuple:
    """Jacobi, held inputs, with fmpy's FMU2Slave methods; returns (seconds per macro step, trajectory)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    fmus, vrs = {}, {}
    for name, path in (("chain", chain), ("joint", joint)):
        md = read_model_description(str(path))
        f = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName=name)
        f.instantiate()
        v = {x.name: x.valueReference for x in md.modelVariables}
        f.setInteger([v["solver.method"]], [3])
        for k, val in START[name].items():
            if k != "solver.method":
                f.setReal([v[k]], [val])
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
        f.exitInitializationMode()
        fmus[name], vrs[name] = f, v
    c, j = fmus["chain"], fmus["joint"]
    c_in = [vrs["chain"]["amp.theta"], vrs["chain"]["actuator.w"]]
    c_out = [vrs["chain"]["actuator.tau"]]
    j_in = [vrs["joint"]["tau"]]
    j_out = [vrs["joint"]["theta"], vrs["joint"]["w"]]
    rec = np.empty((n + 1, 3))
    th_w = j.getReal(j_out)
    tau = c.getReal(c_out)
    rec[0] = th_w + tau
    t = 0.0
    w0, c0 = time.perf_counter(), time.process_time()
    for i in range(n):
        c.setReal(c_in, th_w)
        j.setReal(j_in, tau)
        c.doStep(t, H)
        j.doStep(t, H)
        t += H
        tau = c.getReal(c_out)
        th_w = j.getReal(j_out)
        rec[i + 1] = th_w + tau
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    for f in (c, j):
        f.terminate()
        f.freeInstance()
    return wall / n, cpu / n, rec


def master_loop(sysm, estimate=True) -> tuple:
    """fmugen's master on the same system: (seconds per macro step, wall and CPU, result).  The FMUs are
    instantiated before the clocks start, as in the bare loop."""
    with Master(sysm, "jacobi", "hold") as m:
        c0 = time.process_time()
        r = m.run(estimate=estimate)
        cpu = time.process_time() - c0
    assert r.ok, r.summary
    return r.summary.wall_time / r.summary.macro_steps, cpu / r.summary.macro_steps, r


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=20000, help="macro steps per run (default 20000 = 2 s)")
    ap.add_argument("--repeats", type=int, default=5, help="timed runs of each loop after a warm-up (median)")
    ap.add_argument("--set", default="default", choices=["default", "stiff"], help="parameter set of the rig")
    ap.add_argument("--out", default=None, help="folder for the FMUs (default: a temporary folder)")
    args = ap.parse_args(argv)
    out = Path(args.out or tempfile.mkdtemp(prefix="bench_cosim_"))
    out.mkdir(parents=True, exist_ok=True)
    chain, joint = build(out, args.set)
    n = args.steps
    sysm = system(chain, joint, n)
    bare_loop(chain, joint, min(n, 1000))  # warm-up
    run(sysm, "jacobi", "hold", stop=min(n, 1000) * H, detect_divergence=True)
    bare, master, bare_cpu, master_cpu, plain_cpu = [], [], [], [], []
    for _ in range(args.repeats):  # alternate, so both see the same machine load
        b, bc, rec = bare_loop(chain, joint, n)
        bare.append(b)
        bare_cpu.append(bc)
        m, mc, r = master_loop(sysm)
        master.append(m)
        master_cpu.append(mc)
        _, pc, plain = master_loop(sysm, estimate=False)
        plain_cpu.append(pc)
        same = np.array_equal(rec, r.values[:, [0, 1, 2]])
    med = statistics.median
    print(f"split rig ({args.set} set), Jacobi/held, H = {H:g} s, {n} macro steps, 2 FMUs, RK4 one step per macro step")
    print(f"  per macro step, median of {args.repeats}:   CPU time      wall time")
    print(f"  bare fmpy loop              : {med(bare_cpu) * 1e6:8.2f} us   {med(bare) * 1e6:8.2f} us")
    print(f"  fmugen master               : {med(master_cpu) * 1e6:8.2f} us   {med(master) * 1e6:8.2f} us")
    print(f"  ratio master / bare = {med(master_cpu) / med(bare_cpu):.2f} CPU, {med(master) / med(bare):.2f} wall"
          f"  (goal <= 1.5)")
    print(f"  master without the error estimate: {med(plain_cpu) * 1e6:8.2f} us CPU; the estimate costs "
          f"{100 * (med(master_cpu) / med(plain_cpu) - 1):+.1f} % (goal <= 5 %; {r.summary.estimate_samples} "
          f"shadow windows: {100 * (r.summary.do_steps / plain.summary.do_steps - 1):.1f} % more fmi2DoStep calls)")
    print(f"  same trajectory bit for bit: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
