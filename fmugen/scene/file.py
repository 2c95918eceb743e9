"""Read and check a scene file: a TOML description of a whole system.

Every key is checked where it is read, with the file, the key and the
reason in the message; the file is parsed by :mod:`tomllib` and never
evaluated.  The format is documented, key by key, in ``examples/scenes/README.md``.
What this module returns is plain data (:class:`SceneSpec`); the models are
made in :mod:`fmugen.scene.instances`.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from ..cosim.settings import KEYS as COSIM_SETTING_KEYS, check_table
from ..errors import read_text_file, toml_problem
from .errors import SceneError, did_you_mean

SCENE_KEYS = {"name", "description", "parameter_set", "start", "stop", "step", "tolerance", "record",
              "initial", "prune", "connections", "monolithic", "connect", "record_bonds",
              "inputs", "platforms", "fmi_version"}
COMMON_INSTANCE_KEYS = {"parameters", "fixed", "start", "hold"}
ROBOT_KEYS = {"robot", "formulation", "locked", "outputs", "mimic", "armature", "friction", "limits"}
FACTORY_KEYS = {"factory", "options", "parameter_set"}
GROUP_KEYS = {"members", "fmi_type", "solver", "tolerance", "jacobian"}
SOLVERS = {"dopri5": 1, "rodas3": 2, "rk4": 3}
COSIM_KEYS = set(COSIM_SETTING_KEYS)  # one list for every command and the API: fmugen.cosim.settings
INITIAL_MODES = ("given", "equilibrium")


@dataclass(frozen=True)
class InstanceSpec:
    name: str
    kind: str  # "robot", "component", "file" (a component file) or "factory"
    source: str  # robot file (absolute), component type, component file (absolute), or "module:function"
    options: dict = field(default_factory=dict)  # fidelity options / factory keywords / formulation, outputs
    parameter_set: Optional[str] = None
    parameters: dict = field(default_factory=dict)  # overrides
    fixed: object = ()  # "all" or tuple of parameter names folded into constants
    start: dict = field(default_factory=dict)  # start values of states and undriven inputs
    hold: tuple = ()  # states held at their start value when solving for equilibrium
    locked: dict = field(default_factory=dict)  # robots: {joint number: position}
    keep: tuple = ()  # parameters never folded as zero-valued (a sweep sets them per run; not in files)


@dataclass(frozen=True)
class GroupSpec:
    name: str
    members: tuple
    fmi_type: str = "cs"
    solver: str = "rodas3"
    tolerance: Optional[float] = None
    jacobian: object = "auto"  # "auto", True or False


@dataclass
class SceneSpec:
    path: Path
    name: str
    description: str
    parameter_set: str
    start: float
    stop: float
    step: float
    tolerance: float
    record: tuple
    initial: str
    prune: bool
    connections: tuple  # of (source, target, factor or None)
    instances: dict  # name -> InstanceSpec
    groups: dict  # name -> GroupSpec
    monolithic: bool
    cosim: dict
    connect: tuple = ()  # of (end, end): bonds between connectors or signals, causality inferred (scene/connect.py)
    bonds: tuple = ()  # the expanded connect pairs (fmugen.scene.connect.Bond), set by Scene
    record_bonds: bool = False  # also record each bond's effort and flow (fmugen/scene/bonds.py)
    inputs: tuple = ()  # undriven inputs kept as inputs of the FMUs (not fixed) when pruning
    external: Optional[dict] = None  # [external]: an SSP's components beside the instances (scene/external.py)
    platforms: Optional[tuple] = None  # FMI 2.0 binaries/ folders of every FMU (None: this machine's only)
    fmi_version: int = 2  # of every FMU of the scene: 2 (FMI 2.0) or 3 (FMI 3.0)


def _number(v, where, positive=False, nonneg=False) -> float:
    if isinstance(v, int) and not isinstance(v, bool):
        try:
            v = float(v)
        except OverflowError:  # an integer beyond the double range: a clear error, not a traceback
            raise SceneError(f"{where} must be a finite number, got an integer of {len(str(abs(v)))} digits "
                             f"(beyond the double-precision range)") from None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SceneError(f"{where} must be a finite number, got {v!r}")
    if positive and v <= 0:
        raise SceneError(f"{where} must be positive, got {v!r}")
    if nonneg and v < 0:
        raise SceneError(f"{where} must not be negative, got {v!r}")
    return float(v)


#: most communication points one run may have (a step so small, or a run so long, that the
#: master would take days and the results gigabytes is refused with the number)
MAX_MACRO_STEPS = 10**8


def check_time_grid(start: float, stop: float, step: float, where: str) -> int:
    """The number of macro steps of a run, refused when no step fits between start and stop in
    double precision (``start + step == start``: 1e15 to 1e15 + 1 ulp) or when there are more
    than :data:`MAX_MACRO_STEPS`."""
    span = stop - start
    if start + step == start or span <= 4 * math.ulp(max(abs(start), abs(stop))):
        raise SceneError(f"{where} no macro step fits between start {start!r} and stop {stop!r} "
                         f"(double precision resolves about {math.ulp(max(abs(start), abs(stop))):.3g} s there; "
                         f"step {step!r})")
    n = (stop - start) / step
    if not n <= MAX_MACRO_STEPS:
        many = f"{n:.3g}" if math.isfinite(n) else "more than 1e308"
        raise SceneError(f"{where} {many} macro steps of {step!r} s from {start!r} to {stop!r}: more than "
                         f"{MAX_MACRO_STEPS:.0e}; use a larger step or a shorter run")
    return int(math.ceil(n - 1e-9))


def _identifier(v, where) -> str:
    if not isinstance(v, str) or not v.isascii() or not v.isidentifier() or len(v) > 64 or "__" in v:
        raise SceneError(f"{where}: {v!r} must be an ASCII identifier (letters, digits, single '_'; "
                         f"at most 64 characters)")
    return v


def _str_list(v, where) -> tuple:
    if not isinstance(v, list) or not all(isinstance(s, str) for s in v):
        raise SceneError(f"{where} must be a list of strings, got {v!r}")
    return tuple(v)


def _numbers_table(v, where) -> dict:
    if not isinstance(v, dict):
        raise SceneError(f"{where} must be a table of numbers")
    return {k: _number(x, f"{where}.{k}") for k, x in v.items()}


def read_toml(path: Path) -> dict:
    text = read_text_file(path, "scene file")
    try:
        return tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise SceneError(f"{path}: {toml_problem(exc)}") from None


def apply_sets(data: dict, sets: dict, src: str) -> dict:
    """Put ``--set`` values into the raw file data; return the ones for models.

    ``scene.stop=3``, ``cosim.step=1e-3`` and ``fmus.arm.solver=dopri5`` change
    those keys; ``inst.key`` changes an instance key the file may hold
    (``amp1.control=PI``, ``arm.formulation=lagrange``); anything else
    (``joint.J=5``, ``arm.q[2]=-0.5``) is returned as
    ``{instance: {name: value}}``, resolved against the instance's model
    (a parameter, or the start value of a state or input).
    """
    deferred: dict = {}
    instances = data.get("instances", {})
    for name, value in sets.items():
        head, _, rest = name.partition(".")
        if not rest:
            raise SceneError(f"{src}: --set {name}: a scene value is named 'instance.name', 'scene.key', "
                             f"'cosim.key' or 'fmus.group.key'")
        if head in ("scene", "cosim"):
            if rest not in (SCENE_KEYS if head == "scene" else COSIM_KEYS):
                known = SCENE_KEYS if head == "scene" else COSIM_SETTING_KEYS
                raise SceneError(f"{src}: --set {name}: no key {rest!r} in [{head}]{did_you_mean(rest, known)}; "
                                 f"valid keys: {', '.join(known if head == 'cosim' else sorted(known))}")
            data.setdefault(head, {})[rest] = value
        elif head == "fmus":
            group, _, key = rest.partition(".")
            if group not in data.get("fmus", {}) or key not in GROUP_KEYS:
                raise SceneError(f"{src}: --set {name}: no [fmus.{group}] key {key!r}")
            data["fmus"][group][key] = value
        elif head in instances:
            spec = instances[head]
            kind_keys = _instance_keys(spec)
            if rest in kind_keys and rest not in COMMON_INSTANCE_KEYS:
                spec[rest] = value
            else:
                deferred.setdefault(head, {})[rest] = value
        else:
            raise SceneError(f"{src}: --set {name}: no instance {head!r}{did_you_mean(head, instances)}; "
                             f"instances: {', '.join(instances)}")
    return deferred


def _instance_keys(spec: dict) -> set:
    if not isinstance(spec, dict):
        return set()
    if "robot" in spec:
        return ROBOT_KEYS | COMMON_INSTANCE_KEYS
    if "factory" in spec:
        return FACTORY_KEYS | COMMON_INSTANCE_KEYS
    from ..components.assembly import COMPONENT_TYPES  # here: the component library imports sympy (start-up)

    typ = spec.get("type")
    opts = set(COMPONENT_TYPES[typ][1]) if isinstance(typ, str) and typ in COMPONENT_TYPES else set()
    return {"type", "parameter_set"} | opts | COMMON_INSTANCE_KEYS


def parse_scene(data: dict, path: Path) -> SceneSpec:
    src = str(path)
    extra = sorted(set(data) - {"scene", "instances", "fmus", "cosim", "external"})
    if extra:
        raise SceneError(f"{src}: unknown top-level key(s) {', '.join(extra)}; a scene has [scene], "
                         f"[instances.*], [fmus.*], [cosim] and [external]")
    sc = data.get("scene")
    if not isinstance(sc, dict):
        raise SceneError(f"{src}: missing [scene] table")
    for k in sc:
        if k not in SCENE_KEYS:
            raise SceneError(f"{src}: [scene] has unknown key {k!r}{did_you_mean(k, SCENE_KEYS)}")
    name = _identifier(sc.get("name"), f"{src}: [scene] name")
    start = _number(sc.get("start", 0.0), f"{src}: [scene] start")
    stop = _number(sc.get("stop", 1.0), f"{src}: [scene] stop")
    if stop <= start:
        raise SceneError(f"{src}: [scene] stop ({stop}) must be after start ({start})")
    step = _number(sc.get("step", 1e-3), f"{src}: [scene] step", positive=True)
    if step > stop - start:
        raise SceneError(f"{src}: [scene] step ({step}) is longer than the run ({stop - start})")
    check_time_grid(start, stop, step, f"{src}: [scene]")
    tolerance = _number(sc.get("tolerance", 1e-6), f"{src}: [scene] tolerance", positive=True)
    pset = sc.get("parameter_set", "default")
    if not isinstance(pset, str):
        raise SceneError(f"{src}: [scene] parameter_set must be a string")
    if pset.endswith(".toml"):  # a file next to the scene, as every other file the scene names
        pset = str(Path(pset) if Path(pset).is_absolute() else path.parent / pset)
    initial = sc.get("initial", "given")
    if initial not in INITIAL_MODES:
        raise SceneError(f"{src}: [scene] initial = {initial!r}; choose {' or '.join(map(repr, INITIAL_MODES))}")
    for flag in ("prune", "monolithic", "record_bonds"):
        if flag in sc and not isinstance(sc[flag], bool):
            raise SceneError(f"{src}: [scene] {flag} must be true or false")
    desc = sc.get("description", "")
    if not isinstance(desc, str):
        raise SceneError(f"{src}: [scene] description must be a string")
    from ..fmi.platforms import parse_platforms  # the names build_fmu(platforms=) and --platforms take

    fmi_version = _fmi_version(sc.get("fmi_version", 2), sc.get("platforms"), src)
    try:  # FMI 3.0 folders (x86_64-windows ...) when the FMUs are FMI 3.0
        platforms = parse_platforms(sc.get("platforms"), f"{src}: [scene]", fmi_version)
    except ValueError as exc:
        raise SceneError(str(exc)) from None

    inst_tab = data.get("instances")
    if not isinstance(inst_tab, dict) or not inst_tab:
        raise SceneError(f"{src}: no [instances.<name>] tables")
    instances = {iname: _instance(iname, spec, path) for iname, spec in inst_tab.items()}

    conns = []
    raw_conns = sc.get("connections", [])
    if not isinstance(raw_conns, list):
        raise SceneError(f"{src}: [scene] connections must be a list")
    for k, c in enumerate(raw_conns):
        where = f"{src}: [scene] connections[{k}]"
        if isinstance(c, dict):
            bad = set(c) - {"from", "to", "factor"}
            if bad or "from" not in c or "to" not in c:
                raise SceneError(f"{where}: a table connection has keys from, to and (optional) factor")
            s_, t_, f_ = c["from"], c["to"], c.get("factor")
            if f_ is not None:
                f_ = _number(f_, f"{where} factor")
                if f_ == 0:
                    raise SceneError(f"{where} factor must not be zero")
        elif isinstance(c, list) and len(c) in (2, 3):
            s_, t_, f_ = c[0], c[1], (c[2] if len(c) == 3 else None)
            if f_ is not None:
                f_ = _number(f_, f"{where} factor")
                if f_ == 0:
                    raise SceneError(f"{where} factor must not be zero")
        else:
            raise SceneError(f"{where}: expected [\"source\", \"target\"], [\"source\", \"target\", factor] or "
                             f"{{ from = ..., to = ..., factor = ... }}, got {c!r}")
        if not isinstance(s_, str) or not isinstance(t_, str):
            raise SceneError(f"{where}: endpoints must be strings 'instance.variable'")
        conns.append((s_, t_, f_))

    record = _str_list(sc.get("record", []), f"{src}: [scene] record")
    twice = sorted({r for r in record if record.count(r) > 1})
    if twice:  # a result table has one column per name: refused here, not after the run
        raise SceneError(f"{src}: [scene] record lists {', '.join(twice)} more than once")
    exposed = _str_list(sc.get("inputs", []), f"{src}: [scene] inputs")
    connect = sc.get("connect", [])
    if not isinstance(connect, list) or not all(isinstance(c, list) and len(c) == 2 and all(
            isinstance(e, str) for e in c) for c in connect):
        raise SceneError(f"{src}: [scene] connect must be a list of pairs [\"inst.connector\", \"inst.connector\"] "
                         f"(or two variables)")

    groups = {}
    fm = data.get("fmus", {})
    if not isinstance(fm, dict):
        raise SceneError(f"{src}: [fmus] must hold tables [fmus.<name>]")
    monolithic = sc.get("monolithic", not fm)
    for gname, g in fm.items():
        groups[gname] = _group(gname, g, instances, src)
    if not monolithic:
        owner = {}
        for g in groups.values():
            for mbr in g.members:
                if mbr in owner:
                    raise SceneError(f"{src}: instance {mbr!r} is in two FMUs: [fmus.{owner[mbr]}] and [fmus.{g.name}]")
                owner[mbr] = g.name
        missing = [i for i in instances if i not in owner]
        if missing:
            raise SceneError(f"{src}: instance(s) {', '.join(missing)} belong to no [fmus.<name>] group "
                             f"(or set monolithic = true)")
        if not groups:
            raise SceneError(f"{src}: monolithic = false needs [fmus.<name>] groups")

    cosim = data.get("cosim", {})
    if not isinstance(cosim, dict):
        raise SceneError(f"{src}: [cosim] must be a table")
    for k in cosim:
        if isinstance(cosim[k], (int, float)) and not isinstance(cosim[k], bool):
            _number(cosim[k], f"{src}: [cosim] {k}")  # finite, and an int within the double range
    try:  # every key and value checked as every command and the API will read it (unknown keys listed)
        check_table(cosim, f"{src}: [cosim]")
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    return SceneSpec(path=path, name=name, description=desc, parameter_set=pset, start=start, stop=stop,
                     step=step, tolerance=tolerance, record=record, initial=initial,
                     prune=sc.get("prune", True), connections=tuple(conns), instances=instances,
                     groups=groups, monolithic=bool(monolithic), cosim=dict(cosim),
                     connect=tuple(tuple(c) for c in connect), record_bonds=bool(sc.get("record_bonds", False)),
                     inputs=exposed, external=data.get("external"), platforms=platforms,
                     fmi_version=fmi_version)


def _fmi_version(value, platforms, src) -> int:
    """[scene] fmi_version: 2 or 3 (an integer; "3" from --set or --fmi-version is read as one), checked with
    the platforms as build_fmu checks them, so that a scene which cannot be built is refused on loading."""
    if isinstance(value, str) and value.strip() in ("2", "3"):
        value = int(value)
    if isinstance(value, float) and value in (2.0, 3.0):
        value = int(value)
    if isinstance(value, bool) or value not in (2, 3):
        raise SceneError(f"{src}: [scene] fmi_version = {value!r}; give 2 (FMI 2.0, the default) or 3 (FMI 3.0)")
    from ..fmi.build import _check_fmi_version

    try:
        _check_fmi_version(value, platforms)
    except ValueError as exc:
        raise SceneError(f"{src}: [scene] {exc}") from None
    return value


def _instance(iname: str, spec, path: Path) -> InstanceSpec:
    src = str(path)
    where = f"{src}: [instances.{iname}]"
    _identifier(iname, f"{src}: instance name")
    if not isinstance(spec, dict):
        raise SceneError(f"{where} must be a table")
    kinds = [k for k in ("robot", "type", "factory") if k in spec]
    if len(kinds) != 1:
        raise SceneError(f"{where} needs exactly one of robot = \"file.toml\", type = \"<component>\" "
                         f"or factory = \"module:function\"")
    allowed = _instance_keys(spec)
    for k in spec:
        if k not in allowed:
            raise SceneError(f"{where} has unknown key {k!r}{did_you_mean(k, allowed)}; known: {', '.join(sorted(allowed))}")
    params = _numbers_table(spec.get("parameters", {}), f"{where} parameters")
    start = _numbers_table(spec.get("start", {}), f"{where} start")
    fixed = spec.get("fixed", ())
    if fixed != "all":
        fixed = _str_list(list(fixed) if isinstance(fixed, (list, tuple)) else fixed, f"{where} fixed (or \"all\")")
    hold = _str_list(spec.get("hold", []), f"{where} hold")
    pset = spec.get("parameter_set")
    if pset is not None and not isinstance(pset, str):
        raise SceneError(f"{where} parameter_set must be a string")
    if pset is not None and pset.endswith(".toml"):
        p = Path(pset)
        pset = str(p if p.is_absolute() else path.parent / p)
    if "robot" in spec:
        rpath = spec["robot"]
        if not isinstance(rpath, str):
            raise SceneError(f"{where} robot must be a file name")
        rp = Path(rpath)
        rp = rp if rp.is_absolute() else (path.parent / rp)
        if not rp.is_file():
            raise SceneError(f"{where} robot = {rpath!r}: no such file ({rp})")
        form = spec.get("formulation", "newton_euler")
        if form not in ("newton_euler", "lagrange"):
            raise SceneError(f"{where} formulation must be 'newton_euler' or 'lagrange', got {form!r}")
        outs = _str_list(spec.get("outputs", []), f"{where} outputs")
        for o in outs:
            if o not in ("p_ee", "qdd") and not (o[:2] in ("p:", "R:", "J:") and len(o) > 2):
                raise SceneError(f"{where} outputs: {o!r} is not a robot output (p_ee, qdd, p:FRAME, R:FRAME, "
                                 "J:FRAME)")
        locked_raw = spec.get("locked", {})
        if not isinstance(locked_raw, dict):
            raise SceneError(f"{where} locked must be a table like {{ \"q[4]\" = 0.3 }}")
        locked = {}
        for k, v in locked_raw.items():
            if not (k.startswith("q[") and k.endswith("]") and k[2:-1].isdigit()):
                raise SceneError(f"{where} locked: {k!r} is not a joint position 'q[i]'")
            locked[int(k[2:-1])] = _number(v, f"{where} locked.{k}")
        mimic = spec.get("mimic", "independent")
        if mimic not in ("independent", "tied"):
            raise SceneError(f"{where} mimic must be 'independent' or 'tied' (URDF mimic joints), got {mimic!r}")
        opts = {"formulation": form, "outputs": outs}
        if mimic != "independent":
            opts["mimic"] = mimic  # only when set: the FMU cache keys of existing scenes stay the same
        armature = spec.get("armature", {})
        if not isinstance(armature, dict):
            raise SceneError(f"{where} armature must be a table of URDF joint names and rotor inertias, "
                             f"like {{ LHand = 1e-3 }}")
        if armature:  # only when set, as mimic; the reader checks the joint names (URDF robots only)
            opts["armature"] = {str(k): _number(v, f"{where} armature.{k}", nonneg=True) for k, v in armature.items()}
        # joint friction and limits as events (robots/README.md "Friction and limits as events"); only when
        # set, as mimic, so that the FMU cache keys of existing scenes stay the same
        for key, choices in (("friction", ("smooth", "stick-slip")), ("limits", ("range", "stops"))):
            v = spec.get(key, choices[0])
            if v not in choices:
                raise SceneError(f"{where} {key} must be {' or '.join(repr(c) for c in choices)}, got {v!r}")
            if v != choices[0]:
                opts[key] = v
        return InstanceSpec(iname, "robot", str(rp.resolve()), opts,
                            None, params, fixed, start, hold, locked)
    if "factory" in spec:
        ref = spec["factory"]
        if not isinstance(ref, str) or ":" not in ref or not all(
                part.replace(".", "").replace("_", "a").isalnum() for part in ref.split(":", 1)):
            raise SceneError(f"{where} factory must be 'package.module:function', got {ref!r}")
        opts = spec.get("options", {})
        if not isinstance(opts, dict):
            raise SceneError(f"{where} options must be a table")
        return InstanceSpec(iname, "factory", ref, dict(opts), pset, params, fixed, start, hold)
    from ..components.assembly import COMPONENT_TYPES

    typ = spec["type"]
    if isinstance(typ, str) and typ.startswith(FILE_TYPE_PREFIXES):
        return _file_instance(iname, typ, path, where, pset, params, fixed, start, hold)
    if not isinstance(typ, str) or typ not in COMPONENT_TYPES:
        raise SceneError(f"{where} type = {typ!r} is not a component type{did_you_mean(str(typ), COMPONENT_TYPES)}; "
                         f"known: {', '.join(COMPONENT_TYPES)}")
    _, options = COMPONENT_TYPES[typ]
    opts = {}
    for k, v in spec.items():
        if k in options:
            want = options[k]
            if isinstance(v, bool) != (want is bool) or not isinstance(v, want):
                raise SceneError(f"{where} {k} = {v!r} must be of type {want.__name__}")
            opts[k] = v
    if typ == "table_trajectory" and (params or pset):
        raise SceneError(f"{where}: a table_trajectory has no parameters (its knots are data)")
    return InstanceSpec(iname, "component", typ, opts, pset, params, fixed, start, hold)


FILE_TYPE_PREFIXES = ("file:", "lib:")


def _file_instance(iname, typ, path: Path, where, pset, params, fixed, start, hold) -> InstanceSpec:
    """``type = "file:components/x.toml"`` (relative to the scene) or ``"lib:<shipped name>"``."""
    from ..components.equations import library_path, read_cached

    try:
        if typ.startswith("lib:"):
            fp = library_path(typ[4:])
        else:
            fp = Path(typ[5:])
            fp = fp if fp.is_absolute() else path.parent / fp
        read_cached(fp)  # declarations, equations and dimensions checked now, with the file named
    except ValueError as exc:
        raise SceneError(f"{where} type = {typ!r}: {exc}") from None
    return InstanceSpec(iname, "file", str(fp.resolve()), {}, pset, params, fixed, start, hold)


def _group(gname, g, instances, src) -> GroupSpec:
    where = f"{src}: [fmus.{gname}]"
    _identifier(gname, f"{src}: FMU name")
    if not isinstance(g, dict):
        raise SceneError(f"{where} must be a table")
    for k in g:
        if k not in GROUP_KEYS:
            raise SceneError(f"{where} has unknown key {k!r}{did_you_mean(k, GROUP_KEYS)}")
    members = _str_list(g.get("members", []), f"{where} members")
    if not members:
        raise SceneError(f"{where} members must name at least one instance")
    for mbr in members:
        if mbr not in instances:
            raise SceneError(f"{where} members: no instance {mbr!r}{did_you_mean(mbr, instances)}")
    fmi_type = g.get("fmi_type", "cs")
    if fmi_type not in ("cs", "me"):
        raise SceneError(f"{where} fmi_type must be \"cs\" or \"me\", got {fmi_type!r}")
    solver = g.get("solver", "rodas3")
    if not isinstance(solver, str) or solver not in SOLVERS:  # a table or array is no key (unhashable)
        raise SceneError(f"{where} solver = {solver!r}; choose one of {', '.join(SOLVERS)}")
    tol = g.get("tolerance")
    if tol is not None:
        tol = _number(tol, f"{where} tolerance", positive=True)
    jac = g.get("jacobian", "auto")
    if jac not in ("auto", True, False):
        raise SceneError(f"{where} jacobian must be \"auto\", true or false")
    return GroupSpec(gname, members, fmi_type, solver, tol, jac)
