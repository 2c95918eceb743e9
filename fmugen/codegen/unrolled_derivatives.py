"""Unrolled derivatives of the forward dynamics: ∂qdd/∂(q, qd, tau) as straight-line C for one robot.

The Jacobian is the one of the looped runtime (``fmugen_chain_fd_jacobian`` in
``c_runtime/chain_dynamics.c``; Carpentier & Mansard, "Analytical derivatives of rigid body dynamics
algorithms", RSS 2018):

    [∂qdd/∂q, ∂qdd/∂qd, ∂qdd/∂tau] = M^-1 [-∂ID/∂q, -∂ID/∂qd, 1]   at qdd = FD(q, qd, tau),

with ∂ID from the analytical derivatives of recursive Newton-Euler in world coordinates -- an entry
(i, j) is nonzero only when one of the joints lies on the other's path to the base, and it is one dot
product of 6-vectors away from the subtree sums -- and M^-1 from the tree factorisation M = L^T L
without fill-in (Featherstone, IJRR 2005).  Here those passes run in Python over the folding
expression type of :mod:`fmugen.codegen.unrolled_aba` and are written out as one C statement per
remaining sum of products, the robot's numbers folded in:

* qdd = M^-1 (tau - b(q, qd) - passive forces), from the M^-1 the Jacobian holds anyway and the bias
  forces b of one more Newton-Euler pass at qdd = 0, in place of the articulated-body algorithm: the
  derivatives' passes then run in the forward dynamics' order -- what does not depend on qdd first
  (velocities, subtree sums, M and its factors), the accelerations after.  Against the ABA in the same
  program: iiwa 9,900 instructions per call against 11,150, 0.87-0.90x the time on the arms and Atlas,
  0.95x on Talos, 0.97x on Tiago (whose M^-1 rows are long);
* the world poses are products by the joint-axis frames' constant placements (mostly signed
  permutations: free), the first bodies' poses fold to constants;
* every subtree sum (composite inertia, the velocity term K, momenta and forces) and every entry of
  L, L^-1, M^-1 and of -∂ID is one sum of products over its terms, so the zeros of the tree's
  sparsity are never written: the code holds exactly the nonzero pattern of this robot (an entry of L
  or L^-1 is its sum times 1/d, not 1/d in every term; qdd is L^-1 (L^-T rhs) over the paths where that
  has fewer products than M^-1 rhs: Tiago's factors and qdd in 9,600 products against 13,600);
* the product M^-1 (-∂ID), dense rows of M^-1 against the sparse columns of -∂ID, is a loop over what
  the statements stored (:class:`_DenseProduct`), vectorised: as straight-line sums it was most of the
  large trees' code and time; where M^-1 = X X^T has thousands of products (Tiago, Tiago dual), M^-1
  is a loop as well, its 116 kB of statements the part of Tiago's code that put it past a 512 kB
  second-level cache.

The model is the runtime's: rotor inertia, damping and smooth Coulomb friction included, external
wrenches not (a model with them keeps the runtime's loops).  :func:`chain_step` writes the function a
generated model calls in place of the runtime (the end-effector position and its derivative added), when
the robot's numbers are known (:func:`fmugen.codegen.chain.unrolled_choice`).

The Jacobians' functions are compiled three times, for x86-64-v4 (AVX-512), x86-64-v3 (AVX2 and FMA) and
the baseline, and the loader picks one (gcc on glibc, :func:`fmugen.codegen.unrolled_aba.emit_c`): the
code is bound by instruction fetch (iiwa: 100 kB of code, 16,500 instructions, 3,000 of them register
copies that three-operand AVX instructions do without; 9,300 in the x86-64-v3 build), which takes 0.70x
the time; the x86-64-v4 clone at -Os, 43 kB against 48, 0.92x again on an Intel Xeon.  The forward
dynamics are built so too; the inverse dynamics alone keep the baseline.  Results differ between
the builds by rounding (fused multiply-adds), as glibc's own libm does between CPUs.

Measured (``examples/bench_derivatives.py --unrolled-only``, an AMD EPYC, with :func:`emit_c`'s windows
and statement order): ∇FD 0.19-0.23x Pinocchio's ``computeABADerivatives`` on the arms, 0.21-0.27x on
HyQ, Atlas and Talos, 0.29-0.30x on Tiago, against 0.47-0.78x for the loops (Talos 0.35x while a
neighbour loads the host); with the product as straight-line sums Talos and Tiago were at 0.36x and
0.70x and compiled for 25 and 65 s, now 12 and 17 s.  That is still long for an FMU build, so models
beyond ``UNROLLED_JACOBIAN_MAX`` bodies (:mod:`fmugen.codegen.chain`) keep the loops.

The generated function::

    int NAME(const double *q, const double *qd, const double *tau, double *qdd, double *J);

writes qdd (n) and J (n x 3n, row-major: [∂qdd/∂q, ∂qdd/∂qd, M^-1]) and returns 0, 1 (an articulated
inertia or a pivot of M not positive) or 2 (qdd not finite).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .unrolled_aba import (CompiledUnrolled, NotPositiveDefinite, Program, UnrolledFD, Var, _aba, body_frames,
                           c_value, congruence, cross, emit_c)

__all__ = ["UnrolledJacobian", "unrolled_jacobian", "chain_step", "STEP_KINDS", "from_kernels", "evaluate_numeric",
           "CompiledUnrolledJacobian"]

_EYE = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]

#: M^-1 = X X^T as a loop (:meth:`_DenseProduct._minv`) from this many products of its statements on (the sum
#: of s (s + 1) / 2 over the bodies, s the size of a body's subtree): Tiago has 7,215 (the loop 0.95x the time),
#: Talos 2,120 and Atlas 741 (the loop 0.98x and 1.03x), the arms under 200 (iiwa: 1.07x; each timed in one process)
MINV_LOOP_MIN = 4000


# ------------------------------------------------------------ spatial algebra as lists of product terms
def _cross_terms(a, b):
    return [[(a[1], b[2]), (-1.0, a[2], b[1])], [(a[2], b[0]), (-1.0, a[0], b[2])],
            [(a[0], b[1]), (-1.0, a[1], b[0])]]


def _crm_terms(m, y):
    """m x y (motion cross motion): [w x yw ; w x yv + v x yw]."""
    a, b, c = _cross_terms(m[:3], y[:3]), _cross_terms(m[:3], y[3:]), _cross_terms(m[3:], y[:3])
    return a + [b[k] + c[k] for k in range(3)]


def _crf_terms(m, f):
    """m x* f (motion cross force): [w x n + v x f ; w x f]."""
    a, b, c = _cross_terms(m[:3], f[:3]), _cross_terms(m[3:], f[3:]), _cross_terms(m[:3], f[3:])
    return [a[k] + b[k] for k in range(3)] + c


def _scaled(terms, s):
    return [[(s, *t) for t in row] for row in terms]


def _si6(I):
    """The 6x6 of a ten-number spatial inertia at the world origin (m, h = m c, J about the origin:
    xx yy zz xy xz yz): [[J, [h]x], [[h]x^T, m 1]]."""
    m, h, J = I[0], I[1:4], I[4:10]
    Jm = [[J[0], J[3], J[4]], [J[3], J[1], J[5]], [J[4], J[5], J[2]]]
    hx = [[0.0, -h[2], h[1]], [h[2], 0.0, -h[0]], [-h[1], h[0], 0.0]]
    out = [[0.0] * 6 for _ in range(6)]
    for r in range(3):
        for k in range(3):
            out[r][k] = Jm[r][k]
            out[r][k + 3] = hx[r][k]
            out[k + 3][r] = hx[r][k]
        out[r + 3][r + 3] = m
    return out


def _apply_terms(A, x):
    return [[(A[r][k], x[k]) for k in range(6)] for r in range(6)]


def _sqrt(P: Program, x):
    if not isinstance(x, Var):
        return math.sqrt(x) if x > 0.0 else float("nan")
    return P._emit(f"sqrt({'-' if x.neg else ''}{x.name})", (x.name,))


# ------------------------------------------------------------ the passes
def _paths(bodies):
    """path[i]: i and its ancestors, i first; subtree[i]: the bodies below i and i."""
    n = len(bodies)
    path = []
    for i, b in enumerate(bodies):
        path.append([i] + (path[b.parent] if b.parent >= 0 else []))
    subtree = [[] for _ in range(n)]
    for i in range(n):
        for j in path[i]:
            subtree[j].append(i)
    return path, subtree


def _friction_slope_terms(P: Program, b, qd):
    """d(passive force)/dqd of one joint as product terms: damping b and the smooth Coulomb friction's
    slope F_c (1 - tanh^2(qd / v_c)) / v_c (its tanh the one of :func:`_passive`: one statement)."""
    terms = [(b.damping,)]
    if b.friction != 0.0:
        t = P.call("tanh", P.mul(1.0 / b.friction_velocity, qd))
        k = b.friction / b.friction_velocity
        terms += [(k,), (-k, t, t)]
    return terms


def _world_kinematics(P: Program, bodies: list, q, block0: int):
    """World pose of every joint-axis frame B_i (R_i, p_i), the motion subspaces S_i and the body inertias
    at the world origin (ten numbers each, see _si6); body i in block block0 + i."""
    n = len(bodies)
    # R_i = R_parent Rc_i Rz(q_i) (Rc_i mostly a signed permutation: free)
    R, p, S, I = [None] * n, [None] * n, [None] * n, [None] * n
    for i, b in enumerate(bodies):
        P.block = block0 + i
        Rp, pp = (R[b.parent], p[b.parent]) if b.parent >= 0 else (_EYE, [0.0, 0.0, 0.0])
        Rc = [[float(x) for x in row] for row in b.Rc]
        Rq = [[P.sop([(Rp[r][k], Rc[k][c]) for k in range(3)]) for c in range(3)] for r in range(3)]
        pi = [P.sop([(pp[r],)] + [(Rp[r][k], float(b.pc[k])) for k in range(3)]) for r in range(3)]
        z = [Rq[r][2] for r in range(3)]
        if b.revolute:
            co, si = P.call("cos", q[i]), P.call("sin", q[i])
            Ri = [[P.sop([(co, Rq[r][0]), (si, Rq[r][1])]), P.sop([(co, Rq[r][1]), (-1.0, si, Rq[r][0])]), Rq[r][2]]
                  for r in range(3)]
            S[i] = z + cross(P, pi, z)
        else:
            Ri = Rq
            pi = [P.sop([(pi[r],), (z[r], q[i])]) for r in range(3)]
            S[i] = [0.0, 0.0, 0.0] + z
        m, cl = b.mass, b.com
        c = [P.sop([(pi[r],)] + [(Ri[r][k], cl[k]) for k in range(3)]) for r in range(3)]
        Jw = congruence(P, Ri, [list(row) for row in b.inertia_com], True)
        I[i] = [m] + [P.mul(m, c[k]) for k in range(3)] + [
            P.sop([(Jw[0][0],), (m, c[1], c[1]), (m, c[2], c[2])]),
            P.sop([(Jw[1][1],), (m, c[0], c[0]), (m, c[2], c[2])]),
            P.sop([(Jw[2][2],), (m, c[0], c[0]), (m, c[1], c[1])]),
            P.sop([(Jw[0][1],), (-m, c[0], c[1])]),
            P.sop([(Jw[0][2],), (-m, c[0], c[2])]),
            P.sop([(Jw[1][2],), (-m, c[1], c[2])])]
        R[i], p[i] = Ri, pi

    return R, p, S, I


def _rnea_derivatives(P: Program, bodies: list, gravity, q, qd, qdd, block0: int, solve=None):
    """Recursive Newton-Euler at (q, qd, qdd) and its analytical derivatives: (nq, nd, Mlow, tauF, parts)
    with nq[i, j], nd[i, j] = -∂ID_i/∂q_j, -∂ID_i/∂qd_j for every related pair (one joint on the other's
    path), Mlow[i, j] = M[i][j] for j on i's path (rotor inertia on the diagonal), tauF[i] = S_i . F_i (ID_i
    without rotor inertia and friction) and parts = (al, P, Q, w, dv, S, slope): the per-body vectors the
    entries are dot products of (slope: d(passive force)/dqd), for a loop to form them
    (:class:`_DenseProduct`).  Blocks block0 .. block0 + 4n.

    With ``solve`` (qdd None), the order of the forward dynamics, whose qdd is not known yet: first what
    does not depend on it -- velocities, momenta, the subtree sums, M, and the bias forces at qdd = 0,
    bias[i] = S_i . F_i -- then ``qdd, block = solve(Mlow, bias, block)`` (its blocks from block0 + 3n + 1
    on; it returns the next free one), then the accelerations and what depends on them (w, f, F, Q): blocks
    up to block0 + 9n + 1.  That is one more pass of Newton-Euler at qdd = 0 than with qdd given, and no
    articulated-body algorithm: M^-1, which the Jacobian needs anyway, gives qdd = M^-1 (tau - bias)."""
    n = len(bodies)
    path, subtree = _paths(bodies)
    children = [[] for _ in range(n)]
    for i, b in enumerate(bodies):
        if b.parent >= 0:
            children[b.parent].append(i)
    fd = solve is not None

    R, p, S, I = _world_kinematics(P, bodies, q, block0)

    # recursive Newton-Euler at qdd, forward: v, a, momenta h = I v, forces f = I a + v x* h, and per
    # joint dv_j = S_j x v_parent, w_j = S_j x a_parent - dv_j x v_parent (u_j = -2 dv_j)
    a0 = [0.0, 0.0, 0.0] + [-float(x) for x in gravity]
    v, a, h, f, dv, w, vxh = ([None] * n for _ in range(7))
    I6 = [_si6(I[i]) for i in range(n)]

    def parent_motion(i):
        par = bodies[i].parent
        return (v[par], a[par]) if par >= 0 else ([0.0] * 6, a0)

    def w_of(i, vp, ap):
        return [P.sop(t1 + [(-1.0, *x) for x in t2]) for t1, t2 in zip(_crm_terms(S[i], ap), _crm_terms(dv[i], vp))]

    def a_of(i, ap, acc):
        # a_i = a_parent + S_i qdd_i + (v_i x S_i) qd_i, and v_i x S_i = v_parent x S_i = -dv_i
        return [P.sop([(ap[k],), (-1.0, dv[i][k], qd[i])] + ([(S[i][k], acc[i])] if acc else [])) for k in range(6)]

    for i, b in enumerate(bodies):
        P.block = block0 + n + i
        vp, ap = parent_motion(i)
        Si = S[i]
        dv[i] = [P.sop(t) for t in _crm_terms(Si, vp)]
        if not fd:
            w[i] = w_of(i, vp, ap)
        v[i] = [P.sop([(vp[k],), (Si[k], qd[i])]) for k in range(6)]
        a[i] = a_of(i, ap, qdd)  # the forward dynamics: at qdd = 0, the bias accelerations
        h[i] = [P.sop(t) for t in _apply_terms(I6[i], v[i])]
        if fd:  # v x* h kept: the pass at qdd adds it again
            vxh[i] = [P.sop(t) for t in _crf_terms(v[i], h[i])]
            f[i] = [P.sop(t + [(vxh[i][k],)]) for k, t in enumerate(_apply_terms(I6[i], a[i]))]
        else:
            f[i] = [P.sop(t1 + t2) for t1, t2 in zip(_apply_terms(I6[i], a[i]), _crf_terms(v[i], h[i]))]

    # backward: the subtree sums IC (ten numbers), K, HC, F, each entry one sum over the body's own terms
    # and its children's sums; then al_i = [IC S_i ; K S_i + gamma_i], P_i, Q_i (the entries of dID) and
    # M's lower triangle.  K = -sum (A + A^T), A = I crm(v), is the velocity term of d(I a + v x* I v):
    # with I = [[J, [h]x], [[h]x^T, m 1]] its lower right block vanishes, the upper right one is
    # [u]x for u = h x w - m v_O ([h]x[w]x - [w]x[h]x = [h x w]x) and the upper left one is the
    # symmetric -(J W + (J W)^T + v_O h^T + h v_O^T - 2 (h . v_O) 1): nine numbers, not 36, and
    #   K x = [Ks x_w - u x x_v ; u x x_w]
    IC, Ks, Ku, HC, F, Kdv = ([None] * n for _ in range(6))
    al, Pv, Qv, bias = [None] * n, [None] * n, [None] * n, [None] * n
    Mlow = {}

    def k_apply(i, x):
        a, b = _cross_terms(Ku[i], x[3:]), _cross_terms(Ku[i], x[:3])
        return [P.sop([(Ks[i][r][k], x[k]) for k in range(3)] + [(-1.0, *t) for t in a[r]]) for r in range(3)] + \
               [P.sop(b[r]) for r in range(3)]

    def f_sums(i):
        F[i] = [P.sop([(f[i][k],)] + [(F[c][k],) for c in children[i]]) for k in range(6)]

    def q_of(i):
        # Q_i = S_i x* F - (IC w_i + K dv_i + dv_i x* HC)
        Qv[i] = [P.sop(_crf_terms(S[i], F[i])[r] + _scaled(_apply_terms(_si6(IC[i]), w[i]), -1.0)[r]
                       + [(-1.0, Kdv[i][r])] + _scaled(_crf_terms(dv[i], HC[i]), -1.0)[r]) for r in range(6)]

    for i in range(n - 1, -1, -1):
        P.block = block0 + 3 * n - i
        b, Si, kids = bodies[i], S[i], children[i]
        IC[i] = [P.sop([(I[i][k],)] + [(IC[c][k],) for c in kids]) for k in range(10)]
        wi, vo = v[i][:3], v[i][3:]
        m, hm, Jm = I[i][0], I[i][1:4], [row[:3] for row in I6[i][:3]]
        W = [[0.0, -wi[2], wi[1]], [wi[2], 0.0, -wi[0]], [-wi[1], wi[0], 0.0]]
        Ksi = [[None] * 3 for _ in range(3)]
        for r in range(3):
            for c in range(r, 3):
                terms = [(Ks[ch][r][c],) for ch in kids]
                terms += [(-1.0, Jm[r][k], W[k][c]) for k in range(3)] + [(-1.0, Jm[c][k], W[k][r]) for k in range(3)]
                terms += [(-1.0, vo[r], hm[c]), (-1.0, hm[r], vo[c])]
                if r == c:
                    terms += [(2.0, hm[k], vo[k]) for k in range(3)]
                Ksi[r][c] = Ksi[c][r] = P.sop(terms)
        Ks[i] = Ksi
        hw = _cross_terms(hm, wi)
        Ku[i] = [P.sop(hw[k] + [(-m, vo[k])] + [(Ku[ch][k],) for ch in kids]) for k in range(3)]
        HC[i] = [P.sop([(h[i][k],)] + [(HC[c][k],) for c in kids]) for k in range(6)]
        f_sums(i)
        if fd:  # F at qdd = 0: the bias forces
            bias[i] = P.sop([(Si[k], F[i][k]) for k in range(6)])
        IC6 = _si6(IC[i])
        KS, Kdv[i] = k_apply(i, Si), k_apply(i, dv[i])
        g1, g2, g3 = _cross_terms(HC[i][:3], Si[:3]), _cross_terms(HC[i][3:], Si[3:]), _cross_terms(HC[i][3:], Si[:3])
        al[i] = [P.sop(t) for t in _apply_terms(IC6, Si)] + \
                [P.sop([(KS[k],)] + g1[k] + g2[k]) for k in range(3)] + \
                [P.sop([(KS[3 + k],)] + g3[k]) for k in range(3)]
        # P_i = IC u_i + K S_i + S_i x* HC with u_i = -2 dv_i
        Pv[i] = [P.sop(_scaled(_apply_terms(IC6, dv[i]), -2.0)[r] + [(KS[r],)] + _crf_terms(Si, HC[i])[r])
                 for r in range(6)]
        if not fd:
            q_of(i)
        for j in path[i]:
            Mlow[i, j] = P.sop([(al[i][k], S[j][k]) for k in range(6)] + ([(b.rotor,)] if j == i else []))

    block = block0 + 3 * n + 1
    if fd:
        # qdd, then the passes at qdd: w, a, f forward, F and Q backward
        qdd, block = solve(Mlow, bias, block)
        for i in range(n):
            P.block = block + i
            vp, ap = parent_motion(i)
            w[i] = w_of(i, vp, ap)
            a[i] = a_of(i, ap, qdd)
            f[i] = [P.sop(t + [(vxh[i][k],)]) for k, t in enumerate(_apply_terms(I6[i], a[i]))]
        for i in range(n - 1, -1, -1):
            P.block = block + 2 * n - 1 - i
            f_sums(i)
            q_of(i)
        block += 2 * n

    # -dID: entries (i, j) for j on the path of i (row i: al_i) and (j, i) for j strictly above i (column i: P, Q)
    nq, nd, slope = {}, {}, [None] * n
    for i, b in enumerate(bodies):
        P.block = block + i
        slope[i] = P.sop(_friction_slope_terms(P, b, qd[i]))
        for j in path[i]:
            nq[i, j] = P.sop([(al[i][k], w[j][k]) for k in range(6)] + [(al[i][6 + k], dv[j][k]) for k in range(6)])
            terms = [(2.0, al[i][k], dv[j][k]) for k in range(6)] + [(-1.0, al[i][6 + k], S[j][k]) for k in range(6)]
            if j == i:
                terms += [(-1.0, slope[i])]
            nd[i, j] = P.sop(terms)
            if j != i:
                nq[j, i] = P.sop([(-1.0, S[j][k], Qv[i][k]) for k in range(6)])
                nd[j, i] = P.sop([(-1.0, S[j][k], Pv[i][k]) for k in range(6)])

    tauF = [P.sop([(S[i][k], F[i][k]) for k in range(6)]) for i in range(n)]
    return nq, nd, Mlow, tauF, (al, Pv, Qv, w, dv, S, slope)


def _passive(P: Program, b, qd):
    """The joint's passive force as product terms: damping and the smooth Coulomb friction (the runtime's)."""
    terms = [(b.damping, qd)]
    if b.friction != 0.0:
        terms.append((b.friction, P.call("tanh", P.mul(1.0 / b.friction_velocity, qd))))
    return terms


def _fd_jacobian(P: Program, bodies: list, gravity, q, qd, tau, out: str = "qdd", product: bool = True):
    """qdd (n values, written to the C array ``out``) and J (n x 3n values) = [∂qdd/∂q, ∂qdd/∂qd, M^-1];
    without ``product``, M^-1 and J's first 2n columns are left to loops (:class:`_DenseProduct`): J is then
    (X, related, parts), X = L^-1 (its entries (i, k), k on i's path), ``parts`` the vectors -∂ID's entries
    are formed of (:func:`_rnea_derivatives`).

    qdd = M^-1 (tau - bias - passive) from the M^-1 the Jacobian holds, not by the articulated-body
    algorithm (11 % fewer instructions on iiwa): the derivatives' passes run in the forward dynamics'
    order (:func:`_rnea_derivatives` with ``solve``)."""
    n = len(bodies)
    path, subtree = _paths(bodies)
    Minv, solved, Xs = {}, [], {}
    minv_loop = sum(len(s) * (len(s) + 1) // 2 for s in subtree) >= MINV_LOOP_MIN

    def solve(Mlow, bias, block):
        # M = L^T L without fill-in, leaves first: L[k][j] (j on k's path) from M[k][j] minus the terms of
        # k's descendants, each entry one sum; then X = L^-1 (nonzero on the paths) and M^-1 = X X^T
        L, pend = {}, {key: [] for key in Mlow}
        for k in range(n - 1, -1, -1):
            P.block = block + (n - 1 - k)
            dkk = P.sop([(Mlow[k, k],)] + pend[k, k])
            if isinstance(dkk, Var):
                P.effect(f"if (!({c_value(dkk)} > 0.0)) return 1;", [dkk])
            elif not dkk > 0.0:
                raise NotPositiveDefinite(f"body {k}: the mass matrix is not positive definite")
            d = _sqrt(P, dkk)
            inv = P.recip(d)
            L[k, k] = d
            for j in path[k][1:]:  # the sum, then one product by 1/d (not 1/d in every term)
                L[k, j] = P.mul(P.sop([(Mlow[k, j],)] + pend[k, j]), inv)
            for i in path[k][1:]:
                for j in path[i]:
                    pend[i, j].append((-1.0, L[k, i], L[k, j]))
        X = {}
        for i in range(n):
            P.block = block + n + i
            X[i, i] = P.recip(L[i, i])
            for kk in path[i][1:]:
                upto = path[i][1:path[i].index(kk) + 1]  # from the parent of i up to k
                X[i, kk] = P.sop([(-1.0, P.sop([(L[i, j], X[j, kk]) for j in upto]), X[i, i])])
        Xs.update(X)
        for ai in range(n) if product or not minv_loop else ():  # else M^-1 = X X^T is a loop (_DenseProduct)
            P.block = block + 2 * n + ai
            pa = set(path[ai])
            for bi in range(ai + 1):
                common = [k for k in path[bi] if k in pa]
                val = P.sop([(X[ai, k], X[bi, k]) for k in common]) if common else 0.0
                Minv[ai, bi] = Minv[bi, ai] = val
        P.block = block + 3 * n
        rhs = [P.sop([(tau[i],), (-1.0, bias[i])] + [(-1.0, *t) for t in _passive(P, b, qd[i])])
               for i, b in enumerate(bodies)]
        # qdd = M^-1 rhs (other branches' zeros fold away), or X (X^T rhs), two passes over the paths, where
        # M^-1 is left to the loop or that has fewer products: on a tree, not on a chain (Tiago 922 against
        # 2,118; iiwa 56 against 49)
        rows = [[(Minv[r, i], rhs[i]) for i in range(n) if isinstance(Minv[r, i], Var) or Minv[r, i] != 0.0]
                for r in range(n)] if Minv else None
        if not Minv or 2 * sum(len(p_) for p_ in path) < sum(len(t) for t in rows):
            y = [P.sop([(X[i, k], rhs[i]) for i in subtree[k]]) for k in range(n)]
            rows = [[(X[r, k], y[k]) for k in path[r]] for r in range(n)]
        qdd = []
        for r in range(n):
            qdd.append(P.sop(rows[r]))
            P.effect(f"{out}[{r}] = {c_value(qdd[r])};", [qdd[r]])
        solved.extend(qdd)
        return qdd, block + 3 * n + 1

    nq, nd, Mlow, _, parts = _rnea_derivatives(P, bodies, gravity, q, qd, None, 0, solve)

    # the columns: J_q[r][c] = sum_i M^-1[r][i] (-dID_q)[i][c] over the i related to c
    related = [sorted(set(path[c]) | set(subtree[c])) for c in range(n)]
    if not product:
        return solved, (Xs, Minv, related, parts)
    J = [[0.0] * (3 * n) for _ in range(n)]
    for r in range(n):
        P.block = 9 * n + 2 + r
        for c in range(n):
            J[r][c] = P.sop([(Minv[r, i], nq[i, c]) for i in related[c]])
            J[r][n + c] = P.sop([(Minv[r, i], nd[i, c]) for i in related[c]])
            J[r][2 * n + c] = Minv[r, c]
    return solved, J


class _DenseProduct:
    """[∂qdd/∂q, ∂qdd/∂qd] = M^-1 [-∂ID/∂q, -∂ID/∂qd] as loops instead of straight-line sums.

    On the large trees the product is most of the Jacobian's arithmetic (Tiago: 76,000 of 136,000
    multiplications) and M^-1 is dense on each root branch, so straight-line code spends it one scalar
    at a time from a megabyte of instructions.  Here the statements store M^-1 (into J's last n columns,
    where it belongs) -- or, where X X^T has many products (``MINV_LOOP_MIN``: Tiago, not Talos), X's rows
    -- and the per-body vectors of -∂ID (the scratch ``fmugen_wb``), and the loops follow:

    * M^-1 = X X^T from X's rows (:meth:`_minv`), where the statements did not form it;
    * -∂ID's entries, two per pair of related joints: column j's rows i in j's subtree are
      al_i . [w_j; dv_j] and 2 al_i . dv_j - al_i . S_j (less the friction's slope on the diagonal), its rows
      above j -S_j . Q_i and -S_j . P_i -- dot products of 12 and 6 numbers, four rows i at a time over
      the runs of consecutive bodies of j's subtree (al, P, Q stored component by component).  As
      statements they were a sixth of Tiago's time (two loads per multiplication, one at a time);
    * for each column c and each joint i related to c, the scaled row i of M^-1 over c's branch: axpys of
      the branch's length, up to 48 rows of sums in twelve registers (both kinds, q and qd, in one pass
      up to 24 rows), stored contiguously into the scratch T;
    * T into J's rows, four by four through register shuffles: stored straight from the sums, a row of
      J apart, the scalars took a sixth of the loops' instructions.

    gcc vectorises them (AVX2 in the x86-64-v3 build).  Where M^-1 is a loop too (Tiago), the loops have
    an AVX-512 variant, called where the CPU has x86-64-v4: eight rows a register and 32 registers, so a
    column's sums of both kinds fit one pass up to 64 rows (Tiago's 46: 0.89x the time of the AVX loops,
    timed in one process); on Atlas, Talos and the arms it measured 1.00-1.03x, and they keep the AVX
    loops.  Rows of other branches are zeros, stored by statements.  The product as a loop was faster
    than the sums on every robot measured (µs, both timed in one run per robot: UR5 0.86 against 0.91,
    iiwa 1.10 against 1.18, Atlas 7.0 against 7.8, Talos 13.0 against 20.1, Tiago 22.2 against 44.0), for
    0.3-0.6 of the compile time on the large trees (Tiago 16 against 62 s) and 0.8-0.9 on the arms.  The
    passes into T, the transposes and M^-1 as a loop on Tiago against the product's earlier stores and
    M^-1 as statements: 0.90x the time on Atlas, 0.96x Talos, 0.94x Tiago, 0.99x HyQ, the arms within
    1.5 % (both timed in one process)."""

    def __init__(self, n: int, X, Minv, related, parts, bodies):
        if any(not b.parent < i for i, b in enumerate(bodies)):
            raise ValueError("bodies must follow their parents (parent < body)")
        self.n = n
        path, subtree = _paths(bodies)
        self.path = path
        self.poff = [0]  # X's row i: entries poff[i] .. poff[i + 1] - 1, for path[i] in order
        for p_ in path:
            self.poff.append(self.poff[-1] + len(p_))
        root = [p[-1] for p in path]
        # each column's rows: the span of its root branch (a branch broken by another: its span holds
        # the other's zero entries of M^-1, which are stored like the rest)
        span = {}
        for i, r in enumerate(root):
            lo, hi = span.get(r, (i, i + 1))
            span[r] = (min(lo, i), max(hi, i + 1))
        self.rows = [span[root[c]] for c in range(n)]
        self.X, self.Minv, self.related, self.parts = X, Minv, related, parts
        self.start = [0]
        for c in range(n):
            self.start.append(self.start[-1] + len(related[c]))
        # parents first: column j's related joints are its ancestors by depth, then its subtree in order,
        # so (i, j) is entry start[j] + depth[j] + (rank of i in the subtree) and (j, i), j above i, entry
        # start[i] + depth[j]
        self.depth = [len(p) - 1 for p in path]
        self.sub = [sorted(x) for x in subtree]
        for j in range(n):
            assert related[j] == sorted(path[j][1:]) + self.sub[j]
        t = self.start[-1] + 7
        # the spans (rows lo..hi-1), their columns and where their sums start in T (q's, then qd's) and
        # their columns of X in Xc
        self.spans, t0, x0 = [], 0, 0
        for lo, hi in sorted(set(self.rows)):
            cols = [c for c in range(n) if self.rows[c] == (lo, hi)]
            self.spans.append((lo, hi, cols, t0, x0))
            t0 += 2 * len(cols) * (hi - lo)
            x0 += len(cols) * (hi - lo)
        # the scratch: -∂ID/∂q's and -∂ID/∂qd's entries (each followed by seven slots that the last run's
        # four- or eight-row store may overrun), al (12 x n), P, Q (6 x n), [w, dv, S] of each body, the friction's
        # slopes, T (the product's sums, column after column), X's rows (by path) and X's columns over the
        # spans' rows (zeros off the subtrees; these two where the loop forms M^-1)
        e = 2 * t + 43 * n
        self.at = {"bq": 0, "bd": t, "al": 2 * t, "P": 2 * t + 12 * n, "Q": 2 * t + 18 * n, "ws": 2 * t + 24 * n,
                   "slope": 2 * t + 42 * n, "T": e, "Xp": e + t0, "Xc": e + t0 + self.poff[-1],
                   "end": e + t0 + (self.poff[-1] + x0 if not Minv else 0)}

    def emit_args(self, target: str, base: int) -> dict:
        """emit_c's arguments for the loops: the scratch and the loops' function."""
        wide = [self.loop(target, base, lanes=8)] if not self.Minv else []  # measured: Tiago, not Talos
        return {"scratch": self.at["end"], "loops": [("product", self.loop(target, base), *wide)]}

    def effects(self, P: Program, target: str, base: int):
        """The statements: X's rows, the zero rows of the first 2n columns and the vectors of -∂ID, each
        stored in the block that computes it (from a register: through the work array, M^-1 alone took 8%
        of Tiago's time)."""
        n, end, at = self.n, P.block, self.at
        al, Pv, Qv, w, dv, S, slope = self.parts

        def store(text, v):
            P.block = P.home([v], end)
            P.effect(text, [v])

        for r in range(n) if self.Minv else ():
            for c in range(n):
                store(f"{target}[{base + 3 * n * r + 2 * n + c}] = {c_value(self.Minv[r, c])};", self.Minv[r, c])
        for i in range(n) if not self.Minv else ():
            for m, k in enumerate(self.path[i]):
                store(f"fmugen_wb[{at['Xp'] + self.poff[i] + m}] = {c_value(self.X[i, k])};", self.X[i, k])
        for c in range(n):
            lo, hi = self.rows[c]
            for r in [*range(lo), *range(hi, n)]:
                store(f"{target}[{base + 3 * n * r + c}] = 0.0;", 0.0)
                store(f"{target}[{base + 3 * n * r + n + c}] = 0.0;", 0.0)
        for i in range(n):
            for k in range(12):
                store(f"fmugen_wb[{at['al'] + n * k + i}] = {c_value(al[i][k])};", al[i][k])
            for k in range(6):
                store(f"fmugen_wb[{at['P'] + n * k + i}] = {c_value(Pv[i][k])};", Pv[i][k])
                store(f"fmugen_wb[{at['Q'] + n * k + i}] = {c_value(Qv[i][k])};", Qv[i][k])
            for k, v in enumerate([*w[i], *dv[i], *S[i]]):
                store(f"fmugen_wb[{at['ws'] + 18 * i + k}] = {c_value(v)};", v)
            if isinstance(slope[i], Var):
                store(f"fmugen_wb[{at['slope'] + i}] = {c_value(slope[i])};", slope[i])
        P.block = end

    def _runs(self, first: int) -> list:
        """(j, first body, length) of the runs of consecutive bodies in each j's subtree (its own row left
        out for ``first`` = 1)."""
        runs = []
        for j in range(self.n):
            for i in self.sub[j][first:]:
                if runs and runs[-1][0] == j and runs[-1][1] + runs[-1][2] == i:
                    runs[-1][2] += 1
                else:
                    runs.append([j, i, 1])
        return runs

    def _did(self, lanes: int = 4) -> list:
        """The loops forming -∂ID's entries (``lanes`` rows i at a time with the vector type, the rest in
        scalars)."""
        n, at = self.n, self.at
        lower, upper = self._runs(0), self._runs(1)
        # the lower runs' first entries: start[j] + depth[j] + rank in the subtree
        low = [self.start[j] + self.depth[j] + self.sub[j].index(i) for j, i, _ in lower]
        lines = [f"static const int lower[{len(lower)}][4] = {{"
                 + ", ".join(f"{{{j}, {i}, {m}, {k}}}" for (j, i, m), k in zip(lower, low)) + "};",
                 f"static const int upper[{len(upper)}][4] = {{"
                 + ", ".join(f"{{{j}, {i}, {m}, {self.depth[j]}}}" for j, i, m in upper) + "};",
                 f"double *const bq = w_ + {at['bq']}, *const bd = w_ + {at['bd']};",
                 f"const double *const al = w_ + {at['al']}, *const Pt = w_ + {at['P']}, "
                 f"*const Qt = w_ + {at['Q']};",
                 "/* rows i in the subtree of column j: al_i . [w_j; dv_j] and 2 al_i . dv_j - al_i . S_j */",
                 f"for (int u = 0; u < {len(lower)}; u++) {{",
                 "    const int i0 = lower[u][1], len = lower[u][2];",
                 f"    const double *W = w_ + {at['ws']} + 18 * lower[u][0];",
                 "    double *oq = bq + lower[u][3], *od = bd + lower[u][3];",
                 "    int t = 0;"]

        def body(vec: bool, what: str) -> list:
            ty = ("fmugen_v8" if lanes == 8 else "fmugen_v4") if vec else "double"
            if vec:
                ld = (lambda a, k: f"memcpy(&x, {a} + {n * k} + i0 + t, sizeof x);")
            else:
                ld = (lambda a, k: f"x = {a}[{n * k} + i0 + t];")
            if what == "lower":
                ls = [f"{ty} sq = {{0.0}}, sd = {{0.0}}, x;" if vec else "double sq = 0.0, sd = 0.0, x;"]
                for k in range(6):
                    ls += [ld("al", k), f"sq += W[{k}] * x;", f"sd += (2.0 * W[{6 + k}]) * x;"]
                for k in range(6):
                    ls += [ld("al", 6 + k), f"sq += W[{6 + k}] * x;", f"sd -= W[{12 + k}] * x;"]
                ls += ["memcpy(oq + t, &sq, sizeof sq);", "memcpy(od + t, &sd, sizeof sd);"] if vec else \
                    ["oq[t] = sq;", "od[t] = sd;"]
            else:
                ls = [f"{ty} sq = {{0.0}}, sd = {{0.0}}, x;" if vec else "double sq = 0.0, sd = 0.0, x;"]
                for k in range(6):
                    ls += [ld("Qt", k), f"sq -= S[{k}] * x;", ld("Pt", k), f"sd -= S[{k}] * x;"]
                if vec:
                    ls += [f"for (int l = 0; l < {lanes} && t + l < len; l++) {{",
                           "    const int e = first[i0 + t + l] + dj;",
                           "    bq[e] = sq[l];", "    bd[e] = sd[l];", "}"]
                else:
                    ls += ["bq[first[i0 + t] + dj] = sq;", "bd[first[i0 + t] + dj] = sd;"]
            return ls

        # four (eight) rows at a time to the end of the run: the lanes past it (rows of other subtrees, or
        # past n into the next component) land on the run's next entries -- the next run's, the next
        # column's, written after this one -- or on the seven spare slots after the last column (no scalar
        # tail: it was most of these loops' instructions on the arms)
        lines += ["#ifdef FMUGEN_UNROLLED_V4", f"    for (; t < len; t += {lanes}) {{"]
        lines += ["        " + x for x in body(True, "lower")]
        lines += ["    }", "#else", "    for (; t < len; t++) {"]
        lines += ["        " + x for x in body(False, "lower")]
        lines += ["    }", "#endif", "}"]
        # the friction's slope on the diagonal
        for j, s in enumerate(self.parts[6]):
            if isinstance(s, Var):
                lines.append(f"bd[{self.start[j] + self.depth[j]}] -= w_[{at['slope'] + j}];")
            elif s != 0.0:
                lines.append(f"bd[{self.start[j] + self.depth[j]}] -= {c_value(s)};")
        lines += ["/* rows j above column i: -S_j . Q_i and -S_j . P_i, four columns i at a time */",
                  f"for (int u = 0; u < {len(upper)}; u++) {{",
                  "    const int i0 = upper[u][1], len = upper[u][2], dj = upper[u][3];",
                  f"    const double *S = w_ + {at['ws']} + 18 * upper[u][0] + 12;",
                  "    int t = 0;",
                  "#ifdef FMUGEN_UNROLLED_V4",
                  f"    for (; t < len; t += {lanes}) {{  /* the lanes past the run not stored */"]
        lines += ["        " + x for x in body(True, "upper")]
        lines += ["    }", "#else", "    for (; t < len; t++) {"]
        lines += ["        " + x for x in body(False, "upper")]
        lines += ["    }", "#endif", "}"]
        return lines

    def loop(self, target: str, base: int, lanes: int = 4) -> list:
        """The loops' C lines: -∂ID's entries, then the product, one loop per branch span (its length a
        constant) over the span's columns, each column's sums into the scratch T (column after column),
        then T written into J's rows.  ``lanes``: the doubles of a register of sums, 4 (AVX) or 8 (the
        AVX-512 variant, twice the rows per instruction and 32 registers)."""
        n = self.n
        rel = ", ".join(str(i) for c in range(n) for i in self.related[c])
        # joints and columns fit a short; offsets into the entries (about n^2 / 2 on a chain) an int
        lines = [f"static const short rel[{self.start[-1]}] = {{{rel}}};  /* the joints related to each column */",
                 f"static const int first[{n + 1}] = {{{', '.join(str(x) for x in self.start)}}};",
                 "double *const w_ = fmugen_wb;",
                 f"double *const out = {target} + {base};"]
        lines += self._minv(target, base, lanes) if not self.Minv else []
        lines += ["{"] + ["    " + x for x in self._did(lanes)] + ["}"]
        for s_, (lo, hi, cols, t0, _) in enumerate(self.spans):
            nb = hi - lo
            if _gapless(cols):
                lines += [f"for (int c = {cols[0]}; c <= {cols[-1]}; c++) {{  /* rows {lo}..{hi - 1} */",
                          f"    const int u = c - {cols[0]};"]
            else:  # a branch broken by another
                lines += [f"static const short cols{s_}[{len(cols)}] = {{{', '.join(str(c) for c in cols)}}};",
                          f"for (int u = 0; u < {len(cols)}; u++) {{  /* rows {lo}..{hi - 1} */",
                          f"    const int c = cols{s_}[u];"]
            # a pass holds its sums in registers: both kinds at once up to half of ROWS, else one kind at
            # a time, ROWS rows a pass
            R = self._rows(lanes)
            passes = [(("q", "d"), 0, nb)] if 2 * nb <= R else \
                [((kind,), r0, min(R, nb - r0)) for kind in ("q", "d") for r0 in range(0, nb, R)]
            for kinds, r0, w in passes:
                lines += ["    " + x for x in self._pass(kinds, lo, r0, w, nb, len(cols), t0, lanes)]
            lines += ["}"]
            lines += self._transpose(lo, nb, cols, t0)
        return lines

    #: rows of sums a pass over a column's terms holds in registers: 48, twelve AVX registers; 128 in the
    #: AVX-512 variant, sixteen of its 32 registers
    ROWS = 48
    ROWS_WIDE = 128

    def _rows(self, lanes: int) -> int:
        """The rows of sums a pass holds with registers of ``lanes`` doubles."""
        return self.ROWS if lanes == 4 else self.ROWS_WIDE

    def _pass(self, kinds, lo: int, r0: int, w: int, nb: int, ncols: int, t0: int, lanes: int = 4) -> list:
        """Span rows lo + r0 .. lo + r0 + w - 1 of column c (the span's u-th) for each kind ("q": the column
        of ∂qdd/∂q, "d": of ∂qdd/∂qd), summed over the related joints' rows of M^-1, into T."""
        at = self.at
        coef = {"q": "fmugen_wb[t]", "d": f"fmugen_wb[{at['bd']} + t]"}
        dest = {k: f"fmugen_wb + {at['T'] + t0 + (0 if k == 'q' else ncols * nb) + r0} + {nb} * u" for k in kinds}
        return self._sums("first[c]", "first[c + 1]", f"out + {3 * self.n} * rel[t] + {2 * self.n + lo + r0}",
                          {k: coef[k] for k in kinds}, dest, w, lanes)

    @staticmethod
    def _sums(t0: str, t1: str, row: str, coef: dict, dest: dict, w: int, lanes: int = 4) -> list:
        """For each kind k of ``coef``: the sum over t = t0 .. t1 - 1 of coef[k] times the w doubles at
        ``row`` (C expressions of t), stored at ``dest[k]``: with gcc's and clang's vector types ``lanes``
        rows a register (the rows past the last ones: one more register overlapping the one before; below
        8 rows four a register, below four scalars), else plain loops.  A pass of the loop over t holds at
        most ROWS (ROWS_WIDE) rows of sums."""
        kinds = list(coef)
        if w < lanes:
            lanes = 4
        nv = w // lanes
        regs = [lanes * k for k in range(nv)] + ([w - lanes] if nv and w % lanes else [])
        vt = "fmugen_v8" if lanes == 8 else "fmugen_v4"
        head = [f"    for (int t = {t0}; t < {t1}; t++) {{", f"        const double *m = {row};"]
        head += [f"        const double b{k} = {coef[k]};" for k in kinds]
        vec = ["#ifdef FMUGEN_UNROLLED_V4", "{"]
        if regs:
            vec += [f"    {vt} " + ", ".join(f"{k}{j} = {{0.0}}" for k in kinds for j in range(len(regs))) + ", x;"]
            vec += head + [f"        memcpy(&x, m + {a}, sizeof x);" + "".join(f" {k}{j} += b{k} * x;" for k in kinds)
                           for j, a in enumerate(regs)]
            vec += ["    }"] + [f"    memcpy({dest[k]} + {a}, &{k}{j}, sizeof {k}{j});"
                                for k in kinds for j, a in enumerate(regs)]
        else:
            vec += ["    double " + ", ".join(f"{k}{j} = 0.0" for k in kinds for j in range(w)) + ";"]
            vec += head + [f"        {k}{j} += b{k} * m[{j}];" for j in range(w) for k in kinds]
            vec += ["    }"] + [f"    ({dest[k]})[{j}] = {k}{j};" for k in kinds for j in range(w)]
        vec += ["}", "#else", "{"]
        vec += ["    double " + ", ".join(f"{k}[{w}]" for k in kinds) + ";",
                f"    for (int r = 0; r < {w}; r++) {{ " + " ".join(f"{k}[r] = 0.0;" for k in kinds) + " }"]
        vec += head + [f"        for (int r = 0; r < {w}; r++) {{ " + " ".join(f"{k}[r] += b{k} * m[r];" for k in kinds)
                       + " }", "    }"]
        vec += [f"    for (int r = 0; r < {w}; r++) {{ " + " ".join(f"({dest[k]})[r] = {k}[r];" for k in kinds) + " }"]
        return vec + ["}", "#endif"]

    def _minv(self, target: str, base: int, lanes: int = 4) -> list:
        """M^-1 = X X^T into J's last n columns: per span, X's columns over the span's rows (zeros off the
        subtrees) from its rows by path, then column b of M^-1 (row b: M^-1 is symmetric) the sum of
        X[b][k] times column k over the joints k on b's path, ROWS rows a pass; entries outside a row's span
        zero.  As statements (one sum per entry, X X^T over the common paths) M^-1 was a fifth of Tiago's
        code, 116 of 552 kB in the x86-64-v3 build, which then streams from the third-level cache at every
        call: more than a 512 kB second-level cache holds (callgrind's cache model with one of 512 kB: 8,900
        misses of instructions a call, 6,900 with the loop)."""
        n, k3, at = self.n, 3 * self.n, self.at
        u_of = {}
        for lo, hi, cols, _, _ in self.spans:
            u_of.update({c: u for u, c in enumerate(cols)})
        pcol = [u_of[k] for i in range(n) for k in self.path[i]]
        lines = ["{",
                 f"    static const int pfirst[{n + 1}] = {{{', '.join(str(x) for x in self.poff)}}};",
                 f"    static const short pcol[{len(pcol)}] = {{{', '.join(str(x) for x in pcol)}}};",
                 f"    double *const out2 = {target} + {base + 2 * n};"]
        for s_, (lo, hi, cols, _, x0) in enumerate(self.spans):
            nb, ncols = hi - lo, len(cols)
            src = [self.poff[b] + m for b in cols for m in range(len(self.path[b]))]
            dst = [u_of[k] * nb + b - lo for b in cols for k in self.path[b]]
            contiguous = _gapless(cols)
            lines += ["    {",
                      f"        double *const Xc = fmugen_wb + {at['Xc'] + x0};  /* rows {lo}..{hi - 1} */",
                      f"        static const int xsrc[{len(src)}] = {{{', '.join(str(x) for x in src)}}};",
                      f"        static const int xdst[{len(dst)}] = {{{', '.join(str(x) for x in dst)}}};",
                      f"        memset(Xc, 0, {ncols * nb} * sizeof(double));",
                      f"        for (int t = 0; t < {len(src)}; t++) Xc[xdst[t]] = fmugen_wb[{at['Xp']} + xsrc[t]];"]
            if contiguous:
                lines += [f"        for (int c = {cols[0]}; c <= {cols[-1]}; c++) {{"]
            else:
                lines += [f"        static const short mcols{s_}[{ncols}] = {{{', '.join(str(c) for c in cols)}}};",
                          f"        for (int u = 0; u < {ncols}; u++) {{", f"            const int c = mcols{s_}[u];"]
            if lo > 0:
                lines.append(f"            memset(out2 + {k3} * c, 0, {lo} * sizeof(double));")
            if hi < n:
                lines.append(f"            memset(out2 + {k3} * c + {hi}, 0, {n - hi} * sizeof(double));")
            R = self._rows(lanes)
            for r0 in range(0, nb, R):
                w = min(R, nb - r0)
                lines += ["            " + x for x in self._sums(
                    "pfirst[c]", "pfirst[c + 1]", f"Xc + {nb} * pcol[t] + {r0}", {"x": f"fmugen_wb[{at['Xp']} + t]"},
                    {"x": f"out2 + {k3} * c + {lo + r0}"}, w, lanes)]
            lines += ["        }", "    }"]
        return lines + ["}"]

    def _transpose(self, lo: int, nb: int, cols: list, t0: int) -> list:
        """T (a column's rows contiguous) into J's rows: four by four with register shuffles where the
        span's columns are its rows (a branch numbered without a gap) and four or more, else one by one.
        Scalar stores straight from the sums, a row of J apart, took a sixth of the loops' instructions."""
        n, k3, T = self.n, 3 * self.n, self.at["T"] + t0
        ncols = len(cols)
        plain = [f"for (int u = 0; u < {ncols}; u++)" + (f"  /* columns {cols[0]}..{cols[-1]} */" if ncols > 1 else ""),
                 f"    for (int r = 0; r < {nb}; r++) {{",
                 f"        const int c = {'u + %d' % cols[0] if _gapless(cols) else 'colsT[u]'};",
                 f"        out[{k3} * ({lo} + r) + c] = fmugen_wb[{T} + {nb} * u + r];",
                 f"        out[{k3} * ({lo} + r) + {n} + c] = fmugen_wb[{T + ncols * nb} + {nb} * u + r];",
                 "    }"]
        if not _gapless(cols):
            return ["{", f"    static const short colsT[{ncols}] = {{{', '.join(str(c) for c in cols)}}};"] + \
                ["    " + x for x in plain] + ["}"]
        if nb < 4 or cols != list(range(lo, lo + nb)):
            return plain
        starts = list(range(0, nb - 3, 4)) + ([nb - 4] if nb % 4 else [])
        lines = ["#ifdef FMUGEN_UNROLLED_V4",
                 "{",
                 f"    static const short st[{len(starts)}] = {{{', '.join(str(x) for x in starts)}}};",
                 f"    for (int x = 0; x < {len(starts)}; x++)",
                 f"        for (int y = 0; y < {len(starts)}; y++)",
                 "            for (int h = 0; h < 2; h++) {  /* q, then qd */",
                 f"                const double *s = fmugen_wb + {T} + h * {ncols * nb} + {nb} * st[y] + st[x];",
                 f"                double *d = out + {k3} * ({lo} + st[x]) + h * {n} + {lo} + st[y];",
                 "                fmugen_v4 a0, a1, a2, a3;",
                 f"                memcpy(&a0, s, sizeof a0); memcpy(&a1, s + {nb}, sizeof a1);",
                 f"                memcpy(&a2, s + {2 * nb}, sizeof a2); memcpy(&a3, s + {3 * nb}, sizeof a3);",
                 "                const fmugen_v4 b0 = FMUGEN_SHUFFLE(a0, a1, 0, 4, 2, 6),",
                 "                                b1 = FMUGEN_SHUFFLE(a0, a1, 1, 5, 3, 7);",
                 "                const fmugen_v4 b2 = FMUGEN_SHUFFLE(a2, a3, 0, 4, 2, 6),",
                 "                                b3 = FMUGEN_SHUFFLE(a2, a3, 1, 5, 3, 7);",
                 "                a0 = FMUGEN_SHUFFLE(b0, b2, 0, 1, 4, 5); a1 = FMUGEN_SHUFFLE(b1, b3, 0, 1, 4, 5);",
                 "                a2 = FMUGEN_SHUFFLE(b0, b2, 2, 3, 6, 7); a3 = FMUGEN_SHUFFLE(b1, b3, 2, 3, 6, 7);",
                 f"                memcpy(d, &a0, sizeof a0); memcpy(d + {k3}, &a1, sizeof a1);",
                 f"                memcpy(d + {2 * k3}, &a2, sizeof a2); memcpy(d + {3 * k3}, &a3, sizeof a3);",
                 "            }",
                 "}",
                 "#else"]
        return lines + plain + ["#endif"]

def _gapless(cols: list) -> bool:
    """Whether a span's columns are consecutive numbers (a branch numbered without a gap)."""
    return cols == list(range(cols[0], cols[-1] + 1))


def _id_jacobian(P: Program, bodies: list, gravity, q, qd, qdd):
    """tau (n values) and J (n x 3n values) = [∂tau/∂q, ∂tau/∂qd, M]."""
    n = len(bodies)
    nq, nd, Mlow, tauF, _ = _rnea_derivatives(P, bodies, gravity, q, qd, qdd, 0)
    P.block = 4 * n + 1
    tau = []
    for i, b in enumerate(bodies):
        tau.append(P.sop([(tauF[i],), (b.rotor, qdd[i])] + _passive(P, b, qd[i])))
    J = [[0.0] * (3 * n) for _ in range(n)]
    for (i, j), x in nq.items():
        J[i][j] = -x
    for (i, j), x in nd.items():
        J[i][n + j] = -x
    for (i, j), x in Mlow.items():
        J[i][2 * n + j] = J[j][2 * n + i] = x
    return tau, J


#: the two generated functions: (pass function, its argument names, what it writes, the header's words)
_KINDS = {"fd": (_fd_jacobian, ("q", "qd", "tau"), "qdd", "the forward dynamics of one robot and its Jacobian "
                 "[dqdd/dq, dqdd/dqd, M^-1]"),
          "id": (_id_jacobian, ("q", "qd", "qdd"), "tau", "the inverse dynamics of one robot and its Jacobian "
                 "[dtau/dq, dtau/dqd, M]")}


@dataclass
class UnrolledJacobian(UnrolledFD):
    """The generated C (as :class:`fmugen.codegen.unrolled_aba.UnrolledFD`); ``kind``: "fd" or "id" (the
    functions of :func:`unrolled_jacobian`), or one of :data:`STEP_KINDS` (:func:`chain_step`)."""
    kind: str = "fd"


def unrolled_jacobian(revolute: Sequence[bool], parents: Sequence[int], constants, gravity, kind: str = "fd",
                      name: str = "", static: bool = False, block_statements: int = 200,
                      dense_product: bool = True) -> UnrolledJacobian:
    """Straight-line C of the forward (``kind="fd"``) or inverse (``"id"``) dynamics and its Jacobian
    (``constants``: n x NC, the numbers of :class:`fmugen.batch.Kernels`)::

        int NAME(const double *q, const double *qd, const double *tau, double *qdd, double *J);   fd
        int NAME(const double *q, const double *qd, const double *qdd, double *tau, double *J);   id

    J is n x 3n, row-major.  Returns 0, 1 (an articulated inertia or a pivot of M not positive; fd) or 2
    (the result not finite).  ``dense_product``: the product M^-1 (-∂ID) of fd as a loop
    (:class:`_DenseProduct`, faster on every robot measured) or as straight-line sums (False: the
    reference the tests hold the loop against)."""
    if kind not in _KINDS:
        raise ValueError(f"kind {kind!r}: 'fd' or 'id'")
    passes, ins, out, words = _KINDS[kind]
    name = name or f"fmugen_unrolled_{kind}_jacobian"
    n = len(revolute)
    bodies = body_frames(revolute, parents, constants)
    P = Program()
    args = [[Var(f"{a}[{i}]") for i in range(n)] for a in ins]
    loop = kind == "fd" and dense_product
    res, J = passes(P, bodies, gravity, *args, **({"product": False} if loop else {}))
    P.block = 11 * n + 3  # after the passes' last block (blocks follow the order of emission)
    if kind == "id":
        for i in range(n):
            P.effect(f"tau[{i}] = {c_value(res[i])};", [res[i]])
    dense = _DenseProduct(n, *J, bodies) if loop else None
    if dense:
        dense.effects(P, "J", 0)
    else:
        for r in range(n):
            for c in range(3 * n):
                P.effect(f"J[{3 * n * r + c}] = {c_value(J[r][c])};", [J[r][c]])
    header = [f"/* generated by fmugen.codegen.unrolled_derivatives: {words} ({n} bodies),",
              " * the robot's numbers folded into the code */"]
    params = tuple(f"const double *{a}" for a in ins) + (f"double *{out}", "double *J")
    source, count, nblocks = emit_c(P, name, params, header,
                                    [f"for (int i = 0; i < {n}; i++)", f"    if (!isfinite({out}[i])) return 2;"],
                                    static=static, block_statements=block_statements, clones="v4",
                                    schedule=kind == "fd", **(dense.emit_args("J", 0) if dense else {}))
    return UnrolledJacobian(name, n, source, count, nblocks, kind)


def evaluate_numeric(revolute, parents, constants, gravity, q, qd, u, kind: str = "fd"):
    """The same passes on numbers (every value folds): (qdd, J) for ``u = tau`` (fd) or (tau, J) for
    ``u = qdd`` (id), without a compiler."""
    bodies = body_frames(revolute, parents, constants)
    res, J = _KINDS[kind][0](Program(), bodies, gravity, [float(x) for x in q], [float(x) for x in qd],
                             [float(x) for x in u])
    return np.array(res, float), np.array(J, float)


def from_kernels(kernels, kind: str = "fd", **kw) -> UnrolledJacobian:
    """:func:`unrolled_jacobian` of a :class:`fmugen.batch.Kernels`."""
    return unrolled_jacobian(kernels.revolute, kernels.parents, kernels.constants, np.asarray(kernels.globals)[:3],
                             kind, **kw)


# ------------------------------------------------------------ a step of a generated model
def _end_effector(P: Program, bodies: list, q, ee_body: int, ee_position, block0: int):
    """p_ee (3 values) and dp_ee/dq (3 x n values): the point ``ee_position`` of body ``ee_body``'s frame
    F (-1: none, zeros).  B = F Q with its origin moved by ``shift`` along the joint axis, so
    p_ee = p_B + R_B (Q^T ee_position - shift e_z); a joint j on the body's path moves it by
    z_j x (p_ee - p_j) (revolute) or z_j (prismatic) per unit of q_j."""
    n = len(bodies)
    dp = [[0.0] * n for _ in range(3)]
    if ee_body < 0:
        return [0.0, 0.0, 0.0], dp
    R, p, S, _ = _world_kinematics(P, bodies, q, block0)  # the same statements as the passes' (shared)
    b = bodies[ee_body]
    c = np.array(b.Q).T @ np.asarray(ee_position, float) - np.array([0.0, 0.0, b.shift])
    pe = [P.sop([(p[ee_body][r],)] + [(R[ee_body][r][k], float(c[k])) for k in range(3)]) for r in range(3)]
    j = ee_body
    while j >= 0:
        if bodies[j].revolute:
            z = S[j][:3]
            col = cross(P, z, [P.sop([(pe[r],), (-1.0, p[j][r])]) for r in range(3)])
        else:
            col = S[j][3:]
        for r in range(3):
            dp[r][j] = col[r]
        j = bodies[j].parent
    return pe, dp


#: what a runtime step computes (fmugen.codegen.chain.ChainDynamics: kind -> the layout of X)
STEP_KINDS = ("fd", "jacobian", "id", "id_jacobian")


def chain_step(kind: str, revolute: Sequence[bool], parents: Sequence[int], constants, gravity, ee_body: int,
               ee_position, name: str) -> UnrolledJacobian:
    """A static C function computing what the runtime call of a :class:`fmugen.codegen.chain.ChainDynamics`
    step of this ``kind`` computes, for the robot's numbers (no external wrenches)::

        static int NAME(const double *q, const double *qd, const double *u, double *x);

    u is tau (fd, jacobian) or qdd (id, id_jacobian); x receives the step's X: fd [qdd, p_ee],
    jacobian [qdd, dqdd (n x 3n), dp_ee/dq (3 x n)], id [tau], id_jacobian [tau, dtau (n x 3n)].
    Returns the runtime's statuses (FMUGEN_OK, _NOT_POSITIVE_DEFINITE, _NOT_FINITE).  The text is
    one piece of a larger C file (:func:`fmugen.codegen.unrolled_aba.emit_c`, ``standalone=False``)."""
    if kind not in STEP_KINDS:
        raise ValueError(f"kind {kind!r}: one of {', '.join(STEP_KINDS)}")
    n = len(revolute)
    bodies = body_frames(revolute, parents, constants)
    P = Program()
    q, qd, u = ([Var(f"{a}[{i}]") for i in range(n)] for a in ("q", "qd", "u"))
    J, dense = None, None
    if kind == "fd":
        _aba(P, bodies, gravity, q, qd, u, out="x")
    elif kind == "jacobian":
        _, parts = _fd_jacobian(P, bodies, gravity, q, qd, u, out="x", product=False)
        dense = _DenseProduct(n, *parts, bodies)
    else:
        tau, J = _id_jacobian(P, bodies, gravity, q, qd, u)
        P.block = 11 * n + 3
        for i in range(n):
            P.effect(f"x[{i}] = {c_value(tau[i])};", [tau[i]])
    P.block = 11 * n + 4  # after the passes' blocks (blocks follow the order of emission)
    if dense:
        dense.effects(P, "x", n)
    elif kind == "id_jacobian":
        for r in range(n):
            for c in range(3 * n):
                P.effect(f"x[{n + 3 * n * r + c}] = {c_value(J[r][c])};", [J[r][c]])
    if kind == "fd":
        pe, _ = _end_effector(P, bodies, q, ee_body, ee_position, 11 * n + 5)
        for r in range(3):
            P.effect(f"x[{n + r}] = {c_value(pe[r])};", [pe[r]])
    elif kind == "jacobian":
        _, dp = _end_effector(P, bodies, q, ee_body, ee_position, 11 * n + 5)
        for r in range(3):
            for j in range(n):
                P.effect(f"x[{n + 3 * n * n + n * r + j}] = {c_value(dp[r][j])};", [dp[r][j]])
    words = {"fd": "forward dynamics and end-effector position", "jacobian": "forward dynamics, its Jacobian and "
             "the end effector's", "id": "inverse dynamics", "id_jacobian": "inverse dynamics and its Jacobian"}[kind]
    header = [f"/* {name}: the {words} of the {n}-body robot, generated by fmugen.codegen.unrolled_derivatives",
              " * (its numbers folded into the code) */"]
    source, count, nblocks = emit_c(P, name, ("const double *q", "const double *qd", "const double *u", "double *x"),
                                    header, [f"for (int i = 0; i < {n}; i++)", "    if (!isfinite(x[i])) return 2;"],
                                    static=True, standalone=False,
                                    clones="v4" if kind in ("jacobian", "id_jacobian") else kind == "fd",
                                    schedule=kind in ("fd", "jacobian"),
                                    **(dense.emit_args("x", n) if dense else {}))
    return UnrolledJacobian(name, n, source, count, nblocks, kind)


# ------------------------------------------------------------ the C harness (tests, benchmarks)
_HARNESS = r"""
#define _POSIX_C_SOURCE 199309L
#include <time.h>
int %(name)s(const double *q, const double *qd, const double *u, double *y, double *J);
/* rows of states: the status of the first row that fails, 0 when all succeed */
int unrolled_rows(int rows, int n, const double *q, const double *qd, const double *u, double *y, double *J)
{
    for (int r = 0; r < rows; r++) {
        int s = %(name)s(q + n * r, qd + n * r, u + n * r, y + n * r, J + 3 * n * n * r);
        if (s) return s;
    }
    return 0;
}
/* CPU seconds of the calling thread per call over k calls at one state */
double unrolled_time(int k, const double *q, const double *qd, const double *u, double *y, double *J)
{
    struct timespec a, b;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &a);
    for (int i = 0; i < k; i++) %(name)s(q, qd, u, y, J);
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &b);
    return ((b.tv_sec - a.tv_sec) + 1e-9 * (b.tv_nsec - a.tv_nsec)) / k;
}
"""


class CompiledUnrolledJacobian(CompiledUnrolled):
    """An :class:`UnrolledJacobian` compiled into a shared library in a temporary folder (as
    :class:`fmugen.codegen.unrolled_aba.CompiledUnrolledFD`).  ``derivatives(q, qd, u)`` returns, in the
    order of :meth:`fmugen.batch.Kernels.fd_derivatives` and ``id_derivatives``, (qdd, ∂qdd/∂q, ∂qdd/∂qd,
    M^-1) for u = tau (fd) or (tau, ∂tau/∂q, ∂tau/∂qd, M) for u = qdd (id)."""

    def __init__(self, gen: UnrolledJacobian, cc: str = "cc", flags: Sequence[str] = ("-O2",)):
        self.kind = gen.kind
        self.inputs = ("q", "qd", "tau" if gen.kind == "fd" else "qdd")
        super().__init__(gen.source, _HARNESS % {"name": gen.name}, gen.n, 5, cc, flags, "the unrolled Jacobian")

    def derivatives(self, q, qd, u) -> tuple:
        """(result, ∂/∂q, ∂/∂qd, third block) of every row of states (one row: without the leading axis)."""
        one = np.ndim(q) == 1
        q, qd, u = self._arrays(q, qd, u)
        rows, n = q.shape
        y, J = np.zeros_like(q), np.zeros((rows, n, 3 * n))
        s = self._lib.unrolled_rows(rows, n, q.ctypes.data, qd.ctypes.data, u.ctypes.data, y.ctypes.data,
                                    J.ctypes.data)
        if s == 1:
            raise np.linalg.LinAlgError("an articulated inertia or a pivot of the mass matrix is not positive")
        if s:
            raise FloatingPointError(f"{self.kind.upper()}: a result is NaN or infinite")
        out = (y, J[:, :, :n], J[:, :, n:2 * n], J[:, :, 2 * n:])
        return tuple(x[0] for x in out) if one else out

    def time_per_call(self, q, qd, u, k: int) -> float:
        """CPU seconds per call over k calls from a C loop at one state."""
        q, qd, u = self._arrays(q, qd, u)
        y, J = np.zeros(self.n), np.zeros(3 * self.n * self.n)
        return self._lib.unrolled_time(int(k), q.ctypes.data, qd.ctypes.data, u.ctypes.data, y.ctypes.data,
                                       J.ctypes.data)
