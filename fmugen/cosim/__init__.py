"""Co-simulation of scenes: the master, reference solutions, reports.

* :mod:`.system`    -- what a co-simulation runs (:class:`CosimSystem`) and the
  monolithic problem it is measured against (:class:`ReferenceProblem`);
* :mod:`.master`    -- :func:`run`: Jacobi, Gauss-Seidel, iterative and Newton
  coupling, extrapolation, adaptive macro step, failure reports;
* :mod:`.reference` -- :func:`solve_reference`: Radau at 1e-12 with its own error estimate;
* :mod:`.report`    -- error against wall time over schemes and macro steps;
* :mod:`.commands`  -- the ``fmugen cosim | reference | report`` subcommands.
"""
from .errors import CosimError
from .master import CosimResult, FailureReport, Master, Summary, run
from .reference import ReferenceSolution, solve_reference
from .system import CosimSystem, Coupling, Recorded, ReferenceProblem, Unit

__all__ = ["CosimError", "CosimResult", "FailureReport", "Master", "Summary", "run", "ReferenceSolution",
           "solve_reference", "CosimSystem", "Coupling", "Recorded", "ReferenceProblem", "Unit"]
