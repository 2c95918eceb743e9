"""FMI 3.0 FMUs in the co-simulation master: the FMI 2.0 units' interface over the fmi3 functions.

The master (``master.py``, ``schemes.py``, ``me_block.py``, ``loops.py``, ``dense.py``) calls a unit's raw
entry points with FMI 2.0's argument lists -- ``u._getReal(c, vrs, n, values)``, ``u._doStep(c, t, H,
noSetFMUStatePriorToCurrentPoint)``, ``u._dirDer(c, unknowns, nUnknowns, knowns, nKnowns, seed,
sensitivity)`` -- and reads the status they return.  For an FMI 2.0 FMU these are the ctypes functions
themselves (units.py: nothing between the hot loop and the C call).  :class:`Slave3Unit` and
:class:`Model3Unit` bind the same names to small closures over the FMI 3.0 functions, which differ:

* ``fmi3GetFloat64``/``fmi3SetFloat64`` take the number of values besides the number of value references
  (arrays); ``fmi3GetOutputDerivatives`` too; ``fmi3GetDirectionalDerivative`` takes the sizes of seed and
  sensitivity;
* ``fmi3DoStep`` has the out-arguments eventHandlingNeeded, terminateSimulation, earlyReturn and
  lastSuccessfulTime.  The FMU is instantiated with eventModeUsed = false and earlyReturnAllowed = false, so
  it handles its events inside the step and never returns early; terminateSimulation = true ends the run
  (:class:`~.units.SimulationTerminated`, the run's failure report says so);
* Model Exchange: ``fmi3GetContinuousStateDerivatives``, ``fmi3UpdateDiscreteStates`` (instead of
  fmi2NewDiscreteStates' event info struct), ``fmi3CompletedIntegratorStep`` with fmi3Boolean out-arguments.

A closure raises :class:`~.units.UnitFailure` itself when the status is fmi3Discard or worse, naming the
fmi3 call and the fmi3 status; the master's own check of the status (written for FMI 2.0, naming the fmi2
call) then never sees one.  The one exception is ``_getOutDer``, whose refusal dense output takes as "no
slopes" (dense.py), as from an FMI 2.0 FMU: it returns the status, and the master names the call by the
unit's ``OUTPUT_DERIVATIVES``.  An fmi3Discard of fmi3DoStep is status 2 as in FMI 2.0, so an adaptive run
retries it smaller as it does an fmi2Discard.

FMI 3.0 has no input derivatives (no canInterpolateInputs, no fmi2SetRealInputDerivatives).  Its replacement
is the intermediate update with intermediateVariableSetRequested = true: an FMU that declares
providesIntermediateUpdate and inputs with intermediateUpdate="true" (fmugen's do) is instantiated with an
intermediate-update callback and those inputs as requiredIntermediateVariables, and asks for its inputs inside
fmi3DoStep wherever its solver needs them; the callback evaluates the master's input polynomial for this unit
there and sets them with fmi3SetFloat64.  The master treats such a unit as one that interpolates
(``can_interpolate``): ``_setReal`` of its inputs and ``_setInDer`` keep the polynomial's value and derivatives
at the communication point in Python, as fmi2SetReal and fmi2SetRealInputDerivatives keep them in an FMI 2.0
FMU, and the callback evaluates it with the runtime's formula (``fmugen_inputs_at``), so such a unit sees the
inputs its FMI 2.0 twin sees.  Any other FMI 3.0 Co-Simulation FMU holds its inputs at the extrapolant's
midpoint over a step, as an FMI 2.0 FMU with canInterpolateInputs = false does (``Summary.warnings`` says so).  Array
variables (a ``<Dimension>``) are refused where a coupling, a recorded column or a start value names one.
fmpy's model description gives FMI 3.0's instantiationToken as ``guid`` and the types as Float64, Int32,
Boolean; the ModelStructure (outputs and their dependencies, derivatives) reads as in FMI 2.0.
"""
from __future__ import annotations

