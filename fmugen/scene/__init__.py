"""Scenes: one file describes a whole system -- arm, actuator chains, controllers, paths.

    scene = fmugen.load_scene("examples/scenes/puma_hydraulic.toml", set={"cosim.step": 1e-3})
    built = scene.build("out/fmus")        # one FMU per [fmus.<group>], cached, pruned
    built.system                           # what fmugen.cosim runs
    scene.monolithic_model()               # the whole scene as one SymbolicModel
    scene.reference_problem()              # ... with its initial state, for reference solutions

The file format is documented in ``examples/scenes/README.md``.
"""
from .errors import SceneError
from .settings import parse_sets


def __getattr__(name):  # Scene and load_scene import sympy and numpy: only when used (start-up time)
    if name in ("Scene", "load_scene"):
        from . import scene

        return getattr(scene, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = ["Scene", "SceneError", "load_scene", "parse_sets"]
