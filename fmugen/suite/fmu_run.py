"""One run of a Co-Simulation FMU with one solver setting: a plain fixed-step
master (fmpy's FMU2Slave) that records the compared variables at every
communication point, the FMU's log, its status and its work counters.

Wall time is the time spent inside fmi2DoStep only (the C solver and model),
not the master's Python bookkeeping.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import fmpy
import numpy as np
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

from .cases import RK4, Method

STATUS = {0: "OK", 1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal", 5: "Pending"}


@dataclass
class Run:
    t: np.ndarray
    values: np.ndarray  # len(t) x len(names), up to the last completed step
    names: list
    completed: bool  # every communication step returned fmi2OK/fmi2Warning
    status: str  # "OK", or the fmi2Status of the failed call
    messages: list = field(default_factory=list)  # (status, category, text)
    steps: int = 0
    rejected: int = 0
    f_evals: int = 0
    jac_evals: int = 0
    stiffness_detected: int = 0
    wall: float = 0.0  # s inside fmi2DoStep

    def warnings(self) -> list:
        return [m for s, _, m in self.messages if s >= 1]

    def failure_message(self) -> str:
        bad = [m for s, _, m in self.messages if s >= 2]
        return bad[0] if bad else ""


class _Log:
    def __init__(self):
        self.messages = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)

    def _log(self, env, name, status, category, message):
        self.messages.append((int(status), category.decode(errors="replace"), message.decode(errors="replace")))


class Unpacked:
    """An FMU extracted once and run many times."""

    def __init__(self, fmu_path, unzip_dir):
        self.md = read_model_description(str(fmu_path))
        self.dir = fmpy.extract(str(fmu_path), unzipdir=str(unzip_dir))
        self.vr = {v.name: v for v in self.md.modelVariables}

    def ref(self, name):
        try:
            return self.vr[name].valueReference
        except KeyError:
            raise KeyError(f"{self.md.modelName}: the FMU has no variable {name!r}") from None


def run(fmu: Unpacked, method: Method, start: dict, stop: float, H: float, names, rk4_h: float = 0.0) -> Run:
    """Simulate from 0 to ``stop`` with communication step ``H``; ``rk4_h`` is
    the RK4 step actually requested (already resolved from the method)."""
    log = _Log()
    slave = FMU2Slave(guid=fmu.md.guid, unzipDirectory=fmu.dir,
                      modelIdentifier=fmu.md.coSimulation.modelIdentifier, instanceName="suite")
    slave.instantiate(callbacks=log.callbacks)
    n = int(round(stop / H))
    times = np.arange(n + 1) * H
    vrs = [fmu.ref(v) for v in names]
    counters = [fmu.ref(c) for c in ("solver.n_steps", "solver.n_rejected", "solver.n_rhs", "solver.n_jac",
                                     "solver.stiffness_detected")]
    out, status, wall = [], "OK", 0.0
    try:
        slave.setupExperiment(startTime=0.0)
        slave.setInteger([fmu.ref("solver.method")], [method.solver])
        reals = dict(start)
        if method.solver == RK4:
            reals["solver.fixed_step"] = rk4_h
        else:
            reals.update({"solver.rtol": method.tol, "solver.atol": method.tol})
        slave.setReal([fmu.ref(k) for k in reals], list(reals.values()))
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        out.append(slave.getReal(vrs))
        for k in range(n):
            t0 = time.perf_counter()
            try:
                slave.doStep(currentCommunicationPoint=times[k], communicationStepSize=H)
            finally:
                wall += time.perf_counter() - t0
            out.append(slave.getReal(vrs))
    except FMICallException as exc:
        status = STATUS.get(getattr(exc, "status", 3), str(exc))
    work = slave.getInteger(counters)
    try:
        slave.terminate()
    except FMICallException:
        pass
    slave.freeInstance()
    values = np.array(out, dtype=float).reshape(len(out), len(vrs))
    return Run(times[:len(out)], values, list(names), status == "OK", status, log.messages, *work, wall=wall)
