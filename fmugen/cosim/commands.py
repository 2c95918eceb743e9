"""The ``fmugen cosim``, ``fmugen reference`` and ``fmugen report`` subcommands.

    fmugen cosim SCENE.toml [--scheme jacobi|gauss-seidel|iterative|newton] [--extrapolation hold|linear|quadratic|cubic]
                 [--step H] [--adaptive --tol E] [--stop T] [--workers N] [--set NAME=VALUE ...] --out DIR
    fmugen reference SCENE.toml [--stop T] [--points N] [--set ...] --out DIR
    fmugen report SCENE.toml [--steps H1,H2,...] [--schemes jacobi/hold,...] [--repeats 5] [--target 1e-4]
                  [--internal rodas3:1e-10,dopri5:1e-8] [--no-monolithic] [--workers N] [--stop T] [--set ...]
                  --out DIR

``cosim`` writes DIR/results.csv (``time``, then every recorded column),
DIR/results.npz (a structured array ``results`` and the summary), DIR/results.png
and DIR/summary.txt; the exit status is 0 on success, 3 when the run ended but is unreliable (its coupling
error estimate exceeds --tol, or grows), 1 with the failure
report when the run failed (the results up to the failure are written).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

# the argument checks and flags that `fmugen report x.ssp` (fmugen.ssp.report) shares with these commands
# live in their own module, which imports neither: no import circle between cosim and ssp
from .run_arguments import check_args as _check_args, run_flags as _flags


def _load(args):
    import fmugen
    from fmugen.scene import parse_sets

    return fmugen.load_scene(args.scene, set=parse_sets(args.set),
                             allow_factories=bool(getattr(args, "allow_factories", False)))


def _common(p) -> None:
    p.add_argument("scene", help="scene TOML file, or an SSP archive (.ssp; cosim and report)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="set a parameter, start value or option (repeatable)")
    p.add_argument("--stop", type=float, default=None, help="stop time [s] (default: the scene's)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--allow-factories", action="store_true",
                   help="allow instances made by a Python factory (runs code named in the file)")


def add_cosim_commands(subparsers) -> None:
    """Register ``cosim``, ``reference`` and ``report`` on an argparse subparsers object."""
    p = subparsers.add_parser("cosim", help="co-simulate a scene's FMUs (results.csv, .npz, plot, summary)")
    _common(p)
    p.add_argument("--scheme", default=None, help="jacobi | gauss-seidel | iterative | newton "
                   "(default: the scene's [cosim] scheme, else gauss-seidel)")
    p.add_argument("--extrapolation", default=None, help="hold | linear | quadratic | cubic (cubic: iterative and "
                   "newton only; default: the scene's, else linear)")
    p.add_argument("--step", type=float, default=None, help="macro step H [s] (default: the scene's [cosim] "
                   "step, else its [scene] step)")
    p.add_argument("--adaptive", action="store_true", default=None,
                   help="control H by the interface defect (with --tol)")
    p.add_argument("--tol", type=float, default=None,
                   help="accuracy relative to each signal's range: a run whose coupling error estimate exceeds it "
                        "ends unreliable (exit 3); with --adaptive also the step's target (default: the scene's, "
                        "else 1e-4)")
    _run_flags(p)
    p.set_defaults(func=cmd_cosim)

    p = subparsers.add_parser("reference", help="solve a scene as one model with Radau at 1e-12 (reference.csv, "
                              "plot)")
    _common(p)
    p.add_argument("--points", default=2001, help="points of the uniform output grid (>= 1001; at most 1e7)")
    p.set_defaults(func=cmd_reference)

    p = subparsers.add_parser("report", help="error against wall time over schemes and macro steps")
    _common(p)
    p.add_argument("--steps", default=None, help="comma-separated macro steps [s] (default: the scene's step "
                   "times 8, 4, 2, 1, 1/2)")
    p.add_argument("--schemes", default=None, help="comma-separated scheme/extrapolation pairs "
                   "(default: jacobi/hold, jacobi/linear, gauss-seidel/hold, gauss-seidel/linear, newton/linear)")
    p.add_argument("--repeats", type=int, default=5, help="timed runs per setting after a warm-up (median)")
    p.add_argument("--target", type=float, default=1e-4, help="error target for the coarsest-setting summary")
    p.add_argument("--no-monolithic", action="store_true", help="leave out the monolithic FMU row")
    _run_flags(p)
    p.add_argument("--internal", default=None, help="comma-separated internal solver:tolerance pairs to sweep "
                   "as well, e.g. rodas3:1e-10,dopri5:1e-8 (default: the scene's)")
    p.set_defaults(func=cmd_report)


WORKERS_HELP = ("threads that step the FMUs side by side under jacobi, iterative and newton, when a sweep of "
                "them costs more than 0.5 ms (default: the scene's [cosim] workers, else 1; results are identical)")


def _run_flags(p) -> None:
    """Flags of run settings shared by ``cosim`` and ``report`` (fmugen.cosim.settings: file < --set < flag)."""
    p.add_argument("--workers", type=int, default=None, help=WORKERS_HELP)
    p.add_argument("--coupling-tol", type=float, default=None, help="iterative, newton: the coupled values "
                   "converge to this, relative to each signal (default: the scene's [cosim] coupling_tol, else "
                   "the master's)")
    p.add_argument("--iterations", type=int, default=None, help="iterative, newton: most iterations per macro "
                   "step (default: the scene's [cosim] iterations, else the master's)")
    p.add_argument("--no-divergence-check", dest="detect_divergence", action="store_false", default=None,
                   help="do not stop a run whose coupling the master judges divergent")


def sampling_period(system):
    """The shortest sample period of the system's FMUs (their clocks), or None."""
    from .units import clocks_of_fmu

    periods = [p for u in system.units for p, _ in clocks_of_fmu(u.path, u.start_values)]
    return min(periods) if periods else None


