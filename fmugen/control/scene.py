"""Models of a scene for control design: closed loop as written, or opened.

``scene.monolithic_model()`` is the scene as the file connects it -- the
closed loop.  A control designer often wants the *plant*: the same scene
with its controllers and path sources taken out, so that the inputs those
drove (the current drivers' voltages ``drv1.u``, say) become inputs of the
model.  :func:`scene_model` removes the listed instances (shell patterns such
as ``"amp*"`` allowed) and every connection that touches them; every other
connection is applied as in the file.
"""
from __future__ import annotations

from fnmatch import fnmatchcase
from typing import Sequence

from .names import FmugenError


def scene_model(scene, without: Sequence[str] = (), outputs=None):
    """The monolithic SymbolicModel of ``scene`` without the instances ``without``.

    ``without=()`` gives ``scene.monolithic_model()`` (closed loop).
    ``outputs``: variables to expose ("inst.var"; default: every state, as
    the monolithic model does, plus the scene's recorded outputs that remain).
    """
    if not without:
        return scene.monolithic_model()
    from ..components import assemble

    names = list(scene.spec.instances)
    removed = {n for n in names for pat in without if fnmatchcase(n, pat)}
    unused = [pat for pat in without if not any(fnmatchcase(n, pat) for n in names)]
    if unused:
        raise FmugenError(f"{scene.src}: no instance matches {', '.join(map(repr, unused))} "
                          f"(instances: {', '.join(names)})")
    kept = {n: scene.base_models[n] for n in names if n not in removed}
    if not kept:
        raise FmugenError(f"{scene.src}: removing {', '.join(sorted(removed))} leaves nothing")
    conns = [(f"{si}.{sv}", f"{ti}.{tv}") + ((f,) if f is not None else ())
             for si, sv, ti, tv, f in scene.connections if si in kept and ti in kept]
    if outputs is None:
        states = [f"{i}.{v.name}" for i, m in kept.items() for v in m.states]
        recorded = [r for r in scene.spec.record if r.split(".", 1)[0] in kept and r not in states]
        outputs = states + recorded
    return assemble(f"{scene.name}_open", kept, conns, outputs=list(outputs),
                    description=f"scene {scene.name} without {', '.join(sorted(removed))}", where=scene.src)
