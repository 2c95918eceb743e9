"""Unrolled forward dynamics: Featherstone's articulated-body algorithm as straight-line C for one robot.

The looped runtime (``c_runtime/chain_dynamics.c``) reads every placement, axis and inertia from
tables at run time and works in base coordinates, so each body costs the full 6x6 spatial
algebra.  For a given robot most of that algebra is known at generation time: placements are
mostly signed permutations with one or two non-zero offsets, joint axes are coordinate axes,
and a leaf's articulated inertia is a constant.  This module runs the three passes of the ABA
(Featherstone, *Rigid Body Dynamics Algorithms*, 2008, table 7.1) in Python over a tiny
expression type -- a value is a float constant or a named C scalar with a sign -- folding
0 x, 1 x, -x, x + 0 and constant (op) constant as it goes, and writes one C statement per
remaining sum of products.  Unused statements are dropped (liveness from the outputs), equal
ones shared (the statement's text is its key).  No sympy: a 100-body tree is generated in
well under a second.

Representation (chosen to keep the operations few):

* body frames: the general joint model of :mod:`fmugen.codegen.chain` (``F_i = F_parent P_i
  J(k_i, q_i)``) re-expressed in a frame ``B_i = F_i Q_i`` whose z axis is the joint axis
  (``Q_i e_z = k_i``; a signed permutation for a coordinate axis).  Then every joint is a
  rotation about or a translation along z, its motion subspace S_i is a unit vector
  (index 2 or 5), ``U_i = IA_i S_i`` is a column of IA_i and ``D_i`` one of its entries;
  the constant inertias and placements are rotated once, at generation time;
* spatial transforms are applied as stages -- translation by a constant offset, a constant
  rotation, the joint's rotation Rz(q) (or translation q e_z) -- each in 3-vector form, so
  a signed-permutation rotation costs nothing and an offset along one axis a few products;
* each frame's origin slides along its joint axis (free: it commutes with the joint) to cancel
  placement offsets; the frame's rotation about the axis is left as chosen by Q_i;
* articulated inertias are symmetric 6x6 (upper triangle computed, the lower mirrored), and
  after the projection ``Ia = IA - U U^T / D`` the row and column of the joint's own
  coordinate are exactly zero without rotor inertia (``Ia S = U - U = 0``), so they are left
  out; the joint's rotation Rz(q) of a symmetric 2x2 block goes by the double angle (5
  products, not 12); a placement a hair from a signed permutation (rpy of a truncated pi/2)
  is applied to first order in its deviation (the dropped term is ~1e-15 relative);
* the bias force of pass 1 is formed at the centre of mass; gravity is the base acceleration
  ``a_0 = -g`` (a constant that folds into the roots);
* the sines and cosines are an inline fdlibm-kernel sincos (:data:`SINCOS_C`), and the code
  is cut into functions of ~200 statements (see :func:`unrolled_fd`).

Measured (``examples/bench_derivatives.py --unrolled-only``, 2 loaded cores): FD 0.11-0.19x
Pinocchio's ``aba`` on iiwa, HyQ, UR5, Panda, Talos, Tiago, Tiago dual, 0.2-0.29x on Atlas (whose
placements are near-permutations with offsets in two or three axes), against 0.45-0.52x for the
looped runtime; gcc needs ~0.3 s of CPU per 1000 lines (Talos: 6,500 lines, 1.8 s).  Not in this
module: external wrenches, the end-effector position, derivatives; it is not part of the FMU build.

The model is that of ``fmugen_chain_forward_dynamics``/``fmugen_chain_fd`` (fixed base, the
numbers of :class:`fmugen.batch.Kernels`: ``revolute``, ``parents``, the ``n x NC`` body
constants and gravity), rotor inertia (added to D_i), damping and smooth Coulomb friction
(subtracted from tau_i) included; external wrenches and the end-effector position are not
(the generated function is the forward dynamics alone).

The generated function::

    int NAME(const double *q, const double *qd, const double *tau, double *qdd);

returns 0 (FMUGEN_OK), 1 (an articulated inertia D_i not positive) or 2 (a result not finite),
as the runtime does.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Mapping, Optional, Sequence

import numpy as np

__all__ = ["Var", "Program", "UnrolledFD", "unrolled_fd", "from_kernels", "body_frames", "evaluate_numeric",
           "CompiledUnrolledFD"]

NC = 29  # per-body constants (c_runtime/chain_dynamics.h), repeated to keep this module free of sympy
_ROT, _POS, _AXIS, _MASS, _COM, _INERTIA, _ROTOR, _DAMPING, _FRICTION, _FRICTION_V = 0, 9, 12, 15, 16, 19, 25, 26, 27, 28


# ------------------------------------------------------------ the expression type
class Var:
    """A named C scalar, possibly negated (the sign is folded into the statements that use it)."""

    __slots__ = ("name", "neg")

    def __init__(self, name: str, neg: bool = False):
        self.name, self.neg = name, neg

    def __neg__(self):
        return Var(self.name, not self.neg)

    def __repr__(self):
        return ("-" if self.neg else "") + self.name


def neg(x):
    return -x


def _fmt(c: float) -> str:
    r = repr(float(c))
    return r if ("e" in r or "." in r or "n" in r) else r + ".0"


class Program:
    """Straight-line code under construction: ``sop`` (sums of products), ``call`` and ``recip`` fold
    constants and return a constant or a :class:`Var`; each non-trivial one is a statement."""

    def __init__(self, prefix: str = "t"):
        self.prefix = prefix
        self.stmts = []  # (name, C text, names used, block); name None: a side effect, always kept
        self.memo = {}
        self.block = 0

    def _emit(self, text: str, deps) -> Var:
        name = self.memo.get(text)
        if name is None:
            name = f"{self.prefix}{len(self.stmts)}"
            self.stmts.append((name, text, tuple(deps), self.block))
            self.memo[text] = name
        return Var(name)

    def effect(self, text: str, uses):
        """A statement kept for its effect (an output, a check); ``uses``: the values it reads."""
        self.stmts.append((None, text, tuple(u.name for u in uses if isinstance(u, Var)), self.block))

    def sop(self, products) -> object:
        """sum over ``products`` (each a sequence of factors: floats and Vars) of the factors' product."""
        const = 0.0
        terms = {}
        for prod in products:
            coef, names = 1.0, []
            for f in prod:
                if isinstance(f, Var):
                    if f.neg:
                        coef = -coef
                    names.append(f.name)
                else:
                    coef *= f
                    if coef == 0.0:
                        break
            if coef == 0.0:
                continue
            if not names:
                const += coef
                continue
            key = tuple(sorted(names))
            terms[key] = terms.get(key, 0.0) + coef
        items = sorted((k, c) for k, c in terms.items() if c != 0.0)
        if not items:
            return const
        if len(items) == 1 and const == 0.0 and len(items[0][0]) == 1 and abs(items[0][1]) == 1.0:
            return Var(items[0][0][0], items[0][1] < 0)
        # canonical sign: the first term positive (so that a - b and b - a share one statement)
        flip = items[0][1] < 0
        if flip:
            items = [(k, -c) for k, c in items]
            const = -const
        parts = []
        for k, c in items:
            body = "*".join(k)
            a = abs(c)
            t = body if a == 1.0 else f"{_fmt(a)}*{body}"
            parts.append(("- " if c < 0 else "+ ") + t)
        if const != 0.0:
            parts.append(("- " if const < 0 else "+ ") + _fmt(abs(const)))
        text = " ".join(parts)
        text = text[2:] if text.startswith("+ ") else "-" + text[2:]
        v = self._emit(text, {n for k, _ in items for n in k})
        return -v if flip else v

    def add(self, *xs):
        return self.sop([(x,) for x in xs])

    def mul(self, a, b):
        return self.sop([(a, b)])

    def call(self, fn: str, x):
        """fn(x) for fn in sin, cos, tanh (folded for a constant)."""
        if not isinstance(x, Var):
            return getattr(math, fn)(x)
        if x.neg and fn in ("sin", "tanh"):
            return -self._emit(f"{fn}({x.name})", (x.name,))
        if x.neg:
            return self._emit(f"{fn}({x.name})", (x.name,))
        return self._emit(f"{fn}({x.name})", (x.name,))

    def recip(self, x):
        if not isinstance(x, Var):
            return 1.0 / x
        v = self._emit(f"1.0 / {x.name}", (x.name,))
        return -v if x.neg else v

    def live(self) -> list:
        """The statements the effects depend on, in order: (name, text, deps, block)."""
        need = set()
        keep = []
        for st in reversed(self.stmts):
            if st[0] is None or st[0] in need:
                keep.append(st)
                need.update(st[2])
        return keep[::-1]


