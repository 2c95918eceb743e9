"""Benchmark: the runtime's looped tree dynamics on the large URDFs of example-robot-data, against Pinocchio.

For each URDF (default: Talos full, 44 DoF fixed base, and Tiago dual, 101 DoF) Pinocchio reads the
file (``pin.buildModelFromUrdf``, fixed base, mimic joints independent); the model's joints --
placements, axes (RX/RY/RZ, unaligned, unbounded/continuous, prismatic), parents -- and inertias
become the body constants of ``c_runtime/chain_dynamics.c`` (:func:`fmugen.codegen.chain.tree_constants`),
so this measures the looped runtime alone, independent of any URDF reader of fmugen.  It

1. checks the forward dynamics and its Jacobian against ``aba`` and ``computeABADerivatives`` at
   ``--states`` random states (relative error, goal 1e-9);
2. times both in alternation (``--repeat`` rounds; CPU time; the C in a compiled loop, Pinocchio from
   Python with the call overhead of a 0-DoF model subtracted, as in bench_large_models.py) and prints
   the ratio (median of the per-round ratios; below 1 the runtime is faster).

3. for the arms (default: UR5, 6 DoF, and the Panda, 9 DoF with its two fingers), read by fmugen's own
   URDF reader, times the generated forward dynamics (the FMU's ``evaluate``; ``--strategy``,
   default straight-line code) and inverse dynamics against ``aba`` and ``rnea`` on Pinocchio's
   reading of the same file, the URDF's numbers folded into constants as Pinocchio has them
   (``--settable``: kept as FMU parameters);
4. with ``--build``, runs ``fmugen build`` of each large URDF in a fresh process (wall and CPU
   time, peak memory).

Run (needs ``pip install pin example-robot-data``):

    python examples/bench_tree_dynamics.py --build
    python examples/bench_tree_dynamics.py --robot talos_data/robots/talos_full_v2.urdf --repeat 9
"""
from __future__ import annotations

import argparse
import ctypes
from dataclasses import replace
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))  # examples/: the benchmarks' shared timing helper
from bench_timing import c_loop, pinocchio_per_call, robots_dir  # noqa: E402
ROBOTS = ["talos_data/robots/talos_full_v2.urdf", "tiago_description/robots/tiago_dual.urdf"]
ARMS = ["ur_description/urdf/ur5_robot.urdf", "panda_description/urdf/panda.urdf"]

TIMER = r"""
#define _POSIX_C_SOURCE 199309L
#include <time.h>
#include <stdlib.h>
#include "chain_dynamics.c"
static double now(void) { struct timespec t; clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
/* seconds per call of the forward dynamics (kind 0) or its Jacobian (kind 1), k calls */
double time_calls(int kind, int k, int n, const int *jt, const double *lc, const double *g, const double *q,
                  const double *qd, const double *tau, double *out, double *work)
{
    double t = now();
    for (int i = 0; i < k; i++) {
        if (kind == 0) fmugen_chain_fd(n, jt, lc, g, q, qd, tau, 0, NULL, NULL, out, out + n, work);
        else fmugen_chain_fd_jacobian(n, jt, lc, g, q, qd, tau, 0, NULL, NULL, out, out + n, out + n + 3 * n * n, work);
    }
    return (now() - t) / k;
}
"""


def tree_of(model):
    """(revolute, parents, body dicts, angle -> pinocchio q) of a fixed-base pinocchio Model."""
    import pinocchio as pin

    revolute, parents, bodies, nq_of = [], [], [], []
    axes = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}
    for j in range(1, model.njoints):
        jm = model.joints[j]
        name = jm.shortname()
        if jm.nv != 1:
            raise ValueError(f"joint {model.names[j]}: {name} (only 1-DoF joints)")
        if name.startswith(("JointModelR", "JointModelP")):
            prismatic = name.startswith("JointModelP")
            tail = name.rstrip("_")[-1]
            if "Unaligned" in name:
                axis = tuple(np.asarray(jm.extract().axis if hasattr(jm, "extract") else jm.axis, float))
            elif tail in axes:
                axis = axes[tail]
            else:
                raise ValueError(f"joint {model.names[j]}: {name}")
        else:
            raise ValueError(f"joint {model.names[j]}: {name}")
        M, I = model.jointPlacements[j], model.inertias[j]
        revolute.append(not prismatic)
        parents.append(model.parents[j] - 1)
        bodies.append(dict(R=M.rotation.copy(), p=M.translation.copy(), axis=axis, mass=I.mass, com=I.lever.copy(),
                           inertia=I.inertia.copy(), rotor_inertia=float(model.armature[j - 1]), damping=0.0))
        nq_of.append(jm.nq)

    def to_q(theta):
        q = []
        for t, k in zip(theta, nq_of):
            q += [np.cos(t), np.sin(t)] if k == 2 else [t]
        return np.array(q)

    return revolute, parents, bodies, to_q


