"""``fmugen suite [FILE.toml] [--cases ...] [--quick] --out DIR``.

Without a file: the named cases of :mod:`fmugen.suite.cases` (all, or the
``--quick`` subset).  With a file: the user's own model run through the same
solvers and judged the same way -- a scene (``[scene]``: its monolithic
model, from its consistent initial state, the recorded variables compared),
a robot file (free motion from the file's start values) or a component
assembly (the start values of its inputs).
"""
from __future__ import annotations

import sys
from pathlib import Path

from .cases import CASES, QUICK_METHODS, TOLERANCE_METHODS, Case, Method, RK4_METHODS, Validity


def parse_sets(items) -> dict:
    """``["amp.theta_ref=0.1", ...]`` -> {name: float}; a clear error otherwise."""
    from ..values import parse_decimal

    out = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        try:
            if not sep or not name.strip():
                raise ValueError
            out[name.strip()] = parse_decimal(value, "")  # plain decimal: float() took 1_5 and 'infinity'
        except ValueError:
            raise ValueError(f"fmugen suite --set {item!r}: expected NAME=NUMBER, e.g. amp.theta_ref=0.1") from None
    return out


def scene_case(path: Path, quick: bool, sets=None) -> Case:
    """A case from a user's file (scene, robot or assembly); ``sets`` gives
    start values of parameters, inputs (held) and states by FMI name."""
    import tomllib

    from ..errors import InputFileError, read_text_file, toml_problem

    text = read_text_file(path, "TOML file")
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise InputFileError(f"{path}: {toml_problem(exc)}") from None
    if "scene" in data:
        from ..scene.scene import load_scene

        scene = load_scene(path)
        model = scene.monolithic_model()
        start = dict(scene.initial.values)
        states = {v.name for v in model.states}
        outputs = {v.name for v in model.outputs}
        units = {v.name: v.unit for v in (*model.states, *model.outputs)}
        recorded = [r for r in scene.spec.record if r in states or r in outputs]
        # one error in one unit: the recorded angles (or positions) when there are any
        compare = tuple(r for r in recorded if units.get(r) == "rad") or \
            tuple(r for r in recorded if units.get(r) == "m") or tuple(recorded[:1]) or \
            tuple(v.name for v in model.states)[:1]
        p_s = max((v.start for v in model.parameters if v.name.endswith(".P_s") and v.start), default=None)
        checks = tuple(Validity(v.name, -p_s, p_s, "the load-pressure form of the valve holds for |P_L| <= P_s")
                       for v in model.states if p_s and v.name.endswith(".P_L"))
        stop, H = scene.spec.stop - scene.spec.start, scene.spec.step
        name, title = scene.name, f"scene {path.name}: {scene.spec.description}"
    else:
        from ..cli import symbolic_model

        model = symbolic_model(path)
        start = {}
        compare = tuple(v.name for v in model.states if v.unit == "rad") or (model.states[0].name,)
        checks, stop, H = (), 1.0, 0.01
        name, title = model.name, f"{path.name}: free run from the start values"
    methods = QUICK_METHODS if quick else TOLERANCE_METHODS + RK4_METHODS
    from ..values import as_number, check_model_values

    sets = {k: as_number(v, f"--set {k}") for k, v in (sets or {}).items()}
    check_model_values(model, sets, lambda k: f"--set {k}")  # the physical checks a file value gets
    start.update(sets)
    return Case(name, title, lambda: model, start, stop, H, compare=compare, methods=methods,
                quick_methods=methods, validity=checks, model_key=name)


def add_parser(sub) -> None:
    """Register ``suite`` on the ``fmugen`` command's subparsers."""
    p = sub.add_parser("suite", help="stiff and extreme cases through every CS solver: accurate / detected / "
                                     "silent failure, table + CSV + plots",
                       description=__doc__.split("\n")[0])
    p.add_argument("file", nargs="?", help="a scene, robot or assembly TOML file to run instead of the named cases")
    p.add_argument("--cases", nargs="+", metavar="NAME",
                   help="named cases (default: all); one of: " + ", ".join(c.name for c in CASES))
    p.add_argument("--quick", action="store_true", help="the quick subset, fewer solver settings per case")
    p.add_argument("--out", default="suite_out", help="directory for suite.csv, the plots and the FMUs")
    p.add_argument("--no-plots", action="store_true", help="skip the plots")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="with FILE: a start value of a parameter, input (held) or state, e.g. amp.theta_ref=0.1")
    p.add_argument("--repeat", type=int, default=1, help="runs per setting, median wall time reported (default 1)")
    p.set_defaults(func=command)


def command(args) -> int:
    from .run import run_suite

    from .. import arguments

    arguments.output_folder(args.out, "--out", inputs=[args.file])  # before any case runs
    arguments.count(args.repeat, "--repeat", 1, 1000)
    sets = parse_sets(args.set)
    if sets and not args.file:
        raise ValueError("fmugen suite --set applies to a FILE.toml run; the named cases fix their own values")
    cases = [scene_case(Path(args.file), args.quick, sets)] if args.file else None
    rows = run_suite(args.cases, quick=args.quick, out=args.out, plots=not args.no_plots, cases=cases,
                     repeats=args.repeat)
    print(f"wrote {Path(args.out) / 'suite.csv'}")
    # a silent failure is a failure of the command
    return 1 if any(r.outcome == "SILENT" for r in rows) else 0


__all__ = ["Method", "add_parser", "command", "scene_case"]


if __name__ == "__main__":  # python -m fmugen.suite.cli ...
    import argparse

    ap = argparse.ArgumentParser(prog="fmugen")
    add_parser(ap.add_subparsers(dest="command", required=True))
    a = ap.parse_args(["suite", *sys.argv[1:]])
    sys.exit(a.func(a))
