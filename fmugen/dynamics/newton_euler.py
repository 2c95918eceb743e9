"""Inverse dynamics by the Newton-Euler nested-body formulation (DYNAMAN).

Source: DYNAMAN report (1985), section 2, after Velman's method of nested
bodies.  *Nest i* is the set of links i..N.  Newton's and Euler's laws for
nest i (report eqs. 6-13),

    sum_{j>=i} m_j  c''_j            = F^c_i + F^motor_i + sum_{j>=i} (m_j g + F^ext_j)
    sum_{j>=i} d/dt L_j (about O_i)  = T^c_i + T^motor_i + moments of gravity and F^ext,

are projected on the joint axis by the principle of virtual work (eqs. 14-16):
the constraint force/torque does no work along the joint's degree of freedom,
so the projection of the nest's momentum balance on the axis is the joint's
generalized force.  Collected for all joints this is the report's eq. (17),
B(x) x'' = f(x, x') + e(x, F^ext, T^ext, F^motor, T^motor).

On a kinematic tree nest i is body i and all its descendants; the inward
pass adds each child's nest force and moment into its parent's (Featherstone's
RNEA over lambda(i), in the report's nested-body form).

The report writes every vector in inertial coordinates.  Here the same nest
sums are accumulated in each link's *joint frame* (see
:mod:`fmugen.dynamics.joint_frames`), where the joint axis is z: the nest
force f_i and the nest moment n_i about the joint origin are built outward-in
from f_{i+1}, n_{i+1}, so the projection q_i^T (.) of eq. (16) is just the z
component.  Same scalar equations, a fraction of the operations, and no
expression is ever expanded: every vector component is a named intermediate.

Per link, the inertial parameters are taken about the joint-frame origin
(first moment m*c and inertia I_o), so that a link's contribution is

    F_i = m a_i + w'_i x (m c_i) + w_i x (w_i x (m c_i))  =  m a_i + U_i (m c_i)
    N_i = I_o w'_i + w_i x (I_o w_i) + (m c_i) x a_i

with a_i the acceleration of the frame origin (gravity enters as a base
acceleration -g, which is exact for a uniform field) and U_i = skew(w'_i) +
skew(w_i)^2 (Khalil & Kleinfinger, 1987), which also carries the acceleration
to the next frame: a_{i+1} = R^T (a_i + U_i p_{i+1}).
"""
from __future__ import annotations

from typing import Optional, Sequence

import sympy as sp

from ..codegen.program import Program
from ..robot.description import PRISMATIC, REVOLUTE
from . import vectors as V
from .joint_frames import joint_transform
from .trig import TrigCache


