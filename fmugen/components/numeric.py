"""Numeric evaluation of a SymbolicModel with numpy, and stable explicit steps.

For tests, linearisation and benchmarks at the Python level.  ``linearise``
is :func:`fmugen.control.linearize` under its British name.  Parameters
take their start values unless given.

>>> from fmugen.components import joint_inertia
>>> ev = NumericModel(joint_inertia())
>>> ev.f(0.0, [0.0, 1.0], [7.0, 0.0]).tolist()   # [w, (tau - B_m w)/J]
[1.0, 1.0]
"""
from __future__ import annotations

import numpy as np

from ..codegen.evaluate import ModelEvaluator
# the one linearisation function (control.StateSpace; ``linearise(m).A`` is df/dx)
from ..control.linearize import linearize as linearise  # noqa: F401


class NumericModel(ModelEvaluator):
    """f(t, x, u), g(t, x, u) and the exact Jacobians dfdx, dfdu as numpy arrays.

    The shared :class:`~fmugen.codegen.evaluate.ModelEvaluator` (compiled
    straight-line programs, any model size) with the two Jacobian blocks the
    component tests read.
    """

    def dfdx(self, t, x, u=None) -> np.ndarray:
        return self.jacobians(t, x, u)[0]

    def dfdu(self, t, x, u=None) -> np.ndarray:
        return self.jacobians(t, x, u)[1]


def stable_step(eigenvalues, method: str = "rk4") -> float:
    """Largest step h with every h*lambda inside the method's stability region.

    Along each eigenvalue's ray h*lambda = r e^{i phi}, the boundary radius is
    found by bisection on |R(z)| = 1 (R the method's stability polynomial:
    1 + z for explicit Euler, 1 + z + z^2/2 + z^3/6 + z^4/24 for RK4); the
    region is star-shaped along the left-half-plane rays used here.
    """
    R = {"euler": lambda z: 1 + z,
         "rk4": lambda z: 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24}[method]
    h = np.inf
    for lam in np.asarray(eigenvalues, dtype=complex):
        if lam == 0:
            continue
        d = lam / abs(lam)
        lo, hi = 0.0, 1.0
        while abs(R(hi * d)) <= 1:
            hi *= 2
        # first crossing: scan then bisect (the region is not convex for RK4)
        grid = np.linspace(0, hi, 4001)[1:]
        k = np.argmax(np.abs(R(grid * d)) > 1 + 1e-15)
        lo, hi = (grid[k - 1] if k > 0 else 0.0), grid[k]
        for _ in range(200):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if abs(R(mid * d)) <= 1 else (lo, mid)
        h = min(h, lo / abs(lam))
    return h
