"""The co-simulation master: macro steps over FMUs coupled by their inputs and outputs.

Notation.  Between communication points t_n and t_{n+1} = t_n + H every FMU
advances on its own (its internal solver); the master exchanges the coupled
values only at communication points.  ``U`` (length m) is the vector of all
coupled inputs, ``Y`` the vector of the outputs they are taken from,
``U = F * Y[S]`` (factor F, source index S).  A scheme decides which inputs an
FMU sees during [t_n, t_{n+1}]:

* ``jacobi``: every FMU steps from the values at t_n (any order, could run in
  parallel);
* ``gauss-seidel``: FMUs step one after another (``order``); an FMU whose
  source has already stepped sees its value at t_{n+1} (held) or the line
  from U_n to U_{n+1} (with extrapolation);
* ``iterative`` / ``newton``: the macro step is implicit in the coupling.
  All FMUs are saved (fmi2GetFMUstate), the end values V = U_{n+1} are guessed
  (extrapolation), every FMU steps with its inputs on the line from U_n to V
  or a Hermite interpolant (fmi2SetRealInputDerivatives), and V is corrected
  -- by the fixed point V <- G(V) or by Newton on R(V) = G(V) - V = 0 -- with
  the FMUs restored before each repetition, until |R| is below
  ``coupling_tol`` relative to the signals.  The interface Jacobian dG/dV is
  the sensitivity of a whole macro step, which the FMUs' directional
  derivatives (partials of f and g) do not give: it is obtained by **finite
  differences of rolled-back steps**, one re-step of FMU k per input of FMU k
  (dG is block-sparse: an FMU's outputs depend only on its own inputs; an
  fmugen FMU without states gives its columns exactly, by
  fmi2GetDirectionalDerivative), reused across macro steps while Newton
  converges fast (modified Newton) and refreshed by Broyden's rank-one secant
  update from each iterate (15-25 % fewer iterations on the PUMA: the steps'
  own adaptive solvers make G rough at their tolerance, which caps the
  contraction of a frozen Jacobian).

Extrapolation of U over the step from past communication points: ``hold``
(constant, order 1), ``linear`` (order 2), ``quadratic`` (through three
points).  FMUs that declare ``canInterpolateInputs`` receive the value at t_n
and its slope (fmi2SetRealInputDerivatives, order 1) and, for ``quadratic``,
its second derivative (order 2): the parabola itself, so Jacobi/quadratic is of
order 3.  Gauss-Seidel gives a later FMU the line to its source's new value
(order 2).  FMUs that cannot interpolate get the extrapolant's value at the
midpoint.  Iterated schemes interpolate between the step's ends instead
(``_slopes_to``): the line to the iterate (``linear``), or Hermite
interpolants whose unknowns are the values *and* the sources' slopes at
t_{n+1} (fmi2GetRealOutputDerivatives): the L-stable parabola arriving with
the end slope (``quadratic``, third order) and a cubic (``cubic``).  A
parabola through U_{n-1}, or one leaving U_n with its slope, destabilised the
PUMA's wrist coupling (measured, and explained by their stability functions).

Adaptive macro step (``adaptive=True``): the local error indicator is the
**interface defect** d = U_{n+1} - P(t_{n+1}), the mismatch between what an FMU
was told its input would be at t_{n+1} (extrapolant P, or the Newton
predictor) and what it turned out to be, relative to ``tol`` times each
signal's magnitude.  A step with max|d|/(tol*scale) > 1 is rolled back
(all FMUs restored) and retried smaller; an accepted step sets the next H by a
PI controller (Gustafsson) with growth at most 2x, no growth right after a
rejection, and a dead band (changes below 20 % are not made) so H does not
chatter.

Threads (``workers``): under Jacobi and the iterated schemes the FMUs of a sweep
step side by side on threads when a sweep is costly enough to pay the hand-over
(timed on the first sweeps); the results are those of one thread, bit for bit.

Failures end the run and return what was computed: an FMU's fmi2Discard or
fmi2Error, a step that does not meet ``tol`` at ``min_step``, a Newton or
fixed-point iteration that does not converge, and **divergence of the
coupling**, detected from the interface defect before any value overflows:
the window maxima of the defect have grown monotonically by more than 10x
while the defect is as large as a tenth of the signal itself (the coupling
error has become the signal), or a coupled value has grown beyond 1e8 times
its initial scale.  The report names the coupling with the largest defect, or
the FMU that failed, the time and the cause; when an FMU fails while the
coupling defect is growing, the report says that the coupling (inputs that
jumped), not stiffness, is the likely cause.
"""
from __future__ import annotations

import math
import time as _time
from collections import deque
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from .errors import CosimError
from .system import CosimSystem
from .units import STATUS, ModelUnit, SlaveUnit, UnitFailure, dptr, vr_array

STATUS_NAMES = dict(enumerate(STATUS))

# iterated schemes, cubic inputs: weight of the source's own slope at t_n in the cubic Hermite interpolant's
# start slope (the rest from the L-stable parabola).  On the split test x' = lambda u, u = x the scheme's
# stability function is A-stable with |R(-inf)| = theta / (2 - theta): 1 (the (2,2) Pade approximant, fourth
# order) lets a mode far faster than the step ring undamped -- it did on the PUMA's wrist at 40 ms, measured --
# while 0.8 damps it by a third per step and keeps most of the cubic's accuracy (third order)
CUBIC_THETA = 0.8

# macro-step controller (Gustafsson PI): safety factor, largest growth, no change inside the dead band
SAFETY, FAC_MAX, DEAD_BAND, GROW_AFTER = 0.8, 2.0, (0.9, 1.3), 4

SCHEMES = ("jacobi", "gauss-seidel", "iterative", "newton")
EXTRAPOLATIONS = ("hold", "linear", "quadratic", "cubic")
_ALIASES = {"gs": "gauss-seidel", "gauss_seidel": "gauss-seidel", "seidel": "gauss-seidel",
            "fixed-point": "iterative", "held": "hold", "constant": "hold", "zoh": "hold"}


@dataclass
class FailureReport:
    """Why and where a run stopped early."""

    time: float  # last accepted communication point [s]
    cause: str  # "fmu-failure", "diverged", "tolerance", "not-converged", "non-finite"
    message: str
    unit: Optional[str] = None  # the FMU that failed
    coupling: Optional[str] = None  # "src.var -> dst.var"
    fmu_messages: list = field(default_factory=list)

    def __str__(self) -> str:
        where = []
        if self.unit:
            where.append(f"FMU {self.unit!r}")
        if self.coupling:
            where.append(f"coupling {self.coupling}")
        lines = [f"co-simulation stopped at t = {self.time:.9g} s ({self.cause})"
                 + (f" [{'; '.join(where)}]" if where else "") + f": {self.message}"]
        lines += [f"  {m}" for m in self.fmu_messages[-5:]]
        return "\n".join(lines)


