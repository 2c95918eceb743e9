"""Exact events against smoothed kinks: stick-slip friction and backlash, two ways, side by side.

1. lib:stick_slip (an inertia with exact Coulomb stick-slip, modes and events) against lib:stribeck (the
   same numbers, J = 0.05 kg.m2, T_c = 2, T_s = 3 N.m, b = 0.02, with the smoothed sign of width w_eps =
   1e-3 rad/s), each as a CS FMU with Dormand-Prince: a constant torque of 2.5 N.m (below breakaway) for
   100 s -- the physical shaft never moves -- and 3.5 N.m (above) against the closed form
   phi(t) = a/k t - a/k^2 (1 - exp(-k t)), a = (tau - T_c)/J, k = b/J.
2. The PUMA shoulder held by a drive with stick-slip motor friction and gear backlash
   (examples/scenes/puma_geared_drive_hybrid.toml), power off until the path starts at 0.3 s, then moved,
   co-simulated with Newton/cubic at 10 ms against its hybrid reference; and the same scene on the
   smoothed twin of the drive (puma_geared_drive_smooth.toml) against its own reference and against the
   hybrid reference (what the smoothing costs).

    python examples/hybrid_drive_table.py [--out DIR]

Times are medians of repeated runs in this process (wall, one core); ratios are the point.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import fmugen
from fmugen.cosim import run, solve_reference

ROOT = Path(__file__).resolve().parents[1]
J, T_C, T_S, B = 0.05, 2.0, 3.0, 0.02


def shaft_runs(out: Path, repeat: int = 5) -> list:
    from fmpy import simulate_fmu

    from fmugen.components.equations import library_path, load_component

    rows = []
    for name in ("stick_slip", "stribeck"):
        fmu = out / f"{name}.fmu"
        fmugen.build_fmu(load_component(library_path(name)), fmu, fmi_type="cs")
        for tau in (2.5, 3.5):
            walls, r = [], None
            for _ in range(repeat):
                w = time.perf_counter()
                r = simulate_fmu(str(fmu), fmi_type="CoSimulation", stop_time=100.0 if tau < 3 else 2.0,
                                 output_interval=0.01, start_values={"tau": tau, "solver.rtol": 1e-10},
                                 output=["phi", "solver.n_steps", "solver.stiffness_detected"],
                                 logger=lambda *args: None)  # the stiffness warning is in the table
                walls.append(time.perf_counter() - w)
            t = r["time"]
            if tau < 3:
                exact = np.zeros_like(t)
            else:
                a, k = (tau - T_C) / J, B / J
                exact = a / k * t - a / k ** 2 * (1 - np.exp(-k * t))
            rows.append({"model": f"lib:{name}", "tau": tau, "T": t[-1], "phi_end": float(r["phi"][-1]),
                         "err": float(np.abs(r["phi"] - exact).max()), "steps": int(r["solver.n_steps"][-1]),
                         "stiff": int(r["solver.stiffness_detected"][-1]),
                         "wall": statistics.median(walls), "doSteps": len(t) - 1})
    return rows


def drive_runs(out: Path, repeat: int = 3) -> list:
    t = np.linspace(0.0, 1.0, 101)
    scenes = {k: fmugen.load_scene(ROOT / "examples" / "scenes" / f"puma_geared_drive_{k}.toml")
              for k in ("hybrid", "smooth")}
    refs = {k: solve_reference(s.reference_problem(), times=t) for k, s in scenes.items()}
    rows = []
    for k, sc in scenes.items():
        built = sc.build(out / k)
        walls, r = [], None
        for _ in range(repeat):
            w = time.perf_counter()
            r = run(built.system, "newton", "cubic", step=0.01)
            walls.append(time.perf_counter() - w)
        idx = np.rint(r.time / 0.01).astype(int)
        q, hold = r["arm.q[2]"], r.time <= 0.3 + 1e-9
        rows.append({"scene": sc.name, "status": r.summary.status,
                     "creep": float(np.abs(q[hold] - q[0]).max()),
                     "err_own": float(np.abs(q - refs[k]["arm.q[2]"][idx]).max()),
                     "err_exact": float(np.abs(q - refs["hybrid"]["arm.q[2]"][idx]).max()),
                     "ref_err": refs[k].error_of("arm.q[2]"), "events": r.summary.events,
                     "doSteps": r.summary.do_steps, "iterations": r.summary.iterations,
                     "wall": statistics.median(walls)})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None, help="folder for the FMUs (default: a temporary one)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out or tmp)
        out.mkdir(parents=True, exist_ok=True)
        print("1. a shaft with friction, constant torque (CS FMU, Dormand-Prince, rtol 1e-10, 10 ms steps)")
        print(f"{'model':16s} {'tau':>5s} {'T [s]':>6s} {'phi(T) [rad]':>14s} {'|err| [rad]':>12s} "
              f"{'solver steps':>12s} {'stiff':>6s} {'wall [s]':>9s} {'us/doStep':>10s}")
        rows = shaft_runs(out)
        for r in rows:
            print(f"{r['model']:16s} {r['tau']:5.1f} {r['T']:6.0f} {r['phi_end']:14.6g} {r['err']:12.3g} "
                  f"{r['steps']:12d} {r['stiff']:6d} {r['wall']:9.4f} {1e6 * r['wall'] / r['doSteps']:10.1f}")
        print("\n2. PUMA shoulder on a stick-slip drive with backlash, power off to 0.3 s, then moved "
              "(newton/cubic, 10 ms)")
        print(f"{'scene':28s} {'status':7s} {'creep 0-0.3 s':>14s} {'err own ref':>12s} {'err exact':>10s} "
              f"{'ref err':>9s} {'events':>7s} {'doSteps':>8s} {'iters':>6s} {'wall [s]':>9s}")
        drows = drive_runs(out)
        for r in drows:
            print(f"{r['scene']:28s} {r['status']:7s} {r['creep']:14.3g} {r['err_own']:12.3g} {r['err_exact']:10.3g} "
                  f"{r['ref_err']:9.2g} {r['events']:7d} {r['doSteps']:8d} {r['iterations']:6d} {r['wall']:9.4f}")
        hyb, smo = drows
        print(f"\nwall time smooth / hybrid: {smo['wall'] / hyb['wall']:.2f}; the smoothed drive's creep while "
              f"held: {smo['creep']:.3g} rad (hybrid {hyb['creep']:.3g}); its departure from the exact physics "
              f"{smo['err_exact']:.3g} rad")
    ok = rows[0]["phi_end"] == 0.0 and hyb["creep"] < 1e-12 and hyb["status"] == "ok"
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
