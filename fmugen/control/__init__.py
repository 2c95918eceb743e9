"""Control design with python-control: operating points and linearisation.

* :func:`trim` -- an operating point with any states, inputs and outputs held;
* :func:`linearize` -- ``control.StateSpace`` at that point, exact Jacobians;
* :func:`linearize_fmu` -- the same matrices from a built FMU through
  ``fmi2GetDirectionalDerivative`` (what any other FMI tool would see);
* :func:`scene_model` -- a scene closed as written, or opened (controllers removed);
* :func:`state_feedback_file` -- u = u_ff - K (x - x_ref) written as a component file (K from ``lqr``;
  ``sample_period=T``: sampled and held, K from ``dlqr``);
* :func:`c2d` -- the linearised plant held by a zero-order hold and sampled (``fmugen linearize --dt``);
* :func:`discrete_controller_file` -- a python-control system with ``dt`` as a clocked component file;
* :mod:`.names` -- the naming rule (FMI names; '.' written '_' for python-control).

Every function takes a SymbolicModel or a scene (an object with
``monolithic_model()``).
"""
from .names import signal_name
from .linearize import linearize
from .trim import OperatingPoint, TrimError, trim
from .scene import scene_model
from .feedback import state_feedback_file
from .sampled import c2d, discrete_controller_file

__all__ = ["trim", "linearize", "linearize_fmu", "scene_model", "OperatingPoint", "TrimError", "signal_name",
           "state_feedback_file", "c2d", "discrete_controller_file"]


def __getattr__(name):
    if name == "linearize_fmu":  # imports fmpy only when used
        from .fmu import linearize_fmu

        return linearize_fmu
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
