"""Benchmark: how long ``fmugen build`` of a 6-DoF arm takes, end to end (goal: <= 5 s wall).

Each case runs the command line in a fresh process (``python -m fmugen.cli build ...``: imports,
derivation, C generation, compiling, zipping -- everything a user waits for) ``--runs`` times and
reports the median wall time and the median CPU time of the process and its compilers (user +
system).  On a shared machine the wall time depends on the load; the CPU time does not, and on an
idle 2-core machine the wall time of a build is about its CPU time (the stages run one after the
other; only the compiles overlap).

The first run of each case starts with an empty cache folder (``FMUGEN_CACHE``): the C runtime's
objects are compiled once then (``fmugen.fmi.build.object_cache_dir``); the other runs reuse them,
as every build after the first one on a machine does.  Scenes are built with ``--no-cache`` (their
FMU cache would otherwise skip the build altogether).  Nothing is written into the repository.

    python examples/bench_build_time.py                  # PUMA file, PUMA scene, UR5 URDF; 5 runs each
    python examples/bench_build_time.py --runs 9 --case robots/puma_thesis.toml
"""
from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = ["robots/puma_thesis_com.toml", "examples/scenes/puma_electric.toml"]
#: a 6-DoF URDF arm, when example-robot-data is installed (pip install example-robot-data)
URDF_ARM = "ur_description/urdf/ur5_robot.urdf"


def default_cases() -> list:
    cases = list(CASES)
    try:
        from importlib.metadata import distribution

        d = Path(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots"))
        if (d / URDF_ARM).is_file():
            cases.append(str(d / URDF_ARM))
    except Exception:  # not installed: the TOML cases only
        pass
    return cases


def one_build(case: str, out: Path, cache: Path) -> dict:
    env = dict(os.environ, FMUGEN_CACHE=str(cache), PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-W", "ignore", "-m", "fmugen.cli", "build", case, "-o", str(out)]
    if "scenes/" in case:
        cmd.append("--no-cache")
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{r.stderr}")
    d = {"wall": wall, "cpu": (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)}
    m = re.search(r"derive ([\d.]+) s, generate\+compile\+zip ([\d.]+) s", r.stdout)
    if m:
        d["derive"], d["gen_cc_zip"] = float(m.group(1)), float(m.group(2))
    return d


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5, help="builds per case (the first with a cold object cache)")
    ap.add_argument("--case", action="append", help=f"robot (TOML, URDF) or scene file (default: {', '.join(CASES)} "
                                                    f"and example-robot-data's {URDF_ARM})")
    args = ap.parse_args(argv)
    load = os.getloadavg()[0]
    print(f"load average at start: {load:.1f} on {os.cpu_count()} cores")
    print(f"{'case':<40s} {'cold wall/CPU s':>16s} {'median wall s':>14s} {'median CPU s':>13s}  stages (median)")
    for case in args.case or default_cases():
        with tempfile.TemporaryDirectory(prefix="fmugen_bench_build_") as tmp:
            tmp = Path(tmp)
            runs = []
            for k in range(args.runs):
                out = tmp / (f"scene{k}" if "scenes/" in case else "arm.fmu")
                runs.append(one_build(case, out, tmp / "cache"))
            warm = runs[1:] or runs
            med = {k: statistics.median(r[k] for r in warm) for k in warm[0]}
            stages = (f"derive {med['derive']:.2f} s, generate+compile+zip {med['gen_cc_zip']:.2f} s"
                      if "derive" in med else "")
            label = case if len(case) <= 40 else "..." + case[-37:]
            print(f"{label:<40s} {runs[0]['wall']:7.2f} / {runs[0]['cpu']:5.2f}  {med['wall']:14.2f} "
                  f"{med['cpu']:13.2f}  {stages}")
    print(f"load average at end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
