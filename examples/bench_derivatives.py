"""Benchmark: ID, M, M^-1, FD, ∇ID and ∇FD of the runtime's looped tree dynamics against Pinocchio, per robot,
beside the CPU and GPU figures GRiD published.

The robots are those of GRiDBenchmarks (iiwa, HyQ, Atlas: their URDFs, fixed base; the files are not part
of fmugen -- get them from https://github.com/robot-acceleration/GRiDBenchmarks, folder urdfs/, and pass
the folder with ``--grid``) and of example-robot-data (UR5, Panda, Talos full v2, Tiago, Tiago dual).
Each file is read twice: by fmugen's URDF reader (:func:`fmugen.robot.urdf.load_urdf`) into the body
constants of ``c_runtime/chain_dynamics.c`` (:class:`fmugen.batch.Kernels`; the files' joint damping and
friction set to 0, which Pinocchio does not model) and by Pinocchio (``buildModelFromUrdf``, fixed base).

1. every algorithm's result, through the batched entry point (fmugen.batch), is checked against
   Pinocchio's at ``--states`` random states (relative error, goal 1e-9): ``rnea``, ``crba``,
   ``computeMinverse``, ``aba``, ``computeRNEADerivatives`` (dtau_dq, dtau_dv) and
   ``computeABADerivatives`` (ddq_dq, ddq_dv, Minv);
2. each algorithm is timed in alternation with Pinocchio's (``--repeat`` rounds, CPU time): the runtime's
   C functions called in a compiled C loop -- ``fmugen_chain_id``, ``fmugen_chain_fd``,
   ``fmugen_chain_id_jacobian``, ``fmugen_chain_fd_jacobian``, ``fmugen_chain_mass_matrix`` (composite rigid
   bodies) and ``fmugen_chain_mass_matrix_inverse`` (the tree factorisation M = L^T L), as ``fmugen.batch``
   computes them by default -- and Pinocchio from Python with
   the call overhead of a 0-DoF model subtracted (examples/bench_timing.py).  Printed: medians of the
   rounds, and the median of the per-round ratios fmugen / Pinocchio (below 1: fmugen faster).

Every robot runs on the looped runtime.  A robot of 6 DoF or fewer (the UR5) gets straight-line code in
its FMU by default, so for those a second table times the generated straight-line code too (the URDF's
numbers folded into constants, as Pinocchio has them; compiled with -O2 and called in a C loop): FD and
∇FD are the FMU's ``evaluate`` and ``jacobian`` (dfdx, dfdu hold ∂qdd/∂q, ∂qdd/∂qd and M^-1), ID and ∇ID
those of the inverse-dynamics model (dtau/du = [∂tau/∂q, ∂tau/∂qd, M]), M the lower triangle of the mass
matrix model (fmugen.codegen.benchmarks); there is no straight-line M^-1.  ``--no-straight`` skips it
(deriving and compiling the straight-line Jacobians takes a minute).

``--unrolled`` adds a table of the per-robot unrolled code -- the forward dynamics
(:mod:`fmugen.codegen.unrolled_aba`: the articulated-body algorithm) and the Jacobians of the inverse and
forward dynamics (:mod:`fmugen.codegen.unrolled_derivatives`) as straight-line C with the robot's numbers
folded, one file each, compiled with -O2: C lines, generation and compile seconds, µs per call beside the
looped runtime's and Pinocchio's (``aba``, ``computeRNEADerivatives``, ``computeABADerivatives``) timed in
alternation, and the error against Pinocchio; ``--unrolled-only`` prints that table alone.

GRiD's figures (Plancher et al., "GRiD: GPU-Accelerated Rigid Body Dynamics with Analytical Gradients",
ICRA 2022; the GRiDBenchmarks README) are µs per call on another machine -- an i7-10700K at 3.8 GHz
(CPU: Pinocchio) and an RTX 3080 (GPU: GRiD) -- printed as context, not as a comparison of this run.

Run (needs ``pip install pin example-robot-data``):

    python examples/bench_derivatives.py --grid path/to/GRiDBenchmarks/urdfs --repeat 5
"""
from __future__ import annotations

