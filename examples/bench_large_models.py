"""Benchmark: large arms -- build time and memory, code size, and speed against Pinocchio.

For every N of ``--sizes`` (an N-link spatial chain, ``fmugen.robot.chain``,
random realisable values) this

1. runs ``fmugen build`` of the ME + CS FMU (Jacobian included) in a fresh
   process and reports its stages (derive, generate, compile, zip: wall
   seconds), the CPU time of the build and its compilers, the peak resident
   memory (largest of the Python process and any compiler it ran), the lines
   of ``model.c``, and the operation counts of ``evaluate`` and ``jacobian``
   (straight-line code plus the runtime's loops, :func:`fmugen.codegen.chain.chain_ops`);
2. compiles the same model.c into a test harness, checks the forward
   dynamics and its Jacobian against Pinocchio's ``aba`` and
   ``computeABADerivatives`` at ``--states`` random states, and times both
   in alternation (``--repeat`` rounds, CPU time; the C in a compiled loop,
   Pinocchio from Python with its call overhead -- the same call on a 0-DOF
   model -- subtracted) and prints the ratios (median of the per-round
   ratios: below 1, the generated C is faster);
3. fits the growth exponent of each column against N (N >= 12).

The strategy is the default one (``state_space_model(strategy="auto")``:
straight-line code below ``LOOP_MIN_LINKS`` links, the runtime's loops from
there on); ``--strategy straight`` measures straight-line code at every N
(minutes per build beyond ~10 links) -- how the crossover was chosen.
Nothing is written into the repository.  Run:

    python examples/bench_large_models.py                       # N = 6 12 24 48 60
    python examples/bench_large_models.py --sizes 6,8,10 --strategy straight
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))  # examples/: the benchmarks' shared timing helper
from bench_timing import c_loop, pinocchio_per_call  # noqa: E402

#: the build, in a fresh process: prints one JSON line of its own measurements
BUILD = r"""
import json, resource, sys, time, zipfile
t0 = time.perf_counter()
from fmugen.dynamics.manipulator import Manipulator
from fmugen.fmi.build import build_fmu
from fmugen.robot.chain import n_link_chain
n, strategy, out = int(sys.argv[1]), sys.argv[2], sys.argv[3]
t1 = time.perf_counter()
model = Manipulator(n_link_chain(n, seed=1)).state_space_model(outputs=("p_ee",), strategy=strategy)
t2 = time.perf_counter()
res = build_fmu(model, out, fmi_type="both", progress=False)
t3 = time.perf_counter()
with zipfile.ZipFile(out) as z:
    lines = z.read("sources/model.c").decode().count("\n")
