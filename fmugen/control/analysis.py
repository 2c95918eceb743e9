"""What a control designer reads first from (A, B, C, D): modes, stiffness, ranks.

Controllability and observability are judged mode by mode (the modal, or
Gilbert, test), not by the rank of [B, AB, ..., A^(n-1) B]: with eigenvalues
from 1e-2 to 1e4 rad/s (an arm on hydraulic actuators) the Krylov matrix
spans hundreds of decades and its numerical rank is meaningless; and the
PBH matrix [A - lambda I; C] is dominated by ||A|| there.  The state is
first divided by each state's nominal value (a diagonal similarity: the
modes do not change) so that pressures in Pa and spool strokes in 1 weigh
alike; then a mode is lost when its left eigenvector sees the inputs below
``tol`` ||B|| (right eigenvector and ||C|| for the outputs).  Groups of equal
eigenvalues (identical actuator chains) are tested as one eigenspace.

>>> import numpy as np
>>> A = np.diag([-1.0, -2.0]); B = np.array([[1.0], [0.0]]); C = np.array([[1.0, 1.0]])
>>> modal_ranks(A, B, C)
(1, 2)
"""
from __future__ import annotations

import numpy as np


def modes(A) -> list:
    """[(eigenvalue, damping ratio [1], natural frequency [rad/s])], slowest first.

    damping = -Re(lambda)/|lambda| (1 for a real stable pole, negative when
    unstable), frequency = |lambda|; a zero eigenvalue has damping nan.
    """
    ev = np.linalg.eigvals(np.asarray(A, dtype=float)) if np.size(A) else np.zeros(0)
    out = []
    for lam in sorted(ev, key=lambda z: (abs(z), z.imag)):
        w = abs(lam)
        out.append((complex(lam), (-lam.real / w) if w > 0 else float("nan"), w))
    return out


def stiffness_ratio(A) -> float:
    """max |Re lambda| / min |Re lambda| over the stable modes (Re lambda < 0).

    Modes on or right of the imaginary axis (to 1e-8 of the largest |lambda|)
    are left out: they set no time scale of decay.  inf if no stable mode.
    """
    ev = np.linalg.eigvals(np.asarray(A, dtype=float)) if np.size(A) else np.zeros(0)
    re = -ev.real
    if not re.size:
        return float("inf")
    stable = re[re > 1e-8 * max(np.abs(ev).max(), 1e-300)]  # rounding of a zero is ~1e-16 ||A||
    return float(stable.max() / stable.min()) if stable.size else float("inf")


def _scaled(A, B, C, state_scale=None):
    """x = T z: T = diag(state_scale) (the variables' nominal values), else a balancing T."""
    A, B, C = (np.asarray(M, dtype=float) for M in (A, B, C))
    if not A.size:
        return A, B, C
    if state_scale is None:
        from scipy.linalg import matrix_balance

        A, T = matrix_balance(A, permute=False)  # T^-1 A T, T diagonal
        t = np.diag(T)
    else:
        t = np.asarray(state_scale, dtype=float)
        A = A / t[:, None] * t[None, :]
    return A, B / t[:, None], C * t[None, :]


def _eigenspaces(A, rtol=1e-6):
    """[(left basis W, right basis V)] of the (geometric) eigenspace of each distinct eigenvalue.

    Eigenvalues closer than ``rtol`` |lambda| are one (identical chains give
    exact repeats, rounding splits them); the eigenspace is the null space of
    A - lambda I from its SVD (singular values below 1e-8 ||A||, at least
    one), so a Jordan block (an arm joint without gravity: a double
    integrator) has one eigenvector, not a spurious second one.
    """
    lam = np.linalg.eigvals(A)
    done = np.zeros(lam.size, bool)
    n = A.shape[0]
    out = []
    for k in range(lam.size):
        if done[k]:
            continue
        same = np.abs(lam - lam[k]) <= rtol * max(abs(lam[k]), 1.0)
        done |= same
        mult = int(same.sum())
        U, S, Vh = np.linalg.svd(A - lam[same].mean() * np.eye(n))
        g = max(1, min(mult, int(np.sum(S <= 1e-8 * max(S[0], 1e-300)))))
        out.append((U[:, n - g:], Vh[n - g:].conj().T))
    return out


def modal_ranks(A, B, C, tol: float = 1e-9, state_scale=None) -> tuple:
    """(controllability rank, observability rank) by the modal (Gilbert) test.

    For every distinct eigenvalue with orthonormal left/right eigenspace
    bases W, V (the PBH test done on the eigenspace): the directions lost to
    the inputs are the singular values of W^H B below ``tol`` ||B||, those
    lost to the outputs the singular values of C V below ``tol`` ||C||, on
    the state scaled by ``state_scale`` (nominal values; else balanced).
    The rank is n minus the lost directions.
    """
    A, B, C = _scaled(A, B, C, state_scale)
    n = A.shape[0]
    if n == 0:
        return 0, 0
    nB, nC = np.linalg.norm(B, 2), np.linalg.norm(C, 2)
    lost_c = lost_o = 0
    for W, V in _eigenspaces(A):
        g = W.shape[1]
        sc = np.linalg.svd(W.conj().T @ B, compute_uv=False) if B.size else np.zeros(0)
        so = np.linalg.svd(C @ V, compute_uv=False) if C.size else np.zeros(0)
        lost_c += g - int(np.sum(sc > tol * nB)) if nB > 0 else g
        lost_o += g - int(np.sum(so > tol * nC)) if nC > 0 else g
    return n - lost_c, n - lost_o
