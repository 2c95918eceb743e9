"""The "final equations" in readable form, as DYNAMAN printed them.

For small arms (closed form) each joint's equation is printed as

    sum_j M_ij(q) qdd_j + h_i(q, qd) = tau_i

with M and h simplified; for larger arms closed forms swell, so the equations
are printed as the straight-line program of named intermediates that the
code generator uses (``form="program"``).
"""
from __future__ import annotations

import sympy as sp

from ..codegen.program import Assign
from .manipulator import Manipulator

CLOSED_FORM_MAX_LINKS = 3


def _simplify(e):
    return sp.factor_terms(sp.trigsimp(sp.expand(e)))


def final_equations(arm: Manipulator, formulation=None, latex: bool = False, form: str = "auto") -> str:
    """Text (or LaTeX) of tau = M(q) qdd + h(q, qd) for ``arm``."""
    formulation = formulation or arm.formulation
    if form == "auto":
        form = "closed" if arm.n <= CLOSED_FORM_MAX_LINKS else "program"
    if form not in ("closed", "program"):
        raise ValueError(f"form must be 'auto', 'closed' or 'program', not {form!r}")
    robot = arm.robot
    lines = [
        f"Equations of motion of {robot.name} ({formulation.replace('_', '-')} formulation)",
        "tau = M(q) qdd + h(q, qd)   [DYNAMAN eq. 17: B(x) x'' = f(x, x') + e]",
        "",
    ]
    for i, L in enumerate(robot.bodies):
        kind = "angle" if L.joint == "revolute" else "displacement"
        lines.append(f"  x{i + 1} = q_{i + 1}: {kind} of joint {i + 1} ({L.joint_name or L.name}, {L.joint})")
    g = ", ".join(str(x) for x in robot.gravity)
    lines += [f"  gravity g0 = [{g}]", ""]

    if form == "closed":
        M, h = arm.closed_form(formulation)
        M = M.applyfunc(_simplify)
        h = h.applyfunc(_simplify)
        for i in range(arm.n):
            lhs = sum((M[i, j] * arm.qdd[j] for j in range(arm.n)), sp.Integer(0)) + h[i]
            if latex:
                lines.append(f"\\text{{Main-Eqn {i + 1}:}}\\quad {sp.latex(lhs)} = {sp.latex(arm.tau[i])}")
            else:
                lines.append(f"Main-Eqn {i + 1}:")
                lines.append(f"  {sp.sstr(lhs)} = {arm.tau[i]}")
        return "\n".join(lines) + "\n"

    P, tau = arm.inverse_dynamics_program(formulation)
    lines.append(f"Inverse dynamics as {len(P.steps)} named intermediates (qdd_i enter linearly):")
    for st in P.steps:
        if isinstance(st, Assign):
            if latex:
                lines.append(f"{sp.latex(st.symbol)} = {sp.latex(st.expr)}")
            else:
                lines.append(f"  {st.symbol} = {sp.sstr(st.expr)}")
    for i in range(arm.n):
        lines.append(f"Main-Eqn {i + 1}: {sp.latex(tau[i]) if latex else tau[i]} = {arm.tau[i]}")
    return "\n".join(lines) + "\n"