import argparse
import ctypes
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # examples/: the benchmarks' shared timing helper
from bench_timing import per_call, robots_dir  # noqa: E402

GRID_ROBOTS = {"iiwa": "iiwa.urdf", "hyq": "hyq.urdf", "atlas": "atlas.urdf"}
ERD_ROBOTS = {"ur5": "ur_description/urdf/ur5_robot.urdf", "panda": "panda_description/urdf/panda.urdf",
              "talos": "talos_data/robots/talos_full_v2.urdf", "tiago": "tiago_description/robots/tiago.urdf",
              "tiago_dual": "tiago_description/robots/tiago_dual.urdf"}
ALGORITHMS = ("ID", "M", "Minv", "FD", "∇ID", "∇FD")
PINOCCHIO = {"ID": "rnea", "M": "crba", "Minv": "computeMinverse", "FD": "aba", "∇ID": "computeRNEADerivatives",
             "∇FD": "computeABADerivatives"}
# GRiDBenchmarks README: µs per call, i7-10700K 3.8 GHz (Pinocchio) and RTX 3080 (GRiD); no row for M
GRID_CPU = {"ID": (0.3, 0.3, 1.1), "Minv": (0.5, 0.8, 3.4), "FD": (0.9, 1.2, 5.3), "∇ID": (1.4, 2.1, 9.8),
            "∇FD": (2.9, 4.3, 20.9)}
GRID_GPU = {"ID": (3.0, 3.2, 8.0), "Minv": (5.2, 5.6, 17.4), "FD": (7.7, 6.9, 22.4), "∇ID": (6.3, 5.8, 19.5),
            "∇FD": (12.9, 11.0, 42.1)}

TIMER = r"""
#define _POSIX_C_SOURCE 199309L
#include <time.h>
#include <string.h>
#include "chain_dynamics.c"
static double now(void) { struct timespec t; clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
/* CPU seconds per call of algorithm `kind` (0 ID, 1 M, 2 Minv, 3 FD, 4 dID, 5 dFD) over k calls;
 * z: n zeros (unused since M and M^-1 have their own functions); out: n + 3 n^2 doubles */
double time_calls(int kind, int k, int n, const int *jt, const double *lc, const double *g, const double *q,
                  const double *qd, const double *x, const double *z, double *out, double *work)
{
    double t = now();
    for (int i = 0; i < k; i++) {
        switch (kind) {
        case 0: fmugen_chain_id(n, jt, lc, g, q, qd, x, 0, NULL, NULL, out, work); break;
        case 1: fmugen_chain_mass_matrix(n, jt, lc, g, q, out, work); break;
        case 2: fmugen_chain_mass_matrix_inverse(n, jt, lc, g, q, out, work); break;
        case 3: fmugen_chain_fd(n, jt, lc, g, q, qd, x, 0, NULL, NULL, out, NULL, work); break;
        case 4: fmugen_chain_id_jacobian(n, jt, lc, g, q, qd, x, 0, NULL, NULL, out, out + n, work); break;
        default: fmugen_chain_fd_jacobian(n, jt, lc, g, q, qd, x, 0, NULL, NULL, out, out + n, NULL, work);
        }
    }
    return (now() - t) / k;
}
"""



def _last_state(kernels, model, mp, q, qd, x, n):
    """The timing loops' arguments at the last state: fmugen's arrays (kept alive) and their pointers,
    and the same state in Pinocchio's coordinates."""
    from fmugen.codegen.benchmarks import to_pinocchio
    from fmugen.codegen.chain import chain_work_doubles

    keep = [kernels.joint_array, kernels.constants, kernels.globals] + \
        [np.ascontiguousarray(a, float) for a in (q[-1], qd[-1], x[-1], np.zeros(n), np.zeros(n + 3 * n * n),
                                                  np.zeros(chain_work_doubles(n, "jacobian")))]
    qp, vp = to_pinocchio(model, mp, q[-1], qd[-1])
    return keep, [a.ctypes.data for a in keep], qp, vp, to_pinocchio(model, mp, None, x[-1])

