"""Metrics of one run: numbers per recorded output that a sweep tabulates.

For a recorded signal y(t_k) at the communication points t_0 .. t_N:

* ``final``    -- y(t_N), in the signal's unit;
* ``peak``     -- the value of largest magnitude, y(t_k*) with k* = argmax |y(t_k)| (signed);
* ``settling`` -- settling time [s] from the start: the first t_k - t_0 after which every later
  sample stays within ``band`` (default 2 %) of |y(t_N) - y(t_0)| around y(t_N); 0 for a signal
  that does not move;
* ``error``    -- L-infinity error max_k |y(t_k) - y_ref(t_k)| against the scene's monolithic
  reference solution for the same parameters (:func:`fmugen.cosim.solve_reference`, Radau at
  1e-12); costs a reference solve per point.

``--metrics final,peak`` asks for these of every recorded column;
``joint.theta:settling`` for one column.  Table columns are named
``<column>:<metric>`` (``joint.theta:final``).  A failed run has no metrics
(NaN): its values stop early.
"""
from __future__ import annotations

import math
from typing import Iterable, Optional, Sequence

import numpy as np

from .errors import SweepError

METRICS = ("final", "peak", "settling", "error")
DEFAULT_METRICS = ("final", "peak", "settling")


def parse_metrics(items: Optional[Iterable[str]], columns: Sequence[str]) -> tuple:
    """``["final,peak", "joint.theta:error"]`` -> ``(("joint.theta", "final"), ...)`` over the recorded columns."""
    items = list(items) if items else [",".join(DEFAULT_METRICS)]
    out = []
    for item in items:
        for word in str(item).split(","):
            word = word.strip()
            if not word:
                continue
            col, _, metric = word.rpartition(":")
            if metric not in METRICS:
                raise SweepError(f"--metrics {word!r}: unknown metric {metric!r}; metrics: {', '.join(METRICS)}")
            if col and col not in columns:
                raise SweepError(f"--metrics {word!r}: {col!r} is not recorded by the scene; recorded: "
                                 f"{', '.join(columns)}")
            for c in ([col] if col else columns):
                if (c, metric) not in out:
                    out.append((c, metric))
    if not out:
        raise SweepError("--metrics: no metric given")
    return tuple(out)


def metric_names(wanted: Sequence[tuple]) -> list:
    return [f"{c}:{m}" for c, m in wanted]


def settling_time(t: np.ndarray, y: np.ndarray, band: float = 0.02) -> float:
    """First t_k - t_0 after which |y - y_N| <= band * |y_N - y_0| for every later sample [s].

    >>> settling_time(np.array([0., 1, 2, 3]), np.array([0., 1.5, 0.99, 1.0]))
    2.0
    """
    if len(y) == 0:
        return math.nan
    dev = np.abs(y - y[-1])
    # a signal that returns to where it started (a pulse) settles within band of its excursion
    scale = abs(y[-1] - y[0]) or float(dev.max())
    outside = np.nonzero(dev > band * scale)[0]
    if len(outside) == 0:
        return 0.0
    return float(t[outside[-1] + 1] - t[0])  # the last sample is never outside (dev = 0)


def compute(time: np.ndarray, values: np.ndarray, columns: Sequence[str], wanted: Sequence[tuple],
            band: float = 0.02, reference: Optional[np.ndarray] = None) -> dict:
    """``{"<column>:<metric>": value}`` of one run; ``reference``: values at ``time`` (same columns)."""
    out = {}
    for col, metric in wanted:
        j = list(columns).index(col)
        y = values[:, j]
        if len(y) == 0:
            v = math.nan
        elif metric == "final":
            v = float(y[-1])
        elif metric == "peak":
            v = float(y[int(np.argmax(np.abs(y)))])
        elif metric == "settling":
            v = settling_time(time, y, band)
        else:  # error
            v = float(np.max(np.abs(y - reference[:, j]))) if reference is not None else math.nan
        out[f"{col}:{metric}"] = v
    return out
