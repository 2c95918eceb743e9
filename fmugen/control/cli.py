"""``fmugen linearize``: trim and linearise a robot, an assembly or a scene from the shell.

    fmugen linearize ROBOT_OR_SCENE.toml [--at NAME=VALUES ...] [--trim NAMES] [--inputs NAMES]
                     [--outputs NAMES] [--set NAME=VALUE ...] [--without INSTANCES] [--no-trim]
                     [--dt T] --out FILE.npz

``--at q=0.3,-0.5,0.8,0.2,-0.4,0.6 --at qd=0 --trim tau``: the pose given,
the torques that hold it solved for.  Every state that ``--at`` does not give
is solved for too (the point is an equilibrium); ``--no-trim`` linearises at
the given and start values as they are.  Names are FMI names, their
python-control spelling ('.' -> '_'), or base names of vectors (``q``).
``--without 'path*,amp*'`` removes scene instances (the plant without its
controllers: the inputs they drove become inputs).

Prints the sizes, the operating point's residual, eigenvalues with damping
and natural frequency, the stiffness ratio, and the controllability and
observability ranks; with ``--dt T`` the plant held by a zero-order hold and sampled every T s
(``A``, ``B`` the discrete ``exp(A T)``, ``int_0^T exp(A s) ds B``; ``dt``, and the continuous
``A_continuous``, ``B_continuous``, in the file too; the eigenvalues printed are then |z|).  Writes
``A``, ``B``, ``C``, ``D``, the operating point
(``t``, ``x0``, ``u0`` -- every input --, ``y0``) and the FMI names
``states``, ``inputs`` (columns of B), ``outputs``, ``all_inputs`` into the
``.npz`` (``numpy.load`` reads it without pickle).
"""
from __future__ import annotations

import sys
import tomllib
from pathlib import Path

import numpy as np

from .names import FmugenError


def add_parser(sub) -> None:
    """Register ``linearize`` on the ``fmugen`` command's subparsers."""
    p = sub.add_parser("linearize", help="trim and linearise a robot, assembly or scene (A, B, C, D into .npz)",
                       description=__doc__.split("\n\n")[2].strip())
    p.add_argument("file", help="robot, assembly or scene TOML file")
    p.add_argument("--at", action="append", default=[], metavar="NAME=VALUES",
                   help="hold a state or input at VALUES (comma separated, or one for all elements), "
                        "or require an output to take them; repeatable")
    p.add_argument("--trim", default="", metavar="NAMES",
                   help="states/inputs to solve for (comma separated; their --at values are guesses)")
    p.add_argument("--no-trim", action="store_true", help="linearise at the given/start values, no solve")
    p.add_argument("--inputs", default=None, metavar="NAMES", help="columns of B, D (default: all inputs)")
    p.add_argument("--outputs", default=None, metavar="NAMES",
                   help="rows of C, D: states or outputs (default: the states exposed as outputs, then the "
                        "computed outputs); robot files also accept p_ee, qdd")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="a parameter (robot, assembly) or any scene setting; repeatable")
    p.add_argument("--without", default="", metavar="INSTANCES",
                   help="scenes: instances to remove (comma separated, shell patterns), opening the loop")
    p.add_argument("--formulation", default="newton_euler", choices=["newton_euler", "lagrange"])
    p.add_argument("--time", type=float, default=0.0, help="time of the operating point [s]")
    p.add_argument("--tol", type=float, default=1e-9, help="largest scaled residual accepted by the trim")
    p.add_argument("--dt", type=float, default=None, metavar="T",
                   help="sample period [s]: write the zero-order-hold discretised plant (A, B discrete; dt)")
    p.add_argument("--out", required=True, metavar="FILE.npz")
    p.set_defaults(func=run)


def _split(text):
    return [n.strip() for n in (text or "").split(",") if n.strip()]