def runtime_version() -> str:
    """The git blob hash of the runtime file measured (the runtime changes faster than the benchmarks are run)."""
    import hashlib

    data = (ROOT / "c_runtime" / "chain_dynamics.c").read_bytes()
    blob = hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()
    return f"chain_dynamics.c blob {blob[:10]}"


def timer(tmp: Path):
    (tmp / "timer.c").write_text(TIMER)
    lib = tmp / "timer.so"
    subprocess.run(["cc", "-std=c99", "-O2", "-fPIC", "-shared", f"-I{ROOT / 'c_runtime'}", "-o", str(lib),
                    str(tmp / "timer.c"), "-lm"], check=True)
    so = ctypes.CDLL(str(lib))
    vp = ctypes.c_void_p
    so.time_calls.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int] + [vp] * 9
    so.time_calls.restype = ctypes.c_double
    return so


def rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(np.max(np.abs(b)), 1e-300))


def sym(upper):
    return np.triu(upper) + np.triu(upper, 1).T


def pinocchio_time(fn, args, k: int) -> float:
    """CPU seconds per call less the same call on a 0-DoF model (Python's call overhead), same arity."""
    from bench_timing import _empty_pinocchio

    empty, ed, z = _empty_pinocchio()
    return per_call(fn, args, k) - per_call(fn, (empty, ed) + (z,) * (len(args) - 2), k)


def measure(name: str, path: Path, states: int, repeat: int, so) -> dict:
    import pinocchio as pin
    from fmugen.batch import Kernels
    from fmugen.codegen.benchmarks import pinocchio_urdf_map, to_pinocchio
    from fmugen.robot.urdf import load_urdf

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # mimic joints read as independent joints, as Pinocchio does
        robot = load_urdf(path)
    zero = {p.name: 0.0 for p in robot.parameters if p.name.startswith(("b_", "fc_"))}
    kernels = Kernels.from_robot(robot, values=zero)
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    mp = pinocchio_urdf_map(model, robot)
    iv = [m[1] for m in mp]
    ix = np.ix_(iv, iv)
    n = kernels.n
    if model.nv != n:
        raise ValueError(f"{name}: fmugen reads {n} joints, Pinocchio {model.nv}")

    # 1. the results, through the batched entry point, against Pinocchio's
    rng = np.random.default_rng(0)
    q, qd, x = rng.uniform(-1, 1, (states, n)), rng.uniform(-1, 1, (states, n)), rng.uniform(-3, 3, (states, n))
    got = {"ID": kernels.id(q, qd, x), "M": kernels.mass_matrix(q), "Minv": kernels.mass_matrix_inverse(q),
           "FD": kernels.fd(q, qd, x), "∇ID": kernels.id_derivatives(q, qd, x),
           "∇FD": kernels.fd_derivatives(q, qd, x)}
    err = dict.fromkeys(ALGORITHMS, 0.0)
    for k in range(states):
        qp, vp = to_pinocchio(model, mp, q[k], qd[k])
        xp = to_pinocchio(model, mp, None, x[k])
        e = {"ID": rel(got["ID"][k], pin.rnea(model, data, qp, vp, xp)[iv]),
             "M": rel(got["M"][k], sym(pin.crba(model, data, qp))[ix]),
             "Minv": rel(got["Minv"][k], sym(pin.computeMinverse(model, data, qp))[ix]),
             "FD": rel(got["FD"][k], pin.aba(model, data, qp, vp, xp)[iv])}
        pin.computeRNEADerivatives(model, data, qp, vp, xp)
        e["∇ID"] = max(rel(got["∇ID"][1][k], data.dtau_dq[ix]), rel(got["∇ID"][2][k], data.dtau_dv[ix]),
                       rel(got["∇ID"][3][k], sym(data.M)[ix]))
        pin.computeABADerivatives(model, data, qp, vp, xp)
        e["∇FD"] = max(rel(got["∇FD"][1][k], data.ddq_dq[ix]), rel(got["∇FD"][2][k], data.ddq_dv[ix]),
                       rel(got["∇FD"][3][k], sym(data.Minv)[ix]))
        err = {a: max(err[a], e[a]) for a in ALGORITHMS}
    kernels.close()

    # 2. timing at the last state, in alternation
    keep, ptrs, qp, vp, xp = _last_state(kernels, model, mp, q, qd, x, n)
    pargs = {"ID": (model, data, qp, vp, xp), "M": (model, data, qp), "Minv": (model, data, qp),
             "FD": (model, data, qp, vp, xp), "∇ID": (model, data, qp, vp, xp), "∇FD": (model, data, qp, vp, xp)}
    budget = 0.02  # CPU seconds per timing: long against the clock's resolution, short against the load's drift
    kc, kp = {}, {}
    for i, a in enumerate(ALGORITHMS):
        kc[a] = max(20, int(budget / max(so.time_calls(i, 20, n, *ptrs), 1e-9)))
        fn = getattr(pin, PINOCCHIO[a])
        kp[a] = max(20, int(budget / max(per_call(fn, pargs[a], 20), 1e-9)))
    t = {a: {"fmugen": [], "pinocchio": []} for a in ALGORITHMS}
    for _ in range(repeat):
        for i, a in enumerate(ALGORITHMS):
            t[a]["fmugen"].append(so.time_calls(i, kc[a], n, *ptrs))
            t[a]["pinocchio"].append(pinocchio_time(getattr(pin, PINOCCHIO[a]), pargs[a], kp[a]))
    out = {"n": n, "err": err, "fmugen": {}, "pinocchio": {}, "ratio": {}}
    for a in ALGORITHMS:
        f, p = np.array(t[a]["fmugen"]), np.array(t[a]["pinocchio"])
        out["fmugen"][a], out["pinocchio"][a] = statistics.median(f), statistics.median(p)
        out["ratio"][a] = statistics.median(f / p)
    return out


