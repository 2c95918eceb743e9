"""One FMU of a co-simulation, driven through fmpy's low-level API.

:class:`SlaveUnit` wraps an ``fmpy.fmi2.FMU2Slave`` (Co-Simulation) and
:class:`ModelUnit` an ``FMU2Model`` (Model Exchange).  Both resolve every
value reference once and keep ctypes pointers to preallocated numpy buffers,
so that the master's hot loop calls the C functions directly
(``fmi2DoStep``, ``fmi2GetReal``, ``fmi2SetReal``, ...) without building a
ctypes array or looking anything up per call.  The raw functions return the
FMI status instead of raising (fmpy's wrappers raise on fmi2Discard), so the
master can roll back or report.

Messages the FMU logs are kept (the last :data:`LOG_KEEP`) for failure
reports.

FMI 3.0 FMUs are units3.py's :class:`~.units3.Slave3Unit` and
:class:`~.units3.Model3Unit`: subclasses that bind the same entry points to
adapters over the fmi3 functions (``units3.open_unit`` picks the class by
the FMU's version), so that this FMI 2.0 path stays the direct C call.
"""
from __future__ import annotations

import atexit
import ctypes
import math
import os
import shutil
import tempfile
from collections import deque
from ctypes import POINTER, byref, c_double, c_int, c_uint, c_void_p
from pathlib import Path

import numpy as np

from .errors import CosimError
from .loading import load_failure, read_description

LOG_KEEP = 20
STATUS = ("fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal", "fmi2Pending")

_extracted: dict = {}
_tmp_root: list = []


def _extract(path: Path) -> str:
    """Unzip an FMU once per (path, size, mtime) for the whole process."""
    import fmpy

    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _extracted:
        if not _tmp_root:
            _tmp_root.append(tempfile.mkdtemp(prefix="fmugen_cosim_"))
            atexit.register(shutil.rmtree, _tmp_root[0], True)
        # the binaries, the model description and the resources; not the sources (5x less to unzip:
        # part of every command's start-up)
        _extracted[key] = fmpy.extract(str(path), unzipdir=tempfile.mkdtemp(dir=_tmp_root[0]),
                                       include=lambda name: not name.startswith(("sources/", "documentation/")))
    return _extracted[key]


def dptr(arr: np.ndarray, offset: int = 0):
    """ctypes double* to ``arr[offset]`` (arr float64, contiguous, kept alive by the caller)."""
    return ctypes.cast(arr.ctypes.data + 8 * offset, POINTER(c_double))


def vr_array(vrs) -> ctypes.Array:
    return (c_uint * max(1, len(vrs)))(*vrs)


def clocks_of_fmu(path, start_values=None) -> list:
    """:func:`_clocks` of an FMU file (its modelDescription.xml read from the zip; [] for a broken one)."""
    import zipfile

    import defusedxml.ElementTree as safe

    try:
        with zipfile.ZipFile(path) as zf:
            root = safe.fromstring(zf.read("modelDescription.xml"))
    except Exception:  # the master's loading names what is wrong with it
        return []
    starts = {}
    for sv in root.iter("ScalarVariable"):
        real = sv.find("Real")
        if real is not None and real.get("start") is not None:
            starts[sv.get("name")] = float(real.get("start"))
    return _clock_values(root, starts, dict(start_values or {}), Path(path))


def _clocks(unzip_dir, variables, start_values) -> list:
    """(period, offset) of each sample clock an fmugen FMU declares in its vendor annotation
    (fmugen/fmi/model_description.py), with the start values the run sets for their parameters."""
    import xml.etree.ElementTree as ET

    import defusedxml.ElementTree as safe  # an FMU is untrusted: no entities, no DTD

    path = Path(unzip_dir) / "modelDescription.xml"
    try:
        root = safe.parse(path).getroot()
    except (OSError, ET.ParseError, ValueError):
        return []
    starts = {k: v.start for k, v in variables.items() if getattr(v, "start", None) is not None}
    return _clock_values(root, starts, start_values, path)