def _divides(h: float, period: float) -> bool:
    k = period / h
    return k >= 1 - 1e-9 and abs(k - round(k)) <= 1e-9 * k


def _plot(result, path, title, units=None) -> None:
    """One panel per physical unit (every column in it, labelled), or per column when units are unknown.

    A dozen panels of their own took seconds to draw; a panel per unit shows the same curves and
    compares like with like (the six joint angles together)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = {}
    for c in result.columns:
        panels.setdefault((units or {}).get(c) or c if units else c, []).append(c)
    n = len(panels)
    height = 2.6 * n + 1 if units else 1.8 * n + 1
    fig, axes = plt.subplots(n, 1, figsize=(8, height), sharex=True, squeeze=False)
    for ax, (unit, cols) in zip(axes[:, 0], panels.items()):
        for c in cols:
            ax.plot(result.time, result[c], lw=1, label=c)
        ax.set_ylabel(f"[{unit}]" if units and unit not in cols else cols[0], fontsize=8)
        if units and len(cols) > 1:
            ax.legend(fontsize=7, ncol=min(len(cols), 6), loc="best")
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].set_title(title, fontsize=9)
    # fixed margins: tight_layout measures every tick label of every axis (seconds for a dozen panels)
    fig.subplots_adjust(left=0.14, right=0.98, top=1 - 0.45 / height, bottom=0.55 / height, hspace=0.15)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_results(result, out_dir, units=None) -> dict:
    """results.csv, results.npz, results.png and summary.txt (also after a failure).

    ``units``: column -> physical unit (the plot draws one panel per unit)."""
    import numpy as np

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {k: out / v for k, v in (("csv", "results.csv"), ("npz", "results.npz"), ("plot", "results.png"),
                                     ("summary", "summary.txt"))}
    np.savetxt(paths["csv"], np.column_stack([result.time, result.values]), delimiter=",",
               header=",".join(["time", *result.columns]), comments="", fmt="%.17g")
    np.savez(paths["npz"], results=result.structured(), summary=json.dumps(result.summary.as_dict()))
    paths["summary"].write_text(str(result.summary) + "\n")
    if len(result.time) > 1:
        s = result.summary
        _plot(result, paths["plot"], f"{s.system}: {s.scheme}/{s.extrapolation}, {s.status}", units)
    return paths


def cmd_cosim(args) -> int:
    from ..ssp import is_ssp
    from .master import run
    from .settings import resolve, resolve_file

    cached = None
    if is_ssp(args.scene):  # an SSP archive: its system as written (fmugen/ssp)
        from ..ssp.cli import scene_like, system_from_args

        scene, system = None, system_from_args(args)
        _check_args(args, scene_like(system))
        resolve(system.settings, **_flags(args))
    else:
        from ..scene.analysis_cache import cached_analysis

        # the scene's analysis from its cache when nothing changed (nothing derived: simulating starts
        # within a second), else the scene analysed now
        cached = cached_analysis(args.scene, args.set, getattr(args, "allow_factories", False))
        scene = cached.scene if cached is not None else _load(args)
        _check_args(args, scene)
        # every run setting checked before anything is built or written: the file's [cosim], --set, the flags
        resolve_file(args.scene, args.set, **_flags(args))
    out = Path(args.out)
    if scene is not None:
        from ..scene.analysis_cache import build_scene_cached

        built = cached.materialise(out / "fmus") if cached is not None else None
        if built is None:
            built = build_scene_cached(args.scene, out / "fmus", sets=args.set, scene=scene,
                                       allow_factories=getattr(args, "allow_factories", False))
        system = built.system
    result = run(system, **_flags(args))  # the scene's [cosim] (with --set), then the flags
    paths = write_results(result, out, {r.column: r.physical_unit for r in system.recorded})
    print(result.summary)
    if scene is not None and scene.spec.bonds:  # power and energy per bond of the scene's connect (those recorded)
        from ..scene.bonds import bond_lines

        lines = bond_lines(scene.spec.bonds, result.time, result.__getitem__)
        if lines:
            print("\n".join(lines))
            with open(paths["summary"], "a") as fh:
                fh.write("\n".join(lines) + "\n")
    print(f"wrote {paths['csv']}, {paths['npz']}, {paths['plot']}, {paths['summary']}")
    if result.summary.status == "unreliable":  # ran to the end, but its error estimate says no (exit 3)
        print("fmugen cosim: unreliable: " + result.summary.reliability, file=sys.stderr)
        return 3
    if not result.ok:
        print("fmugen cosim: " + str(result.summary.failure).splitlines()[0], file=sys.stderr)
        return 1
    return 0


def cmd_reference(args) -> int:
    import numpy as np

    from .reference import solve_reference, write_reference_csv
    from .system import ReferenceProblem

    from ..ssp import is_ssp

    if is_ssp(args.scene):
        from .errors import CosimError

        raise CosimError(f"{args.scene}: an SSP archive has no symbolic model to solve as one ODE; "
                         f"fmugen report {args.scene} measures against the master's own finest run instead")
    scene = _load(args)
    _check_args(args, scene)
    p = scene.reference_problem()
    if args.stop is not None:
        p = ReferenceProblem(p.model, p.x0, p.u, p.columns, p.start_time, float(args.stop), p.nominals)
    ref = solve_reference(p, times=np.linspace(p.start_time, p.stop_time, max(int(args.points), 1001)))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_reference_csv(ref, out / "reference.csv")
    m = p.model
    units = {v.name: v.unit for v in (*m.states, *m.outputs)}
    _plot(ref, out / "reference.png", f"{scene.name}: reference ({ref.settings['method']} rtol "
          f"{ref.settings['rtol']:g}; error estimate {max(ref.error):.2g})", units)
    lines = [f"{scene.name}: reference, {ref.settings['method']} rtol {ref.settings['rtol']:g}, "
             f"atol {ref.settings['atol']}, {ref.settings['steps']} steps" + (" (cached)" if ref.cached else ""),
             "confirmed by: " + "; ".join(ref.settings["confirm"]),
             "error estimate per column (max difference between the solves):"]
    lines += [f"  {c:<28} {e:.3g}" for c, e in zip(ref.columns, ref.error)]
    if scene.spec.bonds:  # the bonds' energies without coupling error, to hold a co-simulation's against
        from ..scene.bonds import bond_lines

        lines += bond_lines(scene.spec.bonds, ref.time, ref.__getitem__)
    (out / "reference.txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"wrote {out / 'reference.csv'}, {out / 'reference.txt'}, {out / 'reference.png'}")
    return 0


def cmd_report(args) -> int:
    import fmugen

    from .master import check_choices
    from .report import DEFAULT_SCHEMES, make_report, write_report
    from ..ssp import is_ssp
    from .settings import resolve_file
    from .system import CosimSystem, Recorded, Unit

    if is_ssp(args.scene):  # no symbolic model: a self-convergence reference (fmugen/ssp/report.py)
        from ..ssp.report import cmd_report_ssp

        return cmd_report_ssp(args)
    scene = _load(args)
    _check_args(args, scene)
    schemes = [tuple(s.split("/", 1)) if "/" in s else (s, "hold") for s in args.schemes.split(",")] \
        if args.schemes else DEFAULT_SCHEMES
    schemes = [check_choices(*sc) for sc in schemes]  # before anything is built or written
    # the other run settings: the scene's [cosim] (with --set), then the flags; schemes and steps are the grid
    settings = resolve_file(args.scene, args.set, **_flags(args))
    internal = []
    for item in (args.internal.split(",") if args.internal else []):
        meth, _, tl = item.partition(":")
        from .. import arguments as a

        internal.append((meth.strip().lower(), a.tolerance(tl.strip(), f"--internal {item!r}: tolerance")))
    out = Path(args.out)
    built = scene.build(out / "fmus")
    system = built.system
    H = float(settings.step or system.step)  # the scene's [cosim] step, else its [scene] step
    if args.steps:
        steps = [float(h) for h in args.steps.split(",")]  # checked
    else:
        steps = [8 * H, 4 * H, 2 * H, H, H / 2]
        period = sampling_period(system)
        if period is not None:  # a sampled scene: steps that land on its sample instants (the master's rule)
            steps = [h for h in steps if _divides(h, period)] or [period]
            while len(steps) < 5:
                steps.append(steps[-1] / 2)
    problem = scene.reference_problem()
    extra = []
    if not args.no_monolithic:
        # the same scene as one CS FMU, run as a one-unit system (no couplings) at the same steps
        # of the scene's FMI version, as its groups' FMUs
        version = scene.spec.fmi_version
        mono_path = out / "fmus" / ("monolithic.fmu" if version == 2 else f"monolithic_fmi{version}.fmu")
        model = scene.monolithic_model()
        if not mono_path.is_file():
            fmugen.build_fmu(model, mono_path, fmi_type="cs", fmi_version=version)
        tol = min(float(u.start_values.get("solver.rtol", 1e-10)) for u in system.units)
        starts = {v.name: float(x) for v, x in zip(model.states, problem.x0)}
        starts.update({"solver.method": 2, "solver.rtol": tol, "solver.atol": tol})
        unit = Unit("monolithic", mono_path, "cs", starts)
        rec = tuple(Recorded(r.column, "monolithic", r.column, r.physical_unit) for r in system.recorded)
        extra.append(("monolithic FMU", CosimSystem(system.name + "_monolithic", (unit,), (), rec,
                                                     system.start_time, system.stop_time, system.step)))
    rep = make_report(system, problem, steps, schemes, repeats=args.repeats, target=args.target, extra_rows=extra,
                      settings=settings, stop=args.stop, progress=lambda s: print("  " + s, file=sys.stderr, flush=True),
                      internal=internal)
    paths = write_report(rep, out)
    print(rep.table())
    print(f"wrote {paths['table']}, {paths['csv']}, {paths['plot']}")
    return 0
