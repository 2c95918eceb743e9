"""Benchmark: the generated C of the PUMA -- operation counts and speed, next to Pinocchio.

For each robot file (default: the thesis PUMA, both readings of its data) and
both formulations (Newton-Euler, recursive Lagrange) this

1. generates the C of the inverse dynamics tau = ID(q, qd, qdd), the mass
   matrix M(q) (lower triangle) and the forward dynamics (the FMU's
   ``evaluate``: qdd = M^{-1}(tau - h) by a Cholesky solve), each with the
   physical parameters as run-time parameters and with all of them folded
   into constants, and prints the operation counts of the printed C next to
   the published figures for the PUMA;
2. compiles each, checks its results against Pinocchio (``pin.rnea``,
   ``pin.crba``, ``pin.aba`` on a ``pin.Model`` built from the same robot
   description, see :mod:`fmugen.codegen.benchmarks`) at random states, and
   times it in a compiled C loop;
3. times ``pin.rnea``, ``pin.crba`` and ``pin.aba`` from Python in the same
   run, in ``--repeat`` rounds alternating with the C loops, with Pinocchio's
   Python call overhead measured as the same call on a 0-DOF model and
   subtracted, and prints the ratios (median of the per-round ratios);
4. times ``fmugen build`` of the PUMA (ME and CS, median of ``--build-repeat``
   runs of the command in a fresh process).

Nothing is written into the repository (temporary directories only).  Run:

    python examples/bench_generated_code.py
    python examples/bench_generated_code.py --robots robots/puma_thesis_com.toml --build-repeat 0

Times are CPU time of the benchmark process (the wall clock on a shared
machine also counts waiting for a core); the median and the best (min) of
the repeats are both printed, and the load average at the start.
"""
from __future__ import annotations

import argparse
import os
import resource
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmugen.codegen.benchmarks import (forward_dynamics_model, inverse_dynamics_model,
                                       mass_matrix_model, pinocchio_model)
from fmugen.codegen.c_code import FunctionOps, generate_c
from fmugen.codegen.c_harness import CompiledModel
from fmugen.dynamics.manipulator import FORMULATIONS, Manipulator
from fmugen.robot.loader import load_robot_description

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_ROBOTS = ("robots/puma_thesis_com.toml", "robots/puma_thesis.toml")

#: Published operation counts of the PUMA (6 DOF) inverse dynamics, as quoted
#: in issue 3 (the first from the McGalliard thesis): (source, mul, add).
PUBLISHED = (
    ("Hollerbach, 4x4 recursive Lagrange (quoted by the thesis)", "4388", "3586"),
    ("Luh-Walker-Paul recursive Newton-Euler", "~850", "~740"),
    ("plain CSE'd sympy Newton-Euler recursion", "~500", "~370"),
    ("Khalil, customised symbolic Newton-Euler, base parameters", "~160", "~113"),
    ("goal: fmugen inverse dynamics, numeric parameters", "<= 250", ""),
)

#: Pinocchio's C++ times for this arm on these machines (issue 3), seconds.
PINOCCHIO_CPP = {"ID": (1.1e-6, 1.1e-6), "M": (0.6e-6, 0.6e-6), "FD": (2.2e-6, 2.6e-6)}
#: fmugen's goals (issue 3), seconds; the mass matrix has none.
GOALS = {"ID": 0.25e-6, "FD": 0.5e-6}

ALGORITHMS = (
    # key, what, model constructor, Pinocchio function
    ("ID", "inverse dynamics tau(q, qd, qdd)", inverse_dynamics_model, "rnea"),
    ("M", "mass matrix M(q), lower triangle", mass_matrix_model, "crba"),
    ("FD", "forward dynamics M^-1 (tau - h)", forward_dynamics_model, "aba"),
)
SHORT_FORM = {"newton_euler": "NE", "lagrange": "Lagrange"}

#: Relative agreement demanded between the generated C and Pinocchio.
RTOL = 1e-10


