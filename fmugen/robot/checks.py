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

from ..errors import InputFileError

INERTIA_RTOL = 1e-6
#: off-diagonal pairs of an inertia matrix in a file are equal when they agree
#: to this fraction of the largest entry (a tensor rotated in floating point
#: is symmetric to ~1e-16 only; data typed twice agree to every digit)
SYMMETRY_RTOL = 1e-9


class RobotFileError(InputFileError):
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


def check_symmetric(rows, location: str, values: dict | None = None, rtol: float = SYMMETRY_RTOL) -> None:
    """Refuse a 3x3 matrix whose transpose differs from it.

    Numeric entries are compared with the relative tolerance ``rtol`` of the
    matrix's largest entry: a tensor rotated in floating point is symmetric
    only to the last bit, and that is symmetric.  Symbolic entries must agree
    symbolically.  The message prints the numbers with all their digits.
    """
    nums = [[numeric(rows[i][j], values or {}) for j in range(3)] for i in range(3)]
    known = [abs(v) for row in nums for v in row if v is not None]
    scale = max(known) if known else 0.0
    for i in range(3):
        for j in range(i + 1, 3):
            a, b = nums[i][j], nums[j][i]
            if a is not None and b is not None:
                if abs(a - b) <= rtol * scale:
                    continue
                raise RobotFileError(
                    f"{location}: inertia matrix is not symmetric: [{i}][{j}] = {a!r} but [{j}][{i}] = {b!r} "
                    f"(differ by {abs(a - b):.3g}, more than {rtol:g} of the largest entry {scale!r})"
                )
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
    lam = np.linalg.eigvalsh(0.5 * I + 0.5 * I.T)  # no overflow for entries near the largest double
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



# --------------------------------------------------------------------------
# well-posedness of the whole chain: M(q) positive definite
# --------------------------------------------------------------------------
def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _trans(x, z):
    T = np.eye(4)
    T[0, 3], T[2, 3] = x, z
    return T


def mass_matrix_numeric(links: list, q, modified: bool, payload=None) -> np.ndarray:
    """M(q) of a chain from numbers only, by Jacobians (N x N, SI units).

    ``links``: dicts with ``prismatic, a, alpha, d, theta, mass, com (3,),
    inertia (3x3 about the COM, link-frame axes), rotor``; ``payload``:
    ``(mass, com)`` in the last frame or None.
    M = sum_i m_i Jv_i^T Jv_i + Jw_i^T R_i I_i R_i^T Jw_i, plus the rotor
    inertias on the diagonal.  A check, independent of the symbolic
    derivation: it is used only to decide whether M can be singular.
    """
    n = len(links)
    T = np.eye(4)
    axes, origins, frames = [], [], []
    for i, L in enumerate(links):
        theta = L["theta"] + (0.0 if L["prismatic"] else q[i])
        d = L["d"] + (q[i] if L["prismatic"] else 0.0)
        if modified:  # Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i); joint axis z_i
            T = T @ _rot_x(L["alpha"]) @ _trans(L["a"], 0.0) @ _rot_z(theta)
            axes.append(T[:3, 2].copy())
            origins.append(T[:3, 3].copy())
            T = T @ _trans(0.0, d)
        else:  # Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i); joint axis z_{i-1}
            axes.append(T[:3, 2].copy())
            origins.append(T[:3, 3].copy())
            T = T @ _rot_z(theta) @ _trans(0.0, d) @ _trans(L["a"], 0.0) @ _rot_x(L["alpha"])
        frames.append(T.copy())
    M = np.zeros((n, n))
    bodies = [(i, L["mass"], np.asarray(L["com"], float), np.asarray(L["inertia"], float))
              for i, L in enumerate(links)]
    if payload is not None:
        bodies.append((n - 1, payload[0], np.asarray(payload[1], float), np.zeros((3, 3))))
    for i, m, com, I in bodies:
        R, p = frames[i][:3, :3], frames[i][:3, :3] @ com + frames[i][:3, 3]
        Jv, Jw = np.zeros((3, n)), np.zeros((3, n))
        for j in range(i + 1):
            if links[j]["prismatic"]:
                Jv[:, j] = axes[j]
            else:
                Jv[:, j] = np.cross(axes[j], p - origins[j])
                Jw[:, j] = axes[j]
        M += m * Jv.T @ Jv + Jw.T @ (R @ I @ R.T) @ Jw
    M += np.diag([L["rotor"] for L in links])
    return M


