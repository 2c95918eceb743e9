"""``connect``: physical bonds between connectors, expanded into checked signal connections.

``[scene] connect = [["valve2.port", "act2.port"], ["act2.flange", "arm.joint[2]"], ["amp2.u", "drv2.u"]]``
names two connectors (``instance.connector``: a component's declared
connector, see :mod:`fmugen.components.connectors`, or an arm's
``joint[k]`` -- also by the joint's name in its file: a URDF joint name, a
DH link name) or two variables (a plain signal).  For each variable of the
connector type that either side has, exactly one side must compute it (a
state or an output) and the other need it (an input): that gives one
connection from the first to the second.  Both computing it, neither
computing it, a side needing a variable the other does not have, or two
connectors of different types, is an error naming both ends.  A signal pair
is directed the same way (no need to write the source first).

The expanded connections are the scene's ``connections`` (units checked
there); the bonds are kept (:class:`Bond`) with the variables that carry
their power (effort x flow), for monitoring and reports.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..components.connectors import BUILTIN, TYPES, arm_joint
from .errors import SceneError, did_you_mean


@dataclass(frozen=True)
class Bond:
    ends: tuple  # ("act2.flange", "arm.joint[2]")
    type: str  # connector type
    signals: tuple  # ((connector variable, source "inst.var", target "inst.var"), ...)
    power: tuple  # ("inst.var" of the effort, "inst.var" of the flow), or () when a side lacks one

    def __str__(self) -> str:
        return f"{self.ends[0]} <-> {self.ends[1]} ({self.type})"


def ports(scene, inst: str) -> dict:
    """Connectors of instance ``inst``: {name: (type, {connector var: variable})}, only variables it has."""
    spec = scene.spec.instances[inst]
    model = scene.base_models[inst]
    names = {v.name for g in (model.states, model.inputs, model.outputs) for v in g}
    if spec.kind == "robot":  # joint[k], and the joint's own name (URDF joint, DH link) for the same port
        import fmugen

        bodies = fmugen.load_robot(spec.source, armature=spec.options.get("armature")).robot.bodies
        raw = {}
        for v in model.states:
            if v.name.startswith("q[") and v.name.endswith("]"):
                k = int(v.name[2:-1])
                raw[f"joint[{k}]"] = arm_joint(k, v.unit == "rad")
                label = bodies[k - 1].joint_name or bodies[k - 1].name
                if label and label not in raw and "." not in label:
                    raw[label] = raw[f"joint[{k}]"]
    elif spec.kind == "file":
        from ..components.equations import read_cached

        raw = read_cached(spec.source).connectors
    elif spec.kind == "component":
        raw = BUILTIN.get(spec.source, {})
    else:
        raw = {}
    return {p: (t, {k: v for k, v in m.items() if v in names}) for p, (t, m) in raw.items()}


def expand_connect(scene, pairs) -> tuple:
    """(connections [(source, target, None)], bonds) of the ``connect`` pairs."""
    src = scene.src
    conns, bonds = [], []

    def split(end, where):
        if not isinstance(end, str) or "." not in end:
            raise SceneError(f"{where}: {end!r} is not 'instance.connector' or 'instance.variable'")
        inst, name = end.split(".", 1)
        if inst not in scene.spec.instances:
            raise SceneError(f"{where}: no instance {inst!r}{did_you_mean(inst, scene.spec.instances)}")
        return inst, name

    def computes(inst, var, where) -> bool:
        kind, _ = scene._var(inst, var, where)
        return kind in ("state", "output")

    # inputs already driven, and by what: a second driver is reported at the connect entry the user wrote (the
    # generic fan-in check further on would name a connections[k] that exists in no file)
    driven = {}
    for k, (s, t, _) in enumerate(scene.spec.connections):
        if isinstance(t, str) and "." in t:
            driven.setdefault(tuple(t.split(".", 1)), f"[scene] connections[{k}] ({s} -> {t})")

    def add(s, t, where):
        key = tuple(t.split(".", 1))
        if key in driven:
            raise SceneError(f"{where}: input {t} is already driven by {driven[key]}")
        driven[key] = where.split(": ", 1)[-1]
        conns.append((s, t, None))

    for k, pair in enumerate(pairs):
        a, b = pair
        for end in (a, b):  # names only: printable ASCII, so that every message naming it stays one line
            if not (isinstance(end, str) and end.isascii() and end.isprintable() and 0 < len(end) <= 200):
                shown = repr(end) if len(repr(end)) <= 60 else repr(end)[:40] + "..."
                raise SceneError(f"{src}: [scene] connect[{k}]: {shown} is not a name 'instance.connector' or "
                                 f"'instance.variable' (printable ASCII, at most 200 characters)")
        where = f"{src}: [scene] connect[{k}] ({a} <-> {b})"
        (ia, na), (ib, nb) = split(a, where), split(b, where)
        pa, pb = ports(scene, ia).get(na), ports(scene, ib).get(nb)
        if pa is None and pb is None:  # a signal: direct it by causality
            ca, cb = computes(ia, na, where), computes(ib, nb, where)
            if ca == cb:
                raise SceneError(f"{where}: {'both' if ca else 'neither'} {a} and {b} "
                                 f"{'compute' if ca else 'computes'} the signal; one must be a state or output, "
                                 f"the other an input")
            add(*((a, b) if ca else (b, a)), where)
            continue
        for end, inst, name, port in ((a, ia, na, pa), (b, ib, nb, pb)):
            if port is None:
                other = pb if port is pa else pa
                known = list(ports(scene, inst))
                raise SceneError(f"{where}: {end} is not a connector of {inst} (connectors: "
                                 f"{', '.join(known) or 'none'}), but the other end is a {other[0]} connector")
        (ta, ma), (tb, mb) = pa, pb
        if ta != tb:
            raise SceneError(f"{where}: {a} is a {ta} connector but {b} is a {tb} connector")
        signals = []
        for var in TYPES[ta]["vars"]:
            va, vb = ma.get(var), mb.get(var)
            if va is None and vb is None:
                continue
            if va is None or vb is None:
                have_end, have_inst, have = (a, ia, va) if vb is None else (b, ib, vb)
                miss_end = b if vb is None else a
                if not computes(have_inst, have, where):
                    raise SceneError(f"{where}: {have_end} needs {var} ({have_inst}.{have} is an input) but "
                                     f"{miss_end} has no {var}")
                continue
            ca, cb = computes(ia, va, where), computes(ib, vb, where)
            if ca and cb:
                raise SceneError(f"{where}: both ends compute {var} ({ia}.{va} and {ib}.{vb} are states or "
                                 f"outputs); one side must take it as an input")
            if not ca and not cb:
                raise SceneError(f"{where}: neither end computes {var} ({ia}.{va} and {ib}.{vb} are both inputs)")
            s, t = (f"{ia}.{va}", f"{ib}.{vb}") if ca else (f"{ib}.{vb}", f"{ia}.{va}")
            add(s, t, where)
            signals.append((var, s, t))
        effort, flow = TYPES[ta]["power"]
        by_var = {v: s for v, s, _ in signals}
        power = (by_var[effort], by_var[flow]) if effort in by_var and flow in by_var else ()
        bonds.append(Bond((a, b), ta, tuple(signals), power))
    return conns, tuple(bonds)