import math
from ctypes import (byref, c_bool, c_double, c_float, c_int, c_int8, c_int16, c_int32, c_int64, c_size_t, c_uint,
                    c_uint8, c_uint16, c_uint32, c_uint64, c_void_p)
from pathlib import Path

import numpy as np

from .errors import CosimError
from .loading import load_failure, read_description
from .units import LOG_KEEP, ModelUnit, SimulationTerminated, SlaveUnit, UnitFailure  # noqa: F401

__all__ = ["STATUS3", "Model3Unit", "Slave3Unit", "open_unit"]

STATUS3 = ("fmi3OK", "fmi3Warning", "fmi3Discard", "fmi3Error", "fmi3Fatal")

#: start values the master sets: fmpy's FMI 3.0 type name -> (setter, ctypes type)
_SETTERS = {"Float64": ("fmi3SetFloat64", c_double), "Float32": ("fmi3SetFloat32", c_float),
            "Int8": ("fmi3SetInt8", c_int8), "UInt8": ("fmi3SetUInt8", c_uint8),
            "Int16": ("fmi3SetInt16", c_int16), "UInt16": ("fmi3SetUInt16", c_uint16),
            "Int32": ("fmi3SetInt32", c_int32), "UInt32": ("fmi3SetUInt32", c_uint32),
            "Int64": ("fmi3SetInt64", c_int64), "UInt64": ("fmi3SetUInt64", c_uint64),
            "Enumeration": ("fmi3SetInt64", c_int64), "Boolean": ("fmi3SetBoolean", c_bool)}


def open_unit(unit, start_time: float, stop_time: float):
    """The master's unit for ``unit`` (a :class:`~.system.Unit` with fmi_type "cs" or "me"): its model
    description read once, then the FMI 2.0 or FMI 3.0 class of that interface."""
    kind = str(unit.fmi_type).lower()
    md = read_description(unit.name, Path(unit.path), kind)
    three = str(md.fmiVersion).startswith("3")
    if kind == "cs":
        cls = Slave3Unit if three else SlaveUnit
    else:
        cls = Model3Unit if three else ModelUnit
    return cls(unit, start_time, stop_time, md)


def _dimensions(v) -> str:
    return " x ".join(str(d.start) if getattr(d, "start", None) is not None else f"(size variable vr "
                      f"{getattr(d, 'valueReference', '?')})" for d in v.dimensions)