@dataclass
class Generated:
    """One generated function, compiled: its operation count, agreement and times."""

    ops: FunctionOps
    max_rel_error: float
    cm: CompiledModel
    args: tuple  # (p, x, u) of the timed call
    times: list = field(default_factory=list)  # CPU s per call, one per round

    @property
    def median_s(self) -> float:
        return statistics.median(self.times)

    @property
    def min_s(self) -> float:
        return min(self.times)


# ------------------------------------------------------------------ helpers
def random_states(n: int, count: int, seed: int = 0) -> list:
    """``count`` random (q, qd, qdd, tau) tuples of n-vectors (rad, rad/s, rad/s^2, N m)."""
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-5, 5, n),
             rng.uniform(-50, 50, n)) for _ in range(count)]


def rel_error(a, b) -> float:
    """max|a - b| / max|b| (inf-norm relative error of a against the reference b)."""
    a, b = np.asarray(a, float).ravel(), np.asarray(b, float).ravel()
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), np.finfo(float).tiny))


def c_call(key: str, n_ext: int, q, qd, qdd, tau) -> tuple:
    """(x, u) of a generated model for algorithm ``key`` at one state."""
    ext = np.zeros(n_ext)
    if key == "ID":
        return np.zeros(0), np.concatenate([q, qd, qdd, ext])
    if key == "M":
        return np.zeros(0), np.asarray(q, float)
    return np.concatenate([q, qd]), np.concatenate([tau, ext])


def c_result(key: str, cm: CompiledModel, p, x, u, n: int) -> np.ndarray:
    """The quantity the generated function computes: tau, lower(M) or qdd."""
    dx, y = cm.evaluate(p, 0.0, x, u, want_y=(key != "FD"))
    return dx[n:] if key == "FD" else y


def pin_result(key: str, pin, pmodel, pdata, q, qd, qdd, tau) -> np.ndarray:
    """Pinocchio's value of the same quantity."""
    if key == "ID":
        return pin.rnea(pmodel, pdata, q, qd, qdd).copy()
    if key == "M":
        upper = pin.crba(pmodel, pdata, q)  # crba fills the upper triangle
        n = len(q)
        return np.array([upper[j, i] for i in range(n) for j in range(i + 1)])
    return pin.aba(pmodel, pdata, q, qd, tau).copy()


# Both timers read the CPU time of this process (time.process_time), not the
# wall clock: on a shared machine the wall clock also counts the time the
# process waits for a core.  The C functions and Pinocchio are timed in
# alternation, round by round, so a busy spell of the machine hits both and
# the per-round ratios stay comparable.


def time_c(g: Generated, calls: int) -> float:
    """CPU seconds per call of the generated evaluate in a C loop of ``calls`` calls.

    The loop is ``CompiledModel.time_per_call`` (compiled, no Python in it);
    the one ctypes call around it is negligible against its iterations.
    """
    t0 = time.process_time()
    g.cm.time_per_call(*g.args, n=calls)
    return (time.process_time() - t0) / calls


def time_python(fn, args: tuple, calls: int) -> float:
    """CPU seconds per ``fn(*args)`` in a Python loop of ``calls`` calls."""
    t0 = time.process_time()
    for _ in range(calls):
        fn(*args)
    return (time.process_time() - t0) / calls


# ------------------------------------------------------------- measurements
def compile_generated(arm: Manipulator, formulation: str, folded: bool, pin, pmodel, states,
                      cflags: list, stack: ExitStack) -> dict:
    """{algorithm key: Generated} for one formulation, parameters symbolic or folded.

    Each function is generated, compiled (kept open on ``stack``) and checked
    against Pinocchio at ``states``.
    """
    pdata = pmodel.createData()
    n, n_ext = arm.n, len(arm.ext_symbols)
    out = {}
    for key, _, make, _ in ALGORITHMS:
        model = make(arm, formulation)
        if folded:
            model = model.with_parameters_folded()
        p = np.array([v.start for v in model.parameters], dtype=float)
        gen = generate_c(model)
        cm = stack.enter_context(CompiledModel.build(gen.source, cflags=cflags))
        err = 0.0
        for q, qd, qdd, tau in states:
            x, u = c_call(key, n_ext, q, qd, qdd, tau)
            err = max(err, rel_error(c_result(key, cm, p, x, u, n),
                                     pin_result(key, pin, pmodel, pdata, q, qd, qdd, tau)))
        out[key] = Generated(gen.op_counts["evaluate"], err, cm, (p, *c_call(key, n_ext, *states[0])))
    return out


