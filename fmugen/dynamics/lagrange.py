"""Inverse dynamics by the recursive Lagrange formulation (McGalliard thesis).

Source: McGalliard (1984), section II.F, Hollerbach's (1980) recursive form of
the Uicker/Kahn Lagrangian with 4x4 homogeneous matrices:

    T_j   = T_{j-1} A_j                                                (33)
    T'_j  = T'_{j-1} A_j + T_{j-1} dA_j qd_j                           (34)
    T''_j = T''_{j-1} A_j + 2 T'_{j-1} dA_j qd_j
            + T_{j-1} ddA_j qd_j^2 + T_{j-1} dA_j qdd_j                (35)
    D_i   = J_i T''_i^T + A_{i+1} D_{i+1}                              (37)
    c_i   = m_i r_i + A_{i+1} c_{i+1}                                  (38)
    f_i   = tr(dT_i/dq_i D_i) - g^T dT_i/dq_i c_i                      (39)

with dT_i/dq_i = T_{i-1} dA_i, J_i the 4x4 pseudo-inertia of link i about its
frame origin (eq. 19), r_i the homogeneous centre of mass and g the
homogeneous gravity vector.  The thesis's actuator kinetic energy (eq. 21)
adds Ia_i qdd_i; viscous damping adds b_i qd_i.  External forces enter as
-J_c^T w (the thesis's K(theta)^T k of eq. 29).

A robot written as joints (URDF) has no DH parameters: its link matrices are
A_j = [R p; 0 1] M(k, q_j) (the placement, then the motion about / along the
unit axis k), dA_j = A_j Q and ddA_j = A_j Q Q with Q the motion's generator,
and on a tree the recursions run over the parent of each body -- T_j from
T_parent(j) in eqs. 33-35, D_i and c_i summed over the children of i in eqs.
37-38 -- which is Hollerbach's recursion unchanged along every path.

This module deliberately shares nothing with the Newton-Euler module except
the program builder: it uses the file's own DH convention and 4x4 matrices,
so the two formulations check each other.
"""
from __future__ import annotations

from typing import Optional, Sequence

import sympy as sp

from ..codegen.program import Program
from ..robot.description import MODIFIED, PRISMATIC, REVOLUTE, Robot, combined_last_link
from .kinematics import dh_transform
from .trig import TrigCache

Z = sp.Integer(0)
ONE = sp.Integer(1)


def _mm(P: Program, A, B, hint="T"):
    """4x4 product with the homogeneous last row [0 0 0 x] exploited by sympy zeros."""
    return [[P.let(sum(A[i][k] * B[k][j] for k in range(4)), hint) for j in range(4)] for i in range(4)]


def _madd(P: Program, *Ms, hint="T"):
    return [[P.let(sum(M[i][j] for M in Ms), hint) for j in range(4)] for i in range(4)]


def _mscale(P: Program, s, A, hint="T"):
    return [[P.let(s * A[i][j], hint) for j in range(4)] for i in range(4)]


def _zero4():
    return [[Z] * 4 for _ in range(4)]


def _identity4():
    return [[ONE if i == j else Z for j in range(4)] for i in range(4)]


def _is_zero(M) -> bool:
    return all(sp.sympify(e) == 0 for row in M for e in row)


