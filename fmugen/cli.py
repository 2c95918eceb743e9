"""The ``fmugen`` command: a thin layer over the Python API.

    fmugen equations ROBOT.toml [--latex] [--formulation lagrange] [--form closed|program]
    fmugen build FILE.toml --fmi-type me|cs|both -o OUT.fmu [--outputs p_ee,qdd] [--fold all]
                           [--model inverse_dynamics]
    fmugen info FILE.toml

FILE is a robot file (a ``[robot]`` table) or an assembly of actuator-chain
components (an ``[assembly]`` table).
"""
from __future__ import annotations

import argparse
import sys
import time
import tomllib
from pathlib import Path


def _kind(path: Path) -> str:
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise SystemExit(f"fmugen: {path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise SystemExit(f"fmugen: {path}: not valid TOML: {exc}") from None
    if "robot" in data:
        return "robot"
    if "assembly" in data:
        return "assembly"
    raise SystemExit(f"fmugen: {path}: neither a robot file ([robot] table) nor an assembly ([assembly] table)")


def symbolic_model(path: Path, outputs=("p_ee",), formulation="newton_euler", model="forward_dynamics"):
    """The SymbolicModel a file describes (robot or component assembly).

    For a robot, ``model`` chooses the forward dynamics (states q, qd; input
    tau) or the inverse dynamics (inputs q, qd, qdd; output tau).
    """
    if _kind(path) == "robot":
        import fmugen

        arm = fmugen.load_robot(path, formulation)
        if model == "inverse_dynamics":
            return arm.inverse_dynamics_model()
        return arm.state_space_model(outputs=outputs)
    from .components.assembly import load_assembly

    return load_assembly(path)


def _cmd_equations(args) -> int:
    import fmugen
    from .dynamics.equations import final_equations

    arm = fmugen.load_robot(args.robot, args.formulation)
    sys.stdout.write(final_equations(arm, latex=args.latex, form=args.form))
    return 0


def _cmd_build(args) -> int:
    from .fmi.build import build_fmu

    path = Path(args.file)
    t0 = time.perf_counter()
    outputs = tuple(o for o in args.outputs.split(",") if o)
    model = symbolic_model(path, outputs, args.formulation, args.model)
    t1 = time.perf_counter()
    fold = None if args.fold == "none" else ("all" if args.fold == "all" else args.fold.split(","))
    out = Path(args.output) if args.output else Path(f"{model.name}.fmu")
    result = build_fmu(model, out, fmi_type=args.fmi_type, fold_parameters=fold)
    t2 = time.perf_counter()
    print(f"wrote {result.path}  (derive {t1 - t0:.2f} s, generate+compile+zip {t2 - t1:.2f} s)")
    if args.ops:
        for name, ops in result.op_counts.items():
            print(f"  {name}: {ops}")
    return 0


def _cmd_info(args) -> int:
    path = Path(args.file)
    model = symbolic_model(path)
    print(f"{model.name}: {model.description}")
    for title, group in (("states", model.states), ("inputs", model.inputs), ("outputs", model.outputs),
                         ("parameters", model.parameters)):
        print(f"{title} ({len(group)}):")
        for v in group:
            start = "" if v.start is None else f" = {v.start:g}"
            print(f"  {v.name} [{v.unit}]{start}  {v.description}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="fmugen", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("equations", help="print the final equations of motion of a robot")
    p.add_argument("robot")
    p.add_argument("--latex", action="store_true", help="LaTeX instead of plain text")
    p.add_argument("--formulation", default="newton_euler", choices=["newton_euler", "lagrange"])
    p.add_argument("--form", default="auto", choices=["auto", "closed", "program"],
                   help="closed forms (default up to 3 links) or the program of named intermediates")
    p.set_defaults(func=_cmd_equations)

    p = sub.add_parser("build", help="derive, generate, compile and zip an FMI 2.0 FMU")
    p.add_argument("file", help="robot or assembly TOML file")
    p.add_argument("--fmi-type", default="both", choices=["me", "cs", "both"])
    p.add_argument("-o", "--output", help="path of the .fmu (default: <model name>.fmu)")
    p.add_argument("--outputs", default="p_ee", help="robot outputs besides q, qd: p_ee, qdd (comma separated)")
    p.add_argument("--formulation", default="newton_euler", choices=["newton_euler", "lagrange"])
    p.add_argument("--model", default="forward_dynamics", choices=["forward_dynamics", "inverse_dynamics"],
                   help="robot files: the arm as a dynamic system (default) or its inverse dynamics tau(q, qd, qdd)")
    p.add_argument("--fold", default="none",
                   help="fold parameters into constants: none (default), all, or comma-separated names")
    p.add_argument("--ops", action="store_true", help="print operation counts of the generated functions")
    p.set_defaults(func=_cmd_build)

    p = sub.add_parser("info", help="list the variables a file's model will have")
    p.add_argument("file")
    p.set_defaults(func=_cmd_info)

    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, KeyError, OSError) as exc:  # clear message, no traceback, for user errors
        print(f"fmugen: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