@dataclass
class Summary:
    """Work and outcome of one run."""

    system: str
    scheme: str
    extrapolation: str
    adaptive: bool
    status: str = "ok"  # "ok" or "failed"
    macro_steps: int = 0  # accepted
    rollbacks: int = 0  # rejected (restored) macro steps
    iterations: int = 0  # coupling iterations beyond the first (iterative/newton)
    jacobians: int = 0  # interface Jacobians by finite differences
    do_steps: int = 0  # fmi2DoStep calls (all FMUs, also rolled-back ones)
    fmu_calls: int = 0  # all fmi2* calls of the master
    wall_time: float = 0.0  # [s]
    simulated_time: float = 0.0  # [s]
    step_min: float = math.inf
    step_max: float = 0.0
    threads: int = 1  # threads that stepped the FMUs (workers > 1 and macro steps costly enough)
    failure: Optional[FailureReport] = None

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.simulated_time / self.wall_time if self.wall_time > 0 else math.inf

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("system", "scheme", "extrapolation", "adaptive", "status",
                                           "macro_steps", "rollbacks", "iterations", "jacobians",
                                           "do_steps", "fmu_calls", "wall_time", "simulated_time",
                                           "step_min", "step_max", "threads")}
        d["real_time_factor"] = self.real_time_factor
        d["failure"] = str(self.failure) if self.failure else ""
        return d

    def __str__(self) -> str:
        s = (f"{self.system}: {self.scheme}/{self.extrapolation}{' adaptive' if self.adaptive else ''}: "
             f"{self.status}; {self.macro_steps} macro steps (H {self.step_min:.4g}..{self.step_max:.4g} s), "
             f"{self.rollbacks} rollbacks, {self.iterations} iterations, {self.jacobians} Jacobians, "
             f"{self.do_steps} doStep, {self.fmu_calls} FMU calls, wall {self.wall_time:.4g} s "
             f"({self.real_time_factor:.3g}x real time)" + (f", {self.threads} threads" if self.threads > 1 else ""))
        if self.failure:
            s += "\n" + str(self.failure)
        return s


@dataclass
class CosimResult:
    """Recorded values at every accepted communication point (t_0 included)."""

    time: np.ndarray  # (n,)
    values: np.ndarray  # (n, len(columns))
    columns: tuple
    summary: Summary

    @property
    def ok(self) -> bool:
        return self.summary.status == "ok"

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(column)]
        except ValueError:
            raise KeyError(f"no recorded column {column!r}; columns: {', '.join(self.columns)}") from None

    def structured(self) -> np.ndarray:
        """A structured array with fields ``time`` and every column (fmpy's result layout)."""
        dt = np.dtype([("time", float)] + [(c, float) for c in self.columns])
        out = np.empty(len(self.time), dtype=dt)
        out["time"] = self.time
        for i, c in enumerate(self.columns):
            out[c] = self.values[:, i]
        return out


def _norm_choice(value, choices, what) -> str:
    v = str(value).strip().lower().replace("_", "-")
    v = _ALIASES.get(v, v)
    if v not in choices:
        raise CosimError(f"unknown {what} {value!r}; choose one of {', '.join(choices)}")
    return v


def check_choices(scheme: str, extrapolation: str) -> tuple:
    """(scheme, extrapolation) normalised, or a CosimError naming the choices (callable before any build)."""
    scheme = _norm_choice(scheme, SCHEMES, "scheme")
    extrapolation = _norm_choice(extrapolation, EXTRAPOLATIONS, "extrapolation")
    if extrapolation == "cubic" and scheme not in ("iterative", "newton"):
        raise CosimError("cubic inputs interpolate between both ends of a macro step (values and slopes): "
                         "they need an iterated scheme, iterative or newton, not " + scheme)
    return scheme, extrapolation


