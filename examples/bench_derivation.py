"""Benchmark: symbolic derivation time against the number of links.

Derives M(q), h(q, qd) and the 6 x N Jacobian with both formulations for
N-link spatial chains (every non-zero quantity a named parameter, as from a
robot file) and for the thesis PUMA, and fits the growth exponent of the
time against N.  Run:

    python examples/bench_derivation.py            # N = 2 4 6 12 24 48
    python examples/bench_derivation.py --sizes 2 4 6 12 --repeat 3

Reports the median of ``--repeat`` runs (one process, one run after another).
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from fmugen.dynamics.manipulator import Manipulator
from fmugen.robot.chain import n_link_chain
from fmugen.robot.loader import load_robot_description

ROOT = Path(__file__).resolve().parents[1]


def derive_all(robot) -> dict:
    """Seconds for M + h + J per formulation, and the program sizes."""
    out = {}
    arm = Manipulator(robot)
    for formulation in ("newton_euler", "lagrange"):
        t0 = time.perf_counter()
        Pm, _ = arm.mass_matrix_program(formulation)
        Ph, _ = arm.bias_program(formulation)
        Pk, _, _ = arm.kinematics_program()
        out[formulation] = (time.perf_counter() - t0, len(Pm.steps) + len(Ph.steps) + len(Pk.steps))
    return out


def median_times(make_robot, repeat: int) -> dict:
    runs = [derive_all(make_robot()) for _ in range(repeat)]
    return {f: (statistics.median(r[f][0] for r in runs), runs[0][f][1]) for f in runs[0]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[2, 4, 6, 12, 24, 48])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)

    print("derivation of M, h and J (median of %d runs)" % args.repeat)
    print(f"{'robot':>14} {'NE [s]':>9} {'steps':>7} {'Lagrange [s]':>13} {'steps':>7} {'both [s]':>9}")
    rows = []
    for n in args.sizes:
        t = median_times(lambda: n_link_chain(n, "R", symbolic=True), args.repeat)
        ne, la = t["newton_euler"], t["lagrange"]
        rows.append((n, ne[0], la[0]))
        print(f"{'chain N=%d' % n:>14} {ne[0]:9.3f} {ne[1]:7d} {la[0]:13.3f} {la[1]:7d} {ne[0] + la[0]:9.3f}")
    t = median_times(lambda: load_robot_description(ROOT / "robots" / "puma_thesis_com.toml"), args.repeat)
    ne, la = t["newton_euler"], t["lagrange"]
    print(f"{'PUMA (thesis)':>14} {ne[0]:9.3f} {ne[1]:7d} {la[0]:13.3f} {la[1]:7d} {ne[0] + la[0]:9.3f}")
    ns = np.array([r[0] for r in rows if r[0] >= 4], dtype=float)
    if len(ns) >= 2:
        for k, name in ((1, "Newton-Euler"), (2, "Lagrange")):
            ts = np.array([r[k] for r in rows if r[0] >= 4])
            slope = np.polyfit(np.log(ns), np.log(ts), 1)[0]
            print(f"fitted growth exponent (N >= 4), {name}: time ~ N^{slope:.2f}")


if __name__ == "__main__":
    main()
