"""The ``fmugen`` command: a thin layer over the Python API.

    fmugen equations ROBOT.toml [--latex] [--formulation lagrange] [--form closed|program]
    fmugen build FILE.toml --fmi-type me|cs|both -o OUT.fmu [--outputs p_ee,qdd] [--fold all]
                           [--model inverse_dynamics] [--platforms linux64,win64,darwin64]
    fmugen info FILE.toml
    fmugen export-urdf ROBOT.toml -o ROBOT.urdf [--set NAME=VALUE ...]   (any robot as URDF, fmugen/robot)
    fmugen build SCENE.toml -o DIR [--set NAME=VALUE ...] [--no-prune] [--no-cache]
    fmugen suite [FILE.toml] [--cases NAME ...] [--quick] --out DIR   (stiff and extreme cases, fmugen/suite)
    fmugen linearize FILE.toml [--at NAME=VALUES ...] [--trim NAMES] [--inputs ...] [--outputs ...]
                     [--set ...] [--without INSTANCES] --out FILE.npz   (operating point, A B C D, fmugen/control)
    fmugen sweep SCENE.toml --grid NAME=v1,v2,... | --sample NAME=dist(...) -n N --seed S [--metrics ...]
                 --out DIR [--scheduler ADDRESS] [--workers K]   (parameter studies on Dask, fmugen/sweep)
    fmugen cosim SCENE.toml [--scheme jacobi|gauss-seidel|iterative|newton] [--extrapolation hold|linear|quadratic]
                 [--step H] [--adaptive --tol E] [--stop T] [--set ...] --out DIR   (co-simulation, fmugen/cosim)
    fmugen reference SCENE.toml [--points N] [--set ...] --out DIR   (the scene as one model, Radau at 1e-12)
    fmugen report SCENE.toml [--steps H1,H2,...] [--schemes S/E,...] [--repeats 5] --out DIR   (error vs wall time)
    fmugen ssp SCENE.toml -o OUT.ssp [--set ...]   (the scene as an SSP 1.0 archive, fmugen/ssp)
    fmugen cosim | report SYSTEM.ssp ...           (any SSP of FMI 2.0 FMUs run by fmugen's master)

FILE is a robot file (a ``[robot]`` table), an assembly of actuator-chain
components (an ``[assembly]`` table), a component file (a ``[component]``
table, fmugen/components/README.md) or a scene (a ``[scene]`` table: one FMU
per group into DIR).  ``--set NAME=VALUE`` (repeatable) gives any parameter or
start value (``--set m=1`` for a robot with a symbolic m, ``--set joint.J=5``
in a scene).
"""
from __future__ import annotations

import argparse
import sys
import time
import tomllib
from pathlib import Path


def _file_arg(text: str) -> Path:
    """The file a command names: a path, or ``lib:NAME`` for a shipped component file (as in a scene and
    ``load_component``)."""
    if text.startswith("lib:"):
        from .components.equations import library_path

        return library_path(text[4:])
    return Path(text)


def _kind(path: Path) -> str:
    # user errors are InputFileError (a ValueError): main() prints one line and exits 2
    from .errors import InputFileError, read_text_file, toml_problem
    from .robot.loader import is_urdf

    if is_urdf(path):
        return "robot"
    try:
        data = tomllib.loads(read_text_file(path, "TOML file"))
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise InputFileError(f"{path}: {toml_problem(exc)}") from None
    if "robot" in data:
        return "robot"
    if "assembly" in data:
        return "assembly"
    if "scene" in data:
        return "scene"
    if "component" in data:
        return "component"
    raise InputFileError(f"{path}: neither a robot file ([robot] table), an assembly ([assembly] table), "
                         f"a scene ([scene] table) nor a component file ([component] table)")


