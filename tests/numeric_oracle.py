"""An independent numeric inverse dynamics, for the tests only.

Plain numpy, base (inertial) coordinates, no recursion over forces: the
DYNAMAN nest balances (report eqs. 7, 12, 16) are summed explicitly,

    tau_i = z_i . sum_{j>=i} [ I_j w'_j + w_j x I_j w_j + (c_j - o_i) x m_j (c''_j - g)
                               - (c_j - o_i) x F_ext_j - T_ext_j ]          (revolute)
    tau_i = z_i . sum_{j>=i} [ m_j (c''_j - g) - F_ext_j ]                    (prismatic)

with link motion obtained by composing relative motions of the DH frames
(velocity and acceleration of each frame origin from the analytic
derivatives of the DH translation).  It shares no code with fmugen's
symbolic formulations -- only the Robot description it reads.
"""
from __future__ import annotations

import numpy as np
import sympy as sp

from fmugen.robot.description import MODIFIED, REVOLUTE, combined_last_link


def numeric(robot, values=None):
    """Robot quantities as floats (parameter defaults, overridden by values)."""
    env = {p.symbol: sp.Float(p.value) for p in robot.parameters if p.value is not None}
    for k, v in (values or {}).items():
        env[robot.parameter(k).symbol] = sp.Float(v)

    def f(e):
        return float(sp.sympify(sp.sympify(e).xreplace(env)).evalf())

    links = []
    for L in combined_last_link(robot):
        links.append(dict(
            joint=L.joint, a=f(L.a), alpha=f(L.alpha), d=f(L.d), theta=f(L.theta), m=f(L.mass),
            c=np.array([f(x) for x in L.com]), I=np.array([[f(x) for x in r] for r in L.inertia_com]),
            Ia=f(L.rotor_inertia), b=f(L.damping), ext=L.external_wrench,
        ))
    return links, np.array([f(x) for x in robot.gravity]), robot.convention == MODIFIED


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def relative_motion(L, q, modified):
    """R, r of frame i in frame i-1, the joint axis u (frame i-1 coords), dr/dq, d2r/dq2."""
    rev = L["joint"] == REVOLUTE
    th = L["theta"] + (q if rev else 0.0)
    d = L["d"] + (0.0 if rev else q)
    a, al = L["a"], L["alpha"]
    if not modified:
        R = _rz(th) @ _rx(al)
        r = np.array([a * np.cos(th), a * np.sin(th), d])
        u = np.array([0.0, 0.0, 1.0])
        if rev:
            dr = np.array([-a * np.sin(th), a * np.cos(th), 0.0])
            ddr = np.array([-a * np.cos(th), -a * np.sin(th), 0.0])
        else:
            dr, ddr = u.copy(), np.zeros(3)
    else:
        R = _rx(al) @ _rz(th)
        u = _rx(al) @ np.array([0.0, 0.0, 1.0])
        r = np.array([a, 0.0, 0.0]) + d * u
        dr = np.zeros(3) if rev else u.copy()
        ddr = np.zeros(3)
    return R, r, u, dr, ddr


def inverse_dynamics(robot, q, qd, qdd, ext=None, values=None):
    links, g, modified = numeric(robot, values)
    n = len(links)
    R, p = np.eye(3), np.zeros(3)
    w, dw, v, acc = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    axes, points, bodies = [], [], []
    for i, L in enumerate(links):
        Rr, r, u, dr, ddr = relative_motion(L, q[i], modified)
        rev = L["joint"] == REVOLUTE
        rb = R @ r
        # relative motion of the frame origin, base coordinates
        vrel = R @ dr * qd[i]
        arel = R @ (dr * qdd[i] + ddr * qd[i] ** 2)
        axis = R @ u
        joint_point = p if not modified else p + rb  # a point on joint i's axis
        acc = acc + np.cross(dw, rb) + np.cross(w, np.cross(w, rb)) + 2 * np.cross(w, vrel) + arel
        v = v + np.cross(w, rb) + vrel
        if rev:
            dw = dw + axis * qdd[i] + np.cross(w, axis * qd[i])
            w = w + axis * qd[i]
        p = p + rb
        R = R @ Rr
        rc = R @ L["c"]
        c = p + rc
        cdd = acc + np.cross(dw, rc) + np.cross(w, np.cross(w, rc))
        axes.append(axis)
        points.append(joint_point)
        bodies.append((c, cdd, w.copy(), dw.copy(), R @ L["I"] @ R.T))
    forces = {}
    if ext is not None:
        k = 0
        for i, L in enumerate(links):
            if L["ext"]:
                forces[i] = (np.asarray(ext[k:k + 3]), np.asarray(ext[k + 3:k + 6]))
                k += 6
    tau = np.zeros(n)
    for i, L in enumerate(links):
        F, N = np.zeros(3), np.zeros(3)
        for j in range(i, n):
            c, cdd, wj, dwj, Ij = bodies[j]
            fj = links[j]["m"] * (cdd - g)
            nj = Ij @ dwj + np.cross(wj, Ij @ wj) + np.cross(c - points[i], fj)
            if j in forces:
                fe, te = forces[j]
                fj = fj - fe
                nj = nj - np.cross(c - points[i], fe) - te
            F += fj
            N += nj
        gen = axes[i] @ (N if L["joint"] == REVOLUTE else F)
        tau[i] = gen + L["Ia"] * qdd[i] + L["b"] * qd[i]
    return tau