def _intermediate_inputs(unzip) -> list:
    """Value references of the scalar Float64 inputs with intermediateUpdate="true" (fmpy's model description
    does not read the attribute): those the importer may set in the intermediate update."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(Path(unzip) / "modelDescription.xml").getroot()
    except (OSError, ET.ParseError):
        return []
    mv = root.find("ModelVariables")
    return [int(el.get("valueReference")) for el in (mv if mv is not None else ())
            if el.tag == "Float64" and el.get("causality") == "input" and el.get("intermediateUpdate") == "true"
            and el.find("Dimension") is None and el.get("valueReference", "").isdigit()]


class _FMI3:
    """What the FMI 3.0 CS and ME units share: logging, instantiation, the checked entry points, start
    values, initialisation, FMU states.  Mixed in before the FMI 2.0 class it adapts."""

    VERSION = "3.0"
    STATUS = STATUS3
    OUTPUT_DERIVATIVES = "fmi3GetOutputDerivatives"
    REAL = "Float64"
    #: why the master holds this FMU's inputs over a step (Summary.warnings, refusals of Hermite inputs)
    no_interpolation = "FMI 3.0 has no input derivatives (no canInterpolateInputs, no fmi2SetRealInputDerivatives)"

    def _logger(self):
        log = self.log

        def logger(env, status, category, message):
            # FMI 3.0's messages are plain text, not printf formats as FMI 2.0's ("%%" stays)
            text = message.decode("utf-8", "replace") if message else ""
            log.append(f"[{STATUS3[status] if 0 <= status < len(STATUS3) else status}] {text}")

        return logger

    def _checked(self, fn, call: str):
        """``fn`` (an fmi3 function whose arguments the master passes as they are) raising on Discard or worse."""
        name, log = self.name, self.log

        def checked(*args):
            st = fn(*args)
            if st > 1:
                raise UnitFailure(name, call, st, list(log), STATUS3)
            return st

        return checked

    def _bind(self, f) -> None:
        name, log = self.name, self.log
        get64, set64, dd = f["fmi3GetFloat64"], f["fmi3SetFloat64"], f["fmi3GetDirectionalDerivative"]

        # FMI 2.0's arguments; the number of values equals the number of value references (scalars only)
        def getReal(c, vrs, n, values):
            st = get64(c, vrs, n, values, n)
            if st > 1:
                raise UnitFailure(name, "fmi3GetFloat64", st, list(log), STATUS3)
            return st

        def setReal(c, vrs, n, values):
            st = set64(c, vrs, n, values, n)
            if st > 1:
                raise UnitFailure(name, "fmi3SetFloat64", st, list(log), STATUS3)
            return st

        def dirDer(c, unknowns, n_unknowns, knowns, n_knowns, seed, sensitivity):
            st = dd(c, unknowns, n_unknowns, knowns, n_knowns, seed, n_knowns, sensitivity, n_unknowns)
            if st > 1:
                raise UnitFailure(name, "fmi3GetDirectionalDerivative", st, list(log), STATUS3)
            return st

        self._getReal, self._setReal, self._dirDer = getReal, setReal, dirDer
        self._getState = self._checked(f["fmi3GetFMUState"], "fmi3GetFMUState")
        self._setState = self._checked(f["fmi3SetFMUState"], "fmi3SetFMUState")
        self._freeState = self._checked(f["fmi3FreeFMUState"], "fmi3FreeFMUState")

    def _initialize(self, start_time: float, stop_time: float) -> None:
        f = self.fmu._functions
        # no tolerance, no stop time (as for FMI 2.0: a run may be continued or given a later stop)
        self.check(f["fmi3EnterInitializationMode"](self.c, False, 0.0, start_time, False, stop_time),
                   "fmi3EnterInitializationMode")
        self.check(f["fmi3ExitInitializationMode"](self.c), "fmi3ExitInitializationMode")

    def variable(self, name: str, causality=None):
        v = self.variables.get(name)
        if v is not None and getattr(v, "dimensions", None):
            raise CosimError(f"FMU {self.name!r} ({self.unit.path}): variable {name!r} is an array "
                             f"({_dimensions(v)}); the master couples and records scalar variables only")
        return super().variable(name, causality)

    def _apply_start_values(self, values) -> None:
        f = self.fmu._functions
        for name, value in dict(values).items():
            v = self.variables.get(name)
            if v is None:
                raise CosimError(f"FMU {self.name!r}: start value for unknown variable {name!r}")
            if getattr(v, "dimensions", None):
                raise CosimError(f"FMU {self.name!r}: start value of {name!r}: it is an array ({_dimensions(v)}); "
                                 f"the master sets scalar start values only")
            if v.type not in _SETTERS:
                raise CosimError(f"FMU {self.name!r}: cannot set {v.type} variable {name!r}")
            if v.type == "Boolean" and isinstance(value, str) and value.strip().lower() in ("true", "false"):
                value = value.strip().lower() == "true"
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise CosimError(f"FMU {self.name!r}: start value of {name!r} is not a number: {value!r}") from None
            if not math.isfinite(value):
                raise CosimError(f"FMU {self.name!r}: start value of {name!r} is not finite: {value}")
            setter, ctype = _SETTERS[v.type]
            x = value != 0.0 if v.type == "Boolean" else (value if v.type.startswith("Float") else int(value))
            st = f[setter](self.c, (c_uint * 1)(v.valueReference), 1, (ctype * 1)(x), 1)
            self.check(st, f"{setter}({name} = {value})")

    def get_integer(self, name: str) -> int:
        v = self.variables[name]
        out = (c_int32 * 1)()
        self.check(self.fmu._functions["fmi3GetInt32"](self.c, (c_uint * 1)(v.valueReference), 1, out, 1),
                   "fmi3GetInt32")
        return out[0]

    TERMINATE = "fmi3Terminate"  # _Unit.close calls it


class Slave3Unit(_FMI3, SlaveUnit):
    """An FMI 3.0 Co-Simulation FMU."""

    def _make_fmu(self):
        from fmpy.fmi3 import FMU3Slave

        cs = self.md.coSimulation
        if cs is None:
            raise CosimError(f"FMU {self.name!r} ({self.unit.path}) has no Co-Simulation interface")
        # inputs the FMU lets the importer set in the intermediate update: what replaces input derivatives
        self.intermediate_inputs = _intermediate_inputs(self._unzip) if cs.providesIntermediateUpdate else []
        self.can_interpolate = bool(self.intermediate_inputs)
        self.intermediate_sets = 0  # fmi3SetFloat64 calls in the callback (the price of interpolated inputs)
        self.intermediate_requests = 0  # callbacks with intermediateVariableSetRequested (0: the FMU never asks)
        self.can_save_state = bool(cs.canGetAndSetFMUstate)
        self.variable_step = bool(cs.canHandleVariableCommunicationStepSize)
        self.max_output_derivative_order = int(cs.maxOutputDerivativeOrder or 0)
        # as for FMI 2.0 (units.py): an fmugen FMU without continuous states is a function of its inputs now
        self.algebraic = (not self.md.derivatives and bool(cs.providesDirectionalDerivative)
                          and str(self.md.generationTool or "").startswith("fmugen"))
        return FMU3Slave(guid=self.md.guid, unzipDirectory=self._unzip, modelIdentifier=cs.modelIdentifier,
                         instanceName=self.name)

    def _instantiate(self, path) -> None:
        extra = {}
        if self.can_interpolate:  # fmpy keeps the CFUNCTYPE of the callback alive with the instance
            extra = dict(intermediateUpdate=self._intermediate_update(),
                         requiredIntermediateVariables=self.intermediate_inputs)
        try:
            # events inside fmi3DoStep (no CS event mode), never an early return: the master's macro steps
            # end where it asked
            self.fmu.instantiate(visible=False, loggingOn=False, eventModeUsed=False, earlyReturnAllowed=False,
                                 logMessage=self._logger(), **extra)
        except Exception as e:  # NULL (e.g. the instantiation token is not the binary's)
            raise load_failure(self.name, path, "fmi3InstantiateCoSimulation", e, list(self.log)) from None

    def _bind(self, f) -> None:
        super()._bind(f)
        name, log = self.name, self.log
        step, od = f["fmi3DoStep"], f["fmi3GetOutputDerivatives"]
        event, term, early, last = c_bool(False), c_bool(False), c_bool(False), c_double(math.nan)
        refs = (byref(event), byref(term), byref(early), byref(last))
        self._last = last

        def doStep(c, t, H, no_prior):
            st = step(c, t, H, no_prior, *refs)
            if st > 1:
                raise UnitFailure(name, f"fmi3DoStep(t = {t:.9g}, H = {H:.4g})", st, list(log), STATUS3)
            if term.value:
                raise SimulationTerminated(name, f"fmi3DoStep(t = {t:.9g}, H = {H:.4g}) (last successful time "
                                                 f"{last.value:.9g})", list(log), STATUS3)
            if early.value or event.value:  # neither was allowed at instantiation: the FMU breaks the standard
                e = UnitFailure(name, "fmi3DoStep", 3, list(log), STATUS3)
                e.args = (f"FMU {name!r}: fmi3DoStep(t = {t:.9g}, H = {H:.4g}) returned "
                          f"{'earlyReturn' if early.value else 'eventHandlingNeeded'} = true, though instantiated "
                          f"with eventModeUsed = false and earlyReturnAllowed = false",)
                raise e
            return st

        def getOutDer(c, vrs, n, orders, values):
            # the status returned, not raised: dense output takes a refusal as "no slopes from this FMU"
            # (dense.py); the master names the call by OUTPUT_DERIVATIVES where it is a failure
            return od(c, vrs, n, orders, values, n)

        def setInDer(*_):
            raise CosimError(f"FMU {name!r}: FMI 3.0 has no input derivatives (fmi2SetRealInputDerivatives)")

        self._doStep, self._getOutDer, self._setInDer = doStep, getOutDer, setInDer
        self._getRealStatus = None
        if self.can_interpolate:
            self._bind_interpolation()

    # -- inputs set in the intermediate update ------------------------------------------------------------
    def _bind_interpolation(self) -> None:
        """``_setReal`` of the coupled inputs and ``_setInDer`` keep the input polynomial here (pending until
        the next fmi3DoStep, which is where an FMI 2.0 FMU's polynomial starts: its communication point);
        ``doStep`` makes it the polynomial of the step before calling fmi3DoStep."""
        name, log = self.name, self.log
        plain_set, plain_step = self._setReal, self._doStep
        self._pending = {}  # 0: values, 1..3: derivatives of that order, set since the last fmi3DoStep
        self._poly = None  # [t0, u0, du, ddu, dddu] (lists) of the running step
        self._iu_error = None

        def setReal(c, vrs, n, values):
            st = plain_set(c, vrs, n, values)  # the values at the communication point go to the FMU as well
            if vrs is getattr(self, "in_vr", None) and n == self.n_in:
                self._pending[0] = values[:n]
            return st

        def setInDer(c, vrs, n, orders, values):
            if not (vrs is getattr(self, "in_vr", None) and n == self.n_in):
                raise CosimError(f"FMU {name!r}: input derivatives are kept for its coupled inputs only")
            self._pending[int(orders[0])] = values[:n]  # the master sends one order per call, for all inputs
            return 0

        def doStep(c, t, H, no_prior):
            if self._pending:
                self._start_polynomial(t)
            self._iu_error = None
            try:
                st = plain_step(c, t, H, no_prior)
            finally:
                err, self._iu_error = self._iu_error, None
            if err is not None:  # the callback cannot raise into the FMU: reported after the step
                st_set, what = err
                raise UnitFailure(name, f"fmi3SetFloat64 in the intermediate update of fmi3DoStep(t = {t:.9g}, "
                                        f"H = {H:.4g}) ({what})", st_set, list(log), STATUS3)
            return st

        self._setReal, self._setInDer, self._doStep = setReal, setInDer, doStep
        # the callback's fmi3SetFloat64 without fmpy's argtypes, its arguments made once per step as ctypes
        # objects: converting them is most of a call's cost (measured 3.4 us with argtypes, 1.5 us without),
        # and it comes at every stage of the FMU's solver
        dll = self.fmu.dll
        self._set64 = dll._FuncPtr(("fmi3SetFloat64", dll))
        self._set64.restype = c_int

    def _start_polynomial(self, t: float) -> None:
        """The input polynomial from t: the old one continued to t (as the FMI 2.0 runtime rebases its
        polynomial at the end of every step), then what was set since replacing its value or derivatives."""
        n = self.n_in
        old = self._poly
        if old is None:
            u0, d = [0.0] * n, [[0.0] * n, [0.0] * n, [0.0] * n]
        else:
            s = t - old[0]
            u0 = self._evaluate(old, t)
            d1, d2, d3 = old[2], old[3], old[4]
            d = [[d1[i] + (d2[i] + 0.5 * d3[i] * s) * s if d3[i] != 0.0 else
                  (d1[i] + d2[i] * s if d2[i] != 0.0 else d1[i]) for i in range(n)],
                 [d2[i] + d3[i] * s if d3[i] != 0.0 else d2[i] for i in range(n)], list(d3)]
        p = self._pending
        if 0 in p:
            u0 = list(p[0])
        for k in (1, 2, 3):
            if k in p:
                d[k - 1] = list(p[k])
        self._pending = {}
        self._poly = [t, u0, d[0], d[1], d[2]]
        if len(getattr(self, "_iu_buf", ())) < n:
            self._iu_buf = (c_double * max(1, n))()  # what the callback passes to fmi3SetFloat64
        self._setter = self._make_setter()

    @staticmethod
    def _evaluate(poly, t):
        """u(t) by the runtime's formula (c_runtime/solver_common.c, fmugen_inputs_at), term for term, so that
        the values set equal those an FMI 2.0 FMU extrapolates from the same derivatives"""
        t0, u0, du, ddu, dddu = poly
        dt = t - t0
        return [u0[i] + (du[i] + (0.5 * ddu[i] + dddu[i] * dt / 6.0) * dt) * dt if dddu[i] != 0.0
                else u0[i] + (du[i] + 0.5 * ddu[i] * dt) * dt if ddu[i] != 0.0
                else u0[i] + du[i] * dt if du[i] != 0.0 else u0[i] for i in range(len(u0))]

    def _intermediate_update(self):
        """The intermediate-update callback (a Python function: fmpy wraps it in its CFUNCTYPE and keeps that
        alive with the instance).  With intermediateVariableSetRequested it sets the coupled inputs to the
        polynomial's values at intermediateUpdateTime (``self._setter``, made per step by ``_make_setter``);
        the calls after accepted solver steps (getting allowed) need nothing.  It never asks for an early
        return.  An exception cannot pass through the FMU: it is kept and raised after fmi3DoStep.  It runs
        at every stage time of the FMU's solver, so it is kept short: one Python call per request."""

        def callback(env, t, set_requested, get_allowed, step_finished, can_return_early, requested, when):
            if not set_requested:
                return
            self.intermediate_requests += 1
            if self._setter is not None:
                try:
                    self._setter(t)
                except Exception as e:  # noqa: BLE001 -- reported by doStep
                    if self._iu_error is None:
                        self._iu_error = (3, f"the callback raised {e!r}")

        self._setter = None
        return callback

    def _make_setter(self):
        """The function the callback calls for u(t): the polynomial of this step evaluated by the runtime's
        formula for its degree (fmugen_inputs_at: the FMI 2.0 FMU's values, to the bit), written into the
        buffer and passed to fmi3SetFloat64.  None when the polynomial is constant (a held input): the values
        set before fmi3DoStep remain, as the standard says, and the FMU needs no call."""
        t0, u0, du, ddu, dddu = self._poly
        n = len(u0)
        if not n or not any(du) and not any(ddu) and not any(dddu):
            return None
        buf, c, vr, set64, nn = self._iu_buf, c_void_p(self.c), self.in_vr, self._set64, c_size_t(n)
        rng = range(n)
        unit = self

        def fail(st, t):
            unit.intermediate_sets += 1
            if st > 1 and unit._iu_error is None:
                unit._iu_error = (st, f"at t = {t:.17g}")

        if not any(ddu) and not any(dddu):  # linear: u0 + du (t - t0), zero slopes exactly u0
            lin = [(i, u0[i], du[i]) for i in rng]

            def setter(t):
                dt = t - t0
                for i, a, b in lin:
                    buf[i] = a + b * dt if b != 0.0 else a
                st = set64(c, vr, nn, buf, nn)
                if st:
                    fail(st, t)
                else:
                    unit.intermediate_sets += 1
            return setter
        evaluate, poly = self._evaluate, self._poly

        def setter(t):
            buf[:n] = evaluate(poly, t)
            st = set64(c, vr, nn, buf, nn)
            if st:
                fail(st, t)
            else:
                unit.intermediate_sets += 1
        return setter


class Model3Unit(_FMI3, ModelUnit):
    """An FMI 3.0 Model-Exchange FMU (integrated by the master's ME block)."""

    def _make_fmu(self):
        from fmpy.fmi3 import FMU3Model

        me = self.md.modelExchange
        if me is None:
            raise CosimError(f"FMU {self.name!r} ({self.unit.path}) has no Model-Exchange interface")
        self.can_save_state = bool(me.canGetAndSetFMUstate)
        self.variable_step = True
        self.directional = bool(me.providesDirectionalDerivative)
        self.n_indicators = int(self.md.numberOfEventIndicators or len(self.md.eventIndicators or ()))
        return FMU3Model(guid=self.md.guid, unzipDirectory=self._unzip, modelIdentifier=me.modelIdentifier,
                         instanceName=self.name)

    def _instantiate(self, path) -> None:
        try:
            self.fmu.instantiate(visible=False, loggingOn=False, logMessage=self._logger())
        except Exception as e:
            raise load_failure(self.name, path, "fmi3InstantiateModelExchange", e, list(self.log)) from None

    def enter_continuous_time(self) -> None:
        f = self.fmu._functions
        self.nx = len(self.md.derivatives)
        self.check(f["fmi3EnterContinuousTimeMode"](self.c), "fmi3EnterContinuousTimeMode")
        self._setTime = self._checked(f["fmi3SetTime"], "fmi3SetTime")
        self._setX = self._checked(f["fmi3SetContinuousStates"], "fmi3SetContinuousStates")
        self._getX = self._checked(f["fmi3GetContinuousStates"], "fmi3GetContinuousStates")
        self._getDer = self._checked(f["fmi3GetContinuousStateDerivatives"], "fmi3GetContinuousStateDerivatives")
        self._getZ = self._checked(f["fmi3GetEventIndicators"], "fmi3GetEventIndicators")
        self._completed = f["fmi3CompletedIntegratorStep"]
        self.x_vrs = [d.variable.derivative.valueReference for d in self.md.derivatives]
        self.der_vrs = [d.variable.valueReference for d in self.md.derivatives]
        self.nominals = self.get_nominals()

    def get_nominals(self) -> np.ndarray:
        nom = (c_double * max(1, self.nx))()
        self.check(self.fmu._functions["fmi3GetNominalsOfContinuousStates"](self.c, nom, self.nx),
                   "fmi3GetNominalsOfContinuousStates")
        return np.array(nom[: self.nx], dtype=float)

    def update_discrete_states(self):
        need, term, nom, val, defined = (c_bool(False) for _ in range(5))
        nxt = c_double(0.0)
        st = self.fmu._functions["fmi3UpdateDiscreteStates"](self.c, byref(need), byref(term), byref(nom),
                                                              byref(val), byref(defined), byref(nxt))
        self.check(st, "fmi3UpdateDiscreteStates")
        if term.value:
            raise SimulationTerminated(self.name, "fmi3UpdateDiscreteStates", list(self.log), STATUS3)
        return bool(need.value), bool(val.value), bool(nom.value), float(nxt.value) if defined.value else None

    def enter_event_mode(self) -> None:
        self.check(self.fmu._functions["fmi3EnterEventMode"](self.c), "fmi3EnterEventMode")

    def reenter_continuous_time(self) -> None:
        self.check(self.fmu._functions["fmi3EnterContinuousTimeMode"](self.c), "fmi3EnterContinuousTimeMode")

    def completed_integrator_step(self) -> bool:
        enter, term = c_bool(False), c_bool(False)
        self.check(self._completed(self.c, False, byref(enter), byref(term)), "fmi3CompletedIntegratorStep")
        if term.value:
            raise SimulationTerminated(self.name, "fmi3CompletedIntegratorStep", list(self.log), STATUS3)
        return bool(enter.value)
