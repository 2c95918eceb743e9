"""Every URDF of example-robot-data that Pinocchio loads as a fixed-base model, built by fmugen and checked.

For each file of the ``example-robot-data`` wheel (PyPI; the robots folder is
found through the installed distribution) the script

1. loads it with Pinocchio's own URDF parser (``pin.buildModelFromUrdf``,
   fixed base) -- files Pinocchio cannot load, or loads without joints, are
   listed as such;
2. reads it with fmugen (:mod:`fmugen.robot.urdf`), derives the FMU's
   state-space model (forward dynamics; with ``--jacobian`` also its exact
   Jacobian, as in the FMU), generates ``model.c`` and compiles it (the
   "build" column: derive + generate + compile, wall seconds and, in
   brackets, CPU seconds of Python and the compiler -- the figure that does
   not depend on how busy the machine is; an FMU build adds the XML and the
   zip);
3. compares, at ``--states`` random states (damping and friction set to zero:
   Pinocchio's algorithms model neither), the compiled forward dynamics
   against ``pin.aba`` (relative inf-norm error), M(q) (Python evaluator of
   the composite-rigid-body program) against ``pin.crba``, and the pose and
   geometric Jacobian of **every** named frame (bodies, links merged by fixed
   joints, the root link) against Pinocchio's frames of the same name
   (``LOCAL_WORLD_ALIGNED``; absolute, m);
4. times the compiled forward dynamics in a C loop against ``pin.aba`` called
   from Python (the call overhead, measured on an empty model, subtracted),
   medians of ``--repeat`` rounds in the same run.

Romeo's hands and grippers (``romeo.urdf``, ``romeo_laas_small.urdf``) are
links without ``<inertial>``: the joints that move them move no mass, M is
singular and Pinocchio's ``aba`` is not finite either, so fmugen refuses them
as they are.  They are built as a user would: with a rotor (armature)
inertia on those joints (:data:`ARMATURE`, ``armature=`` of
``fmugen.load_robot``), and Pinocchio gets the same ``model.armature``.

Robots with more than ``--max-dof`` joints (default 12) are built with the
runtime's looped dynamics (``strategy="loops"``: straight-line code grows as
n^2..n^3) where it takes them, else listed with their size as not built.

    python examples/urdf_table.py                       # the whole table (long: run it on a quiet machine)
    python examples/urdf_table.py --only ur5_robot panda --states 2
"""
from __future__ import annotations

import argparse
import csv
import importlib.metadata
import statistics
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # examples/: the benchmarks' shared timing helper
from bench_timing import c_loop, pinocchio_per_call  # noqa: E402


#: rotor (armature) inertia, kg.m2, given to the joints that move only massless links (the refusal names
#: them); an assumed small servo's reflected rotor inertia -- the URDF has no figure for it
ARMATURE_KGM2 = 1e-3
ARMATURE = {
    "romeo.urdf": [f"{s}{j}" for s in "LR" for j in ("Hand", "Finger12", "Finger13", "Finger21", "Finger22",
                                                      "Finger23", "Finger31", "Finger32", "Finger33", "Thumb1",
                                                      "Thumb2", "Thumb3")],
    "romeo_laas_small.urdf": ["l_gripper_joint", "r_gripper_joint"],
}


def erd_robots() -> Path:
    dist = importlib.metadata.distribution("example-robot-data")
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


def _cpu() -> float:
    """CPU seconds of this process and its finished children (the C compiler): robust to a busy machine."""
    import resource

    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + c.ru_utime + c.ru_stime


def all_frames(arm, names):
    """One compiled program for the pose and Jacobian of every named frame: f(q, p) -> [T1, J1, T2, J2, ...]."""
    import sympy as sp

    from fmugen.codegen.program import Program
    from fmugen.codegen.python_code import compile_program
    from fmugen.dynamics import kinematics

    P = Program("_k")
    Ts = kinematics.body_frames(P, arm.robot, arm.q)
    out = []
    for name in names:
        body, T = kinematics.frame_pose(P, arm.robot, Ts, name)
        out += [sp.Matrix(T), kinematics.geometric_jacobian(P, arm.robot, Ts, [T[r][3] for r in range(3)], body)]
    return compile_program(P, [arm.q, arm.parameter_symbols], out, "frames")