def pinocchio_calls(pin, pmodel, state) -> dict:
    """{key: (function, arguments, arguments on a 0-DOF model)}.

    The 0-DOF call measures Pinocchio's Python call overhead (argument
    conversion, result allocation, dispatch, the Python loop): net = raw -
    overhead is the C++ algorithm alone.
    """
    q, qd, qdd, tau = state
    data = pmodel.createData()
    empty = pin.Model()
    edata, e = empty.createData(), np.zeros(0)
    return {
        "ID": (pin.rnea, (pmodel, data, q, qd, qdd), (empty, edata, e, e, e)),
        "M": (pin.crba, (pmodel, data, q), (empty, edata, e)),
        "FD": (pin.aba, (pmodel, data, q, qd, tau), (empty, edata, e, e, e)),
        "trivial": (pin.neutral, (empty,), None),  # a trivial bound call, for reference
    }


def time_rounds(generated: dict, pincalls: dict, calls: int, repeat: int,
                run_seconds: float = 0.01) -> dict:
    """Time everything ``repeat`` times in alternation; fills ``Generated.times``.

    Returns {key: (raw times, overhead times)} of Pinocchio, CPU s per call.
    """
    loops = {}
    for g in (g for res in generated.values() for g in res.values()):
        guess = time_c(g, 2000)
        loops[id(g)] = max(2000, int(run_seconds / max(guess, 1e-9)))
    pin_times = {key: ([], []) for key in pincalls}
    for _ in range(repeat):
        for key, (fn, args, args0) in pincalls.items():
            for res in generated.values():
                if key in res:
                    g = res[key]
                    g.times.append(time_c(g, loops[id(g)]))
            pin_times[key][0].append(time_python(fn, args, calls))
            if args0 is not None:
                pin_times[key][1].append(time_python(fn, args0, calls))
    return pin_times


