"""Start-up of the ``fmugen`` command: ``fmugen --help``, and a co-simulation whose FMUs are cached.

    python examples/bench_startup.py [--scene examples/scenes/puma_hydraulic.toml] [--repeats 7]
                                     [--compare OTHER_SOURCE_TREE]

Measures, as medians over ``--repeats`` fresh processes (after one warm-up run that fills the
FMU and scene-analysis caches):

* ``python -c pass``: the interpreter alone (the floor on this machine, under its current load);
* ``fmugen --help``: goal < 0.5 s;
* ``fmugen cosim SCENE``: the time from starting the process to the first macro step (the master's
  ``run`` entered, every FMU instantiated and initialised): goal < 1 s with the FMUs cached;
* the same command's whole wall time for two macro steps (results, plot and summary written).

Each process is started with ``python -m fmugen.cli``, as the ``fmugen`` script does.  ``--compare``
runs the same rows from another fmugen source tree (e.g. an older commit unpacked with ``git archive``),
interleaved with these, so both see the same load; each tree keeps its own FMU cache.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# the child: the fmugen command, stopped when the master is about to take its first macro step
FIRST_STEP = r"""
import os, sys, time
t0 = float(sys.argv[1])
import fmugen.cosim.master as M
def first_step(self, *a, **k):
    print(f"FIRST_STEP {time.time() - t0:.6f}", flush=True)
    os._exit(0)
M.Master.run = first_step
from fmugen.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _wall(cmd, env, cwd=None) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=cwd)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    return dt


def _first_step(args, env, cwd=None) -> float:
    r = subprocess.run([sys.executable, "-c", FIRST_STEP, repr(time.time()), *args], env=env, capture_output=True,
                       text=True, cwd=cwd)
    for line in r.stdout.splitlines():
        if line.startswith("FIRST_STEP"):
            return float(line.split()[1])
    raise SystemExit(f"no first step:\n{r.stdout}\n{r.stderr}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="examples/scenes/puma_hydraulic.toml",
                    help="scene file, relative to each source tree (default: the PUMA hydraulic scene)")
    ap.add_argument("--repeats", type=int, default=7, help="fresh processes per measurement (median)")
    ap.add_argument("--compare", default=None, help="another fmugen source tree to measure alongside")
    ap.add_argument("--compare-cache", default=None, help="FMUGEN_CACHE of the other tree (default: a fresh one)")
    args = ap.parse_args(argv)
    py = [sys.executable]
    trees = [("", ROOT)] + ([("other: ", Path(args.compare).resolve())] if args.compare else [])
    with tempfile.TemporaryDirectory() as tmp:
        rows = {"python -c pass": lambda: _wall(py + ["-c", "pass"], dict(os.environ))}
        for label, tree in trees:
            env = dict(os.environ, PYTHONPATH=str(tree))
            if label:
                env["FMUGEN_CACHE"] = args.compare_cache or str(Path(tmp) / "other_cache")
            out = str(Path(tmp) / f"run{len(rows)}")
            cosim = ["cosim", str(tree / args.scene), "--out", out, "--stop", "0.002", "--step", "0.001"]
            print(f"warm-up (fills the caches): {label}fmugen {' '.join(cosim)}", flush=True)
            # run inside the tree: ``python -m`` puts the working folder first on sys.path
            _wall(py + ["-m", "fmugen.cli", *cosim], env, tree)
            rows.update({
                f"{label}fmugen --help": lambda env=env, d=tree: _wall(py + ["-m", "fmugen.cli", "--help"], env, d),
                f"{label}fmugen cosim: first macro step": lambda env=env, c=cosim, d=tree: _first_step(c, env, d),
                f"{label}fmugen cosim: whole, 2 steps": lambda env=env, c=cosim, d=tree: _wall(
                    py + ["-m", "fmugen.cli", *c], env, d),
            })
        res = {k: [] for k in rows}
        for _ in range(args.repeats):  # interleaved: a change in the machine's load hits every row alike
            for k, f in rows.items():
                res[k].append(f())
    print(f"{'':<38} {'median [s]':>10} {'min':>7} {'max':>7}   ({args.repeats} runs; {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f})")
    for k, v in res.items():
        print(f"{k:<38} {statistics.median(v):>10.3f} {min(v):>7.3f} {max(v):>7.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
