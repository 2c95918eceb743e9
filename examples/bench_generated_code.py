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
   times it in a compiled C loop (median of ``--repeat`` runs);
3. times ``pin.rnea``, ``pin.crba`` and ``pin.aba`` from Python in the same
   run, with Pinocchio's Python call overhead measured as the same call on a
   0-DOF model and subtracted, and prints the ratios;
4. times ``fmugen build`` of the PUMA (ME and CS, median of ``--build-repeat``
   runs of the command in a fresh process).

Nothing is written into the repository (temporary directories only).  Run:

    python examples/bench_generated_code.py
    python examples/bench_generated_code.py --robots robots/puma_thesis_com.toml --build-repeat 0

Timings on a shared machine are noisy: the median and the best (min) of the
repeats are both printed.
"""
from __future__ import annotations

import argparse
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
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
class Result:
    """One generated function: its operation count, agreement and time."""

    ops: FunctionOps
    max_rel_error: float
    median_s: float
    min_s: float


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


def time_c(cm: CompiledModel, p, x, u, repeat: int, run_seconds: float = 0.03) -> tuple:
    """(median, min) seconds per call of the generated evaluate, timed in a C loop."""
    guess = cm.time_per_call(p, x, u, n=2000)
    calls = max(2000, int(run_seconds / max(guess, 1e-9)))
    times = [cm.time_per_call(p, x, u, n=calls) for _ in range(repeat)]
    return statistics.median(times), min(times)


def time_python(fn, args: tuple, calls: int, repeat: int) -> tuple:
    """(median, min) seconds per ``fn(*args)`` in a Python loop of ``calls`` calls."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn(*args)
        times.append((time.perf_counter() - t0) / calls)
    return statistics.median(times), min(times)


# ------------------------------------------------------------- measurements
def measure_generated(arm: Manipulator, formulation: str, folded: bool, pin, pmodel, states,
                      repeat: int, cflags: list) -> dict:
    """{algorithm key: Result} for one formulation, parameters symbolic or folded."""
    pdata = pmodel.createData()
    n, n_ext = arm.n, len(arm.ext_symbols)
    out = {}
    for key, _, make, _ in ALGORITHMS:
        model = make(arm, formulation)
        if folded:
            model = model.with_parameters_folded()
        p = np.array([v.start for v in model.parameters], dtype=float)
        gen = generate_c(model)
        with CompiledModel.build(gen.source, cflags=cflags) as cm:
            err = 0.0
            for q, qd, qdd, tau in states:
                x, u = c_call(key, n_ext, q, qd, qdd, tau)
                err = max(err, rel_error(c_result(key, cm, p, x, u, n),
                                         pin_result(key, pin, pmodel, pdata, q, qd, qdd, tau)))
            x, u = c_call(key, n_ext, *states[0])
            med, best = time_c(cm, p, x, u, repeat)
        out[key] = Result(gen.op_counts["evaluate"], err, med, best)
    return out


def measure_pinocchio(pin, pmodel, state, calls: int, repeat: int) -> dict:
    """{key: (raw median, raw min, overhead median, net)} seconds per call from Python.

    The overhead is the same bound function on a 0-DOF model (argument
    conversion, result allocation, dispatch, the Python loop), so net =
    raw - overhead is the C++ algorithm alone.
    """
    q, qd, qdd, tau = state
    data = pmodel.createData()
    empty = pin.Model()
    edata, e = empty.createData(), np.zeros(0)
    calls_of = {
        "ID": (pin.rnea, (pmodel, data, q, qd, qdd), (empty, edata, e, e, e)),
        "M": (pin.crba, (pmodel, data, q), (empty, edata, e)),
        "FD": (pin.aba, (pmodel, data, q, qd, tau), (empty, edata, e, e, e)),
    }
    out = {}
    for key, (fn, args, args0) in calls_of.items():
        raw, raw_min = time_python(fn, args, calls, repeat)
        over, _ = time_python(fn, args0, calls, repeat)
        out[key] = (raw, raw_min, over, raw - over)
    # a trivial bound call for reference: pin.neutral on the 0-DOF model
    out["trivial"] = time_python(pin.neutral, (empty,), calls, repeat)
    return out


def measure_build(robot_path: Path, fmi_type: str, repeat: int) -> list:
    """Wall seconds of ``fmugen build ROBOT --fmi-type T`` in a fresh process, each run."""
    times = []
    with tempfile.TemporaryDirectory(prefix="fmugen_bench_build_") as tmp:
        for k in range(repeat):
            cmd = [sys.executable, "-c", "import sys; from fmugen.cli import main; sys.exit(main())",
                   "build", str(robot_path), "--fmi-type", fmi_type, "-o", str(Path(tmp) / f"arm{k}.fmu")]
            t0 = time.perf_counter()
            r = subprocess.run(cmd, capture_output=True, text=True)
            times.append(time.perf_counter() - t0)
            if r.returncode != 0:
                raise RuntimeError(f"fmugen build failed: {shlex.join(cmd)}\n{r.stderr}")
    return times


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
    la = results["lagrange", True]["ID"].ops.total
    print(f"  -> fmugen NE inverse dynamics: {ne_s.mul} mul / {ne_s.add} add (symbolic parameters), "
          f"{ne.mul} mul / {ne.add} add (folded): goal <= 250 mul {'met' if ne.mul <= 250 else 'NOT met'}")
    print(f"  -> 4x4 recursive Lagrange (Hollerbach) / fmugen NE folded: {4388 / ne.mul:.1f}x the "
          f"multiplications, {3586 / ne.add:.1f}x the additions; fmugen's own (CSE'd, 3x3) recursive "
          f"Lagrange: {la.mul} mul / {la.add} add = {la.mul / ne.mul:.1f}x the NE")