def symbolic_model(path: Path, outputs=("p_ee",), formulation="newton_euler", model="forward_dynamics",
                   sets=None, strategy="auto", friction="smooth", limits="range"):
    """The SymbolicModel a file describes (robot, component assembly, or a scene's monolithic model).

    For a robot, ``model`` chooses the forward dynamics (states q, qd; input
    tau) or the inverse dynamics (inputs q, qd, qdd; output tau).  ``sets``
    ({name: value}) gives parameters and start values by name.  ``friction``
    ("smooth" | "stick-slip") and ``limits`` ("range" | "stops"): a robot's
    Coulomb friction and joint limits as smooth terms and validity ranges, or
    as events (``Manipulator.state_space_model``).
    """
    from .scene import SceneError, load_scene, parse_sets

    sets = parse_sets(sets)
    kind = _kind(path)
    if (friction != "smooth" or limits != "range") and (kind != "robot" or model == "inverse_dynamics"):
        flags = " ".join(f for f, on in ((f"--friction {friction}", friction != "smooth"),
                                         (f"--limits {limits}", limits != "range")) if on)
        what = "the inverse-dynamics model" if kind == "robot" else f"a {kind} file"
        raise SceneError(f"{path}: {flags} is for a robot's forward dynamics, not {what}")
    if kind == "scene":
        return load_scene(path, set=sets).monolithic_model()
    if kind == "robot":
        import fmugen

        arm = fmugen.load_robot(path, formulation)
        m = (arm.inverse_dynamics_model() if model == "inverse_dynamics"
             else arm.state_space_model(outputs=outputs, strategy=strategy, friction=friction, limits=limits))
    elif kind == "component":  # a component file: parameters through its checks (ranges, exact ifs)
        from .components.equations import load_component, read_component_file

        params = {d.name for d in read_component_file(path).of_kind("parameter")}
        m = load_component(path, overrides={k: v for k, v in sets.items() if k in params})
    else:
        from .components.assembly import load_assembly

        m = load_assembly(path)
    if sets:
        names = {v.name for g in (m.states, m.inputs, m.parameters) for v in g}
        from .scene.errors import did_you_mean

        for k, v in sets.items():
            if k not in names:
                raise SceneError(f"{path}: --set {k}: no parameter, state or input named {k!r}"
                                 f"{did_you_mean(k, names)}; parameters: {', '.join(p.name for p in m.parameters)}")
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise SceneError(f"{path}: --set {k}={v!r}: a number is needed")
        from .robot.value_checks import robot_value_problem
        from .values import as_number, check_model_values

        sets = {k: as_number(v, f"{path}: --set {k}") for k, v in sets.items()}
        if kind == "robot":  # the robot file's checks, with the link and quantity named
            params = {p.name for p in m.parameters}
            problem = robot_value_problem(arm.robot, {k: v for k, v in sets.items() if k in params})
            if problem:
                raise SceneError(f"{path}: --set: {problem}")
        check_model_values(m, sets, lambda k: f"{path}: --set {k}")  # the checks file values get
        m = m.with_starts(sets)
    return m


def _cmd_equations(args) -> int:
    import fmugen
    from .dynamics.equations import final_equations

    arm = fmugen.load_robot(args.robot, args.formulation)
    sys.stdout.write(final_equations(arm, latex=args.latex, form=args.form))
    return 0


def _cmd_export_urdf(args) -> int:
    from .robot.loader import load_robot_description
    from .robot.urdf_export import robot_to_urdf
    from .scene import parse_sets

    from .arguments import output_file
    from .robot.value_checks import robot_value_problem

    output_file(args.output, "-o", inputs=[args.robot])  # never over its own input
    robot = load_robot_description(args.robot)
    sets = parse_sets(args.set)
    problem = robot_value_problem(robot, {k: v for k, v in sets.items()
                                          if k in {p.name for p in robot.parameters}})
    if problem:
        raise ValueError(f"{args.robot}: --set: {problem}")
    text = robot_to_urdf(robot, sets or None)
    Path(args.output).write_text(text)
    print(f"wrote {args.output}: {robot.n} joints, {len(robot.frames)} frames")
    return 0