def c_value(x) -> str:
    if isinstance(x, Var):
        return ("-" if x.neg else "") + x.name
    return _fmt(x)


# ------------------------------------------------------------ 3-vector and spatial helpers
def cross(P, a, b):
    return [P.sop([(a[1], b[2]), (-1.0, a[2], b[1])]),
            P.sop([(a[2], b[0]), (-1.0, a[0], b[2])]),
            P.sop([(a[0], b[1]), (-1.0, a[1], b[0])])]


def matvec(P, E, x):
    """E x (E 3x3 of floats or values)."""
    return [P.sop([(E[r][k], x[k]) for k in range(3)]) for r in range(3)]


def matTvec(P, E, x):
    """E^T x."""
    return [P.sop([(E[k][r], x[k]) for k in range(3)]) for r in range(3)]


def rz(c, s):
    return [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]


def congruence(P, E, X, sym: bool):
    """E X E^T (3x3; ``sym``: X symmetric, only the upper triangle computed and mirrored)."""
    T = [[P.sop([(E[i][k], X[k][j]) for k in range(3)]) for j in range(3)] for i in range(3)]
    out = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i if sym else 0, 3):
            out[i][j] = P.sop([(T[i][k], E[j][k]) for k in range(3)])
            if sym:
                out[j][i] = out[i][j]
    return out


def skew(r):
    return [[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]]


def blocks(M):
    A = [[M[i][j] for j in range(3)] for i in range(3)]
    B = [[M[i][j + 3] for j in range(3)] for i in range(3)]
    C = [[M[i + 3][j + 3] for j in range(3)] for i in range(3)]
    return A, B, C


def from_blocks(A, B, C):
    M = [[None] * 6 for _ in range(6)]
    for i in range(3):
        for j in range(3):
            M[i][j], M[i][j + 3], M[j + 3][i], M[i + 3][j + 3] = A[i][j], B[i][j], B[i][j], C[i][j]
    return M


def _near_permutation(E):
    """(Pi, D) with E = Pi + D, Pi a signed permutation and every |D| < 1e-6 (a URDF's rpy of a truncated
    pi/2: cos(1.5707963) = -4.4e-8), or None."""
    Ea = np.array(E, dtype=float)
    Pi = np.round(Ea)
    if not (np.all(np.isin(Pi, (-1.0, 0.0, 1.0))) and np.all(np.sum(Pi != 0, axis=0) == 1)
            and np.all(np.sum(Pi != 0, axis=1) == 1)):
        return None
    D = Ea - Pi
    if not np.any(D) or np.max(np.abs(D)) >= 1e-6:
        return None
    return Pi.tolist(), D.tolist()