def print_times(name: str, results: dict, pinres: dict) -> None:
    print(f"\n== {name}: time per evaluation of the generated C, compiled loop, µs "
          f"(median / min of repeats) ==")
    cols = [(form, folded) for form in FORMULATIONS for folded in (False, True)]
    head = "".join(f"{SHORT_FORM[f] + (' folded' if fo else ' symb.'):>20}" for f, fo in cols)
    print(f"{'function':<36}{head}{'goal':>9}   max rel. diff. to Pinocchio")
    for key, what, _, _ in ALGORITHMS:
        cells = "".join(f"{us(results[c][key].median_s)} / {us(results[c][key].min_s)}"[1:].rjust(20)
                        for c in cols)
        goal = f"<= {GOALS[key] * 1e6:.2f}" if key in GOALS else ""
        err = max(results[c][key].max_rel_error for c in cols)
        print(f"{what:<36}{cells}{goal:>9}   {err:.1e}")

    print(f"\n== {name}: Pinocchio {pinres['version']} from Python, same model, same run, µs ==")
    tr = pinres["trivial"]
    print(f"trivial bound call pin.neutral(0-DOF model): {us(tr[0])} (median), {us(tr[1])} (min)")
    print(f"{'algorithm':<10}{'raw':>9}{'raw min':>9}{'overhead':>10}{'net':>9}{'C++ (issue)':>14}"
          f"{'fmugen NE symb.':>17}{'ratio':>7}{'fmugen NE fold.':>17}{'ratio':>7}")
    for key, _, _, fn in ALGORITHMS:
        raw, raw_min, over, net = pinres[key]
        lo, hi = PINOCCHIO_CPP[key]
        cpp = f"{lo * 1e6:.1f}" if lo == hi else f"{lo * 1e6:.1f}-{hi * 1e6:.1f}"
        s = results["newton_euler", False][key].median_s
        f = results["newton_euler", True][key].median_s
        print(f"{'pin.' + fn:<10}{us(raw):>9}{us(raw_min):>9}{us(over):>10}{us(net):>9}{cpp:>14}"
              f"{us(s):>17}{s / net:7.2f}{us(f):>17}{f / net:7.2f}")
    print("overhead = the same call on a 0-DOF model; net = raw - overhead; "
          "ratio = generated C / Pinocchio net (below 1: the generated C is faster)")


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
    t0 = time.perf_counter()
    results = {(form, folded): measure_generated(arm, form, folded, pin, pmodel, states, args.repeat,
                                                 shlex.split(args.cflags))
               for form in FORMULATIONS for folded in (False, True)}
    t_gen = time.perf_counter() - t0
    pinres = measure_pinocchio(pin, pmodel, states[0], args.calls, args.repeat)
    pinres["version"] = pin.__version__
    name = f"{robot.name} ({path.relative_to(ROOT) if path.is_relative_to(ROOT) else path})"
    print_ops(name, results)
    print_times(name, results, pinres)
    worst = max(r.max_rel_error for res in results.values() for r in res.values())
    ok = worst <= RTOL
    print(f"check: generated C against Pinocchio at {len(states)} random states, worst relative "
          f"difference {worst:.1e} ({'ok' if ok else 'FAILED'}, tolerance {RTOL:g}); "
          f"derive + generate + compile + check + time: {t_gen:.1f} s")
    return ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", nargs="+", default=list(DEFAULT_ROBOTS), help="robot files")
    ap.add_argument("--repeat", type=int, default=9, help="timing repeats (median reported)")
    ap.add_argument("--calls", type=int, default=20000, help="Pinocchio calls per timing repeat")
    ap.add_argument("--states", type=int, default=5, help="random states for the Pinocchio check")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cflags", default="-O2", help="C flags of the timed code (the FMU uses -O2)")
    ap.add_argument("--build-repeat", type=int, default=3,
                    help="runs of 'fmugen build' per FMI type for the first robot (0: skip)")
    args = ap.parse_args(argv)
    try:
        import pinocchio as pin
    except ImportError:
        print("this benchmark needs Pinocchio: pip install pin", file=sys.stderr)
        return 2

    t0 = time.perf_counter()
    ok = True
    for r in args.robots:
        ok = bench_robot(robot_path(r), args, pin) and ok

    if args.build_repeat > 0:
        first = robot_path(args.robots[0])
        print(f"\n== fmugen build {first.name} (fresh process: load, derive, generate, compile, zip), "
              f"wall s, {args.build_repeat} runs ==")
        for fmi_type in ("me", "cs"):
            times = measure_build(first, fmi_type, args.build_repeat)
            print(f"--fmi-type {fmi_type}: median {statistics.median(times):5.2f} s "
                  f"(runs {', '.join(f'{t:.2f}' for t in times)}); goal < 10 s "
                  f"{'met' if statistics.median(times) < 10 else 'NOT met'}")
    print(f"\ntotal benchmark time {time.perf_counter() - t0:.0f} s")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