def _cmd_build_scene(args) -> int:
    from .scene import load_scene

    if args.fmi_type is not None:  # one flag for all groups would hide what the file says per FMU
        raise ValueError(f"{args.file}: --fmi-type does not apply to a scene: each FMU's type is its group's "
                         f"fmi_type (\"cs\" or \"me\"; \"me\" FMUs carry both interfaces), e.g. "
                         f"--set fmus.<group>.fmi_type=me")

    from .arguments import output_folder

    if args.output:
        output_folder(args.output, "-o", inputs=[args.file])
    sets = args.set
    # --platforms and --fmi-version are the scene's [scene] platforms and fmi_version, as --set would give them
    for flag, key, value in (("--platforms", "platforms", args.platforms), ("--fmi-version", "fmi_version",
                                                                               args.fmi_version)):
        if value is None:
            continue
        from .scene import parse_sets

        sets = parse_sets(sets)
        if f"scene.{key}" in sets:
            raise ValueError(f"{args.file}: {flag} and --set scene.{key} both given; give one")
        sets[f"scene.{key}"] = value
    scene = load_scene(args.file, set=sets, allow_factories=args.allow_factories)
    out = Path(args.output) if args.output else Path(scene.name)
    if out.suffix == ".fmu":
        raise ValueError(f"{args.file}: a scene builds one FMU per group: -o names a folder, not {out}")
    output_folder(out, "-o", inputs=[args.file])
    built = scene.build(out, prune=False if args.no_prune else None, use_cache=not args.no_cache)
    print(built.summary())
    print(f"wrote {len(built.fmus)} FMU(s) into {out}")
    return 0


def _bytes(text: str) -> float:
    """'800M', '1.5G', '512k' or a plain number of bytes."""
    units = {"K": 2**10, "M": 2**20, "G": 2**30}
    t = text.strip().upper().rstrip("B").rstrip("I")
    from .values import DECIMAL

    number, scale = (t[:-1], units[t[-1]]) if t and t[-1] in units else (t, 1)
    if not DECIMAL.fullmatch(number):  # the plain decimal grammar of every number given as text (values.py)
        raise ValueError(f"--budget-memory {text!r}: a size such as 800M, 1.5G or a number of bytes")
    v = float(number) * scale
    if not (v > 0 and v < float("inf")):
        raise ValueError(f"--budget-memory {text!r}: a positive size such as 800M, 1.5G")
    return v


def _component_terminals(path: Path, model) -> list:
    """The FMI 3.0 terminals of a component file built alone: one per connector it declares, with those of
    its variables the FMU has (as a scene names them for a group of one instance)."""
    from .components.equations import read_cached
    from .fmi.terminals import connector_terminal, interface

    io = interface(model)
    out = []
    for cname, (ctype, mapping) in read_cached(str(path)).connectors.items():
        t = connector_terminal(cname, ctype, mapping, io, description=f"{ctype} connector {cname}")
        if t is not None:
            out.append(t)
    return out