def _congruence_first_order(P, Pi, D, X, sym: bool):
    """E X E^T for E = Pi + D to first order in D: Pi X Pi^T + D X Pi^T + Pi X D^T (the dropped
    D X D^T is below 1e-12 of X).  Products by Pi are renamings; each entry of D costs one product
    per column instead of the two-sided product's two."""
    XP = [[P.sop([(X[k][l], Pi[j][l]) for l in range(3)]) for j in range(3)] for k in range(3)]  # X Pi^T
    PX = [[P.sop([(Pi[i][l], X[l][k]) for l in range(3)]) for k in range(3)] for i in range(3)]  # Pi X
    out = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i if sym else 0, 3):
            y = P.sop([(Pi[i][k], XP[k][j]) for k in range(3)])
            out[i][j] = P.sop([(y,)] + [(D[i][k], XP[k][j]) for k in range(3)]
                              + [(PX[i][k], D[j][k]) for k in range(3)])
            if sym:
                out[j][i] = out[i][j]
    return out


def sym_rotate(P, E, M):
    """The spatial inertia M (6x6 symmetric) of a frame rotated by E (its axes in the new frame's
    coordinates) in the new frame: blockwise E X E^T."""
    A, B, C = blocks(M)
    near = _near_permutation(E)
    if near is not None:
        Pi, D = near
        return from_blocks(_congruence_first_order(P, Pi, D, A, True), _congruence_first_order(P, Pi, D, B, False),
                           _congruence_first_order(P, Pi, D, C, True))
    return from_blocks(congruence(P, E, A, True), congruence(P, E, B, False), congruence(P, E, C, True))


def sym_translate(P, r, M):
    """X^T M X for the motion transform X = [[1, 0], [-r x, 1]] of a frame whose origin is at r
    (same axes): A' = A + Z^T + W, B' = B + [r]x C, C' = C with Z = [r]x B^T, W = [r]x B'^T
    (only the entries the result needs; [r]x has at most 6 non-zeros)."""
    if all(not isinstance(x, Var) and x == 0.0 for x in r):
        return M
    A, B, C = blocks(M)
    rx = skew(r)
    B2 = [[P.sop([(B[i][j],)] + [(rx[i][k], C[k][j]) for k in range(3)]) for j in range(3)] for i in range(3)]
    A2 = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i, 3):
            # Z[j][i] = sum_k rx[j][k] B[i][k];  W[i][j] = sum_k rx[i][k] B2[j][k]
            A2[i][j] = A2[j][i] = P.sop([(A[i][j],)] + [(rx[j][k], B[i][k]) for k in range(3)]
                                        + [(rx[i][k], B2[j][k]) for k in range(3)])
    return from_blocks(A2, B2, C)


def _rot2(P, c, s, x, y):
    """R2 (x, y) with R2 = [[c, -s], [s, c]]."""
    return P.sop([(c, x), (-1.0, s, y)]), P.sop([(s, x), (c, y)])


def _sym2(P, h, a, b, d):
    """R2 [[a, b], [b, d]] R2^T by the double angle: with hc = cos(2q)/2, hs = sin(2q)/2 and
    m = a - d, a' = (a + d)/2 + hc m - 2 hs b, d' = (a + d)/2 - (hc m - 2 hs b), b' = hs m + 2 hc b
    (5 products where the two-sided product takes 12)."""
    hc, hs = h
    half = P.sop([(0.5, a), (0.5, d)])
    m = P.sop([(a,), (-1.0, d)])
    u = P.sop([(hc, m), (-2.0, hs, b)])
    return P.add(half, u), P.sop([(half,), (-1.0, u)]), P.sop([(hs, m), (2.0, hc, b)])


def _gen2(P, h, a, b, e, d):
    """R2 [[a, b], [e, d]] R2^T: the symmetric part by the double angle, the antisymmetric part
    (b - e)/2 unchanged by a rotation.  Returns a', b', e', d'."""
    hc, hs = h
    half = P.sop([(0.5, a), (0.5, d)])
    m = P.sop([(a,), (-1.0, d)])
    sig = P.add(b, e)
    k = P.sop([(0.5, b), (-0.5, e)])
    u = P.sop([(hc, m), (-1.0, hs, sig)])
    bs = P.sop([(hs, m), (hc, sig)])
    return P.add(half, u), P.add(bs, k), P.sop([(bs,), (-1.0, k)]), P.sop([(half,), (-1.0, u)])


def _rz3(P, c, s, h, X, sym: bool):
    """E X E^T for E = Rz (3x3 X; ``sym``: X symmetric)."""
    out = [[None] * 3 for _ in range(3)]
    if sym:
        a, d, b = _sym2(P, h, X[0][0], X[0][1], X[1][1])
        out[0][0], out[1][1], out[0][1], out[1][0] = a, d, b, b
        out[0][2], out[1][2] = _rot2(P, c, s, X[0][2], X[1][2])
        out[2][0], out[2][1] = out[0][2], out[1][2]
    else:
        out[0][0], out[0][1], out[1][0], out[1][1] = _gen2(P, h, X[0][0], X[0][1], X[1][0], X[1][1])
        out[0][2], out[1][2] = _rot2(P, c, s, X[0][2], X[1][2])
        out[2][0], out[2][1] = _rot2(P, c, s, X[2][0], X[2][1])
    out[2][2] = X[2][2]
    return out


def sym_rotate_z(P, c, s, h, M):
    """sym_rotate for E = Rz(q) (c, s its cosine and sine, h the halved double-angle pair)."""
    A, B, C = blocks(M)
    return from_blocks(_rz3(P, c, s, h, A, True), _rz3(P, c, s, h, B, False), _rz3(P, c, s, h, C, True))


def motion_rotate_T(P, E, m):
    """m (parent coordinates) in the coordinates of a frame rotated by E: E^T m."""
    return matTvec(P, E, m[:3]) + matTvec(P, E, m[3:])


