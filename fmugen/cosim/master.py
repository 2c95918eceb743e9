"""The co-simulation master: macro steps over FMUs coupled by their inputs and outputs.

Between communication points t_n and t_{n+1} = t_n + H every FMU advances on its own (its internal solver);
the master exchanges the coupled values only at communication points.  ``U`` (length m) is the vector of
all coupled inputs, ``Y`` the vector of the outputs they are taken from, ``U = F * Y[S]`` (factor F, source
index S).  One macro step (:meth:`Master.run`) is

1. **predict** the inputs over the step from past communication points (:mod:`.interpolants`);
2. **save** the FMUs' states when the step may be repeated (iterated schemes, adaptive steps);
3. **step** the FMUs by the coupling scheme (:mod:`.schemes`: Jacobi, Gauss-Seidel, fixed-point or Newton
   iteration of the implicit step; the FMUs of a sweep on threads: :mod:`.executor`);
4. **measure** the interface defect d = U_{n+1} - P(t_{n+1}), what the FMUs were told against what came;
5. **accept or reject** the step by the step-size controller (:mod:`.stepsize`, adaptive runs: a rejected
   step is rolled back, fmi2SetFMUstate, and retried smaller);
6. **record** and hand the defect to the divergence monitor (:mod:`.monitor`).

Failures end the run and return what was computed (:class:`~.results.FailureReport`): an FMU's fmi2Discard
or fmi2Error, a step that does not meet ``tol`` at ``min_step``, an iteration that does not converge, and
divergence of the coupling, detected from the interface defect before any value overflows.  When an FMU
fails while the coupling defect is growing, the report says that the coupling (inputs that jumped), not
stiffness, is the likely cause.
"""
from __future__ import annotations

import ctypes
import math
import time as _time
from typing import Optional, Sequence

import numpy as np

from .accuracy import ErrorEstimate, coupling_tolerance, internal_rtol
from .errors import CosimError
from .executor import SweepExecutor
from .physical_units import mismatch as unit_mismatch
from .loops import SingularLoop, algebraic_loops, chain_length, check_scheme, feedthrough_graph, solve_initial
from .interpolants import CUBIC_THETA, EXTRAPOLATIONS, ORDER, InputHistory  # noqa: F401 (public names)
from .monitor import DivergenceMonitor
from .results import CosimResult, FailureReport, Summary
from .schemes import SCHEMES, FixedPoint, GaussSeidel, Jacobi, Newton
from .settings import check_choices, resolve
from .stepsize import StepSizeController
from .system import CosimSystem
from .units import STATUS, SimulationTerminated, UnitFailure, dptr, vr_array
from .units3 import open_unit

__all__ = ["CosimResult", "FailureReport", "Master", "Summary", "run", "check_choices", "SCHEMES",
           "EXTRAPOLATIONS"]

STATUS_NAMES = dict(enumerate(STATUS))

DEFAULT_TOL = 1e-4  # the adaptive macro step's defect target when no tol is given

# what to do about a coupling above its stability limit
# (true for the scheme that ran: Newton is told no "use newton")
ADVICE = {"jacobi": "take a smaller step, extrapolation, or an iterative/newton scheme",
          "gauss-seidel": "take a smaller step, extrapolation, or an iterative/newton scheme",
          "iterative": "take a smaller step, or the newton scheme",
          "newton": "take a smaller step, or quadratic/cubic inputs (L-stable, damped)"}


