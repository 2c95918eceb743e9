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

:func:`pinocchio_model` builds the same robot as a Pinocchio ``Model`` (the
independent numeric oracle of the benchmark and of
``tests/test_pinocchio_crosscheck.py``) from its bodies
(:mod:`fmugen.robot.description`): joint i is Pinocchio joint i + 1 with
parent lambda(i) + 1 (0 is the universe), placement ``SE3(R, p)`` with the
constant offset of q folded in, motion ``JointModelR{X,Y,Z}`` /
``P{X,Y,Z}`` for an aligned axis and the ``RevoluteUnaligned`` /
``PrismaticUnaligned`` joint otherwise; the body's mass, centre of mass and
inertia about it give ``pin.Inertia(m, c, I_c)``; the rotor inertia is
Pinocchio's ``armature``; gravity is ``Model.gravity``.  For a DH robot the
placements come from :func:`~fmugen.robot.description.dh_to_joints`, so
agreement with the recursive Lagrange formulation (which reads the DH
parameters directly) also checks that conversion.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

import numpy as np
import sympy as sp

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

    # Pinocchio's algorithms take every subtree as a contiguous range of joints (depth-first numbering)
    for i in range(robot.n):
        below = [k for k in range(robot.n) if i in robot.ancestors(k)]
        if below != list(range(i, i + len(below))):
            raise ValueError(f"{robot.name}: bodies are not numbered depth-first (the subtree of body {i} is "
                             f"{below}); Pinocchio needs each subtree contiguous")
    model = pin.Model()
    model.name = robot.name
    armature = []
    for i, L in enumerate(robot.bodies):
        where = f"{robot.name}, link {i + 1}"
        if _number(L.damping, env, f"{where} damping") != 0.0:
            raise ValueError(f"{where}: joint damping is not modelled by Pinocchio's rnea/crba/aba")
        if _number(L.friction, env, f"{where} friction") != 0.0:
            raise ValueError(f"{where}: joint friction is not modelled by Pinocchio's rnea/crba/aba")
        R = np.array([[_number(x, env, f"{where} rotation") for x in row] for row in L.rotation])
        p = np.array([_number(x, env, f"{where} translation") for x in L.translation])
        k = np.array([_number(x, env, f"{where} axis") for x in L.axis])
        offset = _number(L.offset, env, f"{where} offset")
        # the constant offset of q folds into the placement (a motion about/along k commutes with itself)
        if L.joint == REVOLUTE:
            R = R @ pin.AngleAxis(offset, k).matrix() if offset else R
        else:
            p = p + offset * (R @ k)
        aligned = [np.array_equal(k, e) for e in np.eye(3)]
        if L.joint == REVOLUTE:
            joint = [pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ][aligned.index(True)]() if any(aligned) \
                else pin.JointModelRevoluteUnaligned(k)
        elif L.joint == PRISMATIC:
            joint = [pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ][aligned.index(True)]() if any(aligned) \
                else pin.JointModelPrismaticUnaligned(k)
        else:
            raise ValueError(f"{where}: unknown joint type {L.joint!r}")
        jid = model.addJoint(L.parent + 1, joint, pin.SE3(R, p), L.joint_name or f"joint{i + 1}")
        mass = _number(L.mass, env, f"{where} mass")
        com = np.array([_number(c, env, f"{where} com") for c in L.com])
        inertia = np.array([[_number(L.inertia_com[r][c], env, f"{where} inertia") for c in range(3)]
                            for r in range(3)])
        model.appendBodyToJoint(jid, pin.Inertia(mass, com, inertia), pin.SE3.Identity())
        armature.append(_number(L.rotor_inertia, env, f"{where} rotor_inertia"))
    model.armature = np.array(armature)
    model.gravity = pin.Motion(np.array([_number(g, env, f"{robot.name} gravity") for g in robot.gravity]),
                               np.zeros(3))
    return model


def pinocchio_urdf_map(model, robot) -> list:
    """``(idx_q, idx_v, nq)`` in a Pinocchio model read from the same URDF, per fmugen joint (by joint name).

    Pinocchio orders joints its own way and writes a continuous joint as
    (cos q, sin q) (nq = 2); :func:`to_pinocchio` converts vectors.
    """
    out = []
    for b in robot.bodies:
        name = b.joint_name or b.name
        if not model.existJointName(name):
            raise KeyError(f"{robot.name}: joint {name!r} not in the Pinocchio model")
        j = model.joints[model.getJointId(name)]
        out.append((j.idx_q, j.idx_v, j.nq))
    return out


def to_pinocchio(model, mapping, q=None, v=None):
    """(q, v) of fmugen's joint order as Pinocchio vectors (``mapping`` from :func:`pinocchio_urdf_map`)."""
    import pinocchio as pin

    out = []
    if q is not None:
        qp = pin.neutral(model)
        for (iq, _, nq), x in zip(mapping, q):
            if nq == 2:
                qp[iq], qp[iq + 1] = np.cos(x), np.sin(x)
            else:
                qp[iq] = x
        out.append(qp)
    if v is not None:
        vp = np.zeros(model.nv)
        for (_, iv, _), x in zip(mapping, v):
            vp[iv] = x
        out.append(vp)
    return out if len(out) > 1 else out[0]