def motion_translate(P, r, m):
    """m at the origin r: [w; v - r x w]."""
    rw = cross(P, r, m[:3])
    return m[:3] + [P.add(m[3 + k], -rw[k] if isinstance(rw[k], Var) else -rw[k]) for k in range(3)]


def force_rotate(P, E, f):
    return matvec(P, E, f[:3]) + matvec(P, E, f[3:])


def force_translate(P, r, f):
    """f of a frame at r, about the parent origin: [n + r x f; f]."""
    rf = cross(P, r, f[3:])
    return [P.add(f[k], rf[k]) for k in range(3)] + f[3:]


# ------------------------------------------------------------ the robot's frames
def _snap(x: float) -> float:
    """Placement numbers within 1e-14 of 0 or +-1 are taken as exact (cos(pi/2) = 6e-17 in a URDF's
    rpy): the model changes by rounding-level amounts and the products by them vanish."""
    for v in (0.0, 1.0, -1.0):
        if abs(x - v) < 1e-14:
            return v
    return float(x)


def _axis_frame(k) -> np.ndarray:
    """A rotation Q with Q e_z = k: a signed permutation when k is a coordinate axis."""
    k = np.asarray(k, float)
    k = k / np.linalg.norm(k)
    big = int(np.argmax(np.abs(k)))
    u = np.zeros(3)
    u[(big + 1) % 3] = 1.0  # a coordinate axis not along k
    u = u - k * (u @ k)
    u /= np.linalg.norm(u)
    v = np.cross(k, u)
    Q = np.column_stack([u, v, k])
    return np.vectorize(_snap)(Q)


@dataclass
class BodyFrame:
    """One body in its joint-axis frame B_i: parent placement (Rc, pc) in B_parent, joint type,
    the spatial inertia at B_i's origin (6x6, floats), rotor inertia, damping, friction."""
    parent: int
    revolute: bool
    Rc: np.ndarray
    pc: np.ndarray
    inertia: list
    rotor: float
    damping: float
    friction: float
    friction_velocity: float
    mass: float = 0.0
    com: tuple = (0.0, 0.0, 0.0)  # B_i coordinates
    inertia_com: tuple = ((0.0,) * 3,) * 3  # about the COM, B_i axes


def _nnz(x) -> int:
    return sum(1 for v in x if v != 0.0)


def body_frames(revolute: Sequence[bool], parents: Sequence[int], constants, shift: bool = True) -> list:
    """The bodies of the general joint model (``n x NC`` constants) in their joint-axis frames.

    ``shift``: each frame's origin may slide along its joint axis (a rotation about z and a
    translation along z commute with the joint's motion), by the distance d_i that leaves the
    fewest non-zero offsets -- its own placement's and its children's along z (zeroing an
    offset component saves a quarter to a third of a translation's products)."""
    n = len(revolute)
    lc = np.asarray(constants, float).reshape(n, NC)
    Qs, d = [], [0.0] * n
    snap = np.vectorize(_snap)
    for L in lc:
        Qs.append(_axis_frame(L[_AXIS:_AXIS + 3]))
    children = [[] for _ in range(n)]
    for i in range(n):
        if parents[i] >= 0:
            children[int(parents[i])].append(i)
    out = []
    for i, L in enumerate(lc):
        par = int(parents[i])
        R = snap(L[_ROT:_ROT + 9].reshape(3, 3))
        p = snap(L[_POS:_POS + 3])
        Q = Qs[i]
        Qp = Qs[par] if par >= 0 else np.eye(3)
        Rc = snap(Qp.T @ R @ Q)
        base = Qp.T @ p
        if par >= 0:
            base[2] -= d[par]  # the parent's origin moved along its z
        base = snap(base)
        if shift:
            kz = Rc[:, 2]  # this joint's axis in the parent's frame
            kids = [snap(Q.T @ snap(lc[c][_POS:_POS + 3]))[2] for c in children[i]]
            cand = {0.0}
            cand.update(-base[k] / kz[k] for k in range(3) if kz[k] != 0.0)
            cand.update(kids)

            def placed(dd):
                x = base + kz * dd
                # a component the shift was chosen to cancel is left with rounding: exactly zero
                return np.array([0.0 if (kz[k] != 0.0 and abs(x[k]) <= 1e-14 * abs(base[k])) else x[k]
                                 for k in range(3)])

            def cost(dd):
                x = placed(dd)
                own = min(_nnz(x), _nnz(snap(Rc.T @ x)))
                return own + sum(1 for z in kids if z - dd != 0.0), abs(dd)

            # far shifts cost accuracy (the inertia about a distant origin cancels): 0.25 m at most
            d[i] = min(sorted(x for x in cand if abs(x) <= 0.25), key=cost)
            pc = snap(placed(d[i]))
        else:
            pc = base
        m = float(L[_MASS])
        c = Q.T @ L[_COM:_COM + 3]
        c[2] -= d[i]
        J = L[_INERTIA:_INERTIA + 6]
        Ic = np.array([[J[0], J[3], J[4]], [J[3], J[1], J[5]], [J[4], J[5], J[2]]])
        Ic = Q.T @ Ic @ Q
        Jo = Ic + m * ((c @ c) * np.eye(3) - np.outer(c, c))  # about B_i's origin
        hx = m * np.array(skew(list(c)))
        M = np.block([[Jo, hx], [hx.T, m * np.eye(3)]])
        M = 0.5 * (M + M.T)
        out.append(BodyFrame(par, bool(revolute[i]), Rc, pc, [[float(x) for x in row] for row in M],
                             float(L[_ROTOR]), float(L[_DAMPING]), float(L[_FRICTION]), float(L[_FRICTION_V]),
                             m, tuple(float(x) for x in c), tuple(tuple(float(x) for x in row) for row in Ic)))
    return out


