"""Physical plausibility checks for robot descriptions, and their errors.

Every problem is reported as a :class:`RobotFileError` whose message starts
with the place it was found, ``"<file>: link 2 (upper_arm): mass: ..."``.

Rigid-body realisability (the inertia tensor ``I_c`` about the centre of mass,
tensor convention ``I = int(|r|^2 E - r r^T) dm``, kg m^2):

* ``I_c`` is symmetric;
* ``I_c`` is positive semidefinite: its principal moments (eigenvalues)
  ``l1, l2, l3 >= 0``;
* the principal moments satisfy the triangle inequalities
  ``l1 + l2 >= l3`` (and permutations), because ``l1 + l2 - l3 = 2 int z^2 dm``
  in principal axes;
* a body of zero mass has zero inertia.

Both inequalities are tested with the relative tolerance
:data:`INERTIA_RTOL` of the largest principal moment, so that published data
rounded to a few digits (a thin disc with ``Ix + Iy = Iz``) pass.
"""
from __future__ import annotations

import numpy as np
import sympy as sp

INERTIA_RTOL = 1e-6


class RobotFileError(ValueError):
    """A robot file (or description) is malformed or physically impossible."""


class UnrealisableInertiaWarning(UserWarning):
    """A link's inertia is not realisable but the file explicitly allows it."""


def where(file, link: int | None = None, link_name: str | None = None, field: str | None = None) -> str:
    """Location prefix of a message: ``file: link i (name): field``."""
    parts = [str(file)]
    if link is not None:
        parts.append(f"link {link} ({link_name})" if link_name else f"link {link}")
    if field:
        parts.append(field)
    return ": ".join(parts)


def numeric(expr, values: dict) -> float | None:
    """Value of ``expr`` with ``values`` substituted, or None if still symbolic."""
    e = sp.sympify(expr)
    if values:
        e = sp.sympify(e.xreplace(values))  # a bare symbol is replaced by a Python float
    if e.free_symbols:
        return None
    return float(e)


def numeric_matrix(rows, values: dict):
    """A 3x3 numpy array of ``rows`` after substitution, or None if symbolic."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            v = numeric(rows[i][j], values)
            if v is None:
                return None
            out[i, j] = v
    return out


def check_finite(value: float, location: str) -> None:
    if not np.isfinite(value):
        raise RobotFileError(f"{location}: non-finite value {value}")


def check_nonnegative(expr, values: dict, location: str, what: str, unit: str) -> None:
    """Refuse a negative ``expr`` (checked when its value is known)."""
    v = numeric(expr, values)
    if v is not None and v < 0:
        raise RobotFileError(f"{location}: negative {what} {v:g} {unit}")


def check_symmetric(rows, location: str) -> None:
    """Refuse a 3x3 matrix whose transpose differs (symbolically) from it."""
    for i in range(3):
        for j in range(i + 1, 3):
            if sp.simplify(rows[i][j] - rows[j][i]) != 0:
                raise RobotFileError(
                    f"{location}: inertia matrix is not symmetric: "
                    f"[{i}][{j}] = {rows[i][j]} but [{j}][{i}] = {rows[j][i]}"
                )


def inertia_problems(mass: float, inertia_com: np.ndarray, rtol: float = INERTIA_RTOL) -> list:
    """Reasons why (mass, inertia about the COM) is not a rigid body; [] if it is."""
    problems = []
    I = np.asarray(inertia_com, dtype=float)
    if not np.allclose(I, I.T, rtol=0, atol=rtol * max(np.abs(I).max(), 1e-300)):
        problems.append(f"inertia about the centre of mass is not symmetric: {I.tolist()}")
        return problems
    if mass == 0:
        if np.any(I != 0):
            problems.append("zero mass but non-zero inertia")
        return problems
    lam = np.linalg.eigvalsh(0.5 * (I + I.T))
    tol = rtol * max(np.abs(lam).max(), 1e-300)
    eig_text = ", ".join(f"{x:.6g}" for x in lam)
    if lam[0] < -tol:
        problems.append(
            "inertia about the centre of mass is not positive semidefinite "
            f"(principal moments {eig_text} kg m^2)"
        )
    else:
        # principal moments sorted ascending: l0 + l1 >= l2 is the binding one
        if lam[0] + lam[1] < lam[2] - tol:
            problems.append(
                "principal moments of inertia violate the triangle inequality "
                f"{lam[0]:.6g} + {lam[1]:.6g} < {lam[2]:.6g} kg m^2 (principal moments {eig_text})"
            )
    return problems