def _clock_values(root, starts: dict, start_values: dict, path) -> list:
    """(period, offset) per <Clock> of fmugen's vendor annotation, parameters at the run's start values."""
    out = []
    for c in root.findall("./VendorAnnotations/Tool[@name='fmugen']/Clock"):
        vals = []
        for key in ("period", "offset"):
            name = c.get(f"{key}Parameter")
            v = start_values.get(name) if name else None
            if v is None and name in starts:
                v = starts[name]
            try:
                vals.append(float(v if v is not None else c.get(key)))
            except (TypeError, ValueError):
                raise CosimError(f"{path}: a clock's {key} {c.get(key)!r} is not a number") from None
        if not (vals[0] > 0 and math.isfinite(vals[0]) and math.isfinite(vals[1])):
            raise CosimError(f"{path}: a clock's period {vals[0]} must be positive and finite")
        out.append(tuple(vals))
    return out


class _Unit:
    """What CS and ME units share: loading, start values, logging, get/set."""

    kind = ""

    VERSION = "2.0"
    #: the names of the FMI status values this unit's functions return (UnitFailure's text)
    STATUS = STATUS
    #: the function behind ``_getOutDer`` (its status is returned, not raised, in both versions)
    OUTPUT_DERIVATIVES = "fmi2GetRealOutputDerivatives"
    #: why the master holds this FMU's inputs over a step, if it does (canInterpolateInputs = false)
    no_interpolation = "canInterpolateInputs = false"
    #: the type name of a coupled (floating-point) variable in fmpy's model description
    REAL = "Real"

    def __init__(self, unit, start_time: float, stop_time: float, md=None):
        self.name = unit.name
        self.unit = unit
        self.c = None
        path = Path(unit.path)
        # a broken or foreign FMU: one line naming it (not the zip/XML/fmpy exception)
        self.md = md if md is not None else read_description(unit.name, path, self.kind)
        if str(self.md.fmiVersion) != self.VERSION:  # units3.open_unit picks the class of the FMU's version
            raise CosimError(f"FMU {unit.name!r} ({path}): FMI {self.md.fmiVersion}; {type(self).__name__} runs "
                             f"FMI {self.VERSION} FMUs (fmugen.cosim.units3.open_unit opens either)")
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.log = deque(maxlen=LOG_KEEP)
        try:
            self._unzip = _extract(path)
        except Exception as e:
            raise load_failure(unit.name, path, "unzipping", e) from None
        cwd = os.getcwd()
        try:
            self.fmu = self._make_fmu()
        except CosimError:
            raise
        except Exception as e:  # the shared library does not load (another architecture, missing symbols)
            raise load_failure(unit.name, path, "loading its binary", e) from None
        finally:
            # fmpy changes into the binary's folder to load it and changes back only when the load works: a
            # broken binary left the host process in a temporary folder (every relative path after it broke)
            os.chdir(cwd)
        self._instantiate(path)
        self.c = self.fmu.component
        self._bind(self.fmu._functions)
        self._apply_start_values(unit.start_values)
        self.clocks = _clocks(self._unzip, self.variables, unit.start_values)
        self._initialize(start_time, stop_time)
        self.n_calls = 4
        self.do_steps = 0  # fmi2DoStep calls by the master (counted per FMU: one thread steps it at a time)

    def _instantiate(self, path) -> None:
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                               fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
        from fmpy import calloc, free

        log = self.log

        def logger(env, instance, status, category, message):
            text = message.decode("utf-8", "replace").replace("%%", "%")
            log.append(f"[{STATUS[status] if 0 <= status < 6 else status}] {text}")

        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(logger)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._callbacks = cb  # keep the CFUNCTYPE alive as long as the instance
        try:
            self.fmu.instantiate(callbacks=cb, loggingOn=False)
        except Exception as e:  # fmi2Instantiate returned NULL (e.g. the GUID is not the binary's)
            raise load_failure(self.name, path, "fmi2Instantiate", e, list(self.log)) from None

    def _bind(self, f) -> None:
        self._getReal = f["fmi2GetReal"]
        self._setReal = f["fmi2SetReal"]
        self._getState = f["fmi2GetFMUstate"]
        self._setState = f["fmi2SetFMUstate"]
        self._freeState = f["fmi2FreeFMUstate"]
        self._dirDer = f["fmi2GetDirectionalDerivative"]

    def _initialize(self, start_time: float, stop_time: float) -> None:
        f = self.fmu._functions
        # the raw C functions return the status (fmpy's wrappers raise without the FMU's message)
        # no stop time: a run may be continued or given a later stop than the system's
        self.check(f["fmi2SetupExperiment"](self.c, 0, 0.0, start_time, 0, stop_time), "fmi2SetupExperiment")
        self.check(f["fmi2EnterInitializationMode"](self.c), "fmi2EnterInitializationMode")
        self.check(f["fmi2ExitInitializationMode"](self.c), "fmi2ExitInitializationMode")

    # -- set-up ---------------------------------------------------------------
    def _apply_start_values(self, values) -> None:
        for name, value in dict(values).items():
            v = self.variables.get(name)
            if v is None:
                raise CosimError(f"FMU {self.name!r}: start value for unknown variable {name!r}")
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise CosimError(f"FMU {self.name!r}: start value of {name!r} is not a number: {value!r}") from None
            if not np.isfinite(value):
                raise CosimError(f"FMU {self.name!r}: start value of {name!r} is not finite: {value}")
            if v.type == "Integer":
                st = self.fmu._functions["fmi2SetInteger"](self.c, (c_uint * 1)(v.valueReference), 1, (c_int * 1)(int(value)))
            elif v.type == "Real":
                st = self.fmu._functions["fmi2SetReal"](self.c, (c_uint * 1)(v.valueReference), 1, (c_double * 1)(value))
            else:
                raise CosimError(f"FMU {self.name!r}: cannot set {v.type} variable {name!r}")
            self.check(st, f"fmi2Set{v.type}({name} = {value})")

    def variable(self, name: str, causality=None):
        v = self.variables.get(name)
        if v is None:
            import difflib

            near = difflib.get_close_matches(name, self.variables, n=3)
            hint = f" (did you mean {', '.join(near)}?)" if near else ""
            raise CosimError(f"FMU {self.name!r} ({self.unit.path}): no variable {name!r}{hint}")
        if v.type != self.REAL:
            raise CosimError(f"FMU {self.name!r}: variable {name!r} is {v.type}; couplings need {self.REAL}")
        if causality is not None and v.causality not in causality:
            raise CosimError(f"FMU {self.name!r}: variable {name!r} has causality {v.causality}, "
                             f"expected {' or '.join(causality)}")
        return v

    def check(self, status: int, what: str) -> None:
        if status > 1:
            raise UnitFailure(self.name, what, status, list(self.log), self.STATUS)

    def messages(self) -> list:
        return list(self.log)

    # -- state ---------------------------------------------------------------
    def new_state(self):
        s = c_void_p()
        self.check(self._getState(self.c, byref(s)), "fmi2GetFMUstate")
        return s

    def save(self, s) -> int:
        """Overwrite FMU state ``s`` (FMI lets a state be reused)."""
        return self._getState(self.c, byref(s))

    def restore(self, s) -> int:
        return self._setState(self.c, s)

    def free_state(self, s) -> None:
        if s:
            self._freeState(self.c, byref(s))

    def get_reals(self, vrs) -> np.ndarray:
        out = np.zeros(len(vrs))
        if len(vrs):
            self.check(self._getReal(self.c, vr_array(vrs), len(vrs), dptr(out)), "fmi2GetReal")
        return out

    def get_integer(self, name: str) -> int:
        v = self.variables[name]
        out = (c_int * 1)()
        self.check(self.fmu._functions["fmi2GetInteger"](self.c, (c_uint * 1)(v.valueReference), 1, out), "fmi2GetInteger")
        return out[0]

    #: fmpy's raw terminate function of the unit's FMI version (units3 names FMI 3.0's)
    TERMINATE = "fmi2Terminate"

    def close(self) -> None:
        if getattr(self, "c", None) is None:
            return
        try:
            getattr(self.fmu, self.TERMINATE)(self.c)
        except Exception:  # terminate after an error state may be refused; free anyway
            pass
        try:
            self.fmu.freeInstance()
        except Exception:
            pass
        self.c = None


