"""FMI 2.0 helpers for tests that drive an FMU through fmpy's low-level classes and assert on what it
logged: callbacks (fmpy's allocator, a logger that keeps every message), opening an FMU with them, entering
it with given start values, and the status of a call that fmpy may raise."""
import fmpy
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2OK)


class Log:
    """Logger callbacks that record (status, category, message)."""

    def __init__(self):
        self.messages = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)

    def _log(self, env, name, status, category, message):
        self.messages.append((status, category.decode(), message.decode()))

    def text(self, status=None) -> str:
        """Every message (of ``status`` only, if given), one a line."""
        return "\n".join(m for s, _, m in self.messages if status is None or s == status)

    def last(self) -> str:
        return self.messages[-1][2] if self.messages else ""


def open_fmu(path, unzip_dir, name, cls=FMU2Slave):
    """Extract ``path`` to ``unzip_dir`` and instantiate it as ``name`` with a :class:`Log` (``fmu.log``);
    ``fmu.md`` is its model description, ``fmu.vr`` maps variable names to value references."""
    md = read_model_description(str(path))
    unzip = fmpy.extract(str(path), unzipdir=str(unzip_dir))
    fmu = cls(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
              instanceName=name)
    fmu.log = Log()
    fmu.instantiate(callbacks=fmu.log.callbacks)
    fmu.md = md
    fmu.vr = {v.name: v.valueReference for v in md.modelVariables}
    return fmu


def start(fmu, t0=0.0, ints=None, reals=None):
    """Set up the experiment at ``t0``, set ``ints``/``reals`` (name -> value) in initialization mode."""
    fmu.setupExperiment(startTime=t0)
    fmu.enterInitializationMode()
    if ints:
        fmu.setInteger([fmu.vr[k] for k in ints], list(ints.values()))
    if reals:
        fmu.setReal([fmu.vr[k] for k in reals], list(reals.values()))
    fmu.exitInitializationMode()


def status_of(call):
    """The fmi2Status of ``call()``: fmpy raises on fmi2Error/fmi2Fatal and may return None for fmi2OK."""
    try:
        r = call()
        return fmi2OK if r is None else r
    except FMICallException as e:
        return e.status


def step(fmu, t, h, flag=fmpy.fmi2.fmi2True):
    """The status of one fmi2DoStep from ``t`` over ``h``."""
    return status_of(lambda: fmu.fmi2DoStep(fmu.component, t, h, flag))