def _positive(name, value):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CosimError(f"{name} must be a number, not {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise CosimError(f"{name} must be finite and positive, not {value!r}")
    return v


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
        self._pool = None  # threads that step FMUs side by side (Jacobi and iterated schemes, workers > 1)
        self._groups = None  # the FMUs each thread steps, balanced by their measured cost
        self.units = []
        try:
            for u in system.units:
                ft = str(u.fmi_type).lower()
                if ft == "cs":
                    self.units.append(SlaveUnit(u, system.start_time, system.stop_time))
                elif ft == "me":
                    self.units.append(ModelUnit(u, system.start_time, system.stop_time))
                else:
                    raise CosimError(f"{system.name}: FMU {u.name!r}: fmi_type must be 'cs' or 'me', not {u.fmi_type!r}")
            self._resolve()
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
            (su, sv), (tu, tv) = c.source, c.target
            for un in (su, tu):
                if un not in index:
                    raise CosimError(f"{sysm.name}: coupling {su}.{sv} -> {tu}.{tv}: no FMU named {un!r}")
            if su == tu:
                raise CosimError(f"{sysm.name}: coupling {su}.{sv} -> {tu}.{tv} connects an FMU to itself")
            self.units[index[su]].variable(sv, ("output", "local"))
            self.units[index[tu]].variable(tv, ("input",))
            if (tu, tv) in src_of:
                raise CosimError(f"{sysm.name}: input {tu}.{tv} is driven twice")
            f = float(c.factor)
            if not math.isfinite(f):
                raise CosimError(f"{sysm.name}: coupling {su}.{sv} -> {tu}.{tv}: factor {c.factor} is not finite")
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
        # buffers (ctypes pointers into them are taken once)
        self.Y = np.zeros(max(ny, 1))  # outputs at t_{n+1} (being computed)
        self.Uset = np.zeros(max(nu, 1))  # input values passed at t_n
        self.DUset = np.zeros(max(nu, 1))  # input slopes passed at t_n
        self.DDUset = np.zeros(max(nu, 1))  # input second derivatives passed at t_n (quadratic inputs)
        self.DDDUset = np.zeros(max(nu, 1))  # input third derivatives passed at t_n (cubic Hermite inputs)
        self.DY = np.zeros(max(ny, 1))  # time derivatives of the coupling sources at t_n (Hermite inputs)
        self.dU0 = np.zeros(max(nu, 1))  # ... as coupled inputs
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
            unit.out_order1 = (__import__("ctypes").c_int * max(1, unit.n_src))(*([1] * unit.n_src))
            unit.in_order = (__import__("ctypes").c_int * max(1, len(in_vrs)))(*([1] * len(in_vrs)))
            unit.in_order2 = (__import__("ctypes").c_int * max(1, len(in_vrs)))(*([2] * len(in_vrs)))
            unit.in_order3 = (__import__("ctypes").c_int * max(1, len(in_vrs)))(*([3] * len(in_vrs)))
            unit.in_names, unit.out_names = list(ins[k]), list(outs[k])
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

    def close(self) -> None:
        for u in getattr(self, "units", []):
            u.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- primitives (hot loop: attributes bound to locals, no allocation) ------
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
                raise CosimError(f"{what}: FMU {u.name!r} cannot interpolate inputs (canInterpolateInputs = "
                                 f"false); use {self.scheme}/linear")

    def _gather(self, Unew, G, units=None) -> int:
        """The coupled values into Unew and G[:nu]; with Hermite inputs also their slopes into G[nu:], read by
        fmi2GetRealOutputDerivatives from the sources (``units``: only those).  Returns the number of calls."""
        nu, calls = self.nu, 0
        self._coupled(Unew)
        G[:nu] = Unew[:nu]
        if self._hermite:
            for u in (self.units if units is None else units):
                if u.n_src:
                    st = u._getOutDer(u.c, u.out_vr, u.n_src, u.out_order1, u.dy_ptr)
                    calls += 1
                    if st > 1:
                        raise UnitFailure(u.name, "fmi2GetRealOutputDerivatives", st, u.messages())
            D = G[nu:]
            np.take(self.DY, self.S, out=D)
            if not self._unit_factors:
                D *= self.F
        return calls

    def _coupled(self, out: np.ndarray) -> np.ndarray:
        nu = self.nu
        if nu:
            np.take(self.Y, self.S, out=out[:nu])
            if not self._unit_factors:
                out[:nu] *= self.F
        return out

    # -- the run ----------------------------------------------------------------
    def run(self, step: Optional[float] = None, stop: Optional[float] = None, adaptive: bool = False,
            tol: float = 1e-4, min_step: Optional[float] = None, max_step: Optional[float] = None,
            coupling_tol: float = 1e-8, max_iterations: int = 30, detect_divergence: bool = True) -> CosimResult:
        sysm = self.system
        t0 = float(sysm.start_time)
        stop = float(sysm.stop_time if stop is None else stop)
        H0 = _positive("step", sysm.step if step is None else step)
        if not (math.isfinite(stop) and stop > t0):
            raise CosimError(f"stop time {stop} must be finite and after the start time {t0}")
        tol = _positive("tol", tol)
        coupling_tol = _positive("coupling_tol", coupling_tol)
        Hmin = _positive("min_step", min_step) if min_step is not None else (H0 * 1e-3 if adaptive else H0)
        Hmax = _positive("max_step", max_step) if max_step is not None else (max(H0, (stop - t0) / 10) if adaptive else H0)
        if Hmin > Hmax:
            raise CosimError(f"min_step {Hmin} exceeds max_step {Hmax}")
        max_iterations = int(max_iterations)
        implicit = self.scheme in ("iterative", "newton")
        summ = Summary(sysm.name, self.scheme, self.extrapolation, bool(adaptive))
        nu = self.nu
        ext = {"hold": 0, "linear": 1, "quadratic": 2, "cubic": 3}[self.extrapolation]
        # the defect (what the predictor said against what came out) is O(H^p_err): the predictor is the
        # extrapolant through 1, 2 or 3 past points, also for the iterated schemes
        p_err = min(ext, 2) + 1

        units = self.units
        Y, Uset, DUset = self.Y, self.Uset, self.DUset
        no_interp = self.no_interp
        any_no_interp = bool(no_interp.any())
        U_hist = np.zeros((3, max(nu, 1)))  # U at t_n, t_{n-1}, t_{n-2}
        t_hist = [t0, t0, t0]
        n_hist = 1
        Unew = np.zeros(max(nu, 1))
        Upred = np.zeros(max(nu, 1))
        d = np.zeros(max(nu, 1))
        scale = np.zeros(max(nu, 1))
        Unew_v, Upred_v, d_v, Uset_v, DUset_v = Unew[:nu], Upred[:nu], d[:nu], Uset[:nu], DUset[:nu]
        U0_v, U1_v, U2_v = U_hist[0, :nu], U_hist[1, :nu], U_hist[2, :nu]
        hold_fast = ext == 0 and not implicit  # Upred = U_n; no input derivatives sent; one history row
        self._send_du = not hold_fast
        self._send_ddu = ext == 2  # quadratic: the parabola itself goes to the FMUs (order 2)
        self.DDUset[:] = 0.0
        # iterated schemes with quadratic or cubic inputs: Hermite interpolants over the step, whose unknowns
        # are the coupled values and the sources' slopes at t_{n+1} (one-step: no history; see _slopes_to)
        self._hermite = implicit and ext >= 2
        if self._hermite:
            self._check_hermite()
        self._cubic = implicit and ext == 3
        hermite = self._hermite
        if hermite:
            self._send_ddu = True
        rec_idx = self.rec_idx
        cap = int(min(max((stop - t0) / Hmin, 16), 1_000_000)) + 2 if not adaptive else 1024
        T = np.empty(cap)
        V = np.empty((cap, len(rec_idx)))
        n_rows = 0
        wall0 = _time.perf_counter()
        calls = 0
        rollback_ok = adaptive or implicit
        need_states = rollback_ok
        n_cs = sum(1 for u in units if u.kind != "me")
        if self.workers > 1 and n_cs > 1 and self.scheme != "gauss-seidel":
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(min(self.workers, n_cs) - 1, thread_name_prefix="fmugen-cosim")
            self._groups, self._cost, self._timed = None, {}, 0
        states = []  # (the pool is shut down in the finally below)
        failure = None
        t = t0
        try:
            # consistent coupled values at t0 (outputs without feedthrough: two passes suffice for
            # chains of feedthrough no longer than one; more would be an algebraic loop)
            for _ in range(2):
                calls += self._read_all()
                self._coupled(Uset)
                for u in units:
                    if u.n_in:
                        st = u._setReal(u.c, u.in_vr, u.n_in, u.u_ptr)
                        calls += 1
                        if st > 1:
                            raise UnitFailure(u.name, "fmi2SetReal", st, u.messages())
            calls += self._read_all()
            self._coupled(U_hist[0])
            G = np.zeros(2 * nu if self._hermite else nu)
            if self._hermite:
                calls += self._gather(Unew, G)
                self.dU0[:nu] = G[nu:]
            np.abs(U_hist[0], out=scale)
            np.maximum(scale[:nu], self.u_nominal, out=scale[:nu])
            scale[nu:] = 1.0
            scale0 = scale.copy()
            T[0] = t
            V[0] = Y[rec_idx]
            n_rows = 1
            if need_states:
                states = [u.new_state() for u in units]
                calls += len(units)
            if self.me_block is not None:
                self.me_block.start(t0)
            H = min(H0, Hmax)
            err_prev = 1.0
            rejected_last = False
            # divergence monitor: every win_len accepted steps, on the block of their defects and values
            win_len, windows, win_count = 5, [], 0
            Dblk = np.zeros((win_len, max(nu, 1)))
            Ublk = np.zeros((win_len, max(nu, 1)))
            recent = deque(maxlen=8)  # (defect, signal, relative defect) of the last macro steps
            peak = np.abs(U_hist[0, :nu]).copy()  # slowly forgetting peak |U| per coupling
            grow_votes = deque(maxlen=GROW_AFTER)  # step-size factors the last accepted steps proposed
            J = None
            J_H = None
            t_last = stop - 1e-12 * max(1.0, abs(stop))  # loop guard, computed once
            while t < t_last:
                if abs(stop - (t + H)) <= 1e-6 * H:
                    pass  # the last step: keep H (bit-identical to a loop that steps H), land on stop
                elif t + H > stop or stop - (t + H) < 1e-3 * H:
                    H = stop - t
                # -- predictor: extrapolant through the last communication points --
                U0 = U_hist[0]
                Uset_v[:] = U0_v
                if hold_fast:
                    Upred_v = U0_v  # held: the prediction of U_{n+1} is U_n (DUset stays zero)
                else:
                    if ext == 0 or n_hist == 1:
                        DUset_v[:] = 0.0
                    elif ext == 1 or n_hist == 2:
                        np.subtract(U0_v, U1_v, out=DUset_v)
                        DUset_v /= t_hist[0] - t_hist[1]
                    else:  # quadratic: P(t_n + s) = U_n + P'(t_n) s + P'' s^2 / 2 through the last three points
                        h1, h2 = t_hist[0] - t_hist[1], t_hist[1] - t_hist[2]
                        d1 = (U0_v - U1_v) / h1
                        d2 = (U1_v - U2_v) / h2
                        c2 = (d1 - d2) / (h1 + h2)
                        DUset_v[:] = d1 + c2 * h1
                        self.DDUset[:nu] = 2.0 * c2
                    Upred_v = Upred[:nu]
                    np.multiply(DUset_v, H, out=Upred_v)
                    if ext >= 2 and n_hist >= 3:
                        Upred_v += 0.5 * H * H * self.DDUset[:nu]
                    Upred_v += U0_v
                if need_states:
                    for k, u in enumerate(units):
                        st = u.save(states[k])
                        if st > 1:
                            raise UnitFailure(u.name, "fmi2GetFMUstate", st, u.messages())
                    calls += len(units)
                # -- the macro step --
                try:
                    if not implicit:
                        if self.scheme == "jacobi":
                            calls += self._step_jacobi(t, H, ext, any_no_interp, rollback_ok)
                        else:
                            calls += self._step_gauss_seidel(t, H, ext, any_no_interp, rollback_ok, U0)
                        self._coupled(Unew)
                    else:
                        if J is not None and J_H is not None and abs(H - J_H) > 1e-12 * H:
                            J = None  # the step's sensitivity depends on H
                        # the unknowns Z: the coupled values at t_{n+1} (and, Hermite, their slopes there)
                        if self._hermite:  # the history parabola's value and slope at t_{n+1} (or the last slope)
                            Zg = np.concatenate([Upred_v, DUset_v + H * self.DDUset[:nu] if n_hist >= 3
                                                 else self.dU0[:nu]])
                        else:
                            Zg = Upred_v.copy()
                        if not self._hermite:
                            self.DDUset[:nu] = 0.0
                        it = 0
                        conv = False
                        err_c_prev = math.inf
                        Z_prev = R_prev = None
                        w = np.concatenate([scale[:nu], scale[:nu] / H]) if self._hermite else scale[:nu]
                        while True:
                            if it > 0:
                                calls += self._restore_all(states)
                            Uset[:nu] = U0[:nu]
                            self._slopes_to(Zg, U0, H)
                            calls += self._step_jacobi(t, H, 1, any_no_interp, True)
                            calls += self._gather(Unew, G)
                            R = G - Zg
                            Vg = Zg[:nu]
                            den = coupling_tol * np.maximum(scale[:nu], np.abs(Vg))
                            err_c = float(np.max(np.abs(R[:nu]) / den)) if nu else 0.0
                            if self._hermite and nu:  # a slope's error moves the input by about H times it
                                err_c = max(err_c, float(np.max(np.abs(R[nu:]) * H / den)))
                            if err_c <= 1.0:
                                conv = True
                                break
                            if it >= max_iterations or not math.isfinite(err_c):
                                break
                            it += 1
                            if self.scheme == "iterative":
                                Zg = G.copy()
                            else:
                                if J is None or err_c > 0.5 * err_c_prev:
                                    J, c2 = self._interface_jacobian(t, H, U0, Zg, G, states, scale)
                                    calls += c2
                                    J_H = H
                                    summ.jacobians += 1
                                elif Z_prev is not None:  # between fresh Jacobians: secant updates
                                    J = _broyden(J, Zg - Z_prev, R - R_prev, w)
                                Z_prev, R_prev = Zg, R
                                Zg = Zg + J @ R
                            err_c_prev = err_c
                        summ.iterations += it
                        if not conv:
                            j = int(np.argmax(np.abs(R[:nu]))) if nu else 0
                            if adaptive and H > Hmin * (1 + 1e-12):
                                calls += self._restore_all(states)
                                summ.rollbacks += 1
                                H = max(Hmin, H / 4)
                                rejected_last = True
                                continue
                            failure = FailureReport(t, "not-converged",
                                                    f"{self.scheme} coupling iteration did not converge in "
                                                    f"{max_iterations} iterations at H = {H:.4g} s "
                                                    f"(residual {err_c:.3g} x coupling_tol)",
                                                    coupling=self.coupling_labels[j] if nu else None)
                            break
                except UnitFailure as e:
                    # an FMU refused the step (fmi2Discard): with rollback, retry smaller -- the FMU may
                    # only have been given inputs that jumped
                    if not (adaptive and e.status == 2 and H > Hmin * (1 + 1e-12)):
                        raise
                    calls += self._restore_all(states)
                    summ.rollbacks += 1
                    H = max(Hmin, H / 4)
                    rejected_last = True
                    continue
                # -- defect, error estimate, divergence --
                np.subtract(Unew_v, Upred_v, out=d_v)
                if adaptive or implicit:
                    if not np.all(np.isfinite(Unew_v)):
                        j = int(np.argmax(~np.isfinite(Unew_v)))
                        failure = FailureReport(t, "non-finite", "a coupled value is not finite",
                                                coupling=self.coupling_labels[j])
                        break
                    np.maximum(scale[:nu], np.abs(Unew_v), out=scale[:nu])
                if adaptive:
                    ratio = np.abs(d[:nu]) / (tol * scale[:nu])
                    err = float(ratio.max()) if nu else 0.0
                    if err > 1.0:
                        if H <= Hmin * (1 + 1e-12):
                            j = int(np.argmax(ratio))
                            failure = FailureReport(t, "tolerance",
                                                    f"interface defect {err:.3g} x tol at the minimum macro step "
                                                    f"{Hmin:.4g} s", coupling=self.coupling_labels[j])
                            break
                        calls += self._restore_all(states)
                        summ.rollbacks += 1
                        grow_votes.clear()
                        H = max(Hmin, H * max(0.2, SAFETY * err ** (-1.0 / p_err)))
                        rejected_last = True
                        continue
                # -- accept --
                t = t + H if stop - (t + H) > 1e-6 * H else stop
                summ.macro_steps += 1
                if H < summ.step_min:
                    summ.step_min = H
                if H > summ.step_max:
                    summ.step_max = H
                if hold_fast:
                    U0_v[:] = Unew_v
                else:  # the history the extrapolants and predictors read
                    U2_v[:] = U1_v
                    U1_v[:] = U0_v
                    U0_v[:] = Unew_v
                    if hermite:
                        self.dU0[:nu] = G[nu:]  # the slopes at t_{n+1}: the next step's predictor
                    t_hist[2], t_hist[1], t_hist[0] = t_hist[1], t_hist[0], t
                    if n_hist < 3:
                        n_hist += 1
                if n_rows == len(T):
                    T = np.concatenate([T, np.empty(len(T))])
                    V = np.concatenate([V, np.empty_like(V)])
                T[n_rows] = t
                np.take(Y, rec_idx, out=V[n_rows])
                n_rows += 1
                if detect_divergence and nu and not adaptive:  # adaptive: the step control bounds the defect
                    Dblk[win_count] = d_v
                    Ublk[win_count] = Unew_v
                    win_count += 1
                    if win_count == win_len:
                        win_count = 0
                        failure = self._monitor(t, H, Dblk[:, :nu], Ublk[:, :nu], scale0[:nu], peak, windows,
                                                recent)
                        if failure is not None:
                            break
                # -- next H --
                if adaptive:
                    err = max(err, 1e-10)
                    fac = SAFETY * err ** (-0.7 / p_err) * err_prev ** (0.4 / p_err)
                    fac = min(FAC_MAX, max(0.2, fac))
                    if rejected_last:
                        fac = min(fac, 1.0)
                    grow_votes.append(fac)
                    if fac > DEAD_BAND[1]:
                        # grow only when the last GROW_AFTER accepted steps all asked for it, by the least
                        # they asked: a lightly damped mode makes the defect oscillate step to step
                        fac = min(grow_votes) if len(grow_votes) == GROW_AFTER else 1.0
                        if fac <= DEAD_BAND[1]:
                            fac = 1.0
                    elif fac >= DEAD_BAND[0]:
                        fac = 1.0  # dead band: an accepted step is kept unless the change is worth it
                    if fac != 1.0:
                        grow_votes.clear()
                    H = min(Hmax, max(Hmin, H * fac))
                    err_prev = err
                    rejected_last = False
                else:
                    H = min(H0, Hmax)
        except UnitFailure as e:
            growing = detect_divergence and nu and (_growing(windows) or _growing_steps(recent))
            coupling = None
            msg = str(e)
            cause = "fmu-failure"
            if growing:
                j = int(np.argmax(np.abs(d[:nu]) / np.maximum(scale0[:nu], 1e-300)))
                coupling = self.coupling_labels[j]
                cause = "diverged"
                msg = (f"the coupling diverges: the interface defect grew over the last macro steps until FMU "
                       f"{e.unit!r} failed ({e.call} returned {STATUS_NAMES.get(e.status, e.status)}). The inputs "
                       f"this FMU was given jumped, so the coupling (H = {H:.4g} s is above this scheme's stability "
                       f"limit: take a smaller step, extrapolation, or an iterative/newton scheme) is the cause, "
                       f"not stiffness of the FMU, whatever its message suggests")
            failure = FailureReport(t, cause, msg, unit=e.unit, coupling=coupling, fmu_messages=e.messages)
        finally:
            summ.threads = len(self._groups) if self._pool is not None and self._groups else 1
            if self._pool is not None:
                self._pool.shutdown(wait=True)
                self._pool = None
            for k, s in enumerate(states):
                try:
                    units[k].free_state(s)
                except Exception:
                    pass
        summ.wall_time = _time.perf_counter() - wall0
        summ.simulated_time = t - t0
        summ.fmu_calls = calls + sum(getattr(u, "n_calls", 0) for u in units)
        summ.do_steps = self._do_steps + sum(getattr(u, "do_steps", 0) for u in units)
        if failure is not None:
            summ.status = "failed"
            summ.failure = failure
        if summ.macro_steps == 0:
            summ.step_min = summ.step_max = 0.0
        return CosimResult(T[:n_rows].copy(), V[:n_rows].copy(), self.columns, summ)

    def _monitor(self, t, H, D, U, scale0, peak, windows, recent):
        """Divergence check on a block of accepted macro steps (defects D, values U: (win_len, nu))."""
        A = np.abs(U)
        R = np.abs(D)
        if not (math.isfinite(A.sum()) and math.isfinite(R.sum())):
            j = int(np.argmax(~np.isfinite(A).all(axis=0) | ~np.isfinite(R).all(axis=0)))
            return FailureReport(t, "non-finite", "a coupled value is not finite", coupling=self.coupling_labels[j])
        A /= scale0
        sn = A.max(axis=1)
        if sn[-1] > 1e8:
            j = int(np.argmax(A[-1]))
            return FailureReport(t, "diverged", f"coupled value grew to {sn[-1]:.3g} x its initial scale",
                                 coupling=self.coupling_labels[j])
        # the defect against the same coupling's recent peak magnitude (not its value now, which crosses
        # zero): ~1 when the coupling error is the signal, ~H*omega for a resolved motion
        np.maximum(peak * PEAK_DECAY ** len(D), np.abs(U).max(axis=0), out=peak)
        Rs = R / scale0
        jd = Rs.argmax(axis=1)
        rows = self._rows[: len(D)]
        dn = Rs[rows, jd]
        rel = R[rows, jd] / np.maximum(peak[jd], REST * scale0[jd])
        recent.extend(zip(dn.tolist(), sn.tolist(), rel.tolist()))
        # grown a thousandfold past its scale while the coupling error is as large as the signal: the
        # coupling has pumped energy in (a PUMA under Jacobi/held at 8 ms spins at 1e5 rad/s within 0.1 s
        # and then wanders, bounded, with defects small against those values)
        if sn[-1] > GROWN and float(rel.max()) >= 0.5:
            j = int(jd[int(np.argmax(rel))])
            return FailureReport(
                t, "diverged",
                f"the coupling diverges: coupled values grew to {sn[-1]:.3g} x their initial scale with an "
                f"interface defect {float(rel.max()):.2g} x the signal (H = {H:.4g} s is above this scheme's "
                f"stability limit: take a smaller step, extrapolation, or an iterative/newton scheme)",
                coupling=self.coupling_labels[j])
        if _explosive(recent):
            return FailureReport(
                t, "diverged",
                f"the coupling diverges: the coupled values grew more than 4x on each of 4 macro steps with a "
                f"defect as large as the signal (H = {H:.4g} s is above this scheme's stability limit: take a "
                f"smaller step, extrapolation, or an iterative/newton scheme)",
                coupling=self.coupling_labels[int(jd[-1])])
        k = int(dn.argmax())
        _push_window(windows, float(dn[k]), float(sn.max()), float(rel[k]))
        div = _diverging(windows)
        if div:
            return FailureReport(
                t, "diverged",
                f"the coupling diverges: the interface defect (changed {div:.3g}x over the last "
                f"{len(D) * max(_run_length(windows), min(len(windows), SUSTAINED))} macro steps) "
                f"does not decay and is as large as the signal (H = {H:.4g} s is above this scheme's stability "
                f"limit: take a smaller step, extrapolation, or an iterative/newton scheme)",
                coupling=self.coupling_labels[int(jd[k])])
        return None

    _do_steps = 0

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
        if u.n_out:
            st = u._getReal(u.c, u.out_vr, u.n_out, u.y_ptr)
            if st > 1:
                raise UnitFailure(u.name, "fmi2GetReal", st, u.messages())
            calls += 1
        return calls + 1

    def _step_parallel(self, t, H, no_prior) -> int:
        """The Jacobi sweep with the groups on threads (fmpy's ctypes calls release the GIL; every FMU is its
        own instance, touched by one thread).  Waits for every group before a failure is raised, so no FMU is
        still stepping when the master restores or reports."""
        futs = [self._pool.submit(self._do_group, g, t, H, no_prior) for g in self._groups[1:]]
        calls, failure = 0, None
        try:
            calls += self._do_group(self._groups[0], t, H, no_prior)
        except UnitFailure as e:
            failure = e
        for f in futs:
            try:
                calls += f.result()
            except UnitFailure as e:
                failure = failure or e
        if failure is not None:
            raise failure
        return calls

    def _do_group(self, group, t, H, no_prior) -> int:
        calls = 0
        for u in group:
            calls += self._do(u, t, H, no_prior)
        return calls

    def _prepare_no_interp(self, H):
        """FMUs without input derivatives: pass the extrapolant's midpoint value, held."""
        m = self.no_interp[: self.nu]
        self.Uset[: self.nu][m] += 0.5 * H * self.DUset[: self.nu][m]

    def _step_jacobi(self, t, H, ext, any_no_interp, rollback_ok) -> int:
        if any_no_interp and ext:
            self._prepare_no_interp(H)
        no_prior = 0 if rollback_ok else 1
        calls = 0
        if self._pool is None:
            for u in self.units:
                if u.kind == "me":
                    continue
                calls += self._do(u, t, H, no_prior)
        elif self._groups is not None:
            calls += self._step_parallel(t, H, no_prior)
        else:  # the first sweeps: sequential, each FMU timed; then the groups
            cost = self._cost
            for u in self.units:
                if u.kind != "me":
                    c0 = _time.perf_counter()
                    calls += self._do(u, t, H, no_prior)
                    cost[u.name] = cost.get(u.name, 0.0) + _time.perf_counter() - c0
            self._timed += 1
            total = sum(cost.values())
            if total >= TIMED_BUDGET or self._timed >= TIMED_SWEEPS:
                if total < self._timed * PARALLEL_MIN_COST:  # a hand-over would cost more than it saves
                    self._pool.shutdown(wait=True)
                    self._pool = None
                else:
                    self._groups = _balanced_groups([u for u in self.units if u.kind != "me"], cost,
                                                    self.workers)
        if self.me_block is not None:
            calls += self.me_block.step(t, H)
        return calls

    def _step_gauss_seidel(self, t, H, ext, any_no_interp, rollback_ok, U0) -> int:
        if any_no_interp and ext:
            self._prepare_no_interp(H)
        Uset, DUset, Y, S, F = self.Uset, self.DUset, self.Y, self.S, self.F
        no_prior = 0 if rollback_ok else 1
        calls = 0
        for k, u in zip(self.gs_k, self.gs_units):
            idx = self.gs_new[k]
            if len(idx):
                new = F[idx] * Y[S[idx]]
                if ext == 0 or not getattr(u, "can_interpolate", False):
                    Uset[idx] = new  # the source's value at t_{n+1}, held
                    DUset[idx] = 0.0
                else:  # the line from U_n to the source's U_{n+1} (a parabola through U_{n-1} as well
                    # destabilises the PUMA's wrist coupling at 2 ms: measured, so it stays a line)
                    Uset[idx] = U0[idx]
                    DUset[idx] = (new - U0[idx]) / H
                self.DDUset[idx] = 0.0
            if u.kind == "me":
                if u is self._first_me:
                    calls += self.me_block.step(t, H)
            else:
                calls += self._do(u, t, H, no_prior)
        return calls

    def _restore_all(self, states) -> int:
        """Every FMU back to its saved state (a rollback); a refused restore is a failure.  Returns the calls."""
        for k, u in enumerate(self.units):
            st = u.restore(states[k])
            if st > 1:
                raise UnitFailure(u.name, "fmi2SetFMUstate", st, u.messages())
        return len(self.units)

    def _slopes_to(self, Z, U0, H) -> None:
        """Inputs over an iterated macro step, from the unknowns Z -- slopes into DUset, curvatures into DDUset,
        third derivatives into DDDUset:

        - linear: the line from U_n to Z = V at t_n + H (trapezoidal: A-stable, second order);
        - quadratic: the parabola from U_n to V that arrives with the sources' slope V' (Z = [V, V']).  The
          slope at the end, not at the start, keeps it L-stable: on x' = lambda u, u = x it is the (1, 2)
          Pade approximant, Radau IIA's third-order stability function (with the slope at the start the
          same test gives |R| -> inf, and the PUMA's wrist diverged: measured);
        - cubic: the cubic Hermite interpolant of U_n, V, V' and a start slope blended from the sources' slope
          at t_n and the parabola's (CUBIC_THETA)."""
        nu = self.nu
        A = Z[:nu] - U0[:nu]
        if self._cubic:
            # start slope: theta x the source's own slope at t_n + (1 - theta) x the L-stable parabola's
            Vd = Z[nu:]
            d0 = CUBIC_THETA * self.dU0[:nu] + (1.0 - CUBIC_THETA) * (2.0 * A / H - Vd)
            self.DUset[:nu] = d0
            self.DDUset[:nu] = 2.0 * (3.0 * A / H - 2.0 * d0 - Vd) / H
            self.DDDUset[:nu] = 6.0 * (d0 + Vd - 2.0 * A / H) / (H * H)
        elif self._hermite:
            Vd = Z[nu:]
            b = (Vd * H - A) / (H * H)
            self.DUset[:nu] = 2.0 * A / H - Vd
            self.DDUset[:nu] = 2.0 * b
        else:
            self.DUset[:nu] = A / H

    def _algebraic_columns(self, u, rows, Jg) -> int:
        """dG/dV of an FMU whose outputs depend only on its inputs now (``u.algebraic``): its exact directional
        derivatives at the end of the step, one seed per input, no re-step.  Returns the number of calls."""
        out_idx = self.S[rows] - u.out_sl.start
        unknowns = vr_array([u.out_vr[i] for i in out_idx])
        seed = np.zeros(u.n_in)
        dv = np.zeros(len(rows))
        for i, j in enumerate(range(u.in_sl.start, u.in_sl.stop)):
            seed[:] = 0.0
            seed[i] = 1.0
            st = u._dirDer(u.c, unknowns, len(rows), u.in_vr, u.n_in, dptr(seed), dptr(dv))
            if st > 1:
                raise UnitFailure(u.name, "fmi2GetDirectionalDerivative", st, u.messages())
            # a held midpoint input (no interpolation) moves by half the end value's change
            Jg[rows, j] = self.F[rows] * dv * (0.5 if self.no_interp[j] else 1.0)
        return u.n_in

    def _interface_jacobian(self, t, H, U0, Zg, G, states, scale):
        """M = (I - dG/dZ)^-1 by finite differences of rolled-back steps, one FMU at a time (Z: the coupled
        values at t_n + H, and with Hermite inputs their slopes there); an algebraic FMU's columns come from
        its directional derivatives."""
        nu = self.nu
        herm = self._hermite
        m = len(Zg)
        Jg = np.zeros((m, m))
        calls = 0
        Y, DY, Uset = self.Y, self.DY, self.Uset
        Y_base, DY_base = Y.copy(), DY.copy()
        Gp = np.zeros(m)
        Up = np.zeros(max(nu, 1))
        Vg = Zg[:nu]
        for k, u in enumerate(self.units):
            if not u.n_in or u.kind == "me":
                continue
            rows = np.nonzero(self.u_src_unit[:nu] == k)[0]
            if not len(rows):
                continue
            if not herm and getattr(u, "algebraic", False):
                calls += self._algebraic_columns(u, rows, Jg)
                continue
            if herm:
                rows = np.concatenate([rows, rows + nu])
            cols = list(range(u.in_sl.start, u.in_sl.stop))
            if herm:
                cols += [j + nu for j in cols]
            for c in cols:
                j = c % nu if nu else c
                ref = scale[j] / H if c >= nu else scale[j]
                delta = 1e-6 * max(abs(Zg[c]), ref)
                u.restore(states[k])
                Uset[:nu] = U0[:nu]
                Zp = Zg.copy()
                Zp[c] += delta
                self._slopes_to(Zp, U0, H)
                if self.no_interp[j]:
                    Uset[j] = 0.5 * (U0[j] + Vg[j] + delta)
                calls += 1 + self._do(u, t, H, 0)
                calls += self._gather(Up, Gp, (u,))
                Jg[rows, c] = (Gp[rows] - G[rows]) / delta
                Y[u.out_sl] = Y_base[u.out_sl]
                DY[u.out_sl] = DY_base[u.out_sl]
        if self.me_block is not None:
            me_units = self.me_block.units
            me_k = [k for k, u in enumerate(self.units) if u.kind == "me"]
            rows = np.nonzero(np.isin(self.u_src_unit[:nu], me_k))[0]
            cols = [j for u in me_units for j in range(u.in_sl.start, u.in_sl.stop)
                    if self.units[self.u_src_unit[j]].kind != "me"]
            for j in cols:
                delta = 1e-6 * max(abs(Vg[j]), scale[j])
                for k in me_k:
                    self.units[k].restore(states[k])
                Uset[:nu] = U0[:nu]
                Vp = Vg.copy()
                Vp[j] += delta
                self._slopes_to(Vp, U0, H)
                calls += len(me_k) + self.me_block.step(t, H)
                Jg[rows, j] = (self.F[rows] * Y[self.S[rows]] - G[rows]) / delta
                for k in me_k:
                    Y[self.units[k].out_sl] = Y_base[self.units[k].out_sl]
        # Newton on R(Z) = G(Z) - Z: Z <- Z + (I - dG/dZ)^-1 R
        return np.linalg.inv(np.eye(m) - Jg), calls


# threads step the FMUs only when one sequential sweep of them took at least this long [s]: handing a group
# to a thread and collecting it costs ~0.1 ms (measured on the PUMA: Jacobi at 0.625 ms, 47 us of FMU work
# per step, ran 3x slower on two threads; Newton/cubic at 40 ms, ~0.8 ms per sweep, 1.37x faster)
PARALLEL_MIN_COST = 5e-4
# the sweeps are timed sequentially until they have cost TIMED_BUDGET [s] or TIMED_SWEEPS sweeps have run;
# the mean decides, the per-FMU sums balance the groups (the first sweeps, from rest, are the cheapest)
TIMED_BUDGET, TIMED_SWEEPS = 0.01, 64


def _balanced_groups(units, cost, n):
    """Longest processing time first: ``units`` into at most ``n`` groups of nearly equal summed cost."""
    groups = [[] for _ in range(min(n, len(units)))]
    load = [0.0] * len(groups)
    for u in sorted(units, key=lambda u: -cost.get(u.name, 0.0)):
        k = load.index(min(load))
        groups[k].append(u)
        load[k] += cost.get(u.name, 0.0)
    return [g for g in groups if g]


def _broyden(M, s, y, w):
    """Broyden's good update of M ~ (I - dG/dZ)^-1 = -(dR/dZ)^-1 from the secant pair (s, y) = (dZ, dR),
    in coordinates scaled by w: M+ = M - (s + M y) s' M / (s' M y)."""
    Mh = M * (w[None, :] / w[:, None])
    sh, yh = s / w, y / w
    Msy = Mh @ yh
    sM = sh @ Mh
    den = float(sh @ Msy)
    if not math.isfinite(den) or abs(den) < 1e-12 * float(np.linalg.norm(sh) * np.linalg.norm(Msy)):
        return M
    Mh = Mh - np.outer(sh + Msy, sM) / den
    return Mh * (w[:, None] / w[None, :])


PEAK_DECAY = 0.995  # per macro step: the peak magnitude forgets over ~200 steps
REST = 1e-6  # coupled signals below this fraction of their nominal scale count as at rest (no growth from noise)
GROWN = 1e3  # coupled values this many times their initial scale (or nominal) count as grown
SUSTAINED = 20  # windows (100 macro steps) of a defect that neither decays nor shrinks against the signal
ENVELOPE = 6  # windows (of 5 macro steps) in the defect's envelope: longer than an oscillation period


class _Window:
    """One window of win_len macro steps, with what the criteria need kept incrementally (O(1) per window)."""

    __slots__ = ("d", "s", "rel", "env", "run", "first_moving", "n_moving", "sustained", "jumps")

    def __getitem__(self, i):  # (defect, signal, relative defect), as a tuple
        return (self.d, self.s, self.rel)[i]


def _push_window(windows, d, s, rel) -> None:
    w = _Window()
    w.d, w.s, w.rel = d, s, rel
    # envelope: the largest defect of the last ENVELOPE windows (longer than an oscillation period)
    w.env = max([d] + [x.d for x in windows[-(ENVELOPE - 1):]]) if ENVELOPE > 1 else d
    # moving: the defect itself is above rest (1e-3 of the coupling's scale); at rest it is round-off,
    # and growth measured from round-off means nothing
    moving = d >= 1e3 * REST
    if windows and w.env >= windows[-1].env:
        p = windows[-1]
        w.run = p.run + 1
        w.first_moving = p.first_moving if p.first_moving is not None else (w if moving else None)
        w.n_moving = p.n_moving + (1 if moving else 0)
    else:
        w.run = 0
        w.first_moving = w if moving else None
        w.n_moving = 1 if moving else 0
    ok = rel >= 0.1 and moving
    w.sustained = (windows[-1].sustained + 1 if windows else 1) if ok else 0
    w.jumps = (windows[-1].jumps + 1 if windows else 1) if (rel >= 1.0 and moving) else 0
    windows.append(w)
    if len(windows) > 4 * SUSTAINED:  # keep the list short; the criteria look back at most SUSTAINED
        del windows[: len(windows) - 2 * SUSTAINED]


def _run_length(windows) -> int:
    """Number of windows over which the defect's envelope has not decreased, ending now."""
    return windows[-1].run if windows else 0


def _diverging(windows) -> float:
    """Growth factor if the coupling diverges, else 0.

    Growth: over a run of windows in which the defect's envelope never decreased (>= 6 of them with the
    signals above rest), the defect grew >= 30x and stays >= 0.2 of its coupling's recent peak (and that
    relative size is not shrinking -- a stable scheme on a ramp from rest also grows, but its defect falls
    behind the signal).  Sustained: a growth that a nonlinearity (valve flow, rails) has bounded, a limit
    cycle whose relative defect stays >= 0.1 over SUSTAINED windows without the envelope halving.
    """
    last = windows[-1]
    first = last.first_moving
    if first is not None and last.n_moving >= 6:
        growth = max(last.d, windows[-2].d) / first.d
        if growth >= 30.0 and last.rel >= 0.2 and last.rel >= 0.5 * first.rel:
            return growth
    # jumps: in 3 windows running, with the envelope not falling, an interface value moved by more than
    # its own recent peak within one macro step (a motion from rest does so in its first window at most)
    if last.jumps >= 3 and last.run >= 2:
        return last.env / max(windows[-1 - min(last.run, len(windows) - 1)].env, REST)
    if last.sustained >= SUSTAINED and len(windows) > SUSTAINED:
        then = windows[-1 - SUSTAINED].env
        if last.env >= 0.5 * then:
            return last.env / max(then, REST)
    return 0.0


def _growing(windows) -> bool:
    return bool(windows) and windows[-1].run >= 2 and windows[-1].rel >= 0.1


def _halves(recent):
    r = list(recent)
    h = len(r) // 2
    return r[:h], r[h:]


def _growing_steps(recent) -> bool:
    """The defect of the latest macro steps is >= 10x that of the ones before and a sizeable part of the signal."""
    if len(recent) < 4:
        return False
    a, b = _halves(recent)
    top = max(b, key=lambda x: x[0])
    return top[0] >= 10 * max(max(x[0] for x in a), 1e-300) and top[2] >= 0.1


def _explosive(recent) -> bool:
    """The coupled signals grew >= 4x on each of the last 4 macro steps, with a defect as large as half the
    signal: geometric growth that no polynomial ramp from rest shows (t^5 grows 3.05x from its 4th to 5th
    step), so the coupling itself amplifies.  (A physically unstable system would be flagged too: switch
    detection off for it.)"""
    if len(recent) < 5:
        return False
    r = list(recent)[-5:]
    return (r[0][1] > 0 and all(b[1] >= 4 * a[1] for a, b in zip(r, r[1:])) and r[-1][2] >= 0.5
            and r[-1][1] >= 1e-3)  # above round-off: signals are scaled by their nominal values


def run(system, scheme: str = "gauss-seidel", extrapolation: str = "hold", step: Optional[float] = None,
        adaptive: bool = False, tol: float = 1e-4, stop: Optional[float] = None,
        order: Optional[Sequence[str]] = None, workers: int = 1, **options) -> CosimResult:
    """Co-simulate ``system`` (a :class:`CosimSystem`, or a scene: it is built into a temporary folder).

    scheme: ``jacobi`` | ``gauss-seidel`` | ``iterative`` | ``newton``;
    extrapolation: ``hold`` | ``linear`` | ``quadratic`` | ``cubic`` (iterated
    schemes only); step: macro step H [s] (default ``system.step``); adaptive:
    control H by the interface defect to ``tol`` (relative to each coupled
    signal's magnitude) between ``min_step`` and ``max_step``; stop: stop time
    [s] (default ``system.stop_time``); workers: threads that step the FMUs
    side by side under Jacobi and the iterated schemes (results are identical
    to one thread; worth it when a macro step costs well above the ~50 us a
    thread hand-over costs).  Further options: ``min_step``, ``max_step``,
    ``coupling_tol`` (iterative, newton), ``max_iterations``,
    ``detect_divergence``.

    Returns a :class:`CosimResult` (``time``, ``values`` per column,
    ``summary``); a run that fails returns its values up to the failure and
    ``summary.failure``.
    """
    if not isinstance(system, CosimSystem) and hasattr(system, "build"):
        import tempfile

        system = system.build(tempfile.mkdtemp(prefix="fmugen_scene_")).system
    with Master(system, scheme, extrapolation, order=order, workers=workers) as m:
        return m.run(step=step, stop=stop, adaptive=adaptive, tol=tol, **options)