def measure(path: Path, args) -> dict:
    import pinocchio as pin

    from fmugen.codegen.benchmarks import pinocchio_urdf_map, to_pinocchio
    from fmugen.codegen.c_code import generate_c
    from fmugen.codegen.c_harness import CompiledModel
    from fmugen.dynamics.manipulator import Manipulator
    from fmugen.robot.checks import RobotFileError
    from fmugen.robot.urdf import load_urdf

    row = {"file": path.name, "dof": "", "kind": "", "status": ""}
    try:
        model = pin.buildModelFromUrdf(str(path))
    except Exception as exc:  # noqa: BLE001 -- Pinocchio's errors are RuntimeError/ValueError
        row["status"] = f"Pinocchio cannot load it ({str(exc).replace(str(path), path.name).splitlines()[0][:60]})"
        return row
    row["dof"] = model.nv
    if model.nv == 0:
        row["status"] = "no joints (Pinocchio: 0 DoF)"
        return row
    armature = {j: ARMATURE_KGM2 for j in ARMATURE.get(path.name, ())}
    for j, a in armature.items():
        model.armature[model.joints[model.getJointId(j)].idx_v] = a
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            robot = load_urdf(path, armature=armature)
    except RobotFileError as exc:
        row["status"] = f"refused: {str(exc).split(': ', 1)[-1][:80]}"
        return row
    row["kind"] = "chain" if robot.is_chain else "tree"
    row["frames"] = len(robot.frame_names())
    arm = Manipulator(robot)
    zero = {p.name: 0.0 for p in robot.parameters if p.name.startswith(("b_", "fc_"))}
    t0, c0 = time.perf_counter(), _cpu()
    if robot.n > args.max_dof:  # straight-line code grows as n^2..n^3: the runtime's loops, where they take trees
        try:
            sm = arm.state_space_model(outputs=(), strategy="loops")
        except ValueError as exc:
            row["status"] = f"not built (> {args.max_dof} DoF; looped runtime: {str(exc)[:60]})"
            return row
    else:
        sm = arm.state_space_model(outputs=())
    row["strategy"] = "loops" if any(type(st).__name__ == "ChainDynamics" for st in sm.program.steps) else "straight"
    if not args.jacobian:
        sm = replace(sm, jacobian=None, dfdx=None, dfdu=None, dgdx=None, dgdu=None)
    source = generate_c(sm).source
    cm = CompiledModel.build(source)
    row["build_s"], row["build_cpu_s"] = time.perf_counter() - t0, _cpu() - c0
    try:
        p = [zero.get(v.name, v.start) for v in sm.parameters]
        data = model.createData()
        mp = pinocchio_urdf_map(model, robot)
        iv = [m[1] for m in mp]
        rng = np.random.default_rng(args.seed)
        n = robot.n
        e_fd = e_m = e_fk = e_j = 0.0
        for _ in range(args.states):
            q, qd, tau = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-5, 5, n)
            qp, vp = to_pinocchio(model, mp, q, qd)
            taup = np.zeros(n)
            taup[iv] = tau
            ref = pin.aba(model, data, qp, vp, taup)[iv]
            dx, _ = cm.evaluate(p, 0.0, np.r_[q, qd], tau, want_y=False)
            e_fd = max(e_fd, np.abs(dx[n:] - ref).max() / np.abs(ref).max())
            Mp = pin.crba(model, data, qp)
            Mp = (np.triu(Mp) + np.triu(Mp, 1).T)[np.ix_(iv, iv)]
            e_m = max(e_m, np.abs(arm.mass_matrix(q, **zero) - Mp).max() / np.abs(Mp).max())
        pin.computeJointJacobians(model, data, qp)
        pin.updateFramePlacements(model, data)
        names = robot.frame_names()
        poses = all_frames(arm, names)(q, arm.parameter_vector())
        for name, T, J in zip(names, poses[0::2], poses[1::2]):
            fid = model.getFrameId(name, pin.BODY)
            e_fk = max(e_fk, np.abs(T[:3, 3] - data.oMf[fid].translation).max())
            Jp = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:, iv]
            e_j = max(e_j, np.abs(J - Jp).max())
        row.update(fd_err=e_fd, m_err=e_m, fk_err=e_fk, j_err=e_j)

        def cloop(k):
            return c_loop(cm, p, np.r_[q, qd], tau, "evaluate", k)

        k = max(2000, int(0.02 / max(cloop(200), 1e-9)))
        fd, aba = [], []
        for _ in range(args.repeat):
            fd.append(cloop(k))
            aba.append(pinocchio_per_call(pin.aba, (model, data, qp, vp, taup), 2000))
        row.update(fd_us=statistics.median(fd) * 1e6, aba_us=statistics.median(aba) * 1e6,
                   ratio=statistics.median(np.array(fd) / np.array(aba)))
        ok = e_fd <= 1e-9 and e_m <= 1e-9 and e_fk <= 1e-12 and e_j <= 1e-12
        row["status"] = "ok" if ok else "ERROR above tolerance"
        if armature:
            row["status"] += f" (armature {ARMATURE_KGM2:g} kg.m2 on {len(armature)} massless joints)"
    finally:
        cm.close()
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", help="file stems to run (default: all)")
    ap.add_argument("--max-dof", type=int, default=12)
    ap.add_argument("--states", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--csv", type=Path, default=None, help="also write the rows as CSV")
    ap.add_argument("--jacobian", action="store_true",
                    help="build the model with its exact Jacobian, as the FMU has it (default: forward dynamics only)")
    args = ap.parse_args(argv)
    files = sorted(erd_robots().rglob("*.urdf"), key=lambda p: p.name)
    if args.only:
        files = [f for f in files if f.stem in args.only]
    head = ("| file | DoF | chain/tree | build s (CPU) | FD err | M err | FK err m | J err | FD µs | aba µs | FD/aba "
            "| status |")
    print(head)
    print("|" + "---|" * 12)
    rows = []
    for f in files:
        try:
            r = measure(f, args)
        except Exception as exc:  # noqa: BLE001 -- a row that says what went wrong, then the next file
            r = {"file": f.name, "dof": "", "kind": "", "status": f"ERROR {type(exc).__name__}: {exc}"[:120]}
        rows.append(r)

        def g(key, fmt):
            return format(r[key], fmt) if key in r else ""
        build = f"{g('build_s', '.1f')} ({g('build_cpu_s', '.1f')})" if "build_s" in r else ""
        kind = r["kind"] + (" (loops)" if r.get("strategy") == "loops" else "")
        print(f"| {r['file']} | {r['dof']} | {kind} | {build} | {g('fd_err', '.1e')} | "
              f"{g('m_err', '.1e')} | {g('fk_err', '.1e')} | {g('j_err', '.1e')} | {g('fd_us', '.2f')} | "
              f"{g('aba_us', '.2f')} | {g('ratio', '.2f')} | {r['status']} |", flush=True)
    built = [r for r in rows if r["status"].startswith("ok")]
    bad = [r for r in rows if r["status"].startswith("ERROR")]
    print(f"\n{len(rows)} files; {len(built)} built and within tolerance (FD, M <= 1e-9 relative; FK, J <= 1e-12), "
          f"{len(bad)} above tolerance")
    if args.csv:
        keys = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k) if k in rows[0] else 99)
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, keys)
            w.writeheader()
            w.writerows(rows)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