def straight_line(name: str, path: Path, states: int, repeat: int) -> dict:
    """The generated straight-line code of a small robot (module docstring), checked and timed like measure()."""
    from dataclasses import replace

    import pinocchio as pin
    from bench_timing import c_loop
    from fmugen.codegen.benchmarks import mass_matrix_model, pinocchio_urdf_map, to_pinocchio
    from fmugen.codegen.c_code import generate_c
    from fmugen.codegen.c_harness import CompiledModel
    from fmugen.dynamics.manipulator import Manipulator
    from fmugen.robot.urdf import load_urdf

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = load_urdf(path)
    zero = {p.name: 0.0 for p in robot.parameters if p.name.startswith(("b_", "fc_"))}
    arm = Manipulator(robot)
    n = robot.n

    def folded(m):
        return m.with_starts({k: x for k, x in zero.items() if k in {v.name for v in m.parameters}}) \
            .with_parameters_folded()

    t0 = time.process_time()
    fd = folded(arm.state_space_model(outputs=(), strategy="straight"))
    idm = folded(arm.inverse_dynamics_model(strategy="straight"))
    mm = folded(mass_matrix_model(arm))
    no_jac = dict(jacobian=None, dfdx=None, dfdu=None, dgdx=None, dgdu=None)
    models = {"FD": fd.without_jacobian(), "∇FD": fd, "ID": replace(idm, **no_jac), "∇ID": idm, "M": mm}
    sources = {a: generate_c(m).source for a, m in models.items()}
    derive = time.process_time() - t0
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    mp = pinocchio_urdf_map(model, robot)
    iv = [m[1] for m in mp]
    ix = np.ix_(iv, iv)
    rng = np.random.default_rng(0)
    q, qd, x = rng.uniform(-1, 1, (states, n)), rng.uniform(-1, 1, (states, n)), rng.uniform(-3, 3, (states, n))
    tri = [(i, j) for i in range(n) for j in range(i + 1)]
    err = dict.fromkeys(("ID", "M", "FD", "∇ID", "∇FD"), 0.0)
    compiled = {a: CompiledModel.build(src) for a, src in sources.items()}
    try:
        for k in range(states):
            qp, vp = to_pinocchio(model, mp, q[k], qd[k])
            xp = to_pinocchio(model, mp, None, x[k])
            u = np.r_[q[k], qd[k], x[k]]
            _, tau = compiled["ID"].evaluate([], 0.0, [], u)
            e = {"ID": rel(tau, pin.rnea(model, data, qp, vp, xp)[iv])}
            _, _, _, dgdu = compiled["∇ID"].jacobian([], 0.0, [], u)
            pin.computeRNEADerivatives(model, data, qp, vp, xp)
            e["∇ID"] = rel(dgdu[:, :3 * n], np.c_[data.dtau_dq[ix], data.dtau_dv[ix], sym(data.M)[ix]])
            _, m_low = compiled["M"].evaluate([], 0.0, [], q[k])
            Mref = sym(pin.crba(model, data, qp))[ix]
            e["M"] = rel(m_low, [Mref[i, j] for i, j in tri])
            dx, _ = compiled["FD"].evaluate([], 0.0, np.r_[q[k], qd[k]], x[k], want_y=False)
            e["FD"] = rel(dx[n:], pin.aba(model, data, qp, vp, xp)[iv])
            dfdx, dfdu, _, _ = compiled["∇FD"].jacobian([], 0.0, np.r_[q[k], qd[k]], x[k])
            pin.computeABADerivatives(model, data, qp, vp, xp)
            e["∇FD"] = rel(np.c_[dfdx[n:], dfdu[n:, :n]],
                           np.c_[data.ddq_dq[ix], data.ddq_dv[ix], sym(data.Minv)[ix]])
            err = {a: max(err[a], e[a]) for a in err}
        qp, vp = to_pinocchio(model, mp, q[-1], qd[-1])
        xp = to_pinocchio(model, mp, None, x[-1])
        calls = {"ID": ("ID", [], np.r_[q[-1], qd[-1], x[-1]], "evaluate"),
                 "M": ("M", [], q[-1], "evaluate"),
                 "FD": ("FD", np.r_[q[-1], qd[-1]], x[-1], "evaluate"),
                 "∇ID": ("∇ID", [], np.r_[q[-1], qd[-1], x[-1]], "jacobian"),
                 "∇FD": ("∇FD", np.r_[q[-1], qd[-1]], x[-1], "jacobian")}
        pargs = {"ID": (model, data, qp, vp, xp), "M": (model, data, qp), "FD": (model, data, qp, vp, xp),
                 "∇ID": (model, data, qp, vp, xp), "∇FD": (model, data, qp, vp, xp)}
        t = {a: ([], []) for a in calls}
        for _ in range(repeat):
            for a, (m, xs, us, which) in calls.items():
                t[a][0].append(c_loop(compiled[m], [], xs, us, which, 20000 if which == "evaluate" else 5000))
                t[a][1].append(pinocchio_time(getattr(pin, PINOCCHIO[a]), pargs[a], 5000))
    finally:
        for cm in compiled.values():
            cm.close()
    out = {"n": n, "derive": derive, "err": err, "fmugen": {}, "pinocchio": {}, "ratio": {}}
    for a, (f, p) in t.items():
        out["fmugen"][a], out["pinocchio"][a] = statistics.median(f), statistics.median(p)
        out["ratio"][a] = statistics.median(np.array(f) / np.array(p))
    return out