def measure_build(robot_path: Path, fmi_type: str, repeat: int) -> list:
    """(wall, CPU) seconds of ``fmugen build ROBOT --fmi-type T`` in a fresh process, each run.

    CPU is user + system time of the process and the compilers it starts
    (the sources compile in parallel, so it can exceed the wall time).
    """
    runs = []
    with tempfile.TemporaryDirectory(prefix="fmugen_bench_build_") as tmp:
        for k in range(repeat):
            cmd = [sys.executable, "-c", "import sys; from fmugen.cli import main; sys.exit(main())",
                   "build", str(robot_path), "--fmi-type", fmi_type, "-o", str(Path(tmp) / f"arm{k}.fmu")]
            c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            r = subprocess.run(cmd, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            if r.returncode != 0:
                raise RuntimeError(f"fmugen build failed: {shlex.join(cmd)}\n{r.stderr}")
            runs.append((wall, c1.ru_utime - c0.ru_utime + c1.ru_stime - c0.ru_stime))
    return runs


# ----------------------------------------------------------------- printing
def us(seconds: float) -> str:
    return f"{seconds * 1e6:7.3f}"


def print_ops(name: str, results: dict) -> None:
    print(f"\n== {name}: operation counts of the generated C (binary * + - /, math calls) ==")
    print(f"{'function':<36} {'formulation':<9} {'parameters':<10} {'mul':>6} {'add':>6} {'div':>5} "
          f"{'calls':>6}   of which Cholesky solve (mul/add/div/sqrt)")
    for key, what, _, _ in ALGORITHMS:
        for form in FORMULATIONS:
            for folded in (False, True):
                if (form, folded) not in results:
                    continue
                r = results[form, folded][key]
                t, s = r.ops.total, r.ops.linear_solve
                solve = f"{s.mul}/{s.add}/{s.div}/{s.n_calls}" if s.mul or s.div else ""
                print(f"{what:<36} {SHORT_FORM[form]:<9} {'folded' if folded else 'symbolic':<10} "
                      f"{t.mul:6d} {t.add:6d} {t.div:5d} {t.n_calls:6d}   {solve}")
    print("\npublished figures, PUMA inverse dynamics (6 DOF):")
    for source, mul, add in PUBLISHED:
        print(f"  {source:<60} {mul:>7} mul {add:>6}{' add' if add else ''}")
    ne = results["newton_euler", True]["ID"].ops.total
    ne_s = results["newton_euler", False]["ID"].ops.total
    print(f"  -> fmugen NE inverse dynamics: {ne_s.mul} mul / {ne_s.add} add (symbolic parameters), "
          f"{ne.mul} mul / {ne.add} add (folded): goal <= 250 mul {'met' if ne.mul <= 250 else 'NOT met'}")
    line = (f"  -> 4x4 recursive Lagrange (Hollerbach) / fmugen NE folded: {4388 / ne.mul:.1f}x the "
            f"multiplications, {3586 / ne.add:.1f}x the additions")
    if ("lagrange", True) in results:
        la = results["lagrange", True]["ID"].ops.total
        line += (f"; fmugen's own (CSE'd, 3x3) recursive Lagrange: {la.mul} mul / {la.add} add = "
                 f"{la.mul / ne.mul:.1f}x the NE")
    print(line)


def print_times(name: str, results: dict, pin_times: dict, version: str) -> None:
    print(f"\n== {name}: time per evaluation of the generated C, compiled loop, CPU µs "
          f"(median / min of the repeats) ==")
    cols = [c for c in ((form, folded) for form in FORMULATIONS for folded in (False, True)) if c in results]
    head = "".join(f"{SHORT_FORM[f] + (' folded' if fo else ' symb.'):>20}" for f, fo in cols)
    print(f"{'function':<36}{head}{'goal':>9}   max rel. diff. to Pinocchio")
    for key, what, _, _ in ALGORITHMS:
        cells = "".join(f"{us(results[c][key].median_s)} / {us(results[c][key].min_s)}"[1:].rjust(20)
                        for c in cols)
        goal = f"<= {GOALS[key] * 1e6:.2f}" if key in GOALS else ""
        err = max(results[c][key].max_rel_error for c in cols)
        print(f"{what:<36}{cells}{goal:>9}   {err:.1e}")

    print(f"\n== {name}: Pinocchio {version} from Python, same model, timed in alternation with the C "
          f"above, CPU µs ==")
    tr = pin_times["trivial"][0]
    print(f"trivial bound call pin.neutral(0-DOF model): {us(statistics.median(tr))} (median), "
          f"{us(min(tr))} (min)")
    print(f"{'':<10}{'median':^27}|{'min':^27}|{'C++':>8}  {'fmugen C / Pinocchio net':^27}")
    print(f"{'algorithm':<10}{'raw':>9}{'overhead':>9}{'net':>9}|{'raw':>9}{'overhead':>9}{'net':>9}|"
          f"{'(issue)':>8}  {'NE symb.':>13}{'NE folded':>14}")
    for key, _, _, fn in ALGORITHMS:
        raw, over = (np.array(t) for t in pin_times[key])
        net = raw - over  # per round
        lo, hi = PINOCCHIO_CPP[key]
        cpp = f"{lo * 1e6:.1f}" if lo == hi else f"{lo * 1e6:.1f}-{hi * 1e6:.1f}"
        ratios = ""
        for folded in (False, True):
            g = results["newton_euler", folded][key]
            per_round = np.median(np.array(g.times) / net)
            ratios += f"{per_round:.2f} / {g.min_s / (raw.min() - over.min()):.2f}".rjust(13 + folded)
        print(f"{'pin.' + fn:<10}{us(np.median(raw)):>9}{us(np.median(over)):>9}{us(np.median(net)):>9}|"
              f"{us(raw.min()):>9}{us(over.min()):>9}{us(raw.min() - over.min()):>9}|{cpp:>8}  {ratios}")
    print("overhead: the same call on a 0-DOF model; net = raw - overhead (the C++ algorithm alone);")
    print("ratio: generated C time / Pinocchio net time, median of the per-round ratios / ratio of the "
          "minima (below 1: the generated C is faster)")


# --------------------------------------------------------------------- main
def robot_path(name: str) -> Path:
    """A robot file as given, else relative to the repository root."""
    path = Path(name)
    if not path.exists() and (ROOT / name).exists():
        path = ROOT / name
    if not path.exists():
        raise SystemExit(f"bench_generated_code: robot file {name} not found")
    return path.resolve()


def bench_robot(path: Path, args, pin) -> bool:
    """Run and print everything for one robot file; False if a check failed."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # puma_thesis.toml's unrealisable link 2 is intended
        robot = load_robot_description(path)
    arm = Manipulator(robot)
    pmodel = pinocchio_model(robot)
    states = random_states(arm.n, args.states, args.seed)
    cflags = shlex.split(args.cflags)
    with ExitStack() as stack:
        t0 = time.perf_counter()
        results = {(form, folded): compile_generated(arm, form, folded, pin, pmodel, states, cflags, stack)
                   for form in args.formulations for folded in (False, True)}
        t1 = time.perf_counter()
        pin_times = time_rounds(results, pinocchio_calls(pin, pmodel, states[0]), args.calls, args.repeat)
        t2 = time.perf_counter()
    name = f"{robot.name} ({path.relative_to(ROOT) if path.is_relative_to(ROOT) else path})"
    print_ops(name, results)
    print_times(name, results, pin_times, pin.__version__)
    worst = max(r.max_rel_error for res in results.values() for r in res.values())
    ok = worst <= RTOL
    print(f"check: generated C against Pinocchio at {len(states)} random states, worst relative "
          f"difference {worst:.1e} ({'ok' if ok else 'FAILED'}, tolerance {RTOL:g})")
    print(f"(derive + generate + compile + check {t1 - t0:.1f} s, timing {t2 - t1:.1f} s)")
    return ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", nargs="+", default=list(DEFAULT_ROBOTS), help="robot files")
    ap.add_argument("--formulations", nargs="+", default=list(FORMULATIONS), choices=FORMULATIONS,
                    help="formulations to generate (newton_euler is needed for the ratios)")
    ap.add_argument("--repeat", type=int, default=15, help="timing rounds (median and min reported)")
    ap.add_argument("--calls", type=int, default=10000, help="Pinocchio calls per round")
    ap.add_argument("--states", type=int, default=5, help="random states for the Pinocchio check")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cflags", default="-O2", help="C flags of the timed code (the FMU uses -O2)")
    ap.add_argument("--build-repeat", type=int, default=3,
                    help="runs of 'fmugen build' per FMI type for the first robot (0: skip)")
    args = ap.parse_args(argv)
    if "newton_euler" not in args.formulations:
        ap.error("--formulations must include newton_euler (the ratios to Pinocchio use it)")
    try:
        import pinocchio as pin
    except ImportError:
        print("this benchmark needs Pinocchio: pip install pin", file=sys.stderr)
        return 2

    t0 = time.perf_counter()
    load = os.getloadavg()
    print(f"{os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} at start; "
          f"C flags {args.cflags}; times are CPU time of this process")
    ok = True
    for r in args.robots:
        ok = bench_robot(robot_path(r), args, pin) and ok

    if args.build_repeat > 0:
        first = robot_path(args.robots[0])
        print(f"\n== fmugen build {first.name} (fresh process: load, derive, generate, compile, zip), "
              f"wall s, {args.build_repeat} runs ==")
        for fmi_type in ("me", "cs"):
            runs = measure_build(first, fmi_type, args.build_repeat)
            wall = statistics.median(w for w, _ in runs)
            print(f"--fmi-type {fmi_type}: median {wall:5.2f} s wall (runs "
                  f"{', '.join(f'{w:.2f}' for w, _ in runs)}; CPU {', '.join(f'{c:.2f}' for _, c in runs)}); "
                  f"goal < 10 s {'met' if wall < 10 else 'NOT met'}")
    print(f"\ntotal benchmark time {time.perf_counter() - t0:.0f} s")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