def parse_at(items) -> dict:
    """``["q=0.3,-0.5", "qd=0"]`` -> ``{"q": [0.3, -0.5], "qd": [0.0]}`` (numbers only)."""
    out = {}
    for item in items:
        if "=" not in item:
            raise FmugenError(f"--at {item!r}: expected NAME=VALUES")
        name, text = (s.strip() for s in item.split("=", 1))
        try:
            vals = [float(v) for v in text.split(",")]
        except ValueError:
            raise FmugenError(f"--at {item!r}: VALUES must be comma-separated numbers") from None
        if not name or not vals or not np.all(np.isfinite(vals)):
            raise FmugenError(f"--at {item!r}: a name and finite numbers are needed")
        out[name] = vals
    return out


def load_model(path: Path, sets: dict, robot_outputs=(), formulation="newton_euler", without=()):
    """(SymbolicModel, parameter values) of a robot, assembly or scene file."""
    from ..errors import InputFileError, read_text_file, toml_problem
    from ..robot.loader import is_urdf

    try:
        data = {"robot": {}} if is_urdf(path) else tomllib.loads(read_text_file(path, "TOML file"))
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise InputFileError(f"{path}: {toml_problem(exc)}") from None
    if "scene" in data:
        from ..scene import load_scene
        from .scene import scene_model

        return scene_model(load_scene(path, set=sets), without), {}
    if without:
        raise FmugenError(f"{path}: --without applies to scenes only")
    bad = {k: v for k, v in sets.items() if isinstance(v, bool) or not isinstance(v, (int, float))}
    if bad:
        raise FmugenError(f"{path}: --set {', '.join(f'{k}={v!r}' for k, v in bad.items())}: a parameter "
                          f"value must be a number")
    from ..robot.value_checks import robot_value_problem
    from ..values import as_number, check_model_values

    sets = {k: as_number(v, f"{path}: --set {k}") for k, v in sets.items()}
    if "robot" in data:
        import fmugen

        arm = fmugen.load_robot(path, formulation)
        model = arm.state_space_model(outputs=robot_outputs)
        problem = robot_value_problem(arm.robot, {k: v for k, v in sets.items()
                                                  if k in {p.name for p in model.parameters}})
        if problem:  # the checks the file's own values passed
            raise FmugenError(f"{path}: --set: {problem}")
        return model, sets
    if "assembly" in data:
        from ..components.assembly import load_assembly

        model = load_assembly(path)
        check_model_values(model, sets, lambda k: f"{path}: --set {k}")
        return model, sets
    if "component" in data:  # a component file: parameters through its own checks (ranges, exact ifs)
        from ..components.equations import load_component, read_component_file

        params = {d.name for d in read_component_file(path).of_kind("parameter")}
        model = load_component(path, overrides={k: v for k, v in sets.items() if k in params})
        return model, {k: v for k, v in sets.items() if k not in params}
    raise InputFileError(f"{path}: neither a robot file ([robot] table), an assembly ([assembly] table), "
                         f"a scene ([scene] table) nor a component file ([component] table)")


def describe(lm, model, op=None, out=None) -> None:
    """The printed summary (module doc)."""
    out = out or sys.stdout
    from .analysis import modal_ranks, modes, stiffness_ratio

    nx, nu, ny = lm.A.shape[0], lm.B.shape[1], lm.C.shape[0]
    print(f"{lm.name}: {nx} states, {nu} inputs, {ny} outputs; A {nx}x{nx}, B {nx}x{nu}, "
          f"C {ny}x{nx}, D {ny}x{nu}", file=out)
    if op is not None:
        print(op.report(), file=out)
    if getattr(lm, "mode", None):
        print("a hybrid model, linearised in the mode it is in: "
              + ", ".join(f"{k} = {v:g}" for k, v in lm.mode.items())
              + " (valid until its next event; another mode: --set NAME=VALUE)", file=out)
    print("eigenvalues (slowest first):", file=out)
    print(f"  {'real':>14} {'imag':>14} {'damping':>9} {'freq [rad/s]':>13}", file=out)
    for lam, zeta, w in modes(lm.A):
        print(f"  {lam.real:14.6g} {lam.imag:14.6g} {zeta:9.4f} {w:13.6g}", file=out)
    print(f"stiffness ratio max|Re|/min|Re| over stable modes: {stiffness_ratio(lm.A):.4g}", file=out)
    scale = np.array([abs(v.nominal) if v.nominal else 1.0 for v in model.states])
    rc, ro = modal_ranks(lm.A, lm.B, lm.C, state_scale=scale)
    print(f"controllability rank {rc}/{nx}, observability rank {ro}/{nx} "
          f"(modal test, states scaled by their nominal values, tol 1e-9)", file=out)