def unrolled(name: str, path: Path, states: int, repeat: int, so) -> dict:
    """The per-robot unrolled code beside the looped runtime and Pinocchio: the forward dynamics
    (fmugen.codegen.unrolled_aba, against ``aba``) and the Jacobians of the inverse and forward dynamics
    (fmugen.codegen.unrolled_derivatives, against ``computeRNEADerivatives`` and ``computeABADerivatives``),
    each checked at ``states`` random states and timed in alternation (``repeat`` rounds, the same budget
    per timing as measure())."""
    import pinocchio as pin
    from fmugen.batch import Kernels
    from fmugen.codegen import unrolled_derivatives
    from fmugen.codegen.benchmarks import pinocchio_urdf_map, to_pinocchio
    from fmugen.codegen.unrolled_aba import CompiledUnrolledFD, from_kernels
    from fmugen.robot.urdf import load_urdf

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = load_urdf(path)
    zero = {p.name: 0.0 for p in robot.parameters if p.name.startswith(("b_", "fc_"))}
    kernels = Kernels.from_robot(robot, values=zero)
    n = kernels.n
    gens, generate, compiled = {}, {}, {}
    try:
        for a in ("FD", "∇ID", "∇FD"):
            t0 = time.perf_counter()
            gens[a] = from_kernels(kernels) if a == "FD" else \
                unrolled_derivatives.from_kernels(kernels, "id" if a == "∇ID" else "fd")
            generate[a] = time.perf_counter() - t0
            compiled[a] = CompiledUnrolledFD(gens[a]) if a == "FD" else \
                unrolled_derivatives.CompiledUnrolledJacobian(gens[a])
        model = pin.buildModelFromUrdf(str(path))
        data = model.createData()
        mp = pinocchio_urdf_map(model, robot)
        iv = [m[1] for m in mp]
        ix = np.ix_(iv, iv)
        rng = np.random.default_rng(0)
        q, qd, x = rng.uniform(-1, 1, (states, n)), rng.uniform(-1, 1, (states, n)), rng.uniform(-3, 3, (states, n))
        got = {"FD": compiled["FD"].fd(q, qd, x), "∇ID": compiled["∇ID"].derivatives(q, qd, x),
               "∇FD": compiled["∇FD"].derivatives(q, qd, x)}
        err = dict.fromkeys(got, 0.0)
        for k in range(states):
            qp, vp = to_pinocchio(model, mp, q[k], qd[k])
            xp = to_pinocchio(model, mp, None, x[k])
            err["FD"] = max(err["FD"], rel(got["FD"][k], pin.aba(model, data, qp, vp, xp)[iv]))
            pin.computeRNEADerivatives(model, data, qp, vp, xp)
            g = got["∇ID"]
            err["∇ID"] = max(err["∇ID"], rel(g[0][k], data.tau[iv]), rel(g[1][k], data.dtau_dq[ix]),
                             rel(g[2][k], data.dtau_dv[ix]), rel(g[3][k], sym(data.M)[ix]))
            pin.computeABADerivatives(model, data, qp, vp, xp)
            g = got["∇FD"]
            err["∇FD"] = max(err["∇FD"], rel(g[0][k], data.ddq[iv]), rel(g[1][k], data.ddq_dq[ix]),
                             rel(g[2][k], data.ddq_dv[ix]), rel(g[3][k], sym(data.Minv)[ix]))
        keep, ptrs, qp, vp, xp = _last_state(kernels, model, mp, q, qd, x, n)
        pargs = (model, data, qp, vp, xp)
        budget = 0.02
        kind = {"FD": 3, "∇ID": 4, "∇FD": 5}  # the timer's algorithm numbers (looped)
        t = {a: ([], [], []) for a in got}
        ks = {}
        for a in got:
            fn = getattr(pin, PINOCCHIO[a])
            ks[a] = [max(20, int(budget / max(f(20), 1e-9))) for f in (
                lambda k: compiled[a].time_per_call(q[-1], qd[-1], x[-1], k),
                lambda k: so.time_calls(kind[a], k, n, *ptrs), lambda k: per_call(fn, pargs, k))]
        for _ in range(repeat):
            for a in got:
                ku, kl, kp = ks[a]
                t[a][0].append(compiled[a].time_per_call(q[-1], qd[-1], x[-1], ku))
                t[a][1].append(so.time_calls(kind[a], kl, n, *ptrs))
                t[a][2].append(pinocchio_time(getattr(pin, PINOCCHIO[a]), pargs, kp))
    finally:
        for c in compiled.values():
            c.close()
        kernels.close()
    out = {"n": n}
    for a in got:
        tu, tl, tp = (np.array(x) for x in t[a])
        out[a] = {"err": err[a], "lines": gens[a].lines, "generate": generate[a],
                  "compile": compiled[a].compile_seconds, "unrolled": statistics.median(tu),
                  "looped": statistics.median(tl), "pinocchio": statistics.median(tp),
                  "ratio": statistics.median(tu / tp), "looped_ratio": statistics.median(tl / tp),
                  "best_ratio": float(np.min(tu) / np.min(tp))}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--grid", type=Path, help="folder with GRiDBenchmarks' iiwa.urdf, hyq.urdf, atlas.urdf "
                                              "(https://github.com/robot-acceleration/GRiDBenchmarks, urdfs/)")
    ap.add_argument("--robot", action="append", choices=[*GRID_ROBOTS, *ERD_ROBOTS],
                    help="robots to run (default: all that are found)")
    ap.add_argument("--states", type=int, default=3, help="random states checked against Pinocchio")
    ap.add_argument("--repeat", type=int, default=5, help="timing rounds (medians)")
    ap.add_argument("--no-straight", action="store_true",
                    help="skip the straight-line code of the robots of 6 DoF and fewer")
    ap.add_argument("--unrolled", action="store_true",
                    help="also time the per-robot unrolled FD, ∇ID and ∇FD (fmugen.codegen.unrolled_aba, "
                         "unrolled_derivatives) against the looped runtime and Pinocchio")
    ap.add_argument("--unrolled-only", action="store_true",
                    help="only the unrolled code's table (implies --unrolled --no-straight)")
    args = ap.parse_args(argv)
    if args.unrolled_only:
        args.unrolled = args.no_straight = True
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
          f"{pin.__version__}; {args.repeat} rounds, medians; CPU µs per call\n")
    paths = {}
    for name, f in GRID_ROBOTS.items():
        if args.grid is not None and (args.grid / f).is_file():
            paths[name] = args.grid / f
        elif args.robot is None or name in args.robot:
            print(f"({name}: no {f} -- pass --grid with GRiDBenchmarks' urdfs/ folder)", file=sys.stderr)
    for name, rel_path in ERD_ROBOTS.items():
        paths[name] = erd / rel_path
    names = [r for r in paths if args.robot is None or r in args.robot]
    results, ok = {}, True
    with tempfile.TemporaryDirectory(prefix="fmugen_bench_derivatives_") as tmp:
        so = timer(Path(tmp))
        for name in names if not args.unrolled_only else ():
            t0 = time.perf_counter()
            results[name] = r = measure(name, paths[name], args.states, args.repeat, so)
            ok = ok and all(e < 1e-9 for e in r["err"].values())
            print(f"({name}: {r['n']} DoF, {time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
        unrolled_results = {}
        for name in names if args.unrolled else ():
            unrolled_results[name] = u = unrolled(name, paths[name], args.states, args.repeat, so)
            ok = ok and all(u[a]["err"] < 1e-9 for a in ("FD", "∇ID", "∇FD"))
            print(f"({name}: unrolled, {u['n']} DoF)", file=sys.stderr, flush=True)
    if unrolled_results:
        print("| Robot | DoF | Algorithm | C lines | generate s | gcc -O2 s | unrolled µs | looped µs | "
              "Pinocchio µs | unrolled / Pinocchio | looped / Pinocchio | fastest / fastest | max rel. error |")
        print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for name, r in unrolled_results.items():
            for a in ("FD", "∇ID", "∇FD"):
                u = r[a]
                print(f"| {name} | {r['n']} | {a} ({PINOCCHIO[a]}) | {u['lines']} | {u['generate']:.2f} | "
                      f"{u['compile']:.2f} | {u['unrolled'] * 1e6:.2f} | {u['looped'] * 1e6:.2f} | "
                      f"{u['pinocchio'] * 1e6:.2f} | {u['ratio']:.3f} | {u['looped_ratio']:.3f} | "
                      f"{u['best_ratio']:.3f} | {u['err']:.1e} |")
        print("\nunrolled: fmugen.codegen.unrolled_aba (FD) and fmugen.codegen.unrolled_derivatives (∇ID, ∇FD), "
              "the "
              "robot's passes as straight-line C (numbers folded), compiled alone with -O2 (the gcc column: its wall "
              "time) and called in a C loop; looped: the runtime's fmugen_chain_fd, _id_jacobian, _fd_jacobian; "
              "ratios: medians of the per-round ratios to Pinocchio (Python's call overhead subtracted); fastest / "
              "fastest: the unrolled code's fastest round over Pinocchio's (a neighbour's load only slows a round, "
              "and slows the larger code more: on a shared host the two columns part).\n")
    if args.unrolled_only:
        print(f"check against Pinocchio (relative, 1e-9): {'ok' if ok else 'FAILED'}")
        return 0 if ok else 1
    print("| Robot | DoF | Algorithm | fmugen µs | Pinocchio µs | ratio | max rel. error | GRiD CPU µs | "
          "GRiD GPU µs |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|")
    for name in names:
        r = results[name]
        for a in ALGORITHMS:
            g = list(GRID_ROBOTS).index(name) if name in GRID_ROBOTS and a in GRID_CPU else None
            cpu = f"{GRID_CPU[a][g]:.1f}" if g is not None else ""
            gpu = f"{GRID_GPU[a][g]:.1f}" if g is not None else ""
            print(f"| {name} | {r['n']} | {a} ({PINOCCHIO[a]}) | {r['fmugen'][a] * 1e6:.2f} | "
                  f"{r['pinocchio'][a] * 1e6:.2f} | {r['ratio'][a]:.2f} | {r['err'][a]:.1e} | {cpu} | {gpu} |")
    print("\nfmugen: the looped runtime (c_runtime/chain_dynamics.c) in a compiled C loop, M by composite "
          "rigid bodies, M^-1 by the tree factorisation M = L^T L; Pinocchio: the call in parentheses, Python's call overhead "
          "subtracted; ratio: median of the per-round ratios fmugen / Pinocchio.  GRiD columns: published "
          "figures, another machine (i7-10700K 3.8 GHz with Pinocchio; RTX 3080 with GRiD), for context.")
    small = [r for r in names if results[r]["n"] <= 6] if not args.no_straight else []
    if small:
        print("\n| Robot | DoF | Algorithm | straight-line µs | looped µs | Pinocchio µs | straight-line ratio | "
              "max rel. error |")
        print("|---|---:|---|---:|---:|---:|---:|---:|")
        for name in small:
            s = straight_line(name, paths[name], args.states, args.repeat)
            ok = ok and all(e < 1e-9 for e in s["err"].values())
            for a in ("ID", "M", "FD", "∇ID", "∇FD"):
                print(f"| {name} | {s['n']} | {a} ({PINOCCHIO[a]}) | {s['fmugen'][a] * 1e6:.2f} | "
                      f"{results[name]['fmugen'][a] * 1e6:.2f} | {s['pinocchio'][a] * 1e6:.2f} | {s['ratio'][a]:.2f} | "
                      f"{s['err'][a]:.1e} |", flush=True)
        print("\nstraight-line: the code generated for the FMU (parameters folded), in a C loop; looped: the "
              "first table's figure; M: the lower triangle only.")
    print(f"check against Pinocchio (relative, 1e-9): {'ok' if ok else 'FAILED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