def build(path: Path, tmp: Path) -> dict:
    """``fmugen build`` of the URDF (ME + CS, Jacobian) in a fresh process: wall and CPU seconds (the
    process and its compilers), peak resident memory of the largest of them, the stages it prints."""
    import re
    import resource

    out = tmp / (path.stem + ".fmu")
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-W", "ignore", "-m", "fmugen.cli", "build", str(path), "-o", str(out)],
                       capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    wall = time.perf_counter() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise RuntimeError(f"fmugen build {path} failed:\n{r.stderr}")
    m = re.search(r"derive ([\d.]+) s, generate\+compile\+zip ([\d.]+) s", r.stdout)
    size = out.stat().st_size
    out.unlink()
    return {"wall": wall, "cpu": (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime),
            "peak": c1.ru_maxrss * 1024, "derive": float(m.group(1)) if m else float("nan"),
            "rest": float(m.group(2)) if m else float("nan"), "size": size}


def library(tmp: Path):
    (tmp / "timer.c").write_text(TIMER)
    lib = tmp / "timer.so"
    subprocess.run(["cc", "-std=c99", "-O2", "-fPIC", "-shared", f"-I{ROOT / 'c_runtime'}", "-o", str(lib),
                    str(tmp / "timer.c"), "-lm"], check=True)
    so = ctypes.CDLL(str(lib))
    dp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
    so.time_calls.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, ip] + [dp] * 7
    so.time_calls.restype = ctypes.c_double
    return so


def measure(path: Path, states: int, repeat: int, so) -> dict:
    import pinocchio as pin
    from fmugen.codegen.chain import chain_work_doubles, evaluate_chain, tree_constants

    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    revolute, parents, bodies, to_q = tree_of(model)
    n = len(revolute)
    g = np.asarray(model.gravity.linear, float)
    lc = np.array([float(x) for x in tree_constants(bodies, g)], float)
    rng = np.random.default_rng(0)
    err_fd = err_j = 0.0
    for _ in range(states):
        th, qd, tau = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-5, 5, n)
        q = to_q(th)
        ref = pin.aba(model, data, q, qd, tau)
        fd = evaluate_chain("fd", revolute, np.r_[th, qd, tau, lc], parent=parents)
        err_fd = max(err_fd, np.max(np.abs(fd[:n] - ref)) / np.max(np.abs(ref)))
        jac = evaluate_chain("jacobian", revolute, np.r_[th, qd, tau, lc], parent=parents)
        pin.computeABADerivatives(model, data, q, qd, tau)
        minv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
        refj = np.c_[data.ddq_dq, data.ddq_dv, minv]
        err_j = max(err_j, np.max(np.abs(jac[n:n + 3 * n * n].reshape(n, 3 * n) - refj)) / np.max(np.abs(refj)))
    jt = (ctypes.c_int * (2 * n + 1))(*([1 if r else 0 for r in revolute] + parents + [n - 1]))
    keep = [np.ascontiguousarray(a, float) for a in (lc, np.r_[g, 0, 0, 0], th, qd, tau)]
    out = np.zeros(n + 3 * n * n + 3 * n + 3)
    work = np.zeros(chain_work_doubles(n, "jacobian"))
    dp = ctypes.POINTER(ctypes.c_double)
    ptrs = [a.ctypes.data_as(dp) for a in keep] + [out.ctypes.data_as(dp), work.ctypes.data_as(dp)]
    k_fd = max(1000, int(0.02 / max(so.time_calls(0, 100, n, jt, *ptrs), 1e-9)))
    k_j = max(50, int(0.02 / max(so.time_calls(1, 10, n, jt, *ptrs), 1e-9)))
    r = {"fd": [], "aba": [], "jac": [], "abad": []}
    for _ in range(repeat):
        r["fd"].append(so.time_calls(0, k_fd, n, jt, *ptrs))
        r["aba"].append(pinocchio_per_call(pin.aba, (model, data, q, qd, tau), 1000))
        r["jac"].append(so.time_calls(1, k_j, n, jt, *ptrs))
        r["abad"].append(pinocchio_per_call(pin.computeABADerivatives, (model, data, q, qd, tau), 100))
    med = {k: statistics.median(v) for k, v in r.items()}
    branches = sum(1 for i in range(n) if sum(1 for p in parents if p == i) > 1)
    return {"n": n, "branch points": branches, "err_fd": err_fd, "err_j": err_j, **med,
            "r_fd": statistics.median(np.array(r["fd"]) / np.array(r["aba"])),
            "r_jac": statistics.median(np.array(r["jac"]) / np.array(r["abad"]))}


