"""What runs on a Dask worker: one point of a sweep, from FMUs shipped once.

The client scatters one :class:`Bundle` to every worker (the .fmu files as
bytes, the co-simulation system, the run options, the metrics).  On first
use a worker process writes the FMUs into a private folder, once per bundle
(:func:`local_system`); the master then unzips each FMU once per process
(:mod:`fmugen.cosim.units`) and instantiates it per run.  Nothing is built
on a worker; a worker needs fmugen and its Python dependencies installed,
and must run the platform the FMUs' binaries were compiled for.

:func:`run_point` never raises for what a point does: a run that fails
returns ``status = "failed"`` with the master's failure report, and an
exception (an FMU that refuses a start value, a reference solve that fails)
returns ``status = "error"`` with its message.
"""
from __future__ import annotations

import atexit
import math
import os
import shutil
import socket
import tempfile
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Optional

import numpy as np

from . import metrics as _metrics
from .prepare import PointTask, point_system

_LOCAL: dict = {}  # bundle digest -> folder holding its FMUs, per process
_LOCK = threading.Lock()


@dataclass(frozen=True)
class Bundle:
    """Everything a worker needs for every point (shipped once per worker)."""

    digest: str  # sha256 of the FMUs' bytes
    fmus: dict  # group -> bytes of the .fmu
    system: object  # CosimSystem (its paths are the client's; replaced on the worker)
    options: dict  # keywords of fmugen.cosim.master.run
    wanted: tuple  # ((column, metric), ...)
    band: float = 0.02  # settling band
    reference: Optional[object] = None  # ReferenceProblem, when an "error" metric is asked
    keep_runs: bool = False  # return the recorded time series too


def make_bundle(plan, options: dict, wanted: tuple, band: float = 0.02, keep_runs: bool = False) -> Bundle:
    fmus = {u.name: Path(u.path).read_bytes() for u in plan.system.units}
    ref = plan.reference_problem if any(m == "error" for _, m in wanted) else None
    return Bundle(plan.digest, fmus, plan.system, dict(options), tuple(wanted), float(band), ref, bool(keep_runs))


def local_system(bundle: Bundle):
    """The bundle's system with its FMUs written into this process's own folder (once per bundle)."""
    with _LOCK:
        d = _LOCAL.get(bundle.digest)
        if d is None:
            d = Path(tempfile.mkdtemp(prefix=f"fmugen_sweep_{bundle.digest[:12]}_"))
            atexit.register(shutil.rmtree, d, True)
            for name, data in bundle.fmus.items():
                (d / f"{name}.fmu").write_bytes(data)
            _LOCAL[bundle.digest] = d
    units = tuple(replace(u, path=d / f"{u.name}.fmu") for u in bundle.system.units)
    return replace(bundle.system, units=units)


def _one_line(text: str) -> str:
    return " | ".join(line.strip() for line in str(text).splitlines() if line.strip())


def run_point(bundle: Bundle, task: PointTask) -> dict:
    """Run one point; returns a row: key, index, status, failure, metrics, work figures (and the run)."""
    from ..cosim.master import run

    row = {"index": task.index, "key": task.key, "status": "error", "failure": "", "wall_time": math.nan,
           "macro_steps": 0, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    row.update({n: math.nan for n in _metrics.metric_names(bundle.wanted)})
    w0 = time.perf_counter()
    try:
        system = point_system(local_system(bundle), task)
        res = run(system, **bundle.options) if system.couplings else run_alone(system, **bundle.options)
        row["macro_steps"] = res.summary.macro_steps
        if bundle.keep_runs:
            row["run"] = (res.time, res.values, res.columns)
        if not res.ok:
            row["status"] = "failed"
            row["failure"] = _one_line(res.summary.failure)
        else:
            ref = None
            if bundle.reference is not None:
                ref = _reference_values(bundle.reference, task, res.time)
            row.update(_metrics.compute(res.time, res.values, res.columns, bundle.wanted, bundle.band, ref))
            row["status"] = "ok"
    except Exception as exc:  # recorded, never raised: one bad point must not abort a sweep
        row["status"] = "error"
        row["failure"] = _one_line(f"{type(exc).__name__}: {exc}")
    row["wall_time"] = time.perf_counter() - w0
    return row


def _reference_values(problem, task: PointTask, times: np.ndarray) -> np.ndarray:
    """The monolithic reference at the run's communication points, for this point's parameters."""
    from ..cosim.reference import solve_reference

    p = replace(problem, x0=np.asarray(task.x0, dtype=float), stop_time=float(times[-1]))
    return solve_reference(p, times=times, parameter_values=task.parameter_values).values


def run_alone(system, step=None, stop=None, **_ignored):
    """A system of one FMU and no couplings (a monolithic scene): fmi2DoStep at the communication step.

    An adapter until :func:`fmugen.cosim.master.run` accepts systems without couplings (it fails on
    them); the FMU is driven through the master's own unit wrapper, so start values, extraction once
    per process and failure messages are the master's.  Coupling options do not apply and are ignored.
    """
    from ..cosim.master import CosimResult, FailureReport, Summary
    from ..cosim.units import UnitFailure
    from ..cosim.units3 import open_unit  # the FMU's own FMI version (a scene with fmi_version = 3)

    (spec,) = system.units
    t0 = float(system.start_time)
    stop = float(system.stop_time if stop is None else stop)
    H = float(system.step if step is None else step)
    summ = Summary(system.name, "single FMU", "none", False)
    w0 = time.perf_counter()
    u = open_unit(spec, t0, stop)
    try:
        vrs = [u.variable(r.variable).valueReference for r in system.recorded]
        T, V = [t0], [u.get_reals(vrs)]
        t, n = t0, 0
        while t < stop - 1e-12 * max(1.0, abs(stop)):
            h = stop - t if (t + H > stop or stop - (t + H) < 1e-3 * H) else H
            st = u._doStep(u.c, t, h, 1)
            if st > 1:
                summ.status = "failed"
                call = "fmi3DoStep" if u.STATUS[0].startswith("fmi3") else "fmi2DoStep"
                summ.failure = FailureReport(t, "fmu-failure", f"FMU {u.name!r}: {call}(t = {t:.9g}, H = {h:.4g}) "
                                             f"returned {u.STATUS[st]}", unit=u.name, fmu_messages=u.messages())
                break
            n += 1
            t = t0 + n * H if h == H else stop
            T.append(t)
            V.append(u.get_reals(vrs))
            summ.step_min, summ.step_max = min(summ.step_min, h), max(summ.step_max, h)
        summ.macro_steps = n
    except UnitFailure as e:
        summ.status = "failed"
        summ.failure = FailureReport(t0, "fmu-failure", str(e), unit=e.unit, fmu_messages=e.messages)
        T, V = [], []
    finally:
        u.close()
    summ.wall_time = time.perf_counter() - w0
    cols = tuple(r.column for r in system.recorded)
    return CosimResult(np.array(T), np.array(V).reshape(len(T), len(cols)), cols, summ)
