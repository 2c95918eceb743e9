"""Scenes: one file describes a whole system -- arm, actuator chains, controllers, paths.

    scene = fmugen.load_scene("examples/scenes/puma_hydraulic.toml", set={"cosim.step": 1e-3})
    built = scene.build("out/fmus")        # one FMU per [fmus.<group>], cached, pruned
    built.system                           # what fmugen.cosim runs
    scene.monolithic_model()               # the whole scene as one SymbolicModel
    scene.reference_problem()              # ... with its initial state, for reference solutions

The file format is documented in ``examples/scenes/README.md``.
"""
from .errors import SceneError
from .scene import Scene, load_scene
from .settings import parse_sets

__all__ = ["Scene", "SceneError", "load_scene", "parse_sets"]