def singular_joint(links: list, modified: bool, payload=None, rtol: float = 1e-10, seed: int = 9):
    """``(joint index, q)`` at which M(q) is singular, ``(-1, q)`` where it
    overflows double precision, or None.

    M is evaluated at q = 0 and at three seeded random configurations (a
    chain whose M is singular everywhere -- a joint that moves no mass, no
    inertia about its axis and no rotor -- is found at any of them).  The
    joint reported is the last one whose column is (nearly) dependent.
    """
    n = len(links)
    rng = np.random.default_rng(seed)
    for q in [np.zeros(n)] + [rng.uniform(-np.pi, np.pi, n) for _ in range(3)]:
        with np.errstate(over="ignore", invalid="ignore"):
            M = mass_matrix_numeric(links, q, modified, payload)
        if not np.all(np.isfinite(M)):
            return -1, q
        scale = np.abs(M).max()
        if scale == 0:
            return 0, q
        lam, vec = np.linalg.eigh(0.5 * (M / scale + (M / scale).T))
        if lam[0] <= rtol * lam[-1]:
            return int(np.argmax(np.abs(vec[:, 0]))), q
    return None


# --------------------------------------------------------------------------
# declared units against use: a [parameters] entry with a unit must fit the field
# --------------------------------------------------------------------------
class _UnitClash(Exception):
    pass


def _dimension(expr, declared: dict):
    """The BaseUnit (angles taken as plain numbers) of ``expr`` from the declared units of its
    symbols, None where it cannot be known -- a symbol without a declared unit, or a number other
    than +-1 (``2*l**2``: the 2 may be a mass in kg) --; :class:`_UnitClash` for a sum of unlike
    quantities or a function of a quantity with a unit."""
    from dataclasses import replace

    from ..fmi.units import BaseUnit

    e = sp.sympify(expr)
    if e in (sp.S.One, sp.S.NegativeOne) or isinstance(e, sp.NumberSymbol):
        return BaseUnit()
    if e.is_Number:  # a number in a robot file is an SI value of whatever unit it needs: unknown
        return None
    if e.is_Symbol:
        return declared.get(e)
    if e.is_Mul:
        out = BaseUnit()
        for a in e.args:
            d = _dimension(a, declared)
            if d is None:
                return None
            out = out * d
        return out
    if e.is_Pow:
        base, k = e.args
        d = _dimension(base, declared)
        if d is None or not k.is_Rational:
            return None
        if k.is_Integer:
            return d ** int(k)
        exps = {b: getattr(d, b) * k for b in ("kg", "m", "s", "A", "K", "mol", "cd")}
        if not all(v.is_Integer for v in exps.values()):
            raise _UnitClash(f"{base} ** {k} has no whole unit ([{_unit_text(d)}] to the power {k})")
        return replace(BaseUnit(**{b: int(v) for b, v in exps.items()}), factor=float(d.factor) ** float(k))
    if e.is_Add:
        dims = [_dimension(a, declared) for a in e.args]
        known = [(a, d) for a, d in zip(e.args, dims) if d is not None]
        for (a, d) in known[1:]:
            if not _same(d, known[0][1]):
                raise _UnitClash(f"it adds {known[0][0]} [{_unit_text(known[0][1])}] and {a} [{_unit_text(d)}]")
        return known[0][1] if len(known) == len(dims) else None
    if isinstance(e, sp.Function):
        for a in e.args:
            d = _dimension(a, declared)
            if d is not None and not _same(d, BaseUnit()):
                raise _UnitClash(f"the argument of {e.func} is in [{_unit_text(d)}], not a plain number")
        return BaseUnit()
    return None


def _same(a, b) -> bool:
    return all(getattr(a, k) == getattr(b, k) for k in ("kg", "m", "s", "A", "K", "mol", "cd")) \
        and abs(a.factor - b.factor) <= 1e-12 * max(abs(a.factor), abs(b.factor))


def _unit_text(d) -> str:
    parts = [f"{k}{'' if v == 1 else v}" for k in ("kg", "m", "s", "A", "K", "mol", "cd") if (v := getattr(d, k))]
    text = ".".join(parts) or "1"
    return text if d.factor == 1 else f"{d.factor:g} {text}"


def unit_problem(expr, unit: str, declared_units: dict) -> str | None:
    """Why ``expr`` (a field in ``unit``) does not fit the units its symbols were declared with
    (``declared_units``: symbol -> unit text), or None (also when a symbol has no declared unit).
    Angles count as plain numbers (rad = 1); a declared scale (g, mm, deg) must cancel out, as
    robot files hold SI values."""
    from dataclasses import replace

    from ..fmi.units import base_units

    declared = {}
    for s in sp.sympify(expr).free_symbols:
        if declared_units.get(s):
            declared[s] = replace(base_units(declared_units[s]), rad=0)
    if not declared:
        return None
    try:
        got = _dimension(expr, declared)
    except _UnitClash as exc:
        return f"{expr}: the declared units do not fit: {exc}"
    want = replace(base_units(unit), rad=0)
    if got is None or _same(got, want):
        return None
    names = ", ".join(f"{s} [{declared_units[s]}]" for s in sorted(declared, key=str))
    return (f"{expr} is in [{_unit_text(got)}] by the declared units ({names}), but this field is in [{unit}]"
            + (" (robot files hold SI values)" if got.factor != 1 and _same(replace(got, factor=1.0), want) else ""))
