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
        revolute:  f = k x h_c,  n = I_c k     (k: the joint's unit axis;
        prismatic: f = m_c k,    n = h_c x k      z for a DH chain)
    M_ii = k.n (or k.f) + Ia_i; carried inwards, f <- R f, n <- R n + p x (R f),
    M_ji = k_j.n (or k_j.f) at joint j.

On a tree the composite of body i sums its children's composites, and a
column is carried inwards only along the path from body i to the base: M_ji
is zero unless joint j is an ancestor of joint i (or i itself).

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
    """M(q) (n x n, symmetric) from the engine's bodies, constants and sin/cos."""
    P, bodies = engine.P, engine.bodies
    n = len(bodies)
    M = sp.zeros(n, n)
    comp = [None] * n  # (m_c, h_c, I_c) of body i and its descendants, in the frame of i
    for i in range(n - 1, -1, -1):
        m, h, I = engine.inertial(i)
        for c in engine.children[i]:
            mc, hc, Ic = comp[c]
            R, p = engine.rotation_translation(c, q[c])
            hr = V.matvec(P, R, hc, "hc")
            Ir = _rotate_inertia(P, R, Ic)
            ph = 2 * V.dot(p, hr)
            pp = V.dot(p, p)
            m = P.let(m + mc, "mc")
            h = [P.let(h[k] + mc * p[k] + hr[k], "hc") for k in range(3)]
            new = [[None] * 3 for _ in range(3)]
            for r in range(3):
                for cc in range(r, 3):
                    e = I[r][cc] + Ir[r][cc] + mc * ((pp if r == cc else 0) - p[r] * p[cc]) \
                        + (ph if r == cc else 0) - p[r] * hr[cc] - hr[r] * p[cc]
                    new[r][cc] = new[cc][r] = P.let(e, "Ic")
            I = new
        comp[i] = (m, h, I)
        k = [sp.sympify(x) for x in bodies[i].axis]
        revolute = bodies[i].joint == REVOLUTE
        if revolute:  # f = k x h_c, n = I_c k
            f = [k[1] * h[2] - k[2] * h[1], k[2] * h[0] - k[0] * h[2], k[0] * h[1] - k[1] * h[0]]
            nm = [sum(I[r][c] * k[c] for c in range(3)) for r in range(3)]
        else:  # f = m_c k, n = h_c x k
            f = [m * k[r] for r in range(3)]
            nm = [h[1] * k[2] - h[2] * k[1], h[2] * k[0] - h[0] * k[2], h[0] * k[1] - h[1] * k[0]]
        M[i, i] = P.let(V.dot(k, nm if revolute else f) + bodies[i].rotor_inertia, "M")
        # carried inwards along the path to the base; zero for joints off the path
        c, j = i, bodies[i].parent
        while j >= 0:
            R, p = engine.rotation_translation(c, q[c])
            f = V.matvec(P, R, f, "f")
            nm = V.add(P, V.matvec(P, R, nm), V.cross(P, p, f), "n")
            kj = [sp.sympify(x) for x in bodies[j].axis]
            M[i, j] = M[j, i] = P.let(V.dot(kj, nm if bodies[j].joint == REVOLUTE else f), "M")
            c, j = j, bodies[j].parent
    return M
