"""Dense output between communication points: cubic Hermite from the FMUs' own output derivatives.

A co-simulation result is known at the communication points only.  Drawn with
straight lines between them, its error between the points is that of the
line (O(H^2) times the curvature), which at large macro steps swamps the
coupling error a report means to measure.  The FMUs know more: the slope of
every output at the end of each step (fmi2GetRealOutputDerivatives, order 1:
der(x) for a state output, dg/dx f + dg/du du/dt for a computed one).  With
value and slope at both ends, the cubic Hermite interpolant on each interval
is accurate to O(H^4) for a smooth signal, so the dense error measures what the
coupling did, not the interpolation.

:class:`SlopeRecorder` reads the slopes of the recorded columns at each
recorded point (the left limit: the FMU's state at the end of its step, its
inputs as they were during it).  Columns of FMUs that cannot give slopes
(maxOutputDerivativeOrder 0, Model-Exchange units) have none (NaN) and are
interpolated linearly.
"""
from __future__ import annotations

from ctypes import c_double, c_int, c_uint
from typing import Optional

import numpy as np


class SlopeRecorder:
    """The slopes of the recorded columns at every recorded point (one fmi2 call per FMU and point)."""

    def __init__(self, units, recorded, cap: int = 1024):
        self.parts = []  # (unit, vr array, order array, value buffer, column indices)
        by_unit = {}
        for j, r in enumerate(recorded):
            by_unit.setdefault(r.unit, []).append((j, r.variable))
        for u in units:
            cols = by_unit.get(u.name)
            if not cols or getattr(u, "max_output_derivative_order", 0) < 1 or not hasattr(u, "_getOutDer"):
                continue
            vrs = [u.variable(v).valueReference for _, v in cols]
            n = len(vrs)
            self.parts.append((u, (c_uint * n)(*vrs), (c_int * n)(*([1] * n)), (c_double * n)(),
                               np.array([j for j, _ in cols], dtype=np.intp)))
        self.D = np.full((cap, len(recorded)), np.nan)
        self.n = 0
        self.calls = 0

    def append(self) -> None:
        if self.n == len(self.D):
            self.D = np.concatenate([self.D, np.full_like(self.D, np.nan)])
        row = self.D[self.n]
        for k, (u, vr, order, buf, cols) in enumerate(self.parts):
            if u is None:
                continue
            st = u._getOutDer(u.c, vr, len(cols), order, buf)
            self.calls += 1
            if st > 1:  # e.g. computed outputs of an FMU generated without its Jacobian: no slopes from it
                self.parts[k] = (None, vr, order, buf, cols)
                self.D[:, cols] = np.nan
                continue
            row[cols] = np.frombuffer(buf, dtype=np.float64, count=len(cols))
        self.n += 1

    def slopes(self) -> np.ndarray:
        return self.D[: self.n].copy()


def hermite(time: np.ndarray, values: np.ndarray, slopes: Optional[np.ndarray], t: np.ndarray) -> np.ndarray:
    """The recorded ``values`` (n, m) at ``t``: cubic Hermite with ``slopes`` (n, m) where they are known
    (finite at both ends of the interval), else the straight line."""
    time, values, t = np.asarray(time, float), np.asarray(values, float), np.asarray(t, float)
    k = np.clip(np.searchsorted(time, t, side="right") - 1, 0, len(time) - 2)
    h = time[k + 1] - time[k]
    s = ((t - time[k]) / h)[:, None]
    y0, y1 = values[k], values[k + 1]
    line = y0 + s * (y1 - y0)
    if slopes is None:
        return line
    d0, d1 = slopes[k] * h[:, None], slopes[k + 1] * h[:, None]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    cubic = h00 * y0 + h10 * d0 + h01 * y1 + h11 * d1
    known = np.isfinite(d0) & np.isfinite(d1)
    return np.where(known, cubic, line)