def _positive(name, value):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CosimError(f"{name} must be a number, not {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise CosimError(f"{name} must be finite and positive, not {value!r}")
    return v


def _land(t, H, stop):
    """The step from t: H, or what lands on ``stop`` (a step within 1e-6 H of it is kept: bit-identical to a
    loop that steps H; one that would leave a sliver below 1e-3 H is stretched)."""
    if abs(stop - (t + H)) <= 1e-6 * H:
        return H
    if t + H > stop or stop - (t + H) < 1e-3 * H:
        return stop - t
    return H



def _event_count(unit) -> int:
    return int(unit.get_integer("solver.n_events"))


def _nominal(variable) -> float:
    """A variable's declared ``nominal`` (positive, finite), else 1.0 (FMI 2.0's default)."""
    try:
        v = abs(float(getattr(variable, "nominal", None)))
    except (TypeError, ValueError):
        return 1.0
    return v if math.isfinite(v) and v > 0 else 1.0

class _Recording:
    """The recorded columns at every accepted communication point (grown by doubling)."""

    def __init__(self, cap, Y, idx, slopes=None):
        self.T = np.empty(cap)
        self.V = np.empty((cap, len(idx)))
        self.n = 0
        self.Y, self.idx = Y, idx
        self.slopes = slopes  # dense output: fmugen.cosim.dense.SlopeRecorder, or None

    def append(self, t) -> None:
        if self.n == len(self.T):
            self.T = np.concatenate([self.T, np.empty(len(self.T))])
            self.V = np.concatenate([self.V, np.empty_like(self.V)])
        self.T[self.n] = t
        self.Y.take(self.idx, out=self.V[self.n])  # the method: np.take's wrapper costs as much
        self.n += 1
        if self.slopes is not None:
            self.slopes.append()


class Master:
    """Instantiates the system's FMUs once and runs it (see the module docstring).

    ``Master(system, scheme, extrapolation)``, then ``run(...)`` (once), then
    ``close()``; or use :func:`run`.  ``order`` (Gauss-Seidel) defaults to
    ``system.order``, else scene order.  ``workers``: threads for the FMUs of
    a sweep (Jacobi, iterated schemes; used when a sweep costs >= 0.5 ms).
    """

    def __init__(self, system: CosimSystem, scheme: str = "gauss-seidel", extrapolation: str = "hold",
                 order: Optional[Sequence[str]] = None, workers: int = 1):
        if not isinstance(system, CosimSystem):
            raise CosimError(f"expected a CosimSystem, got {type(system).__name__}")
        self.system = system
        self.scheme, self.extrapolation = check_choices(scheme, extrapolation)
        if not system.units:
            raise CosimError(f"{system.name}: no FMUs")
        names = [u.name for u in system.units]
        if len(set(names)) != len(names):
            raise CosimError(f"{system.name}: FMU names repeat: {names}")
        order = tuple(order) if order is not None else (tuple(system.order) if system.order else tuple(names))
        if sorted(order) != sorted(names):
            raise CosimError(f"{system.name}: Gauss-Seidel order {list(order)} must name every FMU once: {names}")
        self.order = order
        try:
            self.workers = int(workers)
        except (TypeError, ValueError):
            raise CosimError(f"workers must be a whole number >= 1, not {workers!r}") from None
        if self.workers < 1:
            raise CosimError(f"workers must be >= 1, not {workers!r}")
        self.executor = None  # steps the FMUs of a Jacobi sweep, on threads when that pays (per run)
        self.units = []
        try:
            for u in system.units:
                ft = str(u.fmi_type).lower()
                if ft in ("cs", "me"):  # an FMI 2.0 or FMI 3.0 unit, by the FMU's version
                    self.units.append(open_unit(u, system.start_time, system.stop_time))
                else:
                    raise CosimError(f"{system.name}: FMU {u.name!r}: fmi_type must be 'cs' or 'me', not {u.fmi_type!r}")
            self._resolve()
            check_scheme(self)  # algebraic loops the scheme would run as a delay are refused here
        except UnitFailure as e:
            self.close()
            raise CosimError(f"{system.name}: set-up of FMU {e.unit!r} failed: {e}") from None
        except BaseException:
            self.close()
            raise

    # -- set-up ---------------------------------------------------------------
    def _resolve(self) -> None:
        sysm = self.system
        index = {u.name: k for k, u in enumerate(self.units)}
        outs = [[] for _ in self.units]  # variable names read from each unit
        ins = [[] for _ in self.units]
        src_of, factor_of, label_of = {}, {}, {}
        for c in sysm.couplings:
            ends = (getattr(c, "source", None), getattr(c, "target", None))
            if not all(isinstance(e, (tuple, list)) and len(e) == 2 and all(isinstance(x, str) for x in e)
                       for e in ends):
                raise CosimError(f"{sysm.name}: coupling {ends[0]!r} -> {ends[1]!r}: source and target must each be "
                                 f"(FMU name, variable name)")
            (su, sv), (tu, tv) = ends
            for un in (su, tu):
                if un not in index:
                    raise CosimError(f"{sysm.name}: coupling {su}.{sv} -> {tu}.{tv}: no FMU named {un!r}")
            if su == tu:
                raise CosimError(f"{sysm.name}: coupling {su}.{sv} -> {tu}.{tv} connects an FMU to itself")
            src_var = self.units[index[su]].variable(sv, ("output", "local"))
            dst_var = self.units[index[tu]].variable(tv, ("input",))
            if (tu, tv) in src_of:
                raise CosimError(f"{sysm.name}: input {tu}.{tv} is driven twice")
            try:
                f = float(c.factor)
            except (TypeError, ValueError):
                raise CosimError(f"{sysm.name}: coupling {su}.{sv} -> {tu}.{tv}: factor {c.factor!r} is not a "
                                 f"number") from None
            if not math.isfinite(f):
                raise CosimError(f"{sysm.name}: coupling {su}.{sv} -> {tu}.{tv}: factor {c.factor} is not finite")
            why = unit_mismatch(self.units[index[su]].md, src_var, self.units[index[tu]].md, dst_var, f)
            if why:
                raise CosimError(f"{sysm.name}: coupling {su}.{sv} -> {tu}.{tv}: {why}")
            src_of[(tu, tv)] = (su, sv)
            factor_of[(tu, tv)] = f
            label_of[(tu, tv)] = f"{su}.{sv} -> {tu}.{tv}"
            if sv not in outs[index[su]]:
                outs[index[su]].append(sv)
            ins[index[tu]].append(tv)
        for r in sysm.recorded:
            if r.unit not in index:
                raise CosimError(f"{sysm.name}: recorded column {r.column!r}: no FMU named {r.unit!r}")
            self.units[index[r.unit]].variable(r.variable)
            if r.variable not in outs[index[r.unit]]:
                outs[index[r.unit]].append(r.variable)
        # Y: outputs of unit 0, unit 1, ...; U: inputs of unit 0, unit 1, ...
        y_off, u_off, y_at, u_labels = [], [], {}, []
        ny = nu = 0
        for k, unit in enumerate(self.units):
            y_off.append(ny)
            for v in outs[k]:
                y_at[(unit.name, v)] = ny
                ny += 1
            u_off.append(nu)
            nu += len(ins[k])
        S, F, owner_u, src_unit = [], [], [], []
        for k, unit in enumerate(self.units):
            for v in ins[k]:
                s = src_of[(unit.name, v)]
                S.append(y_at[s])
                F.append(factor_of[(unit.name, v)])
                u_labels.append(label_of[(unit.name, v)])
                owner_u.append(k)
                src_unit.append(index[s[0]])
        self.ny, self.nu = ny, nu
        self.S = np.array(S, dtype=np.intp)
        self.F = np.array(F, dtype=float)
        self._unit_factors = bool(np.all(self.F == 1.0))
        self._rows = np.arange(16)
        self.u_owner = np.array(owner_u, dtype=np.intp)
        self.u_src_unit = np.array(src_unit, dtype=np.intp)
        self.coupling_labels = tuple(u_labels)
        self.columns = tuple(r.column for r in sysm.recorded)
        self.rec_idx = np.array([y_at[(r.unit, r.variable)] for r in sysm.recorded], dtype=np.intp)
        # FMUs that report their events (fmugen's hybrid FMUs count them in solver.n_events): a step in
        # which one had an event may have made its outputs jump (fmugen/cosim/README.md "Events"); ME units
        # too, whose events the ME block handles (the FMU counts them in its event update)
        self.event_units = [u for u in self.units if "solver.n_events" in u.variables]
        # the recorded signals' declared nominal values (else FMI's default, 1): the error estimate's floor
        # for a signal that stays near zero (a joint at rest), where its largest value is round-off
        self.rec_nominal = np.array([_nominal(self.units[index[r.unit]].variables.get(r.variable))
                                     for r in sysm.recorded], dtype=float)
        # buffers (ctypes pointers into them are taken once)
        self.Y = np.zeros(max(ny, 1))  # outputs at t_{n+1} (being computed)
        self._Yv, self._Yzero = self.Y[:ny], np.zeros(ny)  # the outputs read, for the finiteness check
        self.Uset = np.zeros(max(nu, 1))  # input values passed at t_n
        self.DUset = np.zeros(max(nu, 1))  # input slopes passed at t_n
        self.DDUset = np.zeros(max(nu, 1))  # input second derivatives passed at t_n (quadratic inputs)
        self.DDDUset = np.zeros(max(nu, 1))  # input third derivatives passed at t_n (cubic Hermite inputs)
        self.DY = np.zeros(max(ny, 1))  # time derivatives of the coupling sources at t_n (Hermite inputs)
        self.dU0 = np.zeros(max(nu, 1))  # ... as coupled inputs
        self.Uend = np.zeros(max(nu, 1))  # inputs at t_{n+1} of a held feedthrough FMU, set before its outputs are read
        self.unit_io = []
        for k, unit in enumerate(self.units):
            out_vrs = [unit.variables[v].valueReference for v in outs[k]]
            in_vrs = [unit.variables[v].valueReference for v in ins[k]]
            unit.n_in, unit.n_out = len(in_vrs), len(out_vrs)
            unit.in_vr, unit.out_vr = vr_array(in_vrs), vr_array(out_vrs)
            unit.in_sl = slice(u_off[k], u_off[k] + len(in_vrs))
            unit.out_sl = slice(y_off[k], y_off[k] + len(out_vrs))
            unit.u_ptr = dptr(self.Uset, u_off[k])
            unit.du_ptr = dptr(self.DUset, u_off[k])
            unit.ddu_ptr = dptr(self.DDUset, u_off[k])
            unit.dddu_ptr = dptr(self.DDDUset, u_off[k])
            unit.y_ptr = dptr(self.Y, y_off[k])
            unit.dy_ptr = dptr(self.DY, y_off[k])
            # the coupling sources come first in outs[k]: their derivatives are read with one call
            unit.n_src = len({S[j] for j in range(nu) if src_unit[j] == k})
            unit.out_order1 = (ctypes.c_int * max(1, unit.n_src))(*([1] * unit.n_src))
            unit.in_order = (ctypes.c_int * max(1, len(in_vrs)))(*([1] * len(in_vrs)))
            unit.in_order2 = (ctypes.c_int * max(1, len(in_vrs)))(*([2] * len(in_vrs)))
            unit.in_order3 = (ctypes.c_int * max(1, len(in_vrs)))(*([3] * len(in_vrs)))
            unit.in_names, unit.out_names = list(ins[k]), list(outs[k])
            unit.uend_ptr = dptr(self.Uend, u_off[k])
            unit.feedthrough = bool(in_vrs) and _feedthrough(unit, outs[k])
        # which U entries belong to FMUs that cannot take input derivatives
        self.no_interp = np.array([not getattr(self.units[k], "can_interpolate", False) for k in owner_u], dtype=bool)
        # Gauss-Seidel: for the FMU at position i of the order, its inputs whose source steps earlier
        pos = {name: i for i, name in enumerate(self.order)}
        self.gs_new = []
        for k, unit in enumerate(self.units):
            idx = [j for j in range(unit.in_sl.start, unit.in_sl.stop)
                   if pos[self.units[src_unit[j]].name] < pos[unit.name]]
            self.gs_new.append(np.array(idx, dtype=np.intp))
        self.gs_units = [self.units[index[n]] for n in self.order]
        self.gs_k = [index[n] for n in self.order]
        self._first_me = next((u for u in self.gs_units if u.kind == "me"), None)
        if any(u.kind == "me" for u in self.units):
            from .me_block import MEBlock

            self.me_block = MEBlock(self, [u for u in self.units if u.kind == "me"])
        else:
            self.me_block = None
        # scales of the coupled signals: the declared nominal of the source (times the factor), else 1
        nominal = np.ones(nu)
        for j, (k, yi) in enumerate(zip(src_unit, S)):
            nom = getattr(self.units[k].variables[outs[k][yi - y_off[k]]], "nominal", None)
            try:
                if nom not in (None, ""):
                    nominal[j] = abs(float(nom) * F[j]) or 1.0
            except (TypeError, ValueError):
                pass
        self.u_nominal = np.array(nominal, dtype=float)
        # couplings around which every output depends on the input before it (loops.py): solved, or refused
        self.loops = algebraic_loops(self)
        # t0: fmi2SetReal/fmi2GetReal passes enough for the longest feedthrough chain (two as before for
        # chains of one; with loops, Newton at t0 meets every chain as well)
        self.init_passes = 2 if self.loops else max(2, chain_length(feedthrough_graph(self)) + 1)

    def close(self) -> None:
        for u in getattr(self, "units", []):
            u.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- exchanges with the FMUs ------------------------------------------------
    def _read_all(self) -> int:
        calls = 0
        for u in self.units:
            if u.n_out:
                st = u._getReal(u.c, u.out_vr, u.n_out, u.y_ptr)
                calls += 1
                if st > 1:
                    raise UnitFailure(u.name, "fmi2GetReal", st, u.messages())
        return calls

    def _check_hermite(self) -> None:
        """Hermite inputs need the sources' output derivatives and FMUs that take input derivatives."""
        what = f"{self.scheme}/{self.extrapolation}"
        for k, u in enumerate(self.units):
            if u.kind == "me":
                raise CosimError(f"{what}: Model-Exchange FMU {u.name!r} is integrated by the master, which passes "
                                 f"no input derivatives; use {self.scheme}/linear")
            if u.n_src and getattr(u, "max_output_derivative_order", 0) < 1:
                raise CosimError(f"{what}: FMU {u.name!r} declares maxOutputDerivativeOrder = 0; the Hermite "
                                 f"inputs need the slopes of its outputs (fmi2GetRealOutputDerivatives; a fmugen "
                                 f"FMU has them with its Jacobian: jacobian = true in the scene); use "
                                 f"{self.scheme}/linear")
            if u.n_in and not u.can_interpolate:
                raise CosimError(f"{what}: FMU {u.name!r} cannot interpolate inputs ({u.no_interpolation}); "
                                 f"use {self.scheme}/linear")

    def _check_step_sizes(self, t0: float, stop: float, H: float, adaptive: bool) -> None:
        """An FMU that declares canHandleVariableCommunicationStepSize = false (FMI 2.0's default) takes only
        one macro step: adaptive steps (and their landing on events) are refused, and so is a fixed step
        that does not divide the run's span (its last step would be shorter, see _land)."""
        for u in self.units:
            if getattr(u, "variable_step", True):
                continue
            head = (f"{self.system.name}: FMU {u.name!r} ({u.unit.path}) declares "
                    f"canHandleVariableCommunicationStepSize=\"false\" (FMI 2.0's default when it is absent)")
            if adaptive:
                raise CosimError(f"{head}, but adaptive macro steps change the step; run at a fixed step")
            n = (stop - t0) / H
            if round(n) < 1 or abs(n - round(n)) > 1e-6:
                raise CosimError(f"{head}, but {stop - t0:.9g} s is not a whole number of macro steps of {H:.9g} s "
                                 f"(the last one would differ); take a step that divides the run's span")

    def _check_states(self, adaptive: bool) -> None:
        """Iterated schemes and adaptive steps repeat a macro step from saved FMU states: refuse, before
        anything runs, an FMU that declares it cannot save them (canGetAndSetFMUstate = false)."""
        for u in self.units:
            if not getattr(u, "can_save_state", True):
                what = (f"{self.scheme} iteration" if self.scheme in ("iterative", "newton") else
                        "adaptive macro steps")
                raise CosimError(f"{self.system.name}: FMU {u.name!r} ({u.unit.path}) declares "
                                 f"canGetAndSetFMUstate=\"false\", but {what} repeat macro steps from saved FMU "
                                 f"states; run it with jacobi or gauss-seidel at a fixed step")

    def _gather(self, Unew, G, units=None) -> int:
        """The coupled values into Unew and G[:nu]; with Hermite inputs also their slopes into G[nu:], read by
        fmi2GetRealOutputDerivatives from the sources (``units``: only those).  Returns the number of calls."""
        nu, calls = self.nu, 0
        self._coupled(Unew)
        G[:nu] = Unew[:nu]
        if self.hermite:
            for u in (self.units if units is None else units):
                if u.n_src:
                    st = u._getOutDer(u.c, u.out_vr, u.n_src, u.out_order1, u.dy_ptr)
                    calls += 1
                    if st > 1:
                        raise UnitFailure(u.name, u.OUTPUT_DERIVATIVES, st, u.messages(), u.STATUS)
            D = G[nu:]
            self.DY.take(self.S, out=D)
            if not self._unit_factors:
                D *= self.F
        return calls

    def _check_clocks(self, t0: float, H: float, adaptive: bool) -> None:
        """Every sample instant of a sampled FMU must be a communication point: then a sampler reads its
        inputs where they are exact, not extrapolated inside a step.  The macro step must divide the
        period and the offset (from the start); an adaptive run cannot keep to that and is refused."""
        for u in self.units:
            for period, offset in getattr(u, "clocks", ()):
                what = f"FMU {u.name!r} samples every {period:g} s (offset {offset:g} s)"
                if adaptive:
                    raise CosimError(f"{what}: an adaptive macro step cannot land on its sample instants; run "
                                     f"with a fixed step that divides {period:g} s")
                k, j = period / H, (offset - t0) / H
                if k < 1 - 1e-9 or abs(k - round(k)) > 1e-9 * k or abs(j - round(j)) > 1e-9 * max(1.0, abs(j)):
                    raise CosimError(f"{what}: a macro step of {H:g} s does not land on its sample instants; take "
                                     f"a step that divides the period ({period:g} s, {period / 2:g} s, "
                                     f"{period / 5:g} s, ...) and the offset")

    def _event_time_in_step(self, t: float, H: float):
        """The earliest time of an event an FMU reported in the step just taken from t (not yet accepted),
        or None: read from solver.last_event_time of the FMUs whose solver.n_events rose."""
        before = getattr(self, "_n_events", None) or [0] * len(self.event_units)
        times = []
        for u, b in zip(self.event_units, before):
            if _event_count(u) > b and "solver.last_event_time" in u.variables:
                te = float(u.get_reals([u.variables["solver.last_event_time"].valueReference])[0])
                if t < te <= t + H:
                    times.append(te)
        return min(times) if times else None

    def _events_in_step(self, summ) -> bool:
        """Did an FMU report an event in the macro step just accepted?  (solver.n_events rose; an FMU state
        restored by a rollback or a shadow window restores the count too.)"""
        counts = [_event_count(u) for u in self.event_units]
        summ.fmu_calls += len(counts)
        before = getattr(self, "_n_events", None) or [0] * len(counts)
        self._n_events = counts
        new = sum(max(0, a - b) for a, b in zip(counts, before))
        if new:
            summ.events += new
            summ.discontinuities += 1
        return new > 0

    def _coupled(self, out: np.ndarray) -> np.ndarray:
        nu = self.nu
        if nu:
            self.Y.take(self.S, out=out[:nu])
            if not self._unit_factors:
                out[:nu] *= self.F
        return out

    # -- the run ----------------------------------------------------------------
    def run(self, step: Optional[float] = None, stop: Optional[float] = None, adaptive: bool = False,
            tol: Optional[float] = None, min_step: Optional[float] = None, max_step: Optional[float] = None,
            coupling_tol: Optional[float] = None, max_iterations: int = 30, detect_divergence: bool = True,
            dense: bool = False, estimate: bool = True) -> CosimResult:
        sysm = self.system
        t0 = float(sysm.start_time)
        stop = float(sysm.stop_time if stop is None else stop)
        H0 = _positive("step", sysm.step if step is None else step)
        if not (math.isfinite(stop) and stop > t0):
            raise CosimError(f"stop time {stop} must be finite and after the start time {t0}")
        user_tol = None if tol is None else _positive("tol", tol)  # the accuracy the user asked for
        tol = DEFAULT_TOL if tol is None else user_tol  # the adaptive step's target
        if coupling_tol is None:  # what the FMUs' own accuracy allows (accuracy.py)
            coupling_tol, tol_source = coupling_tolerance(self.units)
        else:
            coupling_tol, tol_source = _positive("coupling_tol", coupling_tol), "given"
        Hmin = _positive("min_step", min_step) if min_step is not None else (H0 * 1e-3 if adaptive else H0)
        Hmax = _positive("max_step", max_step) if max_step is not None else (max(H0, (stop - t0) / 10) if adaptive else H0)
        if Hmin > Hmax:
            raise CosimError(f"min_step {Hmin} exceeds max_step {Hmax}")
        _check_resolution(t0, stop, min(Hmin, H0, Hmax), "min_step" if adaptive and min_step is not None else "step",
                          count=not adaptive)  # an adaptive run's step count is its controller's
        self._check_clocks(t0, H0, adaptive)
        self._check_step_sizes(t0, stop, min(H0, Hmax), adaptive)
        scheme = self._prepare(adaptive, coupling_tol, int(max_iterations))
        implicit = scheme.implicit
        summ = Summary(sysm.name, self.scheme, self.extrapolation, bool(adaptive))
        if implicit:
            summ.coupling_tol, summ.coupling_tol_source = coupling_tol, tol_source
        if getattr(sysm, "rest_unstable", ()):
            summ.physics = sysm.rest_unstable[0].split(": the system")[0]
        nu, ext = self.nu, ORDER[self.extrapolation]
        # the defect (what the predictor said against what came out) is O(H^p): the predictor is the
        # extrapolant through 1, 2 or 3 past points, also for the iterated schemes
        control = StepSizeController(min(ext, 2) + 1, Hmin, Hmax) if adaptive else None
        history = self.history = InputHistory(nu, ext, t0, self.DUset, self.DDUset, self.hold_only)
        self.U_n = history.U[0]  # the coupled values at t_n (full buffer)
        Unew, d, scale = np.zeros(max(nu, 1)), np.zeros(max(nu, 1)), np.zeros(max(nu, 1))
        Unew_v, d_v, Uset_v = Unew[:nu], d[:nu], self.Uset[:nu]
        cap = int(min(max((stop - t0) / Hmin, 16), 1_000_000)) + 2 if not adaptive else 1024
        slopes = None
        if dense:  # the recorded columns' slopes too, for dense output (fmugen.cosim.dense)
            from .dense import SlopeRecorder

            slopes = SlopeRecorder(self.units, sysm.recorded)
            linear = sorted({r.unit for r in sysm.recorded} - {p[0].name for p in slopes.parts})
            if linear:
                summ.warnings.append(f"dense output: FMU {', '.join(map(repr, linear))} gives no output derivatives "
                                     f"(maxOutputDerivativeOrder = 0): its columns are linear between "
                                     f"communication points")
        rec = _Recording(cap, self.Y, self.rec_idx, slopes)
        wall0 = _time.perf_counter()
        if adaptive or implicit:  # both repeat macro steps from saved FMU states
            self._check_states(adaptive)
        no_prior = 0 if (adaptive or implicit) else 1  # fmi2DoStep's noSetFMUStatePriorToCurrentPoint
        if self.scheme != "gauss-seidel":
            self.executor = SweepExecutor(self.units, self._do, self.workers)
        states, monitor, failure, calls, scale0 = [], None, None, 0, None
        est = shadow = None  # the a-posteriori error estimate by step doubling on a sample of steps (accuracy.py)
        # the estimate reruns windows from saved FMU states with H/2: an FMU that can do neither gets none, said
        lacking = [u for u in self.units if not (getattr(u, "can_save_state", True) and
                                                 getattr(u, "variable_step", True))]
        if estimate and len(self.rec_idx) and lacking:
            u = lacking[0]
            flag = ("canGetAndSetFMUstate" if not getattr(u, "can_save_state", True)
                    else "canHandleVariableCommunicationStepSize")
            summ.warnings.append(f"no coupling error estimate: FMU {u.name!r} declares {flag}=\"false\", and the "
                                 f"estimate reruns windows of macro steps from saved FMU states with H/2")
        summ.warnings.extend(self.me_block.warnings() if self.me_block is not None else ())
        # FMI 3.0 has no input derivatives: an FMU that takes its inputs in the intermediate update gets the
        # extrapolant there (units3.Slave3Unit, can_interpolate); what one without does instead, said once
        held = [u.name for u in self.units if u.kind == "cs" and u.n_in and getattr(u, "VERSION", "2.0") != "2.0"
                and not u.can_interpolate]
        if held and not self.hold_only:
            summ.warnings.append(f"FMU {', '.join(map(repr, held))}: FMI 3.0 has no input derivatives (no "
                                 f"canInterpolateInputs): its inputs are held at the midpoint of the "
                                 f"{'line U_n -> V' if implicit else 'extrapolant'} over each macro step, as an FMI "
                                 f"2.0 FMU's with canInterpolateInputs = false")
        if estimate and len(self.rec_idx) and not lacking:
            rtols = [r for r in map(internal_rtol, self.units) if r is not None]
            est = ErrorEstimate(self.scheme, self.extrapolation, int((stop - t0) / H0), self.columns,
                                max(rtols) if rtols else 0.0, self.rec_nominal)
            shadow = self._prepare(adaptive, coupling_tol, int(max_iterations)) if implicit else scheme
        t = t0
        H = min(H0, Hmax)
        try:
            calls += self._initialize(history.U[0], coupling_tol)
            self._n_events = [_event_count(u) for u in self.event_units]
            self._relanded = None  # the event an adaptive step was last shortened to land on
            G = np.zeros(2 * nu if self.hermite else nu)  # the iteration's image: values (and slopes) at t_{n+1}
            if self.hermite:
                calls += self._gather(Unew, G)
                self.dU0[:nu] = G[nu:]
            np.abs(history.U[0], out=scale)
            np.maximum(scale[:nu], self.u_nominal, out=scale[:nu])
            scale[nu:] = 1.0
            scale0 = scale.copy()
            rec.append(t)
            if not self._finite():
                failure = self._non_finite(t)
                raise _Stop
            if adaptive or implicit:
                states = [u.new_state() for u in self.units]
                calls += len(self.units)
            if self.me_block is not None:
                self.me_block.start(t0)
            if detect_divergence and nu and not adaptive:  # adaptive: the step control bounds the defect
                monitor = DivergenceMonitor(self.coupling_labels, scale0[:nu], history.U[0, :nu], ADVICE[self.scheme],
                                            getattr(sysm, "rest_unstable", ()))
            t_last = stop - 1e-12 * max(1.0, abs(stop))  # loop guard, computed once
            while t < t_last:
                H = _land(t, H, stop)
                if est is not None and summ.macro_steps >= est.next_at:  # 0. a shadow window, for the estimate
                    if est.due(t, H, stop):
                        calls += self._shadow(t, H, shadow, est, scale, G, summ)
                    else:
                        est.skipped(summ.macro_steps)
                # 1. predict: the inputs at t_n and the extrapolant's derivatives into the FMUs' buffers
                Uset_v[:] = history.U0
                P = history.predict(H)
                # 2. save
                if states:
                    calls += self._save_all(states)
                # 3. step
                try:
                    if implicit:
                        c, it, err_c, R = scheme.step(t, H, self._guess(P, H), states, scale, G, Unew, summ)
                        calls += c
                        summ.iterations += it
                        if not err_c <= 1.0:
                            if adaptive and not control.at_minimum(H):
                                calls += self._restore_all(states)
                                summ.rollbacks += 1
                                H = control.retry(H)
                                if est is not None:
                                    est.discard()
                                continue
                            failure = FailureReport(t, "not-converged",
                                                    f"{self.scheme} coupling iteration did not converge in "
                                                    f"{max_iterations} iterations at H = {H:.4g} s "
                                                    f"(residual {err_c:.3g} x coupling_tol)",
                                                    coupling=self._worst(R))
                            break
                    else:
                        calls += scheme.step(t, H, ext, no_prior)
                        self._coupled(Unew)
                except SingularLoop as e:  # Newton's interface Jacobian: the loop's values are not determined
                    failure = FailureReport(t, "singular", str(e), coupling=e.loop)
                    break
                except UnitFailure as e:
                    # an FMU refused the step (fmi2Discard): with rollback, retry smaller -- the FMU may
                    # only have been given inputs that jumped
                    if not (adaptive and e.status == 2 and not control.at_minimum(H)):
                        raise
                    calls += self._restore_all(states)
                    summ.rollbacks += 1
                    H = control.retry(H)
                    if est is not None:
                        est.discard()
                    continue
                if not self._finite():  # an FMU's NaN or infinity: the run stops there, naming it
                    failure = self._non_finite(t)
                    break
                # 4. measure: the interface defect
                np.subtract(Unew_v, P, out=d_v)
                if adaptive or implicit:
                    if not np.all(np.isfinite(Unew_v)):
                        j = int(np.argmax(~np.isfinite(Unew_v)))
                        failure = FailureReport(t, "non-finite", "a coupled value is not finite",
                                                coupling=self.coupling_labels[j])
                        break
                    np.maximum(scale[:nu], np.abs(Unew_v), out=scale[:nu])
                # 5. accept or reject
                if adaptive:
                    ratio = np.abs(d[:nu]) / (tol * scale[:nu])
                    err = float(ratio.max()) if nu else 0.0
                    if err > 1.0:
                        if control.at_minimum(H):
                            failure = FailureReport(t, "tolerance",
                                                    f"interface defect {err:.3g} x tol at the minimum macro step "
                                                    f"{Hmin:.4g} s", coupling=self.coupling_labels[int(np.argmax(ratio))])
                            break
                        calls += self._restore_all(states)
                        summ.rollbacks += 1
                        H = control.reject(H, err)
                        if est is not None:
                            est.discard()
                        continue
                # an adaptive run lands on an event an FMU reported inside the step: back to t_n and a step
                # that ends just past it, so the jump falls on a communication point (once per event)
                if adaptive and states and self.event_units:
                    te = self._event_time_in_step(t, H)
                    if te is not None and te != self._relanded and t + max(Hmin, 1e-6 * H) < te < t + (1 - 1e-6) * H:
                        calls += self._restore_all(states)
                        summ.rollbacks += 1
                        self._relanded = te
                        H = (te - t) * (1 + 1e-9)
                        if est is not None:
                            est.discard()
                        continue
                t = t + H if stop - (t + H) > 1e-6 * H else stop
                summ.macro_steps += 1
                if H < summ.step_min:
                    summ.step_min = H
                if H > summ.step_max:
                    summ.step_max = H
                history.push(t, Unew_v)
                jump = self._events_in_step(summ) if self.event_units else False
                if jump:
                    history.restart()
                    if implicit and hasattr(scheme, "M"):
                        scheme.M = None  # the interface Jacobian of the old mode
                if self.hermite:
                    self.dU0[:nu] = G[nu:]  # the slopes at t_{n+1}: the next step's predictor
                # 6. record, watch
                rec.append(t)
                if est is not None and est.pending is not None:
                    # a window across an event is kept: the H/2 shadow places the event's effects more
                    # exactly, and their difference is the coupling's error in timing it
                    est.accepted(H, rec.V[rec.n - 1], summ.macro_steps)
                if monitor is not None:
                    # the defect of a step with an event is the jump, not a coupling error: the values are
                    # still watched (a divergence grows them), its defect is not
                    failure = monitor.observe(t, H, np.zeros_like(d_v) if jump else d_v, Unew_v)
                    if failure is not None:
                        break
                    if est is not None and monitor.count == 0:  # a block ended: a window if the defect rose
                        est.active(monitor.level, summ.macro_steps)
                H = control.accept(H, err) if adaptive else min(H0, Hmax)
        except SimulationTerminated as e:  # an FMU ended the simulation: the run stops there and says so
            failure = FailureReport(t, "terminated", str(e), unit=e.unit, fmu_messages=e.messages)
        except UnitFailure as e:
            failure = self._diagnose(e, t, H, d, scale0, monitor)
        except _Stop:
            pass
        finally:
            summ.threads = self.executor.threads if self.executor is not None else 1
            if self.executor is not None:
                self.executor.shutdown()
            for k, s in enumerate(states + (getattr(self, "_shadow_states", None) or [])
                                  + (getattr(self, "_shadow_work", None) or [])):
                try:
                    self.units[k % len(self.units)].free_state(s)
                except Exception:
                    pass
            self._shadow_states = self._shadow_work = None
        summ.wall_time = _time.perf_counter() - wall0
        # an FMI 3.0 FMU that declares inputs settable in the intermediate update but never asked for them held
        # its inputs at U_n over each step (not even the midpoint): the master could not know beforehand
        silent = [u.name for u in self.units if getattr(u, "intermediate_inputs", None) and u.n_in
                  and not u.intermediate_requests]
        if silent and summ.macro_steps and not self.hold_only:
            summ.warnings.append(f"FMU {', '.join(map(repr, silent))}: declares inputs with "
                                 f"intermediateUpdate=\"true\" but never requested them in the intermediate update "
                                 f"(intermediateVariableSetRequested): its inputs were held at their values at t_n "
                                 f"over each macro step, not interpolated")
        summ.simulated_time = t - t0
        summ.fmu_calls = calls + sum(getattr(u, "n_calls", 0) for u in self.units)
        summ.do_steps = self._do_steps + sum(getattr(u, "do_steps", 0) for u in self.units)
        if est is not None:
            summ.error_estimates, summ.error_estimate, summ.error_trend, summ.error_growth, verdict = \
                est.finish(rec.V[: rec.n], user_tol, summ.macro_steps)
            summ.estimate_samples = len(est.local)
            if verdict is not None and failure is None:
                summ.status = "unreliable"
                summ.reliability = verdict
        if failure is not None:
            summ.status = "failed"
            summ.failure = failure
        if summ.macro_steps == 0:
            summ.step_min = summ.step_max = 0.0
        return CosimResult(rec.T[: rec.n].copy(), rec.V[: rec.n].copy(), self.columns, summ,
                           slopes.slopes() if slopes is not None else None)

    # -- the pieces of a run ------------------------------------------------------
    def _prepare(self, adaptive, coupling_tol, max_iterations):
        """The scheme object and the input derivatives the FMUs will be sent."""
        ext = ORDER[self.extrapolation]
        implicit = self.scheme in ("iterative", "newton")
        # zero-order hold of a non-iterated scheme: the prediction is U_n, no input derivatives are sent
        self.hold_only = ext == 0 and not implicit
        self._send_du = not self.hold_only
        self._send_ddu = ext == 2  # quadratic: the parabola itself goes to the FMUs (order 2)
        self.DDUset[:] = 0.0
        # iterated schemes with quadratic or cubic inputs: Hermite interpolants over the step, whose unknowns
        # are the coupled values and the sources' slopes at t_{n+1} (one-step: no history)
        self.hermite = implicit and ext >= 2
        if self.hermite:
            self._check_hermite()
            self._send_ddu = True
        self._cubic = implicit and ext == 3
        self.input_kind = 3 if self._cubic else (2 if self.hermite else 1)
        self.any_no_interp = bool(self.no_interp.any())
        # an FMU that holds its inputs at the step's midpoint value and whose outputs depend on its inputs: its
        # outputs at t_{n+1} are read with the inputs at t_{n+1} (see _do)
        for u in self.units:
            u.end_inputs = (not self.hold_only and getattr(u, "feedthrough", False)
                            and not getattr(u, "can_interpolate", True))
        if self.scheme == "jacobi":
            return Jacobi(self)
        if self.scheme == "gauss-seidel":
            return GaussSeidel(self)
        return (Newton if self.scheme == "newton" else FixedPoint)(self, coupling_tol, max_iterations)

    def _initialize(self, U0, coupling_tol) -> int:
        """Consistent coupled values at t0 into U0: passes of fmi2SetReal/fmi2GetReal, one more than the
        longest feedthrough chain has couplings (at least two), then, when the system has algebraic loops,
        Newton on U = G(U) at t0 (loops.py; a singular loop is refused there).  Returns the FMU calls."""
        calls = 0
        for _ in range(self.init_passes):
            calls += self._read_all()
            self._coupled(self.Uset)
            for u in self.units:
                if u.n_in:
                    st = u._setReal(u.c, u.in_vr, u.n_in, u.u_ptr)
                    calls += 1
                    if st > 1:
                        raise UnitFailure(u.name, "fmi2SetReal", st, u.messages())
        calls += self._read_all()
        self._coupled(U0)
        if self.loops:
            calls += solve_initial(self, U0, coupling_tol)
        return calls

    def _guess(self, P, H):
        """The iterated schemes' first guess of the unknowns at t_{n+1}: the predictor's value (and, Hermite,
        the history parabola's slope there, or the last slope)."""
        nu = self.nu
        if self.hermite:
            return np.concatenate([P, self.DUset[:nu] + H * self.DDUset[:nu] if self.history.n >= 3
                                   else self.dU0[:nu]])
        self.DDUset[:nu] = 0.0
        return P.copy()

    def _worst(self, R):
        return self.coupling_labels[int(np.argmax(np.abs(R[: self.nu])))] if self.nu else None

    def _diagnose(self, e, t, H, d, scale0, monitor) -> FailureReport:
        """An FMU failed: if the coupling defect was growing, the coupling is the cause."""
        if monitor is None or not monitor.growing():
            return FailureReport(t, "fmu-failure", str(e), unit=e.unit, fmu_messages=e.messages)
        j = int(np.argmax(np.abs(d[: self.nu]) / np.maximum(scale0[: self.nu], 1e-300)))
        if monitor.physics:
            msg = (f"the system diverges: the interface values grew over the last macro steps until FMU {e.unit!r} "
                   f"failed ({e.call} returned {e.status_name}); "
                   f"{monitor._stability_limit(H)}")
        else:
            msg = (f"the coupling diverges: the interface defect grew over the last macro steps until FMU "
                   f"{e.unit!r} failed ({e.call} returned {e.status_name}). The inputs "
                   f"this FMU was given jumped, so the coupling (H = {H:.4g} s is above this scheme's stability "
                   f"limit: {monitor.advice}) is the cause, not stiffness of the FMU, whatever its message suggests")
        return FailureReport(t, "diverged", msg, unit=e.unit, coupling=self.coupling_labels[j],
                             fmu_messages=e.messages)

    def _shadow(self, t, H, shadow, est, scale, G, summ) -> int:
        """2 x ``est.window`` steps of H/2 from t by the run's scheme (a shadow run with its own input history),
        its recorded outputs at the window's end handed to the estimate; then the FMUs and the master's buffers
        back as they were (the run goes on bit for bit).  Returns the FMU calls."""
        calls = 0
        if getattr(self, "_shadow_states", None) is None:
            self._shadow_states = [u.new_state() for u in self.units]
            self._shadow_work = [u.new_state() for u in self.units]
            calls += 2 * len(self.units)
        saved, work = self._shadow_states, self._shadow_work
        calls += self._save_all(saved)
        bufs = (self.Uset, self.DUset, self.DDUset, self.DDDUset, self.Y, self.DY, self.dU0)
        copies = [b.copy() for b in bufs]
        history = self.history
        mine = history.copy()  # the shadow's own past points (it writes into the FMUs' slope buffers as well)
        self.history, self.U_n = mine, mine.U[0]
        nu, H2, ok, ts = self.nu, 0.5 * H, True, t
        Us, Gs = np.zeros(max(nu, 1)), np.zeros_like(G)
        try:
            Ymid = None
            for i in range(2 * est.window):
                if i == 2 * (est.window // 2):  # the shadow halfway through the window, for the estimate
                    Ymid = self.Y[self.rec_idx].copy()
                self.Uset[:nu] = mine.U0
                P = mine.predict(H2)
                if shadow.implicit:
                    calls += self._save_all(work)
                    c, it, err, R = shadow.step(ts, H2, self._guess(P, H2), work, scale.copy(), Gs, Us, summ)
                    if not err <= 1.0:
                        ok = False
                        break
                else:
                    c = shadow.step(ts, H2, ORDER[self.extrapolation], 0)
                    self._coupled(Us)
                calls += c
                ts = ts + H2
                mine.push(ts, Us[:nu])
                if self.hermite:
                    self.dU0[:nu] = Gs[nu:]
            Ys = self.Y[self.rec_idx].copy()
            ok = ok and bool(np.all(np.isfinite(Ys)))
        except (UnitFailure, SingularLoop):  # a shadow that fails says nothing about the run's steps
            ok = False
        self.history, self.U_n = history, history.U[0]
        calls += self._restore_all(saved)
        for b, c in zip(bufs, copies):
            b[:] = c
        if ok:
            est.started(t, H, (Ymid, Ys), summ.macro_steps)
        else:
            est.skipped(summ.macro_steps)
        return calls

    def _finite(self) -> bool:
        """Every output read is finite: NaN and infinity times 0 are NaN, any finite value times 0 is 0 (a dot
        product with zeros costs a third of np.isfinite(...).all())."""
        return math.isfinite(self._Yv.dot(self._Yzero))

    def _non_finite(self, t) -> FailureReport:
        """The first output an FMU returned as NaN or infinite (read after the step from ``t``)."""
        i = int(np.argmax(~np.isfinite(self.Y[: self.ny])))
        k = next(k for k, u in enumerate(self.units) if u.out_sl.start <= i < u.out_sl.stop)
        u = self.units[k]
        name = u.out_names[i - u.out_sl.start]
        return FailureReport(t, "non-finite", f"FMU {u.name!r} returned {self.Y[i]} for output {name!r}",
                             unit=u.name, coupling=next((self.coupling_labels[j] for j in range(self.nu)
                                                         if self.S[j] == i), None), fmu_messages=u.messages())

    def _save_all(self, states) -> int:
        for k, u in enumerate(self.units):
            st = u.save(states[k])
            if st > 1:
                raise UnitFailure(u.name, "fmi2GetFMUstate", st, u.messages())
        return len(self.units)

    _do_steps = 0  # fmi2DoStep calls of the ME block (counted by it)

    def _do(self, u, t, H, no_prior) -> int:
        """Set u's inputs (values, slopes), fmi2DoStep, read its outputs.  Returns the number of calls."""
        calls = 0
        if u.n_in:
            st = u._setReal(u.c, u.in_vr, u.n_in, u.u_ptr)
            if st > 1:
                raise UnitFailure(u.name, "fmi2SetReal", st, u.messages())
            calls += 1
            if u.can_interpolate and self._send_du:
                st = u._setInDer(u.c, u.in_vr, u.n_in, u.in_order, u.du_ptr)
                if st > 1:
                    raise UnitFailure(u.name, "fmi2SetRealInputDerivatives", st, u.messages())
                calls += 1
                if self._send_ddu:
                    st = u._setInDer(u.c, u.in_vr, u.n_in, u.in_order2, u.ddu_ptr)
                    if st > 1:
                        raise UnitFailure(u.name, "fmi2SetRealInputDerivatives", st, u.messages())
                    calls += 1
                    if self._cubic:
                        st = u._setInDer(u.c, u.in_vr, u.n_in, u.in_order3, u.dddu_ptr)
                        if st > 1:
                            raise UnitFailure(u.name, "fmi2SetRealInputDerivatives", st, u.messages())
                        calls += 1
        st = u._doStep(u.c, t, H, no_prior)
        u.do_steps += 1
        if st > 1:
            raise UnitFailure(u.name, f"fmi2DoStep(t = {t:.9g}, H = {H:.4g})", st, u.messages())
        if u.end_inputs:
            # the FMU stepped with its inputs held at the midpoint value; its outputs at t_{n+1} depend on its
            # inputs, so they are read with the inputs' value at t_{n+1} (the midpoint would put an O(H) error,
            # a lag of H/2, into every output read: first order, unstable on stiff feedthrough couplings)
            sl = u.in_sl
            DU = self.DUset[sl]
            np.add(self.Uset[sl], 0.5 * H * DU + 0.5 * H * H * self.DDUset[sl], out=self.Uend[sl])
            st = u._setReal(u.c, u.in_vr, u.n_in, u.uend_ptr)
            if st > 1:
                raise UnitFailure(u.name, "fmi2SetReal", st, u.messages())
            calls += 1
        if u.n_out:
            st = u._getReal(u.c, u.out_vr, u.n_out, u.y_ptr)
            if st > 1:
                raise UnitFailure(u.name, "fmi2GetReal", st, u.messages())
            calls += 1
        return calls + 1

    def _restore_all(self, states) -> int:
        """Every FMU back to its saved state (a rollback); a refused restore is a failure.  Returns the calls."""
        for k, u in enumerate(self.units):
            st = u.restore(states[k])
            if st > 1:
                raise UnitFailure(u.name, "fmi2SetFMUstate", st, u.messages())
        return len(self.units)



class _Stop(Exception):
    """Ends a run before its first macro step (the failure is already set)."""


def _check_resolution(t0: float, stop: float, H: float, what: str, count: bool = True) -> None:
    """A macro step must move the time (t + H > t in floating point over the whole run) and a fixed-step run
    must end in at most MAX_STEPS of it: a step of 1e-300 s looped for ever."""
    if not (t0 + H > t0 and stop - H < stop and stop + H > stop):
        raise CosimError(f"{what} {H:g} s is below the time resolution at t = {max(abs(t0), abs(stop)):g} s "
                         f"(t + {what} == t in floating point)")
    if count and (stop - t0) / H > MAX_STEPS:
        raise CosimError(f"{what} {H:g} s would take {(stop - t0) / H:.3g} macro steps from {t0:g} s to {stop:g} s, "
                         f"more than the {MAX_STEPS:.0e} this master takes; take a larger step")


MAX_STEPS = 1e9


def _feedthrough(unit, names) -> bool:
    """Whether any of the outputs ``names`` read from ``unit`` depends on its inputs at the same instant (its
    ModelStructure; an output without ``dependencies`` depends on every known, FMI 2.0 section 2.2.8)."""
    declared = {o.variable.name: o for o in getattr(unit.md, "outputs", None) or ()}
    for name in names:
        o = declared.get(name)
        if o is not None and (o.dependencies is None
                              or any(getattr(d, "causality", "") == "input" for d in o.dependencies)):
            return True
    return False


def run(system, scheme: Optional[str] = None, extrapolation: Optional[str] = None, step: Optional[float] = None,
        adaptive: Optional[bool] = None, tol: Optional[float] = None, stop: Optional[float] = None,
        order: Optional[Sequence[str]] = None, workers: Optional[int] = None, **options) -> CosimResult:
    """Co-simulate ``system``: a :class:`CosimSystem`, a built scene (``scene.build(...)``) or a scene
    (built into a temporary folder).

    Every setting not given here is the scene's (its ``[cosim]`` table, ``system.settings``), else the
    default (:mod:`fmugen.cosim.settings`: gauss-seidel, linear): the same resolution as ``fmugen cosim``.
    scheme: ``jacobi`` | ``gauss-seidel`` | ``iterative`` | ``newton``;
    extrapolation: ``hold`` | ``linear`` | ``quadratic`` | ``cubic`` (iterated
    schemes only); step: macro step H [s] (default ``system.step``); adaptive:
    control H by the interface defect to ``tol`` (relative to each coupled
    signal's magnitude) between ``min_step`` and ``max_step``; stop: stop time
    [s] (default ``system.stop_time``); workers: threads that step the FMUs
    side by side under Jacobi and the iterated schemes (results are identical
    to one thread; worth it when a macro step costs well above the ~50 us a
    thread hand-over costs).  Further options: ``min_step``, ``max_step``,
    ``coupling_tol`` (iterative, newton; default: 10x the FMUs' internal rtol,
    see :mod:`.accuracy`), ``max_iterations``, ``detect_divergence``, ``dense`` (slopes for
    dense output, :mod:`fmugen.cosim.dense`), ``estimate`` (the coupling error estimate, on).

    Returns a :class:`CosimResult` (``time``, ``values`` per column,
    ``summary``); a run that fails returns its values up to the failure and
    ``summary.failure``.
    """
    if not isinstance(system, CosimSystem) and isinstance(getattr(system, "system", None), CosimSystem):
        system = system.system  # a built scene
    elif not isinstance(system, CosimSystem) and hasattr(system, "build"):
        import tempfile

        system = system.build(tempfile.mkdtemp(prefix="fmugen_scene_")).system
    settings = resolve(getattr(system, "settings", None), scheme=scheme, extrapolation=extrapolation, step=step,
                       adaptive=adaptive, tol=tol, stop=stop, order=order, workers=workers, **options)
    with Master(system, **settings.master_keywords()) as m:
        return m.run(**settings.run_keywords())
