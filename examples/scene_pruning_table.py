"""What pruning buys: every shipped scene built with and without it.

For each scene in examples/scenes/ and each of its FMUs: states, operations
(evaluate + Jacobian, as counted in the generated C), library size and build
time, pruned (the default) against unpruned (``--no-prune``: every robot
output, every input, no folding, the Jacobian always).  Builds bypass the
cache, so the times are real; they are wall times on a shared machine,
quote them as ratios.

    python examples/scene_pruning_table.py [--out out/pruning.csv] [--set NAME=VALUE ...] [SCENE ...]
"""
from __future__ import annotations

import argparse
import csv
import tempfile
from pathlib import Path

from fmugen.scene import load_scene
from fmugen.scene.build import Progress

HERE = Path(__file__).resolve().parent


def rows_of(scene_path: Path, sets=()) -> list:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        scene = load_scene(scene_path, set=list(sets))
        built = {p: scene.build(Path(tmp) / str(p), prune=p, use_cache=False, progress=Progress(False))
                 for p in (True, False)}
    for g in built[True].fmus:
        a, b = built[True].fmus[g], built[False].fmus[g]
        rows.append({"scene": scene.name, "fmu": g, "states": f"{a.states} / {b.states}",
                     "ops": f"{a.total_ops} / {b.total_ops}",
                     "library_KiB": f"{a.library_bytes / 1024:.0f} / {b.library_bytes / 1024:.0f}",
                     "build_s": f"{a.build_seconds:.1f} / {b.build_seconds:.1f}",
                     "jacobian": f"{'yes' if a.has_jacobian else 'no'} / {'yes' if b.has_jacobian else 'no'}"})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", type=Path, help="scene files (default: every examples/scenes/*.toml)")
    ap.add_argument("--out", type=Path, help="also write the table as CSV")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="applied to every scene, e.g. fmus.arm.solver=dopri5")
    args = ap.parse_args(argv)
    scenes = args.scenes or sorted((HERE / "scenes").glob("*.toml"))
    rows = [r for s in scenes for r in rows_of(s, args.set)]
    cols = ["scene", "fmu", "states", "ops", "library_KiB", "build_s", "jacobian"]
    print("| " + " | ".join(cols) + " |  (pruned / unpruned)")
    print("|" + "---|" * len(cols))
    for r in rows:
        print("| " + " | ".join(r[c] for c in cols) + " |")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with open(args.out, "w", newline="") as fh:
            w = csv.DictWriter(fh, cols)
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