# ------------------------------------------------------------ the three passes
def _is_identity(R) -> bool:
    return bool(np.all(R == np.eye(3)))


def _aba(P: Program, bodies: list, gravity, q, qd, tau, locked=frozenset()):
    """qdd (list of values) by the articulated-body algorithm over values q, qd, tau.

    ``locked``: bodies whose joints are held (q_i a constant, qd_i = qdd_i = 0): each is welded to its
    parent -- its articulated inertia and bias force pass to the parent whole, no projection."""
    n = len(bodies)
    j_of = [2 if b.revolute else 5 for b in bodies]
    children = [[] for _ in range(n)]
    for i, b in enumerate(bodies):
        if b.parent >= 0:
            children[b.parent].append(i)

    # per body: the stages of the motion transform parent -> child, and their inverse for forces
    # (block 0 of the code: the joints' sines and cosines)
    P.block = 0
    stages = []
    for i, b in enumerate(bodies):
        st = []
        r_parent = list(b.pc)
        r_rotated = list(b.Rc.T @ b.pc)
        # translate where the offset has fewer non-zeros (before or after the constant rotation)
        before = sum(x != 0.0 for x in r_parent) <= sum(x != 0.0 for x in np.vectorize(_snap)(r_rotated))
        Rc = [[float(x) for x in row] for row in b.Rc]
        if before:
            st.append(("t", [float(x) for x in r_parent]))
        if not _is_identity(b.Rc):
            st.append(("r", Rc))
        if not before:
            st.append(("t", [_snap(x) for x in r_rotated]))
        if b.revolute:
            co, si = P.call("cos", q[i]), P.call("sin", q[i])
            ss, sc = P.mul(si, si), P.mul(si, co)
            st.append(("z", rz(co, si), (co, si, (P.sop([(0.5,), (-1.0, ss)]), sc))))
        else:
            st.append(("t", [0.0, 0.0, q[i]]))
        stages.append([s for s in st if not (s[0] == "t" and all(not isinstance(x, Var) and x == 0.0
                                                                 for x in s[1]))])

    def to_child(i, m):
        for kind, x, *_ in stages[i]:
            m = motion_translate(P, x, m) if kind == "t" else motion_rotate_T(P, x, m)
        return m

    def force_to_parent(i, f):
        for kind, x, *_ in reversed(stages[i]):
            f = force_translate(P, x, f) if kind == "t" else force_rotate(P, x, f)
        return f

    def inertia_to_parent(i, M):
        for kind, x, *z in reversed(stages[i]):
            if kind == "t":
                M = sym_translate(P, x, M)
            elif kind == "z":
                co, si, h = z[0]
                M = sym_rotate_z(P, co, si, h, M)
            else:
                M = sym_rotate(P, x, M)
        return M

    # pass 1: velocities v_i, velocity-product accelerations c_i = v_i x S_i qd_i, bias forces
    v, c, pA = [None] * n, [None] * n, [None] * n
    for i, b in enumerate(bodies):
        P.block = 1 + i
        j = j_of[i]
        vi = to_child(i, v[b.parent]) if b.parent >= 0 else [0.0] * 6
        vi = list(vi)
        vi[j] = P.add(vi[j], qd[i])
        w, vl = vi[:3], vi[3:]
        # v x S qd with S = e_z (angular or linear): [w x ez; vl x ez] or [0; w x ez]
        wz = [P.mul(w[1], qd[i]), P.mul(neg(w[0]) if isinstance(w[0], Var) else -w[0], qd[i]), 0.0]
        if b.revolute:
            c[i] = wz + [P.mul(vl[1], qd[i]), P.mul(neg(vl[0]) if isinstance(vl[0], Var) else -vl[0], qd[i]), 0.0]
        else:
            c[i] = [0.0, 0.0, 0.0] + wz
        # bias force v x* I v at the centre of mass: with p = m (v_O + w x c) (momentum),
        # f = [w x I_c w + c x f_lin ; f_lin], f_lin = w x p -- 36 products where I v then v x* (I v) take 42
        Ic, cm, m = b.inertia_com, list(b.com), b.mass
        Icw = [P.sop([(Ic[r][k], w[k]) for k in range(3)]) for r in range(3)]
        ang = cross(P, w, Icw)
        if m != 0.0:
            wc = cross(P, w, [m * x for x in cm])
            p = [P.sop([(m, vl[k]), (wc[k],)]) for k in range(3)]
            flin = cross(P, w, p)
            cf = cross(P, cm, flin)
            pA[i] = [P.add(ang[k], cf[k]) for k in range(3)] + flin
        else:
            pA[i] = ang + [0.0, 0.0, 0.0]
        v[i] = vi

    # pass 2: articulated inertias and bias forces, leaves to base; children's terms gathered per entry
    IA_terms = [[[[(b.inertia[r][k],)] for k in range(6)] for r in range(6)] for b in bodies]
    pA_terms = [[[(x,)] for x in pA[i]] for i in range(n)]
    U, Dinv, u = [None] * n, [None] * n, [None] * n
    for i in range(n - 1, -1, -1):
        P.block = 2 * n - i
        b, j = bodies[i], j_of[i]
        IA = [[None] * 6 for _ in range(6)]
        for r in range(6):
            for k in range(r, 6):
                IA[r][k] = IA[k][r] = P.sop(IA_terms[i][r][k])
        pa = [P.sop(t) for t in pA_terms[i]]
        U[i] = [IA[r][j] for r in range(6)]
        if i in locked:
            D = 1.0
        else:
            D = P.add(U[i][j], b.rotor)
        if isinstance(D, Var):
            P.effect(f"if (!({c_value(D)} > 0.0)) return 1;", [D])
        elif not D > 0.0:
            raise ValueError(f"body {i}: articulated inertia {D} is not positive")
        Dinv[i] = P.recip(D)
        fric = P.mul(b.damping, qd[i])
        if b.friction != 0.0:
            fric = P.add(fric, P.mul(b.friction, P.call("tanh", P.mul(1.0 / b.friction_velocity, qd[i]))))
        tf = P.sop([(tau[i],), (-1.0, fric)])  # tau - friction = S^T pa after the projection
        u[i] = P.sop([(tf,), (-1.0, pa[j])])
        if b.parent < 0:
            continue
        if i in locked:  # welded: c_i = 0 (qd_i = 0), IA_i and pA_i go to the parent as they are
            fp = force_to_parent(i, pa)
            Mp = inertia_to_parent(i, IA)
            for r in range(6):
                for k in range(r, 6):
                    IA_terms[b.parent][r][k].append((Mp[r][k],))
                pA_terms[b.parent][r].append((fp[r],))
            continue
        # without rotor inertia (D = U_j) the joint's row and column of Ia vanish and S^T pa = tau - friction;
        # with it, Ia S = U rotor / D: computed in full
        exact = b.rotor == 0.0
        Ud = [P.mul(U[i][r], Dinv[i]) if (r != j or not exact) else 1.0 for r in range(6)]
        Ia = [[0.0] * 6 for _ in range(6)]
        for r in range(6):
            for k in range(r, 6):
                if not exact or (r != j and k != j):
                    Ia[r][k] = Ia[k][r] = P.sop([(IA[r][k],), (-1.0, U[i][r], Ud[k])])
        uD = P.mul(u[i], Dinv[i])
        ci = c[i]
        pa2 = [P.sop([(pa[r],), (U[i][r], uD)] + [(Ia[r][k], ci[k]) for k in range(6)]) if (r != j or not exact)
               else tf for r in range(6)]
        Mp = inertia_to_parent(i, Ia)
        fp = force_to_parent(i, pa2)
        par = b.parent
        for r in range(6):
            for k in range(r, 6):
                IA_terms[par][r][k].append((Mp[r][k],))
            pA_terms[par][r].append((fp[r],))

    # pass 3: accelerations, base to leaves (a_0 = -g: gravity as a base acceleration)
    a0 = [0.0, 0.0, 0.0] + [-float(x) for x in gravity]
    acc, qdd = [None] * n, [None] * n
    for i, b in enumerate(bodies):
        P.block = 2 * n + 1 + i
        j = j_of[i]
        ap = to_child(i, acc[b.parent] if b.parent >= 0 else a0)
        a = [P.add(ap[k], c[i][k]) for k in range(6)]
        if i in locked:
            qdd[i] = 0.0
            P.effect(f"qdd[{i}] = 0.0;", [])
            acc[i] = a
            continue
        Ua = P.sop([(U[i][k], a[k]) for k in range(6)])
        qdd[i] = P.sop([(u[i], Dinv[i]), (-1.0, Ua, Dinv[i])])
        P.effect(f"qdd[{i}] = {c_value(qdd[i])};", [qdd[i]])
        a[j] = P.add(a[j], qdd[i])
        acc[i] = a
    return qdd