def arm_speed(path: Path, repeat: int, strategy: str, fold: bool = True) -> dict:
    """Generated FD (the FMU's evaluate, straight-line or looped) and ID (tau = ID(q, qd, qdd)) of the
    robot fmugen reads from ``path`` (fmugen.robot.urdf), against Pinocchio's ``aba`` and ``rnea`` on
    Pinocchio's reading of the same file (CPU µs per call)."""
    import warnings

    import pinocchio as pin
    from fmugen.codegen.benchmarks import pinocchio_urdf_map, to_pinocchio
    from fmugen.codegen.c_code import generate_c
    from fmugen.codegen.c_harness import CompiledModel
    from fmugen.dynamics.manipulator import Manipulator
    from fmugen.robot.urdf import load_urdf

    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # mimic joints read as independent joints, as Pinocchio does
        robot = load_urdf(path)
    mp = pinocchio_urdf_map(model, robot)
    iv = [m[1] for m in mp]
    arm = Manipulator(robot)
    n = robot.n
    # Pinocchio models neither damping nor friction: those parameters at 0 (folded like every other)
    zero = {p.name: 0.0 for p in robot.parameters if p.name.startswith(("b_", "fc_"))}
    t0 = time.process_time()
    fd_model = arm.state_space_model(outputs=(), strategy=strategy).without_jacobian()
    id_model = replace(arm.inverse_dynamics_model(strategy="straight"), jacobian=None, dfdx=None, dfdu=None,
                       dgdx=None, dgdu=None)

    def folded(m):  # the URDF's numbers as constants (fmugen build --fold all), like Pinocchio's
        m = m.with_starts({k: x for k, x in zero.items() if k in {p.name for p in m.parameters}})
        return m.with_parameters_folded() if fold else m

    fd_model, id_model = folded(fd_model), folded(id_model)
    t_derive = time.process_time() - t0
    rng = np.random.default_rng(1)
    th, qd, qdd, tau = (rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n),
                        rng.uniform(-5, 5, n))
    q, v = to_pinocchio(model, mp, th, qd)
    a = to_pinocchio(model, mp, None, qdd)
    taup = np.zeros(model.nv)
    taup[iv] = tau
    p_fd = [] if fold else [v.start for v in fd_model.parameters]
    p_id = [] if fold else [v.start for v in id_model.parameters]

    with CompiledModel.build(generate_c(fd_model).source) as cf, \
            CompiledModel.build(generate_c(id_model).source) as ci:
        dx, _ = cf.evaluate(p_fd, 0.0, np.r_[th, qd], tau, want_y=False)
        ref = pin.aba(model, data, q, v, taup)[iv]
        err_fd = np.max(np.abs(dx[n:] - ref)) / np.max(np.abs(ref))
        _, y = ci.evaluate(p_id, 0.0, [], np.r_[th, qd, qdd])
        ref = pin.rnea(model, data, q, v, a)[iv]
        err_id = np.max(np.abs(y - ref)) / np.max(np.abs(ref))
        r = {"fd": [], "aba": [], "id": [], "rnea": []}
        for _ in range(repeat):
            r["fd"].append(c_loop(cf, p_fd, np.r_[th, qd], tau, "evaluate", 100000))
            r["aba"].append(pinocchio_per_call(pin.aba, (model, data, q, v, taup), 20000))
            r["id"].append(c_loop(ci, p_id, [], np.r_[th, qd, qdd], "evaluate", 100000))
            r["rnea"].append(pinocchio_per_call(pin.rnea, (model, data, q, v, a), 20000))
    med = {k: statistics.median(v) for k, v in r.items()}
    return {"n": n, "derive": t_derive, "err_fd": err_fd, "err_id": err_id, **med,
            "r_fd": statistics.median(np.array(r["fd"]) / np.array(r["aba"])),
            "r_id": statistics.median(np.array(r["id"]) / np.array(r["rnea"]))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robot", action="append", help=f"URDF path under example-robot-data's robots/ "
                                                      f"(default: {', '.join(ROBOTS)})")
    ap.add_argument("--arm", action="append", help=f"URDF whose generated FD and ID are timed against aba and "
                                                    f"rnea (default: {', '.join(ARMS)})")
    ap.add_argument("--strategy", default="straight", choices=["straight", "auto", "loops"],
                    help="code of the arms' forward dynamics (default: straight-line)")
    ap.add_argument("--settable", action="store_true",
                    help="arms: keep the URDF's numbers as FMU parameters (default: folded into constants)")
    ap.add_argument("--build", action="store_true",
                    help="also time `fmugen build` of each --robot (fresh process; wall, CPU, peak memory)")
    ap.add_argument("--states", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    try:
        import pinocchio as pin
        base = robots_dir()
    except ImportError as e:
        print(f"this benchmark needs Pinocchio and example-robot-data ({e}): pip install pin example-robot-data",
              file=sys.stderr)
        return 2
    load = os.getloadavg()
    print(f"{os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; Pinocchio {pin.__version__}")
    print(f"{'robot':<44} {'DoF':>4} {'branch':>6} {'FD µs':>7} {'aba µs':>7} {'ratio':>6} {'Jac µs':>8} "
          f"{'ABAder µs':>9} {'ratio':>6} {'err FD':>8} {'err Jac':>8}")
    ok = True
    with tempfile.TemporaryDirectory(prefix="fmugen_bench_tree_") as tmp:
        so = library(Path(tmp))
        for rel in args.robot or ROBOTS:
            s = measure(base / rel, args.states, args.repeat, so)
            ok = ok and s["err_fd"] < 1e-9 and s["err_j"] < 1e-9
            print(f"{rel:<44} {s['n']:4d} {s['branch points']:6d} {s['fd'] * 1e6:7.2f} {s['aba'] * 1e6:7.2f} "
                  f"{s['r_fd']:6.2f} {s['jac'] * 1e6:8.1f} {s['abad'] * 1e6:9.1f} {s['r_jac']:6.2f} "
                  f"{s['err_fd']:8.1e} {s['err_j']:8.1e}", flush=True)
    print(f"\n== arms: generated forward dynamics ({args.strategy}) and inverse dynamics (straight-line), "
          f"{'parameters settable' if args.settable else 'parameters folded'} ==")
    print(f"{'robot':<44} {'DoF':>4} {'derive s':>8} {'FD µs':>7} {'aba µs':>7} {'ratio':>6} {'ID µs':>7} "
          f"{'rnea µs':>7} {'ratio':>6} {'err FD':>8} {'err ID':>8}")
    for rel in args.arm or ARMS:
        a = arm_speed(base / rel, args.repeat, args.strategy, fold=not args.settable)
        ok = ok and a["err_fd"] < 1e-9 and a["err_id"] < 1e-9
        print(f"{rel:<44} {a['n']:4d} {a['derive']:8.2f} {a['fd'] * 1e6:7.2f} {a['aba'] * 1e6:7.2f} "
              f"{a['r_fd']:6.2f} {a['id'] * 1e6:7.2f} {a['rnea'] * 1e6:7.2f} {a['r_id']:6.2f} "
              f"{a['err_fd']:8.1e} {a['err_id']:8.1e}", flush=True)
    if args.build:
        print("\n== fmugen build of the URDF (ME + CS with the Jacobian; fresh process; peak: the largest "
              "process) ==")
        print(f"{'robot':<44} {'wall s':>7} {'CPU s':>6} {'derive s':>8} {'gen+cc+zip s':>12} {'peak MB':>8} "
              f"{'FMU kB':>7}")
        with tempfile.TemporaryDirectory(prefix="fmugen_bench_tree_build_") as tmp:
            for rel in args.robot or ROBOTS:
                b = build(base / rel, Path(tmp))
                print(f"{rel:<44} {b['wall']:7.1f} {b['cpu']:6.1f} {b['derive']:8.2f} {b['rest']:12.2f} "
                      f"{b['peak'] / 2**20:8.0f} {b['size'] / 1024:7.0f}", flush=True)
    print(f"check against Pinocchio (relative, 1e-9): {'ok' if ok else 'FAILED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