class SlaveUnit(_Unit):
    """A Co-Simulation FMU."""

    kind = "cs"

    def _make_fmu(self):
        from fmpy.fmi2 import FMU2Slave

        cs = self.md.coSimulation
        if cs is None:
            raise CosimError(f"FMU {self.name!r} ({self.unit.path}) has no Co-Simulation interface")
        self.can_interpolate = bool(cs.canInterpolateInputs)
        self.can_save_state = bool(cs.canGetAndSetFMUstate)
        # FMI 2.0's default is false: every macro step of such an FMU must be the same
        self.variable_step = bool(cs.canHandleVariableCommunicationStepSize)
        fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self._unzip, modelIdentifier=cs.modelIdentifier,
                        instanceName=self.name)
        f = fmu._functions
        self._doStep = f["fmi2DoStep"]
        self._setInDer = f["fmi2SetRealInputDerivatives"]
        self._getRealStatus = f["fmi2GetRealStatus"]
        self._getOutDer = f["fmi2GetRealOutputDerivatives"]
        self.max_output_derivative_order = int(cs.maxOutputDerivativeOrder or 0)
        # outputs that are functions of the inputs at the same instant, nothing else: an fmugen FMU without
        # continuous states (its generator writes no other memory); then fmi2GetDirectionalDerivative is the
        # sensitivity of a whole step.  A third-party FMU may hide discrete states, so it is not trusted
        self.algebraic = (not self.md.derivatives and bool(cs.providesDirectionalDerivative)
                          and str(self.md.generationTool or "").startswith("fmugen"))
        return fmu

    def last_successful_time(self) -> float:
        t = c_double(float("nan"))
        self._getRealStatus(self.c, 2, byref(t))  # fmi2LastSuccessfulTime
        return t.value


