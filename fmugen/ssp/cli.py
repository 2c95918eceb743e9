"""``fmugen ssp SCENE.toml -o scene.ssp``: a scene as a standard SSP 1.0 archive.

    fmugen ssp SCENE.toml -o OUT.ssp [--set NAME=VALUE ...] [--scheme S] [--extrapolation E] [--fmus DIR]

and the helpers that let ``fmugen cosim`` and ``fmugen report`` take an
``.ssp`` where they take a scene.
"""
from __future__ import annotations

from pathlib import Path


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("ssp", help="write a scene as an SSP 1.0 archive (FMUs, connections, parameters, "
                                          "units, default experiment) that other FMI masters run")
    p.add_argument("scene", help="scene TOML file")
    p.add_argument("-o", "--output", required=True, help="the archive to write (*.ssp)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="set a parameter, start value or option (repeatable); bound in the archive")
    p.add_argument("--scheme", default=None, help="fmugen's scheme recorded in the archive's annotation "
                   "(default: the scene's [cosim], else gauss-seidel)")
    p.add_argument("--extrapolation", default=None, help="likewise (default: the scene's, else linear)")
    p.add_argument("--fmus", default=None, help="folder to build the FMUs in (default: a temporary one)")
    p.add_argument("--allow-factories", action="store_true",
                   help="allow instances made by a Python factory (runs code named in the file)")
    p.set_defaults(func=cmd_ssp)


def cmd_ssp(args) -> int:
    from .. import arguments as a
    from ..scene import load_scene
    from .export import export_ssp

    output = a.output_file(args.output, "-o", inputs=[args.scene])
    if args.fmus:
        a.output_folder(args.fmus, "--fmus", inputs=[args.scene])
    scene = load_scene(args.scene, set=args.set, allow_factories=args.allow_factories)
    r = export_ssp(scene, output, fmus_dir=args.fmus, scheme=args.scheme,
                   extrapolation=args.extrapolation)
    built = r["built"]
    print(built.summary())
    lim = r["jacobi_limit"]
    print(f"wrote {r['path']}: {len(r['fmus'])} FMU(s) ({', '.join(r['fmus'])}); libcosim's fixed step "
          f"{r['libcosim_step']:g} s (held-input Jacobi "
          f"{'has no stability limit found' if lim == float('inf') else 'limit not computed' if lim != lim else f'is stable below {lim:.3g} s'}); "
          f"fmugen's run: {r['scheme']}/{r['extrapolation']} at {r['run_step']:g} s")
    return 0


def scene_like(system):
    """What the commands' argument checks read of a scene (start, stop, step), from an SSP's system."""
    from types import SimpleNamespace

    return SimpleNamespace(spec=SimpleNamespace(start=system.start_time, stop=system.stop_time, step=system.step,
                                                cosim=dict(system.settings)))


def settable(system, name: str, where: str, error=None, hint: str = "") -> tuple:
    """(component, variable, fmpy ScalarVariable) of ``name`` = 'component.variable' whose start value a
    run may set: a parameter (fixed or tunable), an input, or a state (an output or local with an exact
    start).  One check for ``--set`` on ``fmugen cosim/report x.ssp`` and for ``fmugen sweep x.ssp``."""
    from ..errors import InputFileError
    from .loader import can_set
    from .ssd import read_fmi_description

    error = error or InputFileError
    units = {u.name: u for u in system.units}
    if not isinstance(name, str):
        raise error(f"{where}: {name!r:.60}: name a component's variable, 'component.variable'{hint}")
    comp, _, var = name.partition(".")
    if comp not in units or not var:
        raise error(f"{where}: {name}: name a component's variable, 'component.variable' (components: "
                    f"{', '.join(units)}){hint}")
    v = {x.name: x for x in read_fmi_description(units[comp].path).modelVariables}.get(var)
    if v is None or not can_set(v):
        raise error(f"{where}: {name}: {comp} has no parameter, input or state {var!r}")
    return comp, var, v


def with_sets(system, sets: dict, where: str, error=None):
    """``system`` with ``--set`` applied: ``cosim.KEY`` run settings (as on a scene: over the archive's
    annotation, under the flags; checked key by key) and ``component.variable`` start values."""
    from dataclasses import replace

    from ..errors import InputFileError

    error = error or InputFileError
    if not hasattr(sets, "items") or not all(isinstance(k, str) for k in sets):
        raise error(f"{where}: --set: NAME=VALUE pairs (a mapping of names to values) are needed, got {sets!r:.60}")
    cosim = {k[len("cosim."):]: v for k, v in sets.items() if k.startswith("cosim.")}
    if cosim:
        from ..cosim.settings import check_table

        settings = {**dict(system.settings), **cosim}
        check_table(settings, f"{where}: --set cosim")
        system = replace(system, settings=settings)
    starts = {}
    for name, value in sets.items():
        if name.startswith("cosim."):
            continue
        comp, var, _ = settable(system, name, f"{where}: --set", error, ", or a run setting 'cosim.KEY'")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise error(f"{where}: --set {name}={value!r}: a number is needed")
        starts.setdefault(comp, {})[var] = value
    if not starts:
        return system
    return replace(system, units=tuple(replace(u, start_values={**dict(u.start_values), **starts.get(u.name, {})})
                                       for u in system.units))


def system_from_args(args):
    """The CosimSystem of ``args.scene`` (an .ssp) with ``--set`` applied (:func:`with_sets`)."""
    from ..scene import parse_sets
    from .loader import load_system

    return with_sets(load_system(args.scene), parse_sets(getattr(args, "set", None)), str(args.scene))