ops = {k: [v.total.mul, v.total.add, v.total.div] for k, v in res.op_counts.items()}
print(json.dumps({"import": t1 - t0, "derive": t2 - t1, **res.timings, "total": t3 - t0, "lines": lines,
                  "ops": ops, "maxrss_self": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
"""


def run_build(n: int, strategy: str, tmp: Path, timeout: float) -> dict:
    """One ``fmugen build`` in a fresh process; wall/CPU/peak memory of it and its compilers."""
    out = tmp / f"chain{n}.fmu"
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", BUILD, str(n), strategy, str(out)], capture_output=True, text=True,
                       timeout=timeout)
    wall = time.perf_counter() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise RuntimeError(f"build of N={n} failed:\n{r.stderr}")
    d = json.loads(r.stdout.strip().splitlines()[-1])
    d["wall"] = wall
    d["cpu"] = (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)
    # ru_maxrss of the children: the largest single descendant so far (python or a compiler)
    d["peak"] = max(d["maxrss_self"], c1.ru_maxrss * 1024)
    out.unlink()
    return d


def speed(n: int, strategy: str, states: int, repeat: int, pin) -> dict:
    """Agreement with Pinocchio and CPU µs per call of FD and its Jacobian, both sides."""
    from fmugen.codegen.benchmarks import pinocchio_model
    from fmugen.codegen.c_code import generate_c
    from fmugen.codegen.c_harness import CompiledModel
    from fmugen.dynamics.manipulator import Manipulator
    from fmugen.robot.chain import n_link_chain

    robot = n_link_chain(n, seed=1)
    model = Manipulator(robot).state_space_model(outputs=(), strategy=strategy)
    pm = pinocchio_model(robot)
    pd = pm.createData()
    rng = np.random.default_rng(0)
    err_fd = err_j = 0.0
    with CompiledModel.build(generate_c(model).source) as cm:
        p = np.array([v.start for v in model.parameters], float)
        for _ in range(states):
            q, qd, tau = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-30, 30, n)
            dx, _ = cm.evaluate(p, 0.0, np.r_[q, qd], tau, want_y=False)
            ref = pin.aba(pm, pd, q, qd, tau)
            err_fd = max(err_fd, np.max(np.abs(dx[n:] - ref)) / np.max(np.abs(ref)))
            A, B, _, _ = cm.jacobian(p, 0.0, np.r_[q, qd], tau)
            pin.computeABADerivatives(pm, pd, q, qd, tau)
            minv = np.triu(pd.Minv) + np.triu(pd.Minv, 1).T
            refj = np.c_[pd.ddq_dq, pd.ddq_dv, minv]
            err_j = max(err_j, np.max(np.abs(np.c_[A[n:], B[n:]] - refj)) / np.max(np.abs(refj)))
        x, u = np.r_[q, qd], tau
        def cloop(which, k):
            return c_loop(cm, p, x, u, which, k)

        k_fd = max(2000, int(0.02 / max(cloop("evaluate", 200), 1e-9)))
        k_j = max(200, int(0.02 / max(cloop("jacobian", 20), 1e-9)))
        rounds = {"fd": [], "jac": [], "aba": [], "abad": []}
        for _ in range(repeat):
            rounds["fd"].append(cloop("evaluate", k_fd))
            rounds["aba"].append(pinocchio_per_call(pin.aba, (pm, pd, q, qd, tau), 2000))
            rounds["jac"].append(cloop("jacobian", k_j))
            rounds["abad"].append(pinocchio_per_call(pin.computeABADerivatives, (pm, pd, q, qd, tau), 300))
    med = {k: statistics.median(v) for k, v in rounds.items()}
    return {"err_fd": err_fd, "err_j": err_j, **med,
            "r_fd": statistics.median(np.array(rounds["fd"]) / np.array(rounds["aba"])),
            "r_jac": statistics.median(np.array(rounds["jac"]) / np.array(rounds["abad"]))}


def exponent(ns, ys) -> str:
    pts = [(n, y) for n, y in zip(ns, ys) if n >= 12 and y > 0]
    if len(pts) < 2:
        return "  -"
    return f"{np.polyfit(np.log([a for a, _ in pts]), np.log([b for _, b in pts]), 1)[0]:5.2f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.split("\n")[2:]))
    ap.add_argument("--sizes", default="6,12,24,48,60", help="comma-separated numbers of links")
    ap.add_argument("--strategy", default="auto", choices=["auto", "straight", "loops"])
    ap.add_argument("--repeat", type=int, default=7, help="timing rounds (median reported)")
    ap.add_argument("--states", type=int, default=3, help="random states of the check against Pinocchio")
    ap.add_argument("--timeout", type=float, default=1800, help="seconds allowed per build")
    ap.add_argument("--no-build", action="store_true", help="only the speed and agreement part")
    args = ap.parse_args(argv)
    try:
        sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    except ValueError:
        ap.error(f"--sizes {args.sizes!r}: comma-separated integers, e.g. 6,12,24")
    try:
        import pinocchio as pin
    except ImportError:
        print("this benchmark needs Pinocchio: pip install pin", file=sys.stderr)
        return 2
    from fmugen.codegen.chain import LOOP_MIN_LINKS

    load = os.getloadavg()
    print(f"{os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; strategy "
          f"{args.strategy} (auto: loops from {LOOP_MIN_LINKS} links); Pinocchio {pin.__version__}")
    rows = []
    ok = True
    with tempfile.TemporaryDirectory(prefix="fmugen_bench_large_") as tmp:
        for n in sizes:
            b = {} if args.no_build else run_build(n, args.strategy, Path(tmp), args.timeout)
            s = speed(n, args.strategy, args.states, args.repeat, pin)
            ok = ok and s["err_fd"] < 1e-10 and s["err_j"] < 1e-10
            rows.append((n, b, s))
            print(f"N={n}: " + (f"build {b['wall']:.1f} s wall, {b['cpu']:.1f} s CPU, " if b else "")
                  + f"FD {s['fd'] * 1e6:.2f} µs ({s['r_fd']:.2f}x ABA), Jacobian {s['jac'] * 1e6:.1f} µs "
                    f"({s['r_jac']:.2f}x ABA derivatives)", flush=True)

    print("\n== build (fmugen build, ME + CS, Jacobian included; fresh process) ==")
    print(f"{'N':>4} {'derive':>7} {'generate':>9} {'compile':>8} {'zip':>5} {'wall':>7} {'CPU':>7} {'peak MB':>8} "
          f"{'model.c':>8} {'evaluate mul/add':>17} {'jacobian mul/add':>17}")
    for n, b, _ in rows:
        if b:
            e, j = b["ops"]["evaluate"], b["ops"].get("jacobian", [0, 0, 0])
            print(f"{n:4d} {b['derive']:7.2f} {b['generate']:9.2f} {b['compile']:8.2f} {b['zip']:5.2f} "
                  f"{b['wall']:7.2f} {b['cpu']:7.2f} {b['peak'] / 2**20:8.0f} {b['lines']:8d} "
                  f"{e[0]:>8d}/{e[1]:<8d} {j[0]:>8d}/{j[1]:<8d}")
    print("\n== speed (CPU µs per call, median of rounds; ratio: generated C / Pinocchio, median per round) ==")
    print(f"{'N':>4} {'FD C':>8} {'pin.aba':>8} {'ratio':>6} {'Jac C':>8} {'pin.ABAder':>10} {'ratio':>6} "
          f"{'err FD':>8} {'err Jac':>8}")
    for n, _, s in rows:
        print(f"{n:4d} {s['fd'] * 1e6:8.2f} {s['aba'] * 1e6:8.2f} {s['r_fd']:6.2f} {s['jac'] * 1e6:8.1f} "
              f"{s['abad'] * 1e6:10.1f} {s['r_jac']:6.2f} {s['err_fd']:8.1e} {s['err_j']:8.1e}")
    ns = [n for n, _, _ in rows]
    print("\ngrowth exponents fitted from N >= 12 (y ~ N^k):")
    if not args.no_build:
        for key, what in (("wall", "build wall time"), ("cpu", "build CPU time"), ("peak", "peak memory"),
                          ("lines", "model.c lines")):
            print(f"  {what:<22} {exponent(ns, [b[key] for _, b, _ in rows])}")
        print(f"  {'jacobian mul':<22} {exponent(ns, [b['ops'].get('jacobian', [0])[0] for _, b, _ in rows])}")
    print(f"  {'FD µs':<22} {exponent(ns, [s['fd'] for _, _, s in rows])}")
    print(f"  {'Jacobian µs':<22} {exponent(ns, [s['jac'] for _, _, s in rows])}")
    print(f"check against Pinocchio (relative, 1e-10): {'ok' if ok else 'FAILED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