class ModelUnit(_Unit):
    """A Model-Exchange FMU (integrated by the master's ME block)."""

    kind = "me"
    can_interpolate = True  # the master's ME block evaluates the extrapolated inputs itself

    def _make_fmu(self):
        from fmpy.fmi2 import FMU2Model

        me = self.md.modelExchange
        if me is None:
            raise CosimError(f"FMU {self.name!r} ({self.unit.path}) has no Model-Exchange interface")
        self.can_save_state = bool(me.canGetAndSetFMUstate)
        self.variable_step = True  # the master's ME block takes whatever steps it likes
        self.directional = bool(me.providesDirectionalDerivative)  # else the ME block's Jacobian by differences
        self.n_indicators = int(self.md.numberOfEventIndicators or 0)
        fmu = FMU2Model(guid=self.md.guid, unzipDirectory=self._unzip, modelIdentifier=me.modelIdentifier,
                        instanceName=self.name)
        return fmu

    def enter_continuous_time(self) -> None:
        f = self.fmu._functions
        self.nx = len(self.md.derivatives)
        self.check(f["fmi2EnterContinuousTimeMode"](self.c), "fmi2EnterContinuousTimeMode")
        self._setTime = f["fmi2SetTime"]
        self._setX = f["fmi2SetContinuousStates"]
        self._getX = f["fmi2GetContinuousStates"]
        self._getDer = f["fmi2GetDerivatives"]
        self._completed = f["fmi2CompletedIntegratorStep"]
        self._getZ = f["fmi2GetEventIndicators"]
        self.x_vrs = [d.variable.derivative.valueReference for d in self.md.derivatives]
        self.der_vrs = [d.variable.valueReference for d in self.md.derivatives]
        self.nominals = self.get_nominals()

    def get_nominals(self) -> np.ndarray:
        nom = (c_double * max(1, self.nx))()
        self.check(self.fmu._functions["fmi2GetNominalsOfContinuousStates"](self.c, nom, self.nx),
                   "fmi2GetNominalsOfContinuousStates")
        return np.array(nom[: self.nx], dtype=float)

    # -- events (the ME block's state events: me_block.py) -------------------------
    def update_discrete_states(self):
        """One fmi2NewDiscreteStates: (discrete states need another update, values of the continuous states
        changed, nominals changed, next time event or None).  terminateSimulation ends the run."""
        from fmpy.fmi2 import fmi2EventInfo

        ev = fmi2EventInfo()
        self.check(self.fmu._functions["fmi2NewDiscreteStates"](self.c, byref(ev)), "fmi2NewDiscreteStates")
        if ev.terminateSimulation:
            raise SimulationTerminated(self.name, "fmi2NewDiscreteStates", list(self.log), self.STATUS)
        return (bool(ev.newDiscreteStatesNeeded), bool(ev.valuesOfContinuousStatesChanged),
                bool(ev.nominalsOfContinuousStatesChanged),
                float(ev.nextEventTime) if ev.nextEventTimeDefined else None)

    def enter_event_mode(self) -> None:
        self.check(self.fmu._functions["fmi2EnterEventMode"](self.c), "fmi2EnterEventMode")

    def reenter_continuous_time(self) -> None:
        self.check(self.fmu._functions["fmi2EnterContinuousTimeMode"](self.c), "fmi2EnterContinuousTimeMode")

    def completed_integrator_step(self) -> bool:
        """fmi2CompletedIntegratorStep after an accepted step of the ME block: whether the FMU asks for an
        event (enterEventMode); terminateSimulation ends the run.  noSetFMUStatePriorToCurrentPoint is false:
        the master may restore an earlier FMU state (rollback, iterated schemes)."""
        enter, term = c_int(0), c_int(0)
        self.check(self._completed(self.c, 0, byref(enter), byref(term)), "fmi2CompletedIntegratorStep")
        if term.value:
            raise SimulationTerminated(self.name, "fmi2CompletedIntegratorStep", list(self.log), self.STATUS)
        return bool(enter.value)