def _cmd_build(args) -> int:
    from .fmi.build import build_fmu

    path = _file_arg(args.file)
    if _kind(path) == "scene":
        return _cmd_build_scene(args)
    from .arguments import output_file

    t0 = time.perf_counter()
    if args.output:  # checked before anything is derived: never the input, never a folder
        output_file(args.output, "-o", inputs=[path])
    memory = _bytes(args.budget_memory) if args.budget_memory else None
    if args.budget_seconds is not None and not (args.budget_seconds > 0 and args.budget_seconds < float("inf")):
        raise ValueError(f"--budget-seconds {args.budget_seconds!r}: must be a positive number of seconds")
    outputs = tuple(o for o in args.outputs.split(",") if o)
    fmi_version = 2
    if args.fmi_version is not None:  # checked, with the platforms, before anything is derived
        if args.fmi_version.strip() not in ("2", "3"):
            raise ValueError(f"{path}: --fmi-version {args.fmi_version!r}: give 2 (FMI 2.0, the default) or 3")
        fmi_version = int(args.fmi_version)
        from .errors import FmugenError
        from .fmi.build import _check_fmi_version

        try:
            _check_fmi_version(fmi_version, args.platforms)
        except FmugenError as e:
            raise ValueError(f"{path}: --fmi-version {fmi_version}: {str(e).split(': ', 1)[-1]}") from None
    platforms = None
    if args.platforms is not None:  # checked, and the cross compilers found, before anything is derived
        from .fmi.platforms import resolve

        platforms = [t.name for t in resolve(args.platforms, where=f"{path}: --platforms", fmi_version=fmi_version)]
    if sys.stderr.isatty():  # progress of the first stage; build_fmu reports the others
        print(f"fmugen build {path.name}: derive ...", end="", file=sys.stderr, flush=True)
    model = symbolic_model(path, outputs, args.formulation, args.model, sets=args.set, strategy=args.strategy,
                           friction=args.friction, limits=args.limits)
    t1 = time.perf_counter()
    if sys.stderr.isatty():
        print(f" {t1 - t0:.1f} s", file=sys.stderr, flush=True)
    fold = None if args.fold == "none" else ("all" if args.fold == "all" else args.fold.split(","))
    out = output_file(args.output or f"{model.name}.fmu", "-o", inputs=[path])
    # FMI 3.0 terminals: a robot's joints (build_fmu's default), a component file's declared connectors
    terminals = _component_terminals(path, model) if fmi_version == 3 and _kind(path) == "component" else None
    result = build_fmu(model, out, fmi_type=args.fmi_type or "both", fold_parameters=fold, budget_start=t0,
                       budget_seconds=args.budget_seconds, budget_memory=memory, platforms=platforms,
                       fmi_version=fmi_version, terminals=terminals)
    t2 = time.perf_counter()
    print(f"wrote {result.path}  (derive {t1 - t0:.2f} s, generate+compile+zip {t2 - t1:.2f} s)")
    if args.ops:
        for name, ops in result.op_counts.items():
            print(f"  {name}: {ops}")
    return 0


def _cmd_info(args) -> int:
    path = _file_arg(args.file)
    if _kind(path) == "scene":
        from .scene import load_scene

        scene = load_scene(path, set=args.set, allow_factories=args.allow_factories)
        print(f"scene {scene.name}: {scene.spec.description}")
        for g in scene.groups:
            m, removed = scene.group_model(g, prune=scene.spec.prune)
            print(f"FMU {g} ({', '.join(scene.groups[g].members)}): {m.nx} states; inputs "
                  f"{', '.join(v.name for v in m.inputs) or '-'}; outputs "
                  f"{', '.join([v.name for v in m.states if v.output] + [v.name for v in m.outputs]) or '-'}")
            for r in removed:
                print(f"    pruned: {r}")
        for b in scene.spec.bonds:  # the physical bonds of connect, and the signals that make each
            print(f"bond {b}: " + ", ".join(f"{v}: {src} -> {dst}" for v, src, dst in b.signals))
        return 0
    model = symbolic_model(path, sets=args.set)
    print(f"{model.name}: {model.description}")
    for title, group in (("states", model.states), ("inputs", model.inputs), ("outputs", model.outputs),
                         ("parameters", model.parameters)):
        print(f"{title} ({len(group)}):")
        for v in group:
            start = "" if v.start is None else f" = {v.start:g}"
            print(f"  {v.name} [{v.unit}]{start}  {v.description}")
    return 0


