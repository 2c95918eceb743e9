"""The largest macro step at which held-input Jacobi is stable, from the scene's linearisation.

Held-input Jacobi -- every FMU steps from the values at t_n, its inputs held
over the step -- is the loop of most FMI importers (libcosim's fixed-step
algorithm, FMPy's ``simulate_ssp``).  Linearised at the scene's initial state,
x' = A x with A the monolithic model's exact Jacobian, the FMU groups split A
into diagonal blocks A_kk (inside an FMU) and off-diagonal blocks A_kj = B_k C_j
(group j's outputs driving group k's inputs).  One macro step H of the
scheme is then exactly

    x_k(t_n+1) = exp(A_kk H) x_k(t_n) + [integral_0^H exp(A_kk s) ds] sum_j A_kj x_j(t_n),

and the scheme is stable while the spectral radius of that map is no larger
than the exact flow's, exp(A H) (modes at rest -- a free joint angle -- stay
at 1 in both).  :func:`jacobi_hold_limit` bisects H to 1 %.

What it does not see: the linearisation holds near the initial state only
(the PUMA's inertia changes with its pose), and a coupling through direct
feedthrough (an output of one FMU that depends on its input) is taken as
exact where Jacobi delays it by a step.  It is a limit, not a promise of
accuracy: stable steps can still be far off (see ``fmugen report``).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
import scipy.linalg as sl

#: relative margin on the spectral radius: round-off in expm, marginal modes at exactly 1
_MARGIN = 1e-7


def _blocks(scene, model) -> list:
    """State indices of each FMU group, in the monolithic model's state order."""
    groups = {}
    for k, v in enumerate(model.states):
        inst = v.name.split(".", 1)[0]
        groups.setdefault(scene.group_of(inst), []).append(k)
    return [np.array(ix, dtype=int) for ix in groups.values()]


def jacobi_map(A: np.ndarray, blocks: list, H: float) -> np.ndarray:
    """The held-input Jacobi macro-step matrix of x' = A x split into ``blocks`` (state index arrays)."""
    n = len(A)
    Z = np.zeros((n, n))
    for ix in blocks:
        m = len(ix)
        # [[A_kk H, I H], [0, 0]]: exp gives exp(A_kk H) and its integral in one call
        M = np.zeros((2 * m, 2 * m))
        M[:m, :m] = A[np.ix_(ix, ix)] * H
        M[:m, m:] = np.eye(m) * H
        E = sl.expm(M)
        Phi, Gam = E[:m, :m], E[:m, m:]
        coupling = A[ix, :].copy()
        coupling[:, ix] = 0.0
        Z[ix, :] = Gam @ coupling
        Z[np.ix_(ix, ix)] = Phi
    return Z


def _stable(A, blocks, H) -> bool:
    rho_j = max(abs(np.linalg.eigvals(jacobi_map(A, blocks, H))))
    rho_x = max(abs(np.linalg.eigvals(sl.expm(A * H))))
    return bool(np.isfinite(rho_j)) and rho_j <= max(1.0, rho_x) * (1 + _MARGIN)


def jacobi_hold_limit(scene, h_max: Optional[float] = None, rel: float = 0.01) -> float:
    """First unstable macro step of held-input Jacobi on ``scene`` [s] (``math.inf``: stable up to
    ``h_max``, default the run's length; one group: ``inf``)."""
    from ..codegen.evaluate import ModelEvaluator

    model = scene.initial.model
    blocks = _blocks(scene, model)
    if len(blocks) < 2 or not model.states:
        return math.inf
    x0 = np.array([scene.initial.values[v.name] for v in model.states])
    u = np.array([v.start if v.start is not None else 0.0 for v in model.inputs])
    A = np.asarray(ModelEvaluator(model).jacobians(scene.spec.start, x0, u)[0], dtype=float)
    h_max = float(h_max or (scene.spec.stop - scene.spec.start))
    lo = hi = None
    H = scene.spec.step
    if _stable(A, blocks, H):
        lo = H
        while hi is None:
            H *= 2
            if H > h_max:
                return math.inf
            if _stable(A, blocks, H):
                lo = H
            else:
                hi = H
    else:
        hi = H
        while lo is None:
            H /= 2
            if H < 1e-9:
                return 0.0
            if _stable(A, blocks, H):
                lo = H
            else:
                hi = H
    while hi - lo > rel * lo:
        mid = 0.5 * (lo + hi)
        if _stable(A, blocks, mid):
            lo = mid
        else:
            hi = mid
    return hi


def stable_step(limit: float, step: float, safety: float = 0.5) -> float:
    """``step`` if it is below ``safety`` x ``limit``, else the largest 1-2-5 x 10^k step below that
    (so that an importer's integer clock -- libcosim counts nanoseconds -- holds it exactly)."""
    if not math.isfinite(limit) or step <= safety * limit:
        return step
    target = safety * limit
    e = math.floor(math.log10(target))
    for mant in (5, 2, 1):
        h = mant * 10.0 ** e
        if h <= target:
            return float(f"{h:.1e}")
    return float(f"{10.0 ** (e - 1) * 5:.1e}")
