"""Mass matrix by the composite-rigid-body algorithm (Walker & Orin's method 3).

Source: M. W. Walker and D. E. Orin, "Efficient dynamic computer simulation
of robotic mechanisms" (1982) -- the thesis's reference [3] for its
simulator -- in the joint-frame form of Featherstone's CRBA.

Column i of M is the generalized force every joint j <= i feels when joint i
alone accelerates at unit rate from rest without gravity: then links i..N move
as one rigid *composite body*, whose momentum rate is its inertia times the
joint's motion.  Per link, in its joint frame F_i (joint axis z):

    composite inertia of links i..N about the origin of F_i:
        m_c = m_i + m_c'
        h_c = h_i + m_c' p + R h_c'                              (first moment)
        I_c = I_i + R I_c' R^T + m_c' (|p|^2 E - p p^T)
              + 2 (p . R h_c') E - p (R h_c')^T - (R h_c') p^T
      (primes: link i+1's composite in F_{i+1}; R, p: F_{i+1} in F_i)

    unit motion of joint i, momentum rate (f, n) about the origin of F_i:
        revolute:  f = z x h_c,  n = I_c z
        prismatic: f = m_c z,    n = h_c x z
    M_ii = n_z (or f_z) + Ia_i; carried inwards, f <- R f, n <- R n + p x (R f),
    M_ji = n_z (or f_z) at joint j.

Only the lower triangle is built; it costs far less than N inverse-dynamics
passes with unit accelerations (the thesis's ARM2 approach, kept for the
Lagrange formulation).
"""
from __future__ import annotations

import sympy as sp

from ..robot.description import REVOLUTE
from . import vectors as V
from .newton_euler import NestedBodyInverseDynamics


def _rotate_inertia(P, R, I):
    """R I R^T for a symmetric I (list of rows), six entries bound."""
    RI = [[P.let(sum(R[r][k] * I[k][c] for k in range(3)), "RI") for c in range(3)] for r in range(3)]
    out = [[None] * 3 for _ in range(3)]
    for r in range(3):
        for c in range(r, 3):
            out[r][c] = out[c][r] = sum(RI[r][k] * R[c][k] for k in range(3))
    return out


def mass_matrix(engine: NestedBodyInverseDynamics, q) -> sp.Matrix:
    """M(q) (n x n, symmetric) from the engine's links, constants and sin/cos."""
    P, chain = engine.P, engine.chain
    n = len(chain)
    M = sp.zeros(n, n)
    comp = [None] * n  # (m_c, h_c, I_c) of links i..n-1 in F_i
    for i in range(n - 1, -1, -1):
        m, h, I = engine.inertial(i)
        if i + 1 < n:
            mc, hc, Ic = comp[i + 1]
            R, p = engine.rotation_translation(i + 1, q[i + 1])
            hr = V.matvec(P, R, hc, "hc")
            Ir = _rotate_inertia(P, R, Ic)
            ph = 2 * V.dot(p, hr)
            pp = V.dot(p, p)
            m = P.let(m + mc, "mc")
            h = [P.let(h[k] + mc * p[k] + hr[k], "hc") for k in range(3)]
            new = [[None] * 3 for _ in range(3)]
            for r in range(3):
                for c in range(r, 3):
                    e = I[r][c] + Ir[r][c] + mc * ((pp if r == c else 0) - p[r] * p[c]) \
                        + (ph if r == c else 0) - p[r] * hr[c] - hr[r] * p[c]
                    new[r][c] = new[c][r] = P.let(e, "Ic")
            I = new
        comp[i] = (m, h, I)
        if chain[i].joint == REVOLUTE:
            f = [-h[1], h[0], sp.Integer(0)]
            nm = [I[0][2], I[1][2], I[2][2]]
        else:
            f = [sp.Integer(0), sp.Integer(0), m]
            nm = [h[1], -h[0], sp.Integer(0)]
        M[i, i] = P.let((nm[2] if chain[i].joint == REVOLUTE else f[2]) + chain[i].rotor_inertia, "M")
        for j in range(i - 1, -1, -1):
            R, p = engine.rotation_translation(j + 1, q[j + 1])
            f = V.matvec(P, R, f, "f")
            nm = V.add(P, V.matvec(P, R, nm), V.cross(P, p, f), "n")
            M[i, j] = M[j, i] = P.let(nm[2] if chain[j].joint == REVOLUTE else f[2], "M")
    return M
