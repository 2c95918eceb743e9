"""Benchmark: states per second per core of fmugen.batch's fd and fd_derivatives, against Pinocchio.

For each robot (iiwa of GRiDBenchmarks -- https://github.com/robot-acceleration/GRiDBenchmarks, folder
urdfs/, passed with ``--grid`` -- and UR5, Panda and Talos full v2 of example-robot-data), batches of N =
1, 16, 256, 4096 random states go through one call of :class:`fmugen.batch.Kernels` with ``threads`` 1 and
2 -- the runtime's loops, and the code generated for the robot (``Kernels.unrolled()``, built before the
timing) --, against

* a Python loop of Pinocchio calls (``aba``, ``computeABADerivatives``) over the same states -- what a
  Python user of Pinocchio writes; the loop's interpreter cost is part of it, as it is of the user's;
* Pinocchio's own batched call where its Python interface has one: ``abaInParallel`` (a ``ModelPool``,
  OpenMP threads; this build of Pinocchio has it and ``rneaInParallel``, none for the derivatives).

Per core: states per CPU-second of the process (``time.process_time``, every thread's time), so two
threads on two cores give the figure of one if they scale; the wall-clock rate is printed beside it (on a
machine shared with other work it says little).  Each figure is the median of ``--repeat`` rounds, the
contenders alternating within a round.  Both read the same URDF (fmugen's reader, Pinocchio's); the files'
joint damping and friction are set to 0, which Pinocchio does not model.

Run (needs ``pip install pin example-robot-data``):

    python examples/bench_batch.py --grid path/to/GRiDBenchmarks/urdfs --repeat 5
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_derivatives import robots_dir, runtime_version  # noqa: E402

ERD_ROBOTS = {"ur5": "ur_description/urdf/ur5_robot.urdf", "panda": "panda_description/urdf/panda.urdf",
              "talos": "talos_data/robots/talos_full_v2.urdf"}
SIZES = (1, 16, 256, 4096)
BUDGET = 0.05  # CPU seconds per timing at least: long against the clock's resolution


def rate(fn, count: int) -> tuple:
    """(states per CPU-second, states per wall-second) of ``fn()``, which does ``count`` states, repeated
    until BUDGET CPU seconds have passed."""
    calls, c0, w0 = 0, time.process_time(), time.perf_counter()
    while True:
        fn()
        calls += 1
        c, w = time.process_time() - c0, time.perf_counter() - w0
        if c >= BUDGET:
            return calls * count / c, calls * count / w


def measure(path: Path, repeat: int, sizes) -> tuple:
    import pinocchio as pin
    from fmugen.batch import Kernels
    from fmugen.codegen.benchmarks import pinocchio_urdf_map, to_pinocchio
    from fmugen.robot.urdf import load_urdf

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = load_urdf(path)
    zero = {p.name: 0.0 for p in robot.parameters if p.name.startswith(("b_", "fc_"))}
    kernels = Kernels.from_robot(robot, values=zero)
    two = Kernels.from_robot(robot, values=zero, threads=2)  # its own worker thread, started once
    unrolled = {1: kernels.unrolled(threads=1), 2: kernels.unrolled(threads=2)}  # generated code (cached)
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    mp = pinocchio_urdf_map(model, robot)
    iv = [m[1] for m in mp]
    n = kernels.n
    pool = pin.ModelPool(model, 2) if hasattr(pin, "abaInParallel") else None
    rows = []
    rng = np.random.default_rng(0)
    for N in sizes:
        q, qd, tau = rng.uniform(-1, 1, (N, n)), rng.uniform(-1, 1, (N, n)), rng.uniform(-3, 3, (N, n))
        pq = [to_pinocchio(model, mp, q[k], qd[k]) for k in range(N)]
        pt = []
        for k in range(N):
            t = np.zeros(model.nv)
            t[iv] = tau[k]
            pt.append(t)
        # Pinocchio's batch: one state per column
        Q = np.asfortranarray(np.array([a for a, _ in pq]).T)
        V = np.asfortranarray(np.array([b for _, b in pq]).T)
        T = np.asfortranarray(np.array(pt).T)
        A = np.asfortranarray(np.zeros((model.nv, N)))
        # the batch agrees with Pinocchio before it is timed
        assert np.max(np.abs(kernels.fd(q, qd, tau)[0] - pin.aba(model, data, *pq[0], pt[0])[iv])) < 1e-9 * max(
            1.0, np.max(np.abs(pin.aba(model, data, *pq[0], pt[0]))))

        def loop_aba():
            for k in range(N):
                pin.aba(model, data, pq[k][0], pq[k][1], pt[k])

        def loop_abad():
            for k in range(N):
                pin.computeABADerivatives(model, data, pq[k][0], pq[k][1], pt[k])

        contenders = {}
        for th, kern in ((1, kernels), (2, two)):
            contenders[("fd", f"fmugen.batch, threads {th}")] = lambda kern=kern: kern.fd(q, qd, tau)
            contenders[("fd_derivatives", f"fmugen.batch, threads {th}")] = \
                lambda kern=kern: kern.fd_derivatives(q, qd, tau)
            contenders[("fd", f"fmugen.batch unrolled, threads {th}")] = lambda u=unrolled[th]: u.fd(q, qd, tau)
            contenders[("fd_derivatives", f"fmugen.batch unrolled, threads {th}")] = \
                lambda u=unrolled[th]: u.fd_derivatives(q, qd, tau)
            if pool is not None:
                contenders[("fd", f"pinocchio.abaInParallel, threads {th}")] = \
                    lambda th=th: pin.abaInParallel(th, pool, Q, V, T, A)
        contenders[("fd", "Python loop of pinocchio.aba")] = loop_aba
        contenders[("fd_derivatives", "Python loop of pinocchio.computeABADerivatives")] = loop_abad
        res = {k: ([], []) for k in contenders}
        for _ in range(repeat):
            for k, fn in contenders.items():
                c, w = rate(fn, N)
                res[k][0].append(c)
                res[k][1].append(w)
        for (what, who), (c, w) in res.items():
            rows.append((N, what, who, statistics.median(c), statistics.median(w)))
    kernels.close()
    two.close()
    for u in unrolled.values():
        u.close()
    return n, rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--grid", type=Path, help="folder with GRiDBenchmarks' iiwa.urdf "
                                              "(https://github.com/robot-acceleration/GRiDBenchmarks, urdfs/)")
    ap.add_argument("--robot", action="append", choices=["iiwa", *ERD_ROBOTS], help="default: all found")
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), help="batch sizes N")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    try:
        import pinocchio as pin
        erd = robots_dir()
    except ImportError as e:
        print(f"this benchmark needs Pinocchio and example-robot-data ({e}): pip install pin example-robot-data",
              file=sys.stderr)
        return 2
    load = os.getloadavg()
    print(f"{os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; {runtime_version()}; "
          f"Pinocchio "
          f"{pin.__version__}; batched call in Pinocchio's Python interface: "
          f"{'abaInParallel (no derivatives)' if hasattr(pin, 'abaInParallel') else 'none'}; "
          f"{args.repeat} rounds, medians\n")
    paths = {}
    if args.grid is not None and (args.grid / "iiwa.urdf").is_file():
        paths["iiwa"] = args.grid / "iiwa.urdf"
    elif args.robot is None or "iiwa" in args.robot:
        print("(iiwa: no iiwa.urdf -- pass --grid with GRiDBenchmarks' urdfs/ folder)", file=sys.stderr)
    paths.update({k: erd / v for k, v in ERD_ROBOTS.items()})
    print("| Robot | DoF | N | algorithm | code | states / CPU-s | states / wall-s | vs Python loop (CPU) |")
    print("|---|---:|---:|---|---|---:|---:|---:|")
    for name, path in paths.items():
        if args.robot is not None and name not in args.robot:
            continue
        n, rows = measure(path, args.repeat, args.sizes)
        loops = {(N, what): c for N, what, who, c, _ in rows if who.startswith("Python loop")}
        for N, what, who, c, w in rows:
            print(f"| {name} | {n} | {N} | {what} | {who} | {c:,.0f} | {w:,.0f} | {c / loops[(N, what)]:.1f}x |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