def _cross(a, b):
    """a x b, unbound (for products with structural zeros, such as w x (qd z))."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


class NestedBodyInverseDynamics:
    """Builds tau = M(q) qdd + h(q, qd) into a Program, body by body, over a tree.

    ``bodies`` are the robot's :class:`~fmugen.robot.description.Body`
    entries (topological order, parent index per body).  On a tree, nest i
    is body i with all its descendants: the outward pass carries velocities
    and accelerations from each body's parent, the inward pass sums each
    body's children into its nest force and moment.

    One instance per Program: the per-body parameter combinations (first
    moments, inertia about the joint origin) and the sin/cos of every joint
    angle are bound once and shared by every call of :meth:`torques`.
    """

    def __init__(self, program: Program, bodies: Sequence, trig: Optional[TrigCache] = None):
        self.P = program
        self.bodies = tuple(bodies)
        self.children = [[] for _ in self.bodies]
        for i, b in enumerate(self.bodies):
            if b.parent >= 0:
                self.children[b.parent].append(i)
        self.trig = trig or TrigCache(program)
        self._inertial = {}
        self._frames = {}

    @property
    def chain(self) -> tuple:
        return self.bodies

    # --- per-body constants -----------------------------------------------
    def inertial(self, i: int):
        """(m, m*c, I_o) of body i in its body frame, bound once."""
        if i not in self._inertial:
            L, P = self.bodies[i], self.P
            m = P.let(L.mass, "m")
            c = [sp.sympify(x) for x in L.com]
            mc = [P.let(m * ck, "mc") for ck in c]
            Ic = L.inertia_com
            # parallel axis: I_o = I_c + m (|c|^2 E - c c^T)
            cc = sum(ck * ck for ck in c)
            Io = [[None] * 3 for _ in range(3)]
            for r in range(3):
                for k in range(r, 3):
                    e = Ic[r][k] + m * ((cc if r == k else 0) - c[r] * c[k])
                    Io[r][k] = Io[k][r] = P.let(e, "I")
            self._inertial[i] = (m, mc, Io)
        return self._inertial[i]

    def rotation_translation(self, i: int, q_i):
        """^{parent}R_i and ^{parent}p_i of body i (:func:`~.joint_frames.joint_transform`), bound once."""
        key = (i, q_i)
        if key not in self._frames:
            self._frames[key] = joint_transform(self.P, self.trig, self.bodies[i], q_i)
        return self._frames[key]

    def u_matrix(self, w, dw):
        """U = skew(w') + skew(w) skew(w), so that w' x r + w x (w x r) = U r.

        Khalil and Kleinfinger's device: six products of w shared by the
        link's own force (U m c) and the next frame's acceleration (U p).
        Entries a program never reads are dropped by the code generator.
        """
        P = self.P
        xx, yy, zz = P.let(w[0] * w[0]), P.let(w[1] * w[1]), P.let(w[2] * w[2])
        xy, xz, yz = P.let(w[0] * w[1]), P.let(w[0] * w[2]), P.let(w[1] * w[2])
        return [
            [P.let(-yy - zz, "U"), P.let(xy - dw[2], "U"), P.let(xz + dw[1], "U")],
            [P.let(xy + dw[2], "U"), P.let(-xx - zz, "U"), P.let(yz - dw[0], "U")],
            [P.let(xz - dw[1], "U"), P.let(yz + dw[0], "U"), P.let(-xx - yy, "U")],
        ]

    # --- the recursion ----------------------------------------------------
    def torques(
        self,
        q: Sequence,
        qd: Sequence,
        qdd: Sequence,
        gravity: Optional[Sequence] = None,
        external: Optional[dict] = None,
        first: int = 0,
        joint_terms: bool = True,
    ) -> list:
        """Generalized forces tau_i for i >= ``first`` (others returned as None).

        ``gravity``: base-frame gravitational acceleration, or None for none.
        ``external``: {body index: (force[3], torque[3])} in base coordinates,
        the force acting at the body's centre of mass.
        ``joint_terms``: add rotor inertia Ia_i qdd_i, damping b_i qd_i and
        smooth Coulomb friction F_c tanh(qd_i / v_c).
        """
        P, n = self.P, len(self.bodies)
        external = external or {}
        base_acc = [-sp.sympify(g) for g in gravity] if gravity is not None else list(V.ZERO3)
        E = [[sp.Integer(int(r == k)) for k in range(3)] for r in range(3)]
        ws, dws, accs, Us, Rbs = [None] * n, [None] * n, [None] * n, [None] * n, [None] * n
        Fs, Ns = [None] * n, [None] * n
        for i, L in enumerate(self.bodies):
            par = L.parent
            if par < 0:
                w_p, dw_p, a_p, U_p, Rb_p = list(V.ZERO3), list(V.ZERO3), base_acc, None, E
            else:
                w_p, dw_p, a_p, U_p, Rb_p = ws[par], dws[par], accs[par], Us[par], Rbs[par]
            R, p = self.rotation_translation(i, q[i])
            k = [sp.sympify(x) for x in L.axis]
            # acceleration of this frame's origin: a_parent + U_parent p, then into frame i
            a_prev = V.add(P, a_p, V.matvec(P, U_p, p)) if U_p is not None else a_p
            acc = V.matTvec(P, R, a_prev, "a")
            w_in = V.matTvec(P, R, w_p, "w")
            dw_in = V.matTvec(P, R, dw_p, "dw")
            if L.joint == REVOLUTE:
                w = [P.let(w_in[r] + k[r] * qd[i], "w") for r in range(3)]
                # w_in x (qd k) + qdd k; for k = z: [w_y qd, -w_x qd, qdd]
                wk = _cross(w_in, [k[r] * qd[i] for r in range(3)])
                dw = [P.let(dw_in[r] + wk[r] + k[r] * qdd[i], "dw") for r in range(3)]
            else:  # prismatic: Coriolis 2 w x (qd k) and qdd along k
                w, dw = w_in, dw_in
                wk = _cross(w, [k[r] * qd[i] for r in range(3)])
                acc = [P.let(acc[r] + 2 * wk[r] + k[r] * qdd[i], "a") for r in range(3)]
            U = self.u_matrix(w, dw)
            ws[i], dws[i], accs[i], Us[i] = w, dw, acc, U
            m, mc, Io = self.inertial(i)
            # F = m a + w' x mc + w x (w x mc) = m a + U mc
            F = V.add(P, V.scale(P, m, acc), V.matvec(P, U, mc), "F")
            N = V.add(P, V.add(P, V.matvec(P, Io, dw), V.cross(P, w, V.matvec(P, Io, w))), V.cross(P, mc, acc), "N")
            if external:
                Rbs[i] = V.matmul(P, Rb_p, R, "R0")
                if i in external:
                    f_b, t_b = external[i]
                    f = V.matTvec(P, Rbs[i], f_b, "fe")
                    t = V.matTvec(P, Rbs[i], t_b, "te")
                    c = [sp.sympify(x) for x in L.com]
                    F = V.sub(P, F, f, "F")
                    N = V.sub(P, N, V.add(P, V.cross(P, c, f), t), "N")
            Fs[i], Ns[i] = F, N

        tau: list = [None] * n
        fs, ns = [None] * n, [None] * n
        for i in range(n - 1, first - 1, -1):
            f, nm = Fs[i], Ns[i]
            for c in self.children[i]:  # the nest of i: its own body and its children's nests
                R, p = self.rotation_translation(c, q[c])
                Rf = V.matvec(P, R, fs[c], "Rf")
                f = V.add(P, f, Rf, "f")
                nm = V.add(P, nm, V.add(P, V.matvec(P, R, ns[c]), V.cross(P, p, Rf)), "n")
            fs[i], ns[i] = f, nm
            L = self.bodies[i]
            k = [sp.sympify(x) for x in L.axis]
            t = V.dot(k, nm) if L.joint == REVOLUTE else V.dot(k, f)
            if joint_terms:
                t = t + L.rotor_inertia * qdd[i] + L.damping * qd[i]
                if L.friction != 0:  # smooth Coulomb friction
                    t = t + L.friction * sp.tanh(qd[i] / L.friction_velocity)
            tau[i] = P.let(t, "tau")
        return tau


def inverse_dynamics(program: Program, bodies, q, qd, qdd, gravity, external=None, trig=None) -> list:
    """tau = M(q) qdd + h(q, qd) (+ external-force terms) as program expressions."""
    return NestedBodyInverseDynamics(program, bodies, trig).torques(q, qd, qdd, gravity, external)
