"""Pieces of the generated-code benchmark: single-algorithm models and Pinocchio.

The FMU needs only the state-space function ``evaluate`` (forward dynamics);
to count and time the inverse dynamics and the mass matrix on their own,
each is wrapped here as a :class:`~fmugen.codegen.model.SymbolicModel`
*without states*, whose outputs are the quantity:

* :func:`inverse_dynamics_model`  u = [q, qd, qdd, w_ext] (3n + 6e),  y = tau (n)
* :func:`mass_matrix_model`       u = q (n),  y = lower triangle of M(q), row by
                                  row (n(n+1)/2: M11, M21, M22, M31, ...)
* :func:`forward_dynamics_model`  the arm's state-space model without outputs and
                                  without its Jacobian program: evaluate() is
                                  qdd = M^{-1}(tau - h) by a Cholesky solve

so that :func:`~fmugen.codegen.c_code.generate_c` prints each as one
``evaluate`` with the same lowering (one joint CSE, dead steps dropped) and
operation counts as the FMU's, ``SymbolicModel.with_parameters_folded`` folds
their parameters, and :class:`~fmugen.codegen.c_harness.CompiledModel` times
them in a C loop.

:func:`pinocchio_model` builds the same arm as a Pinocchio ``Model`` (the
independent numeric oracle of the benchmark and of
``tests/test_pinocchio_crosscheck.py``).  Pinocchio's joint frames are
fmugen's joint frames F_i (:mod:`fmugen.dynamics.joint_frames`):

    F_i = F_{i-1} Tx(a'_i) Rx(alpha'_i) Rz(theta0_i) Tz(d0_i) J_i(q_i)

with (a'_i, alpha'_i) of the previous link (standard DH) or of link i
(modified DH), J_i = Rz(q_i) (revolute, Pinocchio ``JointModelRZ``) or
Tz(q_i) (prismatic, ``JointModelPZ``); the constant part is the joint
placement.  Link i's mass, centre of mass and inertia about it, moved into
F_i, give ``pin.Inertia(m, c, I_c)``; the rotor inertia is Pinocchio's
``armature``; gravity is ``Model.gravity``.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

import numpy as np
import sympy as sp

from ..dynamics.joint_frames import joint_frame_chain
from ..robot.description import PRISMATIC, REVOLUTE
from .model import SymbolicModel, Variable

__all__ = [
    "inverse_dynamics_model",
    "mass_matrix_model",
    "forward_dynamics_model",
    "pinocchio_model",
]


def _parameters(arm) -> tuple:
    return tuple(Variable(p.name, p.symbol, p.unit, p.description, start=p.value)
                 for p in arm.robot.parameters)


def _inputs(symbols, stem: str) -> list:
    return [Variable(f"{stem}[{i + 1}]", s, start=0.0) for i, s in enumerate(symbols)]


def inverse_dynamics_model(arm, formulation: Optional[str] = None) -> SymbolicModel:
    """tau = ID(q, qd, qdd, w_ext) of ``arm`` as a state-free model, without its Jacobian."""
    m = arm.inverse_dynamics_model(formulation)
    return replace(m, jacobian=None, dfdx=None, dfdu=None, dgdx=None, dgdu=None)


def mass_matrix_model(arm, formulation: Optional[str] = None) -> SymbolicModel:
    """The lower triangle of M(q), row by row, as a state-free model with input q."""
    formulation = formulation or arm.formulation
    P, M = arm.mass_matrix_program(formulation)
    entries = [(i, j) for i in range(arm.n) for j in range(i + 1)]
    outputs = [Variable(f"M[{i + 1},{j + 1}]", sp.Symbol(f"M_out_{i + 1}_{j + 1}", real=True))
               for i, j in entries]
    return SymbolicModel(
        name=f"{arm.robot.name}_mass_matrix",
        description=f"{arm.robot.name}: lower triangle of M(q) ({formulation})",
        states=(), inputs=tuple(_inputs(arm.q, "q")), parameters=_parameters(arm),
        outputs=tuple(outputs), program=P, derivatives=(),
        output_exprs=tuple(M[i, j] for i, j in entries),
        provenance=f"{arm.robot.source or arm.robot.name}; {formulation} formulation",
    )


def forward_dynamics_model(arm, formulation: Optional[str] = None) -> SymbolicModel:
    """x' = [qd, M^{-1}(tau - h)] exactly as in the FMU, minus outputs and Jacobian.

    The Jacobian program is dropped because ``evaluate`` never runs it and
    printing it dominates the generation time.
    """
    m = arm.state_space_model(outputs=(), formulation=formulation)
    return replace(m, jacobian=None, dfdx=None, dfdu=None, dgdx=None, dgdu=None)


# ----------------------------------------------------------------- Pinocchio
def _number(expr, values: dict, what: str) -> float:
    e = sp.sympify(expr).xreplace(values)
    if e.free_symbols:
        raise ValueError(f"{what}: no value for parameter(s) "
                         f"{', '.join(sorted(s.name for s in e.free_symbols))}")
    return float(e)


def pinocchio_model(robot, values: Optional[dict] = None):
    """A ``pinocchio.Model`` of ``robot`` (a :class:`~fmugen.robot.description.Robot`).

    ``values`` overrides parameter values by name (defaults: the file's).
    Joint i of fmugen is Pinocchio joint i (index i, universe is 0), so
    q, qd, qdd and tau are the same n-vectors in both.  Raises ValueError for
    what Pinocchio's rnea/crba/aba do not model: joint damping (viscous
    friction) and parameters without a value.
    """
    import pinocchio as pin

    by_name = {p.name: p for p in robot.parameters}
    unknown = sorted(set(values or {}) - set(by_name))
    if unknown:
        raise KeyError(f"{robot.name}: unknown parameter(s) {unknown}")
    env = {p.symbol: sp.Float(values[p.name]) if values and p.name in values else p.value
           for p in robot.parameters}
    env = {s: sp.sympify(v) for s, v in env.items() if v is not None}

    model = pin.Model()
    model.name = robot.name
    parent = 0
    armature = []
    for i, L in enumerate(joint_frame_chain(robot)):
        where = f"{robot.name}, link {i + 1}"
        if _number(L.damping, env, f"{where} damping") != 0.0:
            raise ValueError(f"{where}: joint damping is not modelled by Pinocchio's rnea/crba/aba")
        a = _number(L.a, env, f"{where} a")
        alpha = _number(L.alpha, env, f"{where} alpha")
        theta0 = _number(L.theta0, env, f"{where} theta")
        d0 = _number(L.d0, env, f"{where} d")
        # Tx(a) Rx(alpha) Rz(theta0) Tz(d0): rotation Rx Rz, translation a x + d (Rx z)
        ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta0), np.sin(theta0)
        Rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
        Rz = np.array([[ct, -st, 0.0], [st, ct, 0.0], [0.0, 0.0, 1.0]])
        placement = pin.SE3(Rx @ Rz, np.array([a, 0.0, 0.0]) + d0 * Rx[:, 2])
        if L.joint == REVOLUTE:
            joint = pin.JointModelRZ()
        elif L.joint == PRISMATIC:
            joint = pin.JointModelPZ()
        else:
            raise ValueError(f"{where}: unknown joint type {L.joint!r}")
        jid = model.addJoint(parent, joint, placement, f"joint{i + 1}")
        mass = _number(L.mass, env, f"{where} mass")
        com = np.array([_number(c, env, f"{where} com") for c in L.com])
        inertia = np.array([[_number(L.inertia_com[r, c], env, f"{where} inertia") for c in range(3)]
                            for r in range(3)])
        model.appendBodyToJoint(jid, pin.Inertia(mass, com, inertia), pin.SE3.Identity())
        armature.append(_number(L.rotor_inertia, env, f"{where} rotor_inertia"))
        parent = jid
    model.armature = np.array(armature)
    model.gravity = pin.Motion(np.array([_number(g, env, f"{robot.name} gravity") for g in robot.gravity]),
                               np.zeros(3))
    return model