class UnitFailure(Exception):
    """An FMU returned fmi2Discard, fmi2Error or fmi2Fatal (fmi3Discard, ... of an FMI 3.0 FMU: ``names``
    are the status names of its version)."""

    def __init__(self, unit: str, call: str, status: int, messages: list, names=STATUS):
        self.unit, self.call, self.status, self.messages = unit, call, status, messages
        self.status_name = names[status] if 0 <= status < len(names) else str(status)
        tail = ("; last message: " + messages[-1]) if messages else ""
        super().__init__(f"FMU {unit!r}: {call} returned {self.status_name}{tail}")


class SimulationTerminated(UnitFailure):
    """An FMU asked to end the simulation (terminateSimulation = true from fmi3DoStep,
    fmi3CompletedIntegratorStep, fmi3UpdateDiscreteStates or FMI 2.0's event info): not an error of the
    call (its status was OK), but the run cannot go on past it."""

    def __init__(self, unit: str, call: str, messages: list, names=STATUS):
        Exception.__init__(self)
        self.unit, self.call, self.status, self.messages = unit, call, 0, messages
        self.status_name = names[0]
        tail = ("; last message: " + messages[-1]) if messages else ""
        self.args = (f"FMU {unit!r}: {call} returned terminateSimulation = true: the FMU ended the "
                     f"simulation{tail}",)