class RecursiveLagrange:
    """Builds the thesis's recursive Lagrange inverse dynamics into a Program."""

    def __init__(self, program: Program, robot: Robot, trig: Optional[TrigCache] = None):
        self.P = program
        self.robot = robot
        # a DH file: its links in its own convention; a robot written as joints (URDF): its bodies, with
        # A_j = [R p; 0 1] M(axis, q_j) (placement, then the motion), on a tree (parent per body)
        self.general = not robot.links
        self.links = robot.bodies if self.general else combined_last_link(robot)
        self.parents = [b.parent for b in robot.bodies]
        self.modified = robot.convention == MODIFIED
        self.trig = trig or TrigCache(program)
        self._pseudo = {}
        self._positions = {}

    def pseudo_inertia(self, i: int):
        """J_i = int r r^T dm (4x4, link frame) and m_i r_i, bound once (eq. 19)."""
        if i not in self._pseudo:
            L, P = self.links[i], self.P
            m = sp.sympify(L.mass)
            c = sp.Matrix(list(L.com))
            Io = sp.Matrix(L.inertia_com) + m * ((c.T * c)[0, 0] * sp.eye(3) - c * c.T)
            Sigma = (Io.trace() / 2) * sp.eye(3) - Io
            J = _zero4()
            for r in range(3):
                for k in range(r, 3):
                    J[r][k] = J[k][r] = P.let(Sigma[r, k], "J")
                J[r][3] = J[3][r] = P.let(m * c[r], "J")
            J[3][3] = P.let(m, "J")
            mr = [J[0][3], J[1][3], J[2][3], J[3][3]]
            self._pseudo[i] = (J, mr)
        return self._pseudo[i]

    def link_matrices(self, i: int, q_i):
        """A_i (eq. 1), dA_i/dq_i (eq. 43) and d2A_i/dq_i^2 (eq. 44).

        With Q the generator of the joint motion (d Rz/d theta or d Tz/d d),
        dA = Q A, ddA = Q Q A in the standard convention (the joint transform
        comes first) and dA = A Q, ddA = A Q Q in the modified one.
        """
        L = self.links[i]
        if self.general:
            return self._general_matrices(L, q_i)
        A = dh_transform(self.P, self.trig, L, q_i, self.modified)
        col = lambda M, j: [M[r][j] for r in range(4)]  # noqa: E731
        if not self.modified:
            if L.joint == REVOLUTE:
                dA = [[-e for e in A[1]], list(A[0]), [Z] * 4, [Z] * 4]
                ddA = [[-e for e in A[0]], [-e for e in A[1]], [Z] * 4, [Z] * 4]
            else:
                dA = [[Z] * 4, [Z] * 4, list(A[3]), [Z] * 4]
                ddA = _zero4()
        else:
            if L.joint == REVOLUTE:
                c0, c1 = col(A, 0), col(A, 1)
                dA = [[c1[r], -c0[r], Z, Z] for r in range(4)]
                ddA = [[-c0[r], -c1[r], Z, Z] for r in range(4)]
            else:
                c2 = col(A, 2)
                dA = [[Z, Z, Z, c2[r]] for r in range(4)]
                ddA = _zero4()
        return A, dA, ddA

    def _general_matrices(self, body, q_i):
        """A = [R p; 0 1] M(k, q + offset), dA = A Q, ddA = A Q Q with Q the motion's generator
        ([k]x for a revolute joint, the translation k for a prismatic one)."""
        P = self.P
        k = [sp.sympify(x) for x in body.axis]
        R0 = [[sp.sympify(x) for x in row] for row in body.rotation]
        p0 = [sp.sympify(x) for x in body.translation]
        theta = q_i + body.offset
        H = [R0[r] + [p0[r]] for r in range(3)] + [[Z, Z, Z, ONE]]
        if body.joint == REVOLUTE:
            c, s_ = self.trig.cos_sin(theta)
            K = [[Z, -k[2], k[1]], [k[2], Z, -k[0]], [-k[1], k[0], Z]]
            C, S = sp.Dummy("c"), sp.Dummy("s")  # c + (1 - c) folds to 1 before numbers come in
            Rm = [[sp.expand((C if r == m else 0) + S * K[r][m] + (1 - C) * k[r] * k[m]).xreplace({C: c, S: s_})
                   for m in range(3)] for r in range(3)]
            Mq = [Rm[r] + [Z] for r in range(3)] + [[Z, Z, Z, ONE]]
            Q = [K[r] + [Z] for r in range(3)] + [[Z] * 4]
        elif body.joint == PRISMATIC:
            Mq = [[ONE if r == m else Z for m in range(3)] + [k[r] * theta] for r in range(3)] + [[Z, Z, Z, ONE]]
            Q = [[Z, Z, Z, k[r]] for r in range(3)] + [[Z] * 4]
        else:
            raise ValueError(f"unknown joint type {body.joint!r}")
        A = _mm(P, H, Mq, "A")
        dA = _mm(P, A, Q, "dA")
        ddA = _mm(P, dA, Q, "dA") if body.joint == REVOLUTE else _zero4()
        return A, dA, ddA

    def _parent(self, j: int) -> int:
        return self.parents[j] if self.general else j - 1

    def positions(self, q):
        """A_j, dA_j, ddA_j, T_j and dT_j/dq_j = T_{j-1} dA_j for all j, bound once per q."""
        key = tuple(q)
        if key not in self._positions:
            P = self.P
            out = ([], [], [], [], [])
            for j in range(len(self.links)):
                par = self._parent(j)
                T_prev = out[3][par] if par >= 0 else _identity4()
                A, dA, ddA = self.link_matrices(j, q[j])
                T_dA = _mm(P, T_prev, dA, "dT")
                T = _mm(P, T_prev, A)
                for lst, v in zip(out, (A, dA, ddA, T, T_dA)):
                    lst.append(v)
            self._positions[key] = out
        return self._positions[key]

    def torques(self, q, qd, qdd, gravity=None, external=None, first: int = 0, joint_terms: bool = True) -> list:
        """Generalized forces f_i (eq. 39) for i >= ``first``; others None."""
        P, n = self.P, len(self.links)
        g = [sp.sympify(x) for x in gravity] + [Z] if gravity is not None else None
        As, dAs, ddAs, Ts, dTs = self.positions(q)
        Tds, Tdds = [], []
        for j in range(n):
            par = self._parent(j)  # the chain (DH) or the tree (joints): T', T'' of the parent
            T_prev, Td_prev, Tdd_prev = (Ts[par], Tds[par], Tdds[par]) if par >= 0 else \
                (_identity4(), _zero4(), _zero4())
            A, dA, ddA, T, T_dA = As[j], dAs[j], ddAs[j], Ts[j], dTs[j]
            terms = [_mm(P, Tdd_prev, A, "Tdd")] if not _is_zero(Tdd_prev) else []
            if qd[j] != 0:
                if not _is_zero(Td_prev):
                    terms.append(_mscale(P, 2 * qd[j], _mm(P, Td_prev, dA, "Tdd"), "Tdd"))
                if not _is_zero(ddA):
                    terms.append(_mscale(P, qd[j] ** 2, _mm(P, T_prev, ddA, "Tdd"), "Tdd"))
            if qdd[j] != 0:
                terms.append(_mscale(P, qdd[j], T_dA, "Tdd"))
            Tdd = _madd(P, *terms, hint="Tdd") if terms else _zero4()
            if qd[j] != 0 or not _is_zero(Td_prev):
                Td_terms = [] if _is_zero(Td_prev) else [_mm(P, Td_prev, A, "Td")]
                if qd[j] != 0:
                    Td_terms.append(_mscale(P, qd[j], T_dA, "Td"))
                Td = _madd(P, *Td_terms, hint="Td")
            else:
                Td = _zero4()
            Tds.append(Td)
            Tdds.append(Tdd)

        tau: list = [None] * n
        Ds, cs = [None] * n, [None] * n
        for i in range(n - 1, first - 1, -1):
            J, mr = self.pseudo_inertia(i)
            Tdd = Tdds[i]
            # D_i = J_i Tdd_i^T + sum over the children c of A_c D_c (a chain: A_{i+1} D_{i+1})
            D = [[sum(J[r][k] * Tdd[c][k] for k in range(4)) for c in range(4)] for r in range(4)]
            c = list(mr)
            for ch in [j for j in range(i + 1, n) if self._parent(j) == i]:
                An, D_next, c_next = As[ch], Ds[ch], cs[ch]
                D = [[D[r][cc] + sum(An[r][k] * D_next[k][cc] for k in range(4)) for cc in range(4)] for r in range(4)]
                c = [c[r] + sum(An[r][k] * c_next[k] for k in range(4)) for r in range(4)]
            D = [[P.let(e, "D") for e in row] for row in D]
            c = [P.let(e, "cm") for e in c]
            Ds[i], cs[i] = D, c
            dT = dTs[i]
            f = sum(dT[r][k] * D[k][r] for r in range(4) for k in range(4))
            if g is not None:
                dTc = [sum(dT[r][k] * c[k] for k in range(4)) for r in range(4)]
                f = f - sum(g[r] * dTc[r] for r in range(4))
            L = self.links[i]
            if joint_terms:
                f = f + L.rotor_inertia * qdd[i] + L.damping * qd[i]
                if getattr(L, "friction", 0) != 0:  # smooth Coulomb friction (bodies of URDF robots)
                    f = f + L.friction * sp.tanh(qd[i] / L.friction_velocity)
            tau[i] = P.let(f, "tau")
        if external:
            self._subtract_external(tau, Ts, dTs, As, external, first)
        return tau

    def _subtract_external(self, tau, Ts, dTs, As, external, first):
        """tau_i -= (d p_c/d q_i) . f + (axis_i) . t  for joints i <= k (eq. 29)."""
        P = self.P
        for k, (f, t) in external.items():
            L = self.links[k]
            w = [sp.sympify(x) for x in L.com] + [ONE]  # w_k = r_k, w_parent(i) = A_i w_i
            i = k
            while i >= 0:  # the joints between link k and the base
                if i >= first:
                    lin = [sum(dTs[i][r][m] * w[m] for m in range(4)) for r in range(3)]
                    proj = sum(lin[r] * f[r] for r in range(3))
                    if self.links[i].joint == REVOLUTE:
                        if self.general:  # the axis in base coordinates: T_i's rotation times k
                            ax = [sum(Ts[i][r][m] * sp.sympify(self.links[i].axis[m]) for m in range(3))
                                  for r in range(3)]
                        else:  # axis of joint i: z of frame i-1 (standard) or of frame i (modified)
                            Tax = Ts[i] if self.modified else (Ts[i - 1] if i > 0 else _identity4())
                            ax = [Tax[r][2] for r in range(3)]
                        proj = proj + sum(ax[r] * t[r] for r in range(3))
                    tau[i] = P.let(tau[i] - proj, "tau")
                w = [P.let(sum(As[i][r][m] * w[m] for m in range(4)), "wc") for r in range(4)]
                i = self._parent(i)


def inverse_dynamics(program: Program, robot: Robot, q, qd, qdd, gravity, external=None, trig=None) -> list:
    return RecursiveLagrange(program, robot, trig).torques(q, qd, qdd, gravity, external)
