"""Do the shipped scenes' own co-simulation settings hold over ten times their horizon?

Runs every scene of ``examples/scenes`` with the settings its file gives (``[cosim]``, else the defaults:
Gauss-Seidel, linear, the scene's step) to 10x its stop time and prints the outcome: status, where it
stopped, the coupling error estimate of the recorded joint angles and its trend.  A setting that holds ends
``ok`` at 10x the horizon with an estimate within the scene's stated accuracy.

    python examples/cosim_defaults_check.py [SCENE.toml ...] [--factor 10] [--out out/defaults_check]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import fmugen  # noqa: E402
from fmugen.cosim import run  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", type=Path)
    ap.add_argument("--factor", type=float, default=10.0)
    ap.add_argument("--out", type=Path, default=Path("out/defaults_check"))
    args = ap.parse_args(argv)
    scenes = args.scenes or sorted((ROOT / "examples" / "scenes").glob("*.toml"))
    bad = 0
    for path in scenes:
        scene = fmugen.load_scene(path)
        T = scene.spec.start + args.factor * (scene.spec.stop - scene.spec.start)
        system = scene.build(args.out / path.stem).system
        r = run(system, stop=T)
        s = r.summary
        est = {c: e for c, e in s.error_estimates.items() if ".q[" in c or c.endswith(".theta")}
        worst = max(est.values()) if est else float("nan")
        print(f"{path.name}: {s.scheme}/{s.extrapolation} H {s.step_max:.4g} s to {T:g} s: {s.status} at "
              f"t = {r.time[-1]:.4g} s; estimated joint-angle error {worst:.3g} rad, trend {s.error_trend}; "
              f"wall {s.wall_time:.3g} s", flush=True)
        if s.failure:
            print("    " + str(s.failure).splitlines()[0][:300])
        bad += s.status != "ok"
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