@dataclass
class UnrolledFD:
    """The generated C: ``source`` (a self-contained C file: includes, the block functions, the entry
    function ``name``), ``statements`` (sums of products and calls), ``blocks`` (functions)."""
    name: str
    n: int
    source: str
    statements: int
    blocks: int

    @property
    def lines(self) -> int:
        return self.source.count("\n")


#: sine and cosine of a joint angle, inline: Cody-Waite reduction by pi/2 (fdlibm's two-part pi/2,
#: exact k pi/2_1 for |k| < 2^20) and fdlibm's kernel polynomials on [-pi/4, pi/4] (errors below
#: 1e-16 absolute); libm beyond |x| = 1e5 and for NaN or infinity.  glibc's sincos takes about 100
#: instructions, this about 40 -- a tenth of the forward dynamics of a 30-body tree.
SINCOS_C = r"""static inline void unrolled_sincos(double x, double *s, double *c)
{
    if (!(fabs(x) < 1e5)) {
        *s = sin(x);
        *c = cos(x);
        return;
    }
    const double k = (x * 6.36619772367581382433e-01 + 6755399441055744.0) - 6755399441055744.0;
    const double r = (x - k * 1.57079632673412561417e+00) - k * 6.07710050650619224932e-11;
    const double z = r * r;
    const double sr = r + r * z * (-1.66666666666666324348e-01 + z * (8.33333333332248946124e-03
        + z * (-1.98412698298579493134e-04 + z * (2.75573137070700676789e-06
        + z * (-2.50507602534068634195e-08 + z * 1.58969099521155010221e-10)))));
    const double cr = 1.0 - (0.5 * z - z * z * (4.16666666666666019037e-02 + z * (-1.38888888888741095749e-03
        + z * (2.48015872894767294178e-05 + z * (-2.75573143513906633035e-07
        + z * (2.08757232129817482790e-09 + z * -1.13596475577881948265e-11))))));
    const int n = (int)k;
    const double v[2] = {sr, cr};
    /* quadrant n mod 4: (sin, cos) = (sr, cr), (cr, -sr), (-sr, -cr), (-cr, sr) */
    *s = (n & 2 ? -1.0 : 1.0) * v[n & 1];
    *c = ((n + 1) & 2 ? -1.0 : 1.0) * v[(n & 1) ^ 1];
}
#define UNROLLED_SINCOS(x, s, c) unrolled_sincos(x, s, c)
"""

_TOKEN = re.compile(r"\bt\d+\b")


