"""The stiff and extreme cases suite: ``fmugen suite``.

Runs named cases -- the stiff actuator chain, the real op-amp, saturation,
stall, the thesis PUMA's light wrist and singularities, extreme parameters,
the free PUMA's energy drift, the thesis's own integrator -- through every
relevant Co-Simulation solver of the generated FMUs, and classifies each run
against a reference computed independently (scipy Radau at rtol 1e-12 on the
same SymbolicModel, confirmed by a second solve):

* ``accurate``: the error is within what the method promised;
* ``detected``: the FMU refused (fmi2Discard/fmi2Error) or warned, and said why;
* ``SILENT``: a wrong result with status OK and no warning -- a failure of
  the runtime that the tests treat as a bug.

>>> from fmugen.suite import run_suite
>>> rows = run_suite(["stiff_P"], quick=True, out="suite_out")      # doctest: +SKIP
"""
from .cases import CASES, Case, Method, case_names


def __getattr__(name):
    # .run imports scipy (the references): loaded on first use, not by every `fmugen` command
    if name in ("SuiteRow", "run_suite"):
        from . import run

        return getattr(run, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["CASES", "Case", "Method", "SuiteRow", "case_names", "run_suite"]
