"""fmugen: FMI 2.0 components for robot manipulators and their actuator chains.

The one-call API::

    import fmugen
    arm = fmugen.load_robot("robots/puma_thesis_com.toml")     # a Manipulator
    arm.mass_matrix(q); arm.forward_dynamics(q, qd, tau)       # numeric evaluators
    model = arm.state_space_model()                            # symbolic x' = f(x, u, p)
    fmugen.build_fmu(model, "puma.fmu", fmi_type="both")       # FMI 2.0 FMU
"""
from __future__ import annotations

__version__ = "0.1.0"

# Nothing heavy is imported here: ``fmugen --help`` and a run from cached FMUs must
# start in well under a second, and sympy, scipy and python-control take seconds.
# The names below are loaded on first use (PEP 562 module ``__getattr__``).
_LAZY = {
    "Manipulator": ("fmugen.dynamics.manipulator", "Manipulator"),
    "FORMULATIONS": ("fmugen.dynamics.manipulator", "FORMULATIONS"),
    "ModelEvaluator": ("fmugen.codegen.evaluate", "ModelEvaluator"),
    "linearize": ("fmugen.control", "linearize"),  # operating points and A, B, C, D for python-control
    "trim": ("fmugen.control", "trim"),
    "load_component": ("fmugen.components.equations", "load_component"),  # a component file -> SymbolicModel
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        value = getattr(importlib.import_module(module), attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'fmugen' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_LAZY))


def load_robot(path, formulation: str = "newton_euler", mimic: str = "independent",
               armature: dict | None = None) -> "Manipulator":
    """Read a robot file (TOML or URDF) and return its :class:`Manipulator`.

    ``formulation`` chooses the default derivation: "newton_euler" (DYNAMAN's
    nested bodies) or "lagrange" (the thesis's recursive Lagrange); every
    numeric evaluator also takes ``formulation=`` per call.  ``mimic``
    (URDF): "independent" (default, as Pinocchio) or "tied" (a mimic joint
    follows its leader in the state-space model).  ``armature`` (URDF):
    ``{joint name: rotor inertia}`` added to M_ii as Pinocchio's
    ``model.armature`` (parameters ``Ia_<joint>``; URDF has no field for it).
    """
    from .dynamics.manipulator import Manipulator
    from .robot.loader import load_robot_description

    return Manipulator(load_robot_description(path, mimic=mimic, armature=armature), formulation)


def load_scene(path, set=None, allow_factories: bool = False):
    """Read a scene file (a whole system: arm, actuator chains, controllers, paths).

    ``set`` overrides values by name (``{"joint.J": 5}`` or ``["joint.J=5"]``);
    ``allow_factories``: run the Python factories the scene names (code: only for files you
    trust); see :mod:`fmugen.scene`.
    """
    from .scene import load_scene as _load

    return _load(path, set=set, allow_factories=allow_factories)


def load_system(path, record=None, workdir=None):
    """An SSP archive (``x.ssp``: fmugen's export or anyone's FMI 2.0 FMUs) as a co-simulation system
    for :func:`fmugen.cosim.run`; ``record``: the "component.connector" columns to keep (default:
    every output, or the scene's record list for an archive fmugen wrote); ``workdir``: an empty or new
    folder to extract the archive into (default: a temporary one).  See :mod:`fmugen.ssp`."""
    from .ssp import load_system as _load

    return _load(path, record=record, workdir=workdir)


def build_fmu(model, output_path, fmi_type: str = "both", **options):
    """Generate, compile and package ``model`` (a SymbolicModel) as an FMU."""
    from .fmi.build import build_fmu as _build

    return _build(model, output_path, fmi_type=fmi_type, **options)


__all__ = ["load_robot", "load_scene", "load_system", "build_fmu", "linearize", "trim", "ModelEvaluator", "Manipulator", "FORMULATIONS", "__version__"]