def unrolled_fd(revolute: Sequence[bool], parents: Sequence[int], constants, gravity,
                name: str = "fmugen_unrolled_fd", static: bool = False, block_statements: int = 200,
                locked: Optional[Mapping[int, float]] = None) -> UnrolledFD:
    """Straight-line C of the forward dynamics of the tree (``constants``: n x NC, the numbers of
    :class:`fmugen.batch.Kernels`); ``static``: the entry function is ``static`` (to be included in a file);
    ``locked``: {body (0-based): position} of joints held still (their q, qd are not read, qdd = 0).

    The code is cut into one function per body and pass (block; not inlined): a value used by a
    later block goes through the work array ``w``, so each function has short live ranges.  One
    function of thousands of statements makes gcc's register allocator spill at random and take
    seconds (Atlas: 10 s at -O2, 136 kB of code); cut, it compiles in a fraction of that."""
    n = len(revolute)
    locked = {int(k): float(v) for k, v in (locked or {}).items()}
    if any(not 0 <= k < n for k in locked):
        raise ValueError(f"locked joints {sorted(locked)}: bodies are numbered 0..{n - 1}")
    bodies = body_frames(revolute, parents, constants)
    P = Program()
    q = [locked[i] if i in locked else Var(f"q[{i}]") for i in range(n)]
    qd = [0.0 if i in locked else Var(f"qd[{i}]") for i in range(n)]
    tau = [Var(f"tau[{i}]") for i in range(n)]
    _aba(P, bodies, gravity, q, qd, tau, frozenset(locked))
    stmts = P.live()
    home = {st[0]: st[3] for st in stmts if st[0] is not None}

    def text_in(t: str, blk: int) -> str:
        return _TOKEN.sub(lambda m: f"w[{slot[m.group(0)]}]" if m.group(0) in slot and home[m.group(0)] != blk
                          else m.group(0), t)

    # consecutive blocks merged up to about ``block_statements`` statements: a call per body and pass
    # costs more than it saves on a small robot
    sizes = {}
    for st in stmts:
        sizes[st[3]] = sizes.get(st[3], 0) + 1
    group, g, acc = {}, 0, 0
    for b in sorted(sizes):
        if acc and acc + sizes[b] > block_statements:
            g, acc = g + 1, 0
        group[b] = g
        acc += sizes[b]
    home = {k: group[v] for k, v in home.items()}
    stmts = [(a, t, d, group[b]) for a, t, d, b in stmts]
    slot = {}
    for name_, text, deps, blk in stmts:
        for d in deps:
            if d in home and home[d] != blk and d not in slot:
                slot[d] = len(slot)
    by_block = {}
    for st in stmts:
        by_block.setdefault(st[3], []).append(st)
    # sin and cos of one angle in one block: one sincos call
    trig = {}
    for name_, text, _, blk in stmts:
        if name_ and text[:4] in ("sin(", "cos("):
            trig.setdefault((blk, text[4:-1]), {})[text[:3]] = name_
    fn = [f"{name}_b{b}" for b in sorted(by_block)]
    lines = ["/* generated by fmugen.codegen.unrolled_aba: the articulated-body algorithm of one robot, its numbers",
             f" * folded into the code ({n} bodies; block 0 the joints' sines and cosines, then per body pass 1",
             " * (velocities, bias forces), pass 2 (articulated inertias, leaves first), pass 3 (accelerations)) */",
             "#include <math.h>", "",
             "#if defined(__GNUC__) && !defined(__clang__)",
             "/* straight-line code: -O2's passes beyond -O1 (scheduling, PRE, SLP vectorising) measured no faster",
             " * here (Atlas, Talos, iiwa: O1/O2 time 0.94-1.02) and take almost half of gcc's time (Talos: 2.9 s",
             " * CPU at -O2, 1.8 s at -O1) */",
             "#pragma GCC optimize(\"O1\")",
             "#endif",
             SINCOS_C,
             "#if defined(__GNUC__)",
             "#define UNROLLED_BLOCK static __attribute__((noinline)) int",
             "#else",
             "#define UNROLLED_BLOCK static int",
             "#endif",
             ""]
    for f, b in zip(fn, sorted(by_block)):
        lines.append(f"UNROLLED_BLOCK {f}(const double *q, const double *qd, const double *tau, double *qdd, "
                     "double *w)")
        lines.append("{")
        lines.append("    (void)q; (void)qd; (void)tau; (void)qdd; (void)w;")
        paired = set()
        for name_, text, deps, blk in by_block[b]:
            t = text_in(text, b)
            if name_ is None:
                lines.append(f"    {t}")
                continue
            if name_ in paired:
                continue
            pair = trig.get((b, text[4:-1])) if text[:4] in ("sin(", "cos(") else None
            if pair is not None and len(pair) == 2:
                s_name, c_name = pair["sin"], pair["cos"]
                lines.append(f"    double {s_name}, {c_name};")
                lines.append(f"    UNROLLED_SINCOS({text[4:-1]}, &{s_name}, &{c_name});")
                paired.update((s_name, c_name))
                for nm in (s_name, c_name):
                    if nm in slot:
                        lines.append(f"    w[{slot[nm]}] = {nm};")
                continue
            lines.append(f"    const double {name_} = {t};")
            if name_ in slot:
                lines.append(f"    w[{slot[name_]}] = {name_};")
        lines.append("    return 0;")
        lines.append("}")
        lines.append("")
    lines.append(f"{'static ' if static else ''}int {name}(const double *q, const double *qd, const double *tau, "
                 "double *qdd)")
    lines.append("{")
    lines.append(f"    double w[{max(len(slot), 1)}];")
    for f in fn:
        lines.append(f"    if ({f}(q, qd, tau, qdd, w)) return 1;")
    lines.append(f"    for (int i = 0; i < {n}; i++)")
    lines.append("        if (!isfinite(qdd[i])) return 2;")
    lines.append("    return 0;")
    lines.append("}")
    return UnrolledFD(name, n, "\n".join(lines) + "\n", len(stmts), len(fn))