def _warn_kinks(path: Path, sets: dict, model, op) -> None:
    from ..robot.loader import is_urdf

    if is_urdf(path):
        return  # a robot: no smoothed kinks
    data = tomllib.loads(path.read_text())
    if "component" in data:
        from .kinks import component_kink_warnings

        for line in component_kink_warnings(path, model, op):
            print(line)
    if "scene" not in data:
        return
    from ..scene import load_scene
    from .kinks import kink_warnings

    for line in kink_warnings(load_scene(path, set=sets), model, op):
        print(line)


def run(args) -> int:
    from ..scene import parse_sets
    from .linearize import linear_model
    from .trim import trim

    from .. import arguments
    from ..cli import _file_arg

    path = _file_arg(args.file)  # a path, or lib:NAME (a shipped component file)
    # every argument first: named in its refusal, nothing derived or written before
    args.tol = arguments.tolerance(args.tol, "--tol")
    args.time = arguments.number(args.time, "--time")
    if args.dt is not None:
        args.dt = arguments.number(args.dt, "--dt")
        if not args.dt > 0:
            raise FmugenError(f"--dt {args.dt!r}: the sample period must be positive [s]")
    arguments.output_file(args.out, "--out", inputs=[path])
    sets = parse_sets(args.set)
    at = parse_at(args.at)
    wanted = _split(args.outputs)
    robot_outputs = tuple(o for o in ("p_ee", "qdd") if any(w == o or w.startswith(o + "[") for w in wanted))
    model, params = load_model(path, sets, robot_outputs, args.formulation, tuple(_split(args.without)))
    free = _split(args.trim)
    op = None
    if args.no_trim:
        if free:
            raise FmugenError("--no-trim and --trim exclude each other")
        from .trim import _expand

        from ..codegen.evaluate import ModelEvaluator

        ev = ModelEvaluator(model, params)
        x, u = ev.x0.copy(), ev.u0.copy()
        for s, v in _expand(model, at, ("state", "input")).items():
            (x if s.kind == "state" else u)[s.index] = v
        lm = linear_model(model, x, u, args.time, params, wanted or "all", _split(args.inputs) or None)
    else:
        op = trim(model, at=at, free=free, parameter_values=params, t=args.time, tol=args.tol)
        lm = linear_model(model, op, outputs=wanted or "all", inputs=_split(args.inputs) or None)
    describe(lm, model, op)
    extra = {}
    if args.dt is not None:
        from .sampled import c2d

        extra = dict(dt=np.float64(args.dt), A_continuous=lm.A, B_continuous=lm.B)
        lm = c2d(lm, args.dt)
        z = np.linalg.eigvals(lm.A) if lm.A.size else np.zeros(0)
        print(f"discretised (zero-order hold) at dt = {args.dt:g} s: x[k+1] = A x[k] + B u[k]; "
              f"|z| of A (largest first): " + ", ".join(f"{v:.6g}" for v in sorted(np.abs(z), reverse=True)))
    if op is not None and not args.no_trim:  # a smoothed kink at the operating point: say so (fmugen/control/kinks.py)
        _warn_kinks(path, sets, model, op)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez(out, A=lm.A, B=lm.B, C=lm.C, D=lm.D, t=np.float64(lm.t), x0=lm.x0, u0=lm.u0, y0=lm.y0,
             states=np.array(lm.states, dtype=str), inputs=np.array(lm.inputs, dtype=str),
             outputs=np.array(lm.outputs, dtype=str), all_inputs=np.array(lm.all_inputs, dtype=str),
             residual=np.float64(op.max_residual if op is not None else np.nan), **extra)
    print(f"wrote {out}")
    return 0
