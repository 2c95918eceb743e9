"""The scene's initial state: as given, or at rest where the scene holds still.

``initial = "equilibrium"`` solves f(t0, x, u) = 0 on the monolithic model
by Newton's method with its exact Jacobian.  Unknowns are all states except
those an instance ``hold``s; the start values are the first guess.  Steps
are least-squares solutions (minimum-norm corrections), so directions the
equations leave free -- a joint whose position nothing fixes -- stay at
their guesses.  The arm comes out held against gravity at its start pose
(within the position error a P loop needs), each chain with the load
pressure, spool position and current that produce that torque, and PI
integrators with the value that makes the error vanish.

No equilibrium -- Newton not converging, or converging outside a state's
declared range -- is refused, naming the equation with the largest residual.

The physics check.  A state of rest that is unstable runs away whatever
couples it (a sign error in a position loop: the joint leaves for -87 rad in
3 s), so the build says so: the growing modes of the linearisation there
(:func:`unstable_modes`), their time to double and dominant states.  It is
made at the solved equilibrium, and at given start values whenever those
are a state of rest themselves (every derivative below
:data:`REST_TOLERANCE` times its state's nominal per second); given start
values that are not at rest are said to be so, in one line -- stability is
then not judged (a linearisation away from rest says nothing about
runaway).  A model with sampled (discrete) states is not judged either: its
loops close through the discrete states, which a continuous linearisation
holds fixed.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..codegen.evaluate import ModelEvaluator
from .errors import SceneError


@dataclass
class InitialState:
    model: object  # the monolithic SymbolicModel
    values: dict  # state name "inst.var" -> value
    mode: str = "given"
    residual: float = 0.0  # max |f_i| * scale_i at the solution (equilibrium)
    iterations: int = 0
    changes: dict = field(default_factory=dict)  # state -> (guess, solution) for the report
    unstable: list = field(default_factory=list)  # the state of rest's unstable modes (sentences), if any
    note: str = ""  # why stability was not judged (given start values not at rest, sampled states), if so

    def report(self) -> str:
        if self.mode == "given":
            lines = ["initial state: as given (start values)"]
            lines += [f"  {self.note}"] if self.note else []
            lines += [f"warning: the state of rest is unstable: {u}" for u in self.unstable]
            return "\n".join(lines)
        lines = [f"initial state: equilibrium after {self.iterations} Newton iterations, "
                 f"scaled residual {self.residual:.1e}"]
        for k, (a, b) in self.changes.items():
            lines.append(f"  {k}: {a:.6g} -> {b:.9g}")
        if self.note:
            lines.append(f"  {self.note}")
        for u in self.unstable:
            lines.append(f"warning: the state of rest is unstable: {u}")
        return "\n".join(lines)


#: given start values are a state of rest when every derivative is at most this many times its state's
#: nominal per second -- the residual an equilibrium is accepted with (:func:`solve_equilibrium`'s stall_tol)
REST_TOLERANCE = 1e-6


def initial_state(scene) -> InitialState:
    model = scene.monolithic_model()
    x = np.array([v.start if v.start is not None else 0.0 for v in model.states], dtype=float)
    values = {v.name: float(x[k]) for k, v in enumerate(model.states)}
    if scene.spec.initial == "given":
        return given_state(scene, model, x, values)
    return solve_equilibrium(scene, model, x)


def _sampled(model) -> bool:
    return model.events is not None and bool(tuple(model.events.discrete))


def given_state(scene, model, x, values) -> InitialState:
    """The given start values; their stability judged when they are a state of rest (see the module)."""
    init = InitialState(model, values)
    if not model.nx:
        return init
    nom = np.array([abs(v.nominal) if v.nominal else 1.0 for v in model.states])
    names = [v.name for v in model.states]
    u = np.array([v.start if v.start is not None else 0.0 for v in model.inputs], dtype=float)
    t0 = scene.spec.start
    try:
        ev = ModelEvaluator(model)
        with np.errstate(all="ignore"):
            f = np.asarray(ev.f(t0, x, u), dtype=float)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError, KeyError, TypeError, NotImplementedError,
            RecursionError) as exc:  # a check, not a gate: the build goes on and says why it was not made
        init.note = (f"stability not judged: the model cannot be evaluated at the start values "
                     f"({type(exc).__name__}: {str(exc).splitlines()[0][:120] if str(exc) else ''})")
        return init
    if not np.all(np.isfinite(f)):
        bad = names[int(np.argmax(~np.isfinite(f)))]
        init.note = f"the start values are not a state of rest (der({bad}) is not finite): stability not judged"
        return init
    r = np.abs(f) / nom
    worst = int(np.argmax(r))
    if r[worst] > REST_TOLERANCE:
        init.note = (f"the start values are not a state of rest (largest derivative der({names[worst]}) = "
                     f"{f[worst]:.3g}, {r[worst]:.3g} x its nominal {nom[worst]:g} per s): stability not judged")
        return init
    if _sampled(model):
        init.note = ("the start values are a state of rest; stability not judged: the model's sampled "
                     "(discrete) states close loops a continuous linearisation holds fixed")
        return init
    try:
        with np.errstate(all="ignore"):
            A = ev.jacobians(t0, x, u)[0]
    except (ValueError, ArithmeticError, np.linalg.LinAlgError, TypeError) as exc:
        init.note = f"stability not judged: no Jacobian at the start values ({type(exc).__name__})"
        return init
    init.unstable = unstable_modes(A, names, nom)
    if not init.unstable:
        init.note = "the start values are a state of rest with no growing mode (linearised there)"
    return init


def solve_equilibrium(scene, model, x0, max_iter: int = 60, tol: float = 1e-10,
                      stall_tol: float = 1e-6, evaluator=None) -> InitialState:
    # evaluator: a ModelEvaluator of ``model`` to reuse (a sweep changes its parameter vector per point
    # instead of compiling the model again)
    ev = ModelEvaluator(model) if evaluator is None else evaluator
    t0 = scene.spec.start
    u = np.array([v.start if v.start is not None else 0.0 for v in model.inputs], dtype=float)
    names = [v.name for v in model.states]
    held = {f"{inst}.{h}" for inst, ins in scene.spec.instances.items() for h in ins.hold}
    free = np.array([k for k, n in enumerate(names) if n not in held], dtype=int)
    # residual scale: a state's rate in units of its nominal per second
    nom = np.array([abs(v.nominal) if v.nominal else 1.0 for v in model.states])
    x = np.array(x0, dtype=float)
    f = ev.f(t0, x, u)
    r = np.max(np.abs(f) / nom) if len(f) else 0.0
    it = 0
    while r > tol and it < max_iter:
        A = ev.jacobians(t0, x, u)[0][:, free]
        dx = np.linalg.lstsq(A / nom[:, None], -f / nom, rcond=None)[0]
        # damped step: halve until the residual falls
        lam = 1.0
        while lam > 1e-6:
            xn = x.copy()
            xn[free] += lam * dx
            fn = ev.f(t0, xn, u)
            rn = np.max(np.abs(fn) / nom) if np.all(np.isfinite(fn)) else np.inf
            if rn < r:
                break
            lam /= 2
        else:
            break
        x, f, r = xn, fn, rn
        it += 1
    where = f"{scene.src}: [scene] initial = \"equilibrium\""
    # Newton stalls at the round-off floor of f (the light PUMA wrist: cond(M) ~ 4e5): accept
    # a residual there, still a million times below any rate the run resolves
    if not np.isfinite(r) or r > max(tol, stall_tol):
        worst = int(np.argmax(np.abs(f) / nom))
        raise SceneError(f"{where}: no state of rest found ({it} Newton iterations, scaled residual {r:.2e}; "
                         f"largest in der({names[worst]}) = {f[worst]:.3g}). The scene cannot hold still here -- "
                         f"e.g. a load above an actuator's stall torque (P_s D_m) or a pose no actuator holds")
    for v, val in zip(model.states, x):
        if (v.min is not None and val < v.min) or (v.max is not None and val > v.max):
            raise SceneError(f"{where}: the state of rest has {v.name} = {val:.6g}, outside its range "
                             f"[{v.min}, {v.max}]: no valid equilibrium (e.g. a load above the stall torque)")
    _check_hydraulics(scene, model, x, where)
    values = {n: float(val) for n, val in zip(names, x)}
    changes = {n: (float(a), float(b)) for n, a, b in zip(names, x0, x) if abs(a - b) > 1e-12 * max(1, abs(a))}
    unstable = unstable_modes(ev.jacobians(t0, x, u)[0], names, nom)
    return InitialState(model, values, "equilibrium", float(r), it, changes, unstable)


def unstable_modes(A, names, nominal, top: int = 3) -> list:
    """Sentences naming the modes of x' = A x with a growing amplitude (Re lambda > 0 beyond round-off), each
    with its time to double and its dominant states (largest entries of the eigenvector in units of each
    state's nominal).  A system that is unstable at rest runs away whatever couples it: a co-simulation that
    diverges from it diverges by physics, not by its macro step."""
    A = np.asarray(A, dtype=float)
    if not A.size or not np.all(np.isfinite(A)):
        return []
    lam, V = np.linalg.eig(A)
    big = float(np.max(np.abs(lam))) if len(lam) else 0.0
    out = []
    seen = set()
    for k in np.argsort(-lam.real):
        a = float(lam[k].real)
        if a <= max(1e-9 * big, 1e-9):
            break
        key = (round(a, 9), round(abs(float(lam[k].imag)), 9))
        if key in seen:  # the conjugate of a pair already named
            continue
        seen.add(key)
        w = np.abs(V[:, k]) / np.asarray(nominal, dtype=float)
        w = w / (w.max() or 1.0)
        dom = [names[i] for i in np.argsort(-w)[:top] if w[i] > 1e-3]
        b = float(lam[k].imag)
        mode = f"lambda = {a:.4g}" + (f" +/- {abs(b):.4g}i" if abs(b) > 1e-12 * big else "")
        out.append(f"mode {mode} 1/s (doubles every {np.log(2) / a:.3g} s), dominant states "
                   f"{', '.join(dom)}: the system itself runs away from rest (check signs and gains of "
                   f"its feedback loops)")
    return out


def _check_hydraulics(scene, model, x, where) -> None:
    """Load pressures beyond the supply, or a spool beyond its stroke, are no state of rest."""
    params = {v.name: v.start for v in model.parameters}
    for k, v in enumerate(model.states):
        inst, var = v.name.split(".", 1)
        if var == "P_L":
            ps = [params.get(f"{i}.P_s") for i in scene.spec.instances if params.get(f"{i}.P_s")]
            P_s = max(ps) if ps else None
            if P_s and abs(x[k]) >= P_s:
                raise SceneError(f"{where}: holding still needs {v.name} = {x[k]:.4g} Pa, beyond the supply "
                                 f"pressure {P_s:.4g} Pa: the load is above the actuator's stall torque")
        if var == "x_v" and abs(x[k]) > 1.0:
            raise SceneError(f"{where}: holding still needs {v.name} = {x[k]:.4g}, beyond the spool's stroke "
                             f"(|x_v| <= 1): the load is above what the valve can hold")