def evaluate_numeric(revolute, parents, constants, gravity, q, qd, tau, locked=None) -> np.ndarray:
    """The same passes on numbers (every value folds): a check of the algorithm without a compiler."""
    bodies = body_frames(revolute, parents, constants)
    P = Program()
    locked = {int(k): float(v) for k, v in (locked or {}).items()}
    q = [locked.get(i, float(x)) for i, x in enumerate(q)]
    qd = [0.0 if i in locked else float(x) for i, x in enumerate(qd)]
    qdd = _aba(P, bodies, gravity, q, qd, [float(x) for x in tau], frozenset(locked))
    return np.array(qdd, float)


def from_kernels(kernels, locked: Optional[Mapping[int, float]] = None, **kw) -> UnrolledFD:
    """:func:`unrolled_fd` of a :class:`fmugen.batch.Kernels` (its revolute flags, parents, body constants
    and gravity)."""
    return unrolled_fd(kernels.revolute, kernels.parents, kernels.constants, np.asarray(kernels.globals)[:3],
                       locked=locked, **kw)


# ------------------------------------------------------------ the C harness (tests, benchmarks)
_HARNESS = r"""
#define _POSIX_C_SOURCE 199309L
#include <time.h>
int %(name)s(const double *q, const double *qd, const double *tau, double *qdd);
/* rows of states: the status of the first row that fails, 0 when all succeed */
int unrolled_rows(int rows, int n, const double *q, const double *qd, const double *tau, double *qdd)
{
    for (int r = 0; r < rows; r++) {
        int s = %(name)s(q + n * r, qd + n * r, tau + n * r, qdd + n * r);
        if (s) return s;
    }
    return 0;
}
/* CPU seconds per call over k calls at one state */
double unrolled_time(int k, const double *q, const double *qd, const double *tau, double *qdd)
{
    struct timespec a, b;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &a);
    for (int i = 0; i < k; i++) %(name)s(q, qd, tau, qdd);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &b);
    return ((b.tv_sec - a.tv_sec) + 1e-9 * (b.tv_nsec - a.tv_nsec)) / k;
}
"""


class CompiledUnrolledFD:
    """An :class:`UnrolledFD` compiled (``cc -std=c99 -O2``, the FMU build's optimisation) into a shared
    library in a temporary folder: ``fd(q, qd, tau)`` (rows of states), ``time_per_call``;
    ``compile_seconds`` is the wall time of compiling the generated file alone."""

    def __init__(self, fd: UnrolledFD, cc: str = "cc", flags: Sequence[str] = ("-O2",)):
        import ctypes
        import shutil
        import subprocess
        import tempfile
        import time
        from pathlib import Path

        self.n = fd.n
        self._dir = Path(tempfile.mkdtemp(prefix="fmugen_unrolled_"))
        self._rm = shutil.rmtree
        src, har = self._dir / "fd.c", self._dir / "harness.c"
        src.write_text(fd.source)
        har.write_text(_HARNESS % {"name": fd.name})
        t = time.perf_counter()
        r = subprocess.run([cc, "-std=c99", *flags, "-fPIC", "-c", "-o", str(self._dir / "fd.o"), str(src)],
                           capture_output=True, text=True)
        self.compile_seconds = time.perf_counter() - t
        if r.returncode == 0:
            r = subprocess.run([cc, "-std=c99", *flags, "-fPIC", "-shared", "-o", str(self._dir / "fd.so"), str(har),
                                str(self._dir / "fd.o"), "-lm"], capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"cannot compile the unrolled forward dynamics:\n{r.stderr}")
        self._lib = ctypes.CDLL(str(self._dir / "fd.so"))
        vp = ctypes.c_void_p
        self._lib.unrolled_rows.argtypes = [ctypes.c_int, ctypes.c_int, vp, vp, vp, vp]
        self._lib.unrolled_rows.restype = ctypes.c_int
        self._lib.unrolled_time.argtypes = [ctypes.c_int, vp, vp, vp, vp]
        self._lib.unrolled_time.restype = ctypes.c_double

    def _arrays(self, q, qd, tau):
        arrs = [np.ascontiguousarray(np.atleast_2d(np.asarray(a, dtype=float))) for a in (q, qd, tau)]
        if any(a.shape != arrs[0].shape or a.shape[1] != self.n for a in arrs):
            raise ValueError(f"q, qd, tau: rows of {self.n} numbers of one shape")
        return arrs

    def fd(self, q, qd, tau) -> np.ndarray:
        """qdd of every row of states (one row: a vector)."""
        one = np.ndim(q) == 1
        q, qd, tau = self._arrays(q, qd, tau)
        out = np.zeros_like(q)
        s = self._lib.unrolled_rows(q.shape[0], self.n, q.ctypes.data, qd.ctypes.data, tau.ctypes.data,
                                    out.ctypes.data)
        if s == 1:
            raise np.linalg.LinAlgError("an articulated inertia is not positive")
        if s:
            raise FloatingPointError("forward dynamics: a result is NaN or infinite")
        return out[0] if one else out

    def time_per_call(self, q, qd, tau, k: int) -> float:
        """CPU seconds per call over k calls from a C loop at one state."""
        q, qd, tau = self._arrays(q, qd, tau)
        out = np.zeros(self.n)
        return self._lib.unrolled_time(int(k), q.ctypes.data, qd.ctypes.data, tau.ctypes.data, out.ctypes.data)

    def close(self):
        if self._dir is not None:
            self._lib = None
            self._rm(self._dir, True)
            self._dir = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