#: subcommand -> (its line in ``fmugen --help``, "module:function" that registers its full parser).
#: Only the command being run is registered in full: its module (and what that imports: sympy,
#: numpy, fmpy, dask) is loaded only then, so ``fmugen --help`` starts in well under a second.
COMMANDS = {
    "equations": ("print the final equations of motion of a robot", "fmugen.cli:_add_own_commands"),
    "build": ("derive, generate, compile and zip an FMI 2.0 FMU", "fmugen.cli:_add_own_commands"),
    "info": ("list the variables a file's model will have", "fmugen.cli:_add_own_commands"),
    "export-urdf": ("write a robot (TOML or URDF) as a URDF file, parameters at their values",
                    "fmugen.cli:_add_own_commands"),
    "suite": ("stiff and extreme cases through every CS solver: accurate / detected / silent failure, "
              "table + CSV + plots", "fmugen.suite.cli:add_parser"),
    "linearize": ("trim and linearise a robot, assembly or scene (A, B, C, D into .npz)",
                  "fmugen.control.cli:add_parser"),
    "sweep": ("run a scene over a parameter grid or Monte-Carlo sample (Dask)", "fmugen.sweep.cli:add_parser"),
    "ssp": ("write a scene as an SSP 1.0 archive (FMUs, connections, parameters, units, default experiment) that "
            "other FMI masters run", "fmugen.ssp.cli:add_parser"),
    "cosim": ("co-simulate a scene's FMUs (results.csv, .npz, plot, summary)",
              "fmugen.cosim.commands:add_cosim_commands"),
    "reference": ("solve a scene as one model with Radau at 1e-12 (reference.csv, plot)",
                  "fmugen.cosim.commands:add_cosim_commands"),
    "report": ("error against wall time over schemes and macro steps", "fmugen.cosim.commands:add_cosim_commands"),
    "size": ("propose an actuator parameter set per joint of an arm (hydraulic or electric)",
             "fmugen.components.arm_sizing:add_parser"),
}


def _add_own_commands(sub) -> None:
    """``equations``, ``build`` and ``info``: defined in this module."""
    p = sub.add_parser("equations", help="print the final equations of motion of a robot")
    p.add_argument("robot")
    p.add_argument("--latex", action="store_true", help="LaTeX instead of plain text")
    p.add_argument("--formulation", default="newton_euler", choices=["newton_euler", "lagrange"])
    p.add_argument("--form", default="auto", choices=["auto", "closed", "program"],
                   help="closed forms (default up to 3 links) or the program of named intermediates")
    p.set_defaults(func=_cmd_equations)

    p = sub.add_parser("build", help="derive, generate, compile and zip an FMI 2.0 FMU")
    p.add_argument("file", help="robot, assembly, component or scene TOML file (lib:NAME: a shipped component file)")
    p.add_argument("--fmi-type", default=None, choices=["me", "cs", "both"],
                   help="robot, assembly and component files (default both); a scene's FMUs take their group's fmi_type")
    p.add_argument("-o", "--output", help="path of the .fmu (default: <model name>.fmu); a folder for a scene")
    p.add_argument("--outputs", default="p_ee", help="robot outputs besides q, qd: p_ee, qdd (comma separated)")
    p.add_argument("--formulation", default="newton_euler", choices=["newton_euler", "lagrange"])
    p.add_argument("--model", default="forward_dynamics", choices=["forward_dynamics", "inverse_dynamics"],
                   help="robot files: the arm as a dynamic system (default) or its inverse dynamics tau(q, qd, qdd)")
    p.add_argument("--fold", default="none",
                   help="fold parameters into constants: none (default), all, or comma-separated names")
    p.add_argument("--ops", action="store_true", help="print operation counts of the generated functions")
    p.add_argument("--strategy", default="auto", choices=["auto", "straight", "loops"],
                   help="robots: straight-line code, or the runtime's looped dynamics (auto: loops from 7 links)")
    p.add_argument("--friction", default="smooth", choices=["smooth", "stick-slip"],
                   help="robots: Coulomb friction as the smooth tanh term (default), or stick and slip modes "
                        "(events)")
    p.add_argument("--limits", default="range", choices=["range", "stops"],
                   help="robots: joint limits as validity ranges (default), or end stops (events)")
    p.add_argument("--budget-seconds", type=float, default=None,
                   help="stop the build (with a message, temporary files removed) after this many seconds")
    p.add_argument("--budget-memory", default=None,
                   help="stop the build when it holds more memory than this (e.g. 1G, 800M)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="set a parameter, start value or option (repeatable), e.g. m=1 or joint.J=5")
    p.add_argument("--platforms", default=None, metavar="P1,P2,...",
                   help="binaries to build: linux64, win64 (MinGW-w64), darwin64 (zig cc: x86_64 + "
                        "arm64 in one file); with --fmi-version 3 also the FMI 3.0 folders x86_64-linux, "
                        "x86_64-windows, x86_64-darwin, aarch64-darwin, aarch64-linux (zig cc); default this "
                        "machine's; a scene's [scene] platforms")
    p.add_argument("--fmi-version", default=None, metavar="2|3",
                   help="2: FMI 2.0 (default); 3: FMI 3.0, opt-in, built on x86_64 Linux, scalar variables "
                        "(fmugen/fmi/README.md); a scene's [scene] fmi_version")
    p.add_argument("--no-prune", action="store_true", help="scenes: keep what the scene does not need")
    p.add_argument("--no-cache", action="store_true", help="scenes: rebuild every FMU")
    p.add_argument("--allow-factories", action="store_true",
                   help="scenes: allow instances made by a Python factory (runs code named in the file)")
    p.set_defaults(func=_cmd_build)

    p = sub.add_parser("export-urdf", help="write a robot (TOML or URDF) as a URDF file, parameters at their values")
    p.add_argument("robot")
    p.add_argument("-o", "--output", required=True, help="the .urdf file to write")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="parameter values")
    p.set_defaults(func=_cmd_export_urdf)

    p = sub.add_parser("info", help="list the variables a file's model will have")
    p.add_argument("file")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="set a parameter, start value or option (repeatable)")
    p.add_argument("--allow-factories", action="store_true",
                   help="scenes: allow instances made by a Python factory (runs code named in the file)")
    p.set_defaults(func=_cmd_info)


