"""Operating points found, not hand-computed: ``fmugen.trim``.

An operating point (trim, equilibrium) of x' = f(t, x, u), y = g(t, x, u) is
a pair (x0, u0) with

    f(t, x0, u0) = 0                         (every state at rest)
    g_j(t, x0, u0) = y_j        for the outputs j whose values are given,

where some states and inputs are *given* (held at a value) and the others
are *free* (solved for).  Examples:

* the arm held at a pose: q and qd given, tau free -> tau = g(q), the gravity
  torque (12 equations, 6 unknowns: der(q) = qd = 0 holds by itself);
* a hydraulic joint holding a load: the reference and the load torque given,
  every state free -> P_L = tau_load/D_m, the spool opening that meters the
  leakage, the current and amplifier voltage behind it, the joint's offset.

The equations are solved with their exact Jacobian (the model's Jacobian
program).  A square system (as many equations as unknowns) goes to
python-control's ``control.find_operating_point`` (Powell's hybrid method,
with the exact Jacobian passed through ``root_kwargs``); an over-determined
one -- which ``find_operating_point`` only warns about ("results may be
meaningless") -- to a Levenberg-Marquardt least-squares solve
(``scipy.optimize.least_squares``), since a consistent over-determined
system is the normal case for a held arm.  An under-determined problem is
refused before solving.

The residual is reported scaled: equation i is divided by
s_i = sum_j |df_i/dv_j| v_j at the initial point (v_j the variable's nominal
value, or max(|start|, 1)), the size of the change a nominal move of every
variable makes in it -- dimensionless, so pressures in Pa and spool strokes in
1 are judged alike.  Where the scaled residual stays above ``tol`` there is
no operating point near the guess: :class:`TrimError` says so, with the worst
equations, and carries the best point found.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Mapping, Optional, Sequence

import numpy as np

from ..codegen.evaluate import ModelEvaluator
from .linearize import as_model
from .names import _ELEMENT, FmugenError, check_signal_names, lookup


class TrimError(FmugenError):
    """No operating point satisfies the conditions (or the request is ill-posed).

    ``operating_point`` holds the best point found (or None), with its
    residual, when the solver ran.
    """

    def __init__(self, message: str, operating_point=None):
        super().__init__(message)
        self.operating_point = operating_point


@dataclass
class OperatingPoint:
    """A solved operating point of a model (FMI names throughout).

    x, u: state and input vectors in model order [model units]; y: computed
    outputs g(t, x, u).  ``residual``: the equations' scaled residuals (see
    module doc), named by ``equations``; ``free``/``given``: FMI names of
    the solved and the held variables.  ``op["q"]`` or ``op["valve.x_v"]``
    reads values by name (base names give arrays).
    """

    model_name: str
    states: list
    inputs: list
    outputs: list
    x: np.ndarray
    u: np.ndarray
    y: np.ndarray
    t: float = 0.0
    parameter_values: dict = field(default_factory=dict)
    free: list = field(default_factory=list)
    given: list = field(default_factory=list)
    equations: list = field(default_factory=list)
    residual: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rank: int = 0
    method: str = ""
    evaluations: int = 0

    @property
    def max_residual(self) -> float:
        return float(np.max(np.abs(self.residual))) if self.residual.size else 0.0

    def _value(self, name: str) -> float:
        for names, values in ((self.states, self.x), (self.inputs, self.u), (self.outputs, self.y)):
            if name in names:
                return float(values[names.index(name)])
        raise KeyError(name)

    def __getitem__(self, name: str):
        from .names import signal_name

        for names in (self.states, self.inputs, self.outputs):
            for n in names:
                if name in (n, signal_name(n)):
                    return self._value(n)
        elems = sorted((int(m.group(2)), n) for names in (self.states, self.inputs, self.outputs) for n in names
                       for m in [_ELEMENT.match(n)] if m and name in (m.group(1), signal_name(m.group(1))))
        if not elems:
            raise KeyError(f"{self.model_name}: no state, input or output named {name!r}")
        return np.array([self._value(n) for _, n in elems])

    def worst(self, k: int = 3) -> list:
        """The k equations with the largest scaled residual: [(name, residual)]."""
        order = np.argsort(-np.abs(self.residual))[:k]
        return [(self.equations[i], float(self.residual[i])) for i in order]

    def report(self) -> str:
        lines = [f"operating point of {self.model_name} ({self.method}, {self.evaluations} evaluations): "
                 f"max scaled residual {self.max_residual:.3g}"]
        n_free = len(self.free)
        if self.rank < n_free:
            lines.append(f"  warning: the Jacobian w.r.t. the {n_free} free variables has rank {self.rank}: "
                         f"the point is not unique")
        for n in self.free:
            lines.append(f"  {n} = {self._value(n):.10g}  (solved)")
        return "\n".join(lines)


def _expand(model, at: Optional[Mapping], kinds) -> dict:
    """{Signal: value} from a mapping of names to scalars or sequences."""
    out = {}
    for name, value in (at or {}).items():
        sigs = lookup(model, name, kinds)
        vals = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
        if vals.size == 1:
            vals = np.full(len(sigs), vals[0])
        if vals.size != len(sigs):
            raise FmugenError(f"{model.name}: {name!r} has {len(sigs)} element(s) "
                              f"({', '.join(s.name for s in sigs)}) but {vals.size} values were given")
        if not np.all(np.isfinite(vals)):
            raise FmugenError(f"{model.name}: {name!r}: values must be finite, got {vals.tolist()}")
        for s, v in zip(sigs, vals):
            out[s] = float(v)
    return out


def trim(source, at: Optional[Mapping] = None, free: Sequence[str] = (), *,
         guess: Optional[Mapping] = None, parameter_values: Optional[Mapping[str, float]] = None,
         t: float = 0.0, tol: float = 1e-9, evaluator: Optional[ModelEvaluator] = None) -> OperatingPoint:
    """Solve for an operating point of ``source`` (a SymbolicModel or a scene).

    at: {name: value(s)} -- states and inputs held at these values, outputs
        required to take them.  Names are FMI names (``q[2]``,
        ``valve.x_v``), python-control names (``valve_x_v``) or base names
        of vectors (``q`` with 6 values, or one value for all).
    free: states and inputs to solve for even though ``at`` (or their start
        value) gives them; their ``at`` value is the initial guess.  States
        that ``at`` does not give are always free; inputs are free only when
        listed here.
    guess: {name: value(s)} initial guesses of free variables (default:
        ``at`` values, else start values).
    tol: largest accepted scaled residual (see module doc).

    Returns an :class:`OperatingPoint`; raises :class:`TrimError` when the
    problem is under-determined or no point satisfies it.
    """
    model = as_model(source)
    check_signal_names(model)
    ev = evaluator if evaluator is not None else ModelEvaluator(model, parameter_values)
    nx, nu, ny = model.nx, model.nu, model.ny
    given = _expand(model, at, ("state", "input", "output"))
    freed = [s for n in (free or ()) for s in lookup(model, n, ("state", "input", "output"))]
    bad = [s.name for s in freed if s.kind == "output"]
    if bad:
        raise TrimError(f"{model.name}: outputs cannot be free ({', '.join(bad)}); give an output a value "
                        f"with at= and free an input or state instead")
    x, u = ev.x0.copy(), ev.u0.copy()
    for s, v in _expand(model, guess, ("state", "input")).items():
        (x if s.kind == "state" else u)[s.index] = v
    for s, v in given.items():  # after the guesses: a given value wins
        if s.kind == "state":
            x[s.index] = v
        elif s.kind == "input":
            u[s.index] = v
    held_x = {s.index for s in given if s.kind == "state"} - {s.index for s in freed if s.kind == "state"}
    fs = [i for i in range(nx) if i not in held_x]
    fu = sorted({s.index for s in freed if s.kind == "input"})
    fy = sorted(s.index for s in given if s.kind == "output")
    y_target = np.zeros(ny)
    for s, v in given.items():
        if s.kind == "output":
            y_target[s.index] = v
    n_unknown, n_eq = len(fs) + len(fu), nx + len(fy)
    free_names = [model.states[i].name for i in fs] + [model.inputs[i].name for i in fu]
    given_names = ([model.states[i].name for i in sorted(held_x)]
                   + [v.name for i, v in enumerate(model.inputs) if i not in fu]
                   + [model.outputs[i].name for i in fy])
    if n_unknown > n_eq:
        raise TrimError(f"{model.name}: under-determined: {n_unknown} free variables "
                        f"({', '.join(free_names)}) but {n_eq} equations (every der(x) = 0"
                        f"{', ' + str(len(fy)) + ' given outputs' if fy else ''}); give values to "
                        f"{n_unknown - n_eq} more state(s)/input(s) or outputs")
    equations = [f"der({v.name})" for v in model.states] + [f"{model.outputs[j].name} (given)" for j in fy]

    # equation scales s_i = sum_j |dF_i/dv_j| v_j at the initial point (module doc)
    def nominal(v, value):
        return abs(v.nominal) if v.nominal else max(abs(value), 1.0)

    vx = np.array([nominal(v, x[i]) for i, v in enumerate(model.states)])
    vu = np.array([nominal(v, u[i]) for i, v in enumerate(model.inputs)])
    A, B, C, D = ev.jacobians(t, x, u)
    s_f = np.abs(A) @ vx + np.abs(B) @ vu
    s_y = (np.abs(C) @ vx + np.abs(D) @ vu)[fy]
    scale = np.concatenate([s_f, s_y])
    scale[~(scale > 0) | ~np.isfinite(scale)] = 1.0

    def unpack(z):
        xz, uz = x.copy(), u.copy()
        xz[fs] = z[: len(fs)]
        uz[fu] = z[len(fs):]
        return xz, uz

    count = [0]

    def residual(z):
        count[0] += 1
        xz, uz = unpack(z)
        r = np.concatenate([ev.f(t, xz, uz), ev.g(t, xz, uz)[fy] - y_target[fy]])
        return r / scale

    def jacobian(z):
        xz, uz = unpack(z)
        A, B, C, D = ev.jacobians(t, xz, uz)
        J = np.vstack([np.hstack([A[:, fs], B[:, fu]]), np.hstack([C[fy][:, fs], D[fy][:, fu]])])
        return J / scale[:, None]

    z0 = np.concatenate([x[fs], u[fu]])
    method, z = ("the initial point" if n_unknown else "nothing free"), z0
    if n_unknown == n_eq and n_unknown:
        z, method = _solve_square(model, ev, t, x, u, fs, fu, fy, y_target, scale, jacobian, nx, ny,
                                  count)
    if n_unknown and (z is None or not np.all(np.isfinite(residual(z)))
                      or np.max(np.abs(residual(z))) > tol):
        from scipy.optimize import least_squares

        ls = least_squares(residual, z0, jac=jacobian, method="lm" if n_eq >= n_unknown else "trf",
                           xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200 * (n_unknown + 1))
        method = ("Levenberg-Marquardt least squares" if n_unknown < n_eq
                  else method + ", then Levenberg-Marquardt least squares")
        z = ls.x
    r = residual(z) if n_unknown else residual(z0)
    xs, us = unpack(z)
    rank = int(np.linalg.matrix_rank(jacobian(z))) if n_unknown else 0
    op = OperatingPoint(model.name, [v.name for v in model.states], [v.name for v in model.inputs],
                        [v.name for v in model.outputs], xs, us, ev.g(t, xs, us), t,
                        dict(parameter_values or {}), free_names, given_names, equations, r, rank, method,
                        count[0])
    if not np.all(np.isfinite(r)) or op.max_residual > tol:
        worst = "; ".join(f"{n}: {v:.3g}" for n, v in op.worst())
        raise TrimError(f"{model.name}: no operating point found: the scaled residual stays at "
                        f"{op.max_residual:.3g} > tol = {tol:g} (worst: {worst}) with "
                        f"{', '.join(given_names) or 'nothing'} held; the conditions cannot all be met "
                        f"(e.g. a load beyond what the actuator can hold) or the guess is too far", op)
    return op


def _solve_square(model, ev, t, x, u, fs, fu, fy, y_target, scale, jacobian, nx, ny, count):
    """python-control's find_operating_point on the scaled equations, exact Jacobian."""
    import control

    s_f, s_y = scale[:nx], np.ones(ny)
    s_y[fy] = scale[nx:]

    def rhs(t_, x_, u_, p_):
        count[0] += 1
        return ev.f(t_, x_, u_) / s_f

    sys = control.nlsys(rhs,
                        lambda t_, x_, u_, p_: ev.g(t_, x_, u_) / s_y,
                        states=model.nx, inputs=model.nu, outputs=ny, name="trim")
    ix = [i for i in range(nx) if i not in fs]
    iu = [i for i in range(model.nu) if i not in fu]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # hybr's "not making good progress"
        # with no output given, find_operating_point (0.10.2) still counts every output as a
        # constraint in this warning although it does not evaluate them: the count is wrong, not the problem
        warnings.filterwarnings("ignore", "number of constraints", UserWarning)
        res = control.find_operating_point(
            sys, x, u, y0=(y_target / s_y) if fy else None, t=t,
            ix=ix or None, iu=iu or None, iy=fy or None, idx=list(range(nx)),
            root_method="hybr", root_kwargs={"jac": jacobian}, return_result=True)
    z = np.concatenate([np.asarray(res.states)[fs], np.asarray(res.inputs)[fu]])
    return z, "control.find_operating_point (hybr, exact Jacobian)"
