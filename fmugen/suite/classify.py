"""Outcome of one run: accurate, detected (with the FMU's own message), or SILENT.

* A run that ended in fmi2Discard/fmi2Error is ``detected``: the message is
  the FMU's reason.
* A run in which a variable left its physical range (:class:`Validity`) is
  ``detected`` only if the FMU's log names the variable; else ``SILENT``.
* A completed run whose error is within the promise is ``accurate`` (with
  any warning it logged, e.g. a stiffness detection, as a note).
* A completed run outside the promise is ``detected`` when the FMU warned
  (e.g. RK4 above its stability limit), else ``SILENT``.

The promise of a tolerance-controlled method is 100 x tol x (1 + max |y_ref|)
x G on the compared variables, and never below 10x the reference's own
uncertainty.  Local error control bounds the error made in each step; the
motion carries it forward amplified by the problem's own sensitivity G =
max_t |dy(t)| / |dx(0)| (measured by a perturbed reference solve, see
:func:`fmugen.suite.reference.sensitivity`; G ~ 1 for the damped actuator
chain, large for an arm falling through a chaotic motion), and a global
error may exceed the local tolerance by one or two orders more.  RK4 (no
error control) promises stability and 1e-3 x (1 + max |y_ref|) x G,
"qualitatively right".
"""
from __future__ import annotations

import numpy as np

from .cases import RK4, Method, Validity

ACCURATE, DETECTED, SILENT = "accurate", "detected", "SILENT"


def promise(method: Method, scale: float, ref_uncertainty: float = 0.0, sensitivity: float = 1.0) -> float:
    base = 1e-3 if method.solver == RK4 else 100 * method.tol
    return max(base * (1 + scale) * max(1.0, sensitivity), 10 * ref_uncertainty)


def violations(values: np.ndarray, names: list, checks) -> list:
    """(check, worst value) for every range left in the recorded values."""
    out = []
    for c in checks:
        if c.variable not in names:
            continue
        col = values[:, names.index(c.variable)]
        bad = col[(col < c.low) | (col > c.high) | ~np.isfinite(col)]
        if bad.size:
            out.append((c, float(bad[np.argmax(np.abs(bad))])))
    return out


def classify(completed: bool, failure: str, warnings: list, error: float, allowed: float,
             left_range: list) -> tuple:
    """(outcome, message) by the rules of the module docstring."""
    if not completed:
        return DETECTED, failure or "the FMU refused a step"
    for check, value in left_range:
        said = [w for w in warnings if check.variable in w]
        if said:
            return DETECTED, said[0]
        return SILENT, (f"{check.variable} reached {value:.3g}, outside [{check.low:.3g}, {check.high:.3g}] "
                        f"({check.why}), with status OK and no warning naming it")
    if np.isfinite(error) and error <= allowed:
        return ACCURATE, (warnings[0] if warnings else "")
    if warnings:
        return DETECTED, warnings[0]
    return SILENT, f"error {error:.2e} above the promised {allowed:.1e}, with status OK and no warning"


__all__ = ["ACCURATE", "DETECTED", "SILENT", "Validity", "classify", "promise", "violations"]