def _parser(argv) -> argparse.ArgumentParser:
    """The ``fmugen`` parser: the command named in ``argv`` in full, the others as one-line stubs."""
    import importlib

    parser = argparse.ArgumentParser(prog="fmugen", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    chosen = next((a for a in argv if not a.startswith("-")), None)
    if chosen in COMMANDS:
        module, _, func = COMMANDS[chosen][1].partition(":")
        getattr(importlib.import_module(module), func)(sub)
    for name, (text, _) in COMMANDS.items():
        if name not in sub.choices:
            sub.add_parser(name, help=text, add_help=False)
    return parser


def _negative_values(argv: list) -> list:
    """``--steps -1e-3`` as ``--steps=-1e-3``: argparse takes a value starting with '-' in exponent form
    (or -inf) for an option, so the option would be refused as having no value; the option's own check
    then names the actual problem (a negative step)."""
    import re

    number = re.compile(r"-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(,[-+0-9.eE]*)*|-(inf|nan|infinity)", re.I)
    out: list = []
    for tok in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and number.fullmatch(tok):
            out[-1] = f"{out[-1]}={tok}"
        else:
            out.append(tok)
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _parser(argv)
    args = parser.parse_args(_negative_values(sys.argv[1:] if argv is None else list(argv)))
    try:
        return args.func(args)
    except (ValueError, KeyError, OSError) as exc:  # clear message, no traceback, for user errors
        text = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        print("fmugen: " + str(text).replace("\n", " "), file=sys.stderr)  # one line
        return 2
    except RuntimeError as exc:  # a C compiler that failed: one line (the command and its first error)
        if not any(c.__name__ == "BuildError" for c in type(exc).__mro__):
            raise
        lines = str(exc).splitlines() or [type(exc).__name__]
        first = next((ln.strip() for ln in lines[1:] if "error" in ln.lower()), "")
        print(f"fmugen: {lines[0].rstrip(':')}{': ' + first if first else ''}"[:1500], file=sys.stderr)
        return 1
    except RecursionError:  # an input nested deeper than any reader handles (a last resort: readers name it)
        print(f"fmugen: {args.command}: an input is nested too deeply to be read", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
