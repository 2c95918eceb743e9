"""Build time and size per platform of the PUMA FMU and of a scene FMU.

    python examples/bench_platforms.py [--platforms linux64,win64,darwin64] [--warm]
    python examples/bench_platforms.py --fmi-version 3 --platforms x86_64-linux,x86_64-windows,x86_64-darwin,aarch64-darwin,aarch64-linux

Each FMU is built once per platform (that platform's binary only), with the
runtime objects cache off (``FMUGEN_OBJECT_CACHE=0``: every file compiled, the
cost of a first build) unless ``--warm`` (model.c alone compiled, the runtime's
objects taken from the cache, as every later build).  Printed per FMU and
platform: the compile wall time, the binary's size and the .fmu's size (the
sources/ included).  The scene FMU is the "chain" group of
examples/scenes/single_joint_split.toml (amplifier, current driver, servo
valve, hydraulic actuator).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def models():
    import fmugen
    from fmugen.scene import load_scene

    arm = fmugen.load_robot(ROOT / "robots" / "puma_thesis_com.toml")
    yield "PUMA (robots/puma_thesis_com.toml)", arm.state_space_model(outputs=("p_ee",))
    scene = load_scene(ROOT / "examples" / "scenes" / "single_joint_split.toml")
    model, _ = scene.group_model("chain", prune=scene.spec.prune)
    yield "scene FMU chain (examples/scenes/single_joint_split.toml)", model


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--platforms", default="linux64,win64,darwin64")
    ap.add_argument("--warm", action="store_true", help="runtime objects from the cache (model.c compiled alone)")
    ap.add_argument("--fmi-version", type=int, choices=(2, 3), default=2)
    args = ap.parse_args()
    if not args.warm:
        os.environ["FMUGEN_OBJECT_CACHE"] = "0"
    from fmugen.fmi.build import build_fmu

    names = args.platforms.split(",")
    print(f"{'FMU':58s} {'platform':14s} {'compile s':>9s} {'binary kB':>10s} {'.fmu kB':>8s}")
    with tempfile.TemporaryDirectory() as tmp:
        for title, model in models():
            for p in names:
                res = build_fmu(model, Path(tmp) / f"{p}.fmu", fmi_type="both", platforms=[p],
                                fmi_version=args.fmi_version)
                with zipfile.ZipFile(res.path) as z:
                    binary = sum(i.file_size for i in z.infolist() if i.filename.startswith("binaries/"))
                print(f"{title:58s} {p:14s} {res.timings['compile']:9.1f} {binary / 1e3:10.0f} "
                      f"{res.path.stat().st_size / 1e3:8.0f}", flush=True)


if __name__ == "__main__":
    main()
