"""The Jacobians of a component file: the chain rule over its straight-line program.

:func:`fmugen.codegen.differentiate.differentiate` (the robots' derivations) with this module's rules for a
step's partial derivatives: for a step ``s = e(a, b, ...)`` the derivative program gets
``ds/dw = de/da da/dw + de/db db/dw + ...`` for each state or input w the step depends on, every term
bound to a fresh symbol, so nothing is ever expanded and the cost is linear in the number of steps
(a chain of n intermediates: n small derivative steps, not 3**n terms).  The partial derivative of one
step's expression with respect to one symbol is taken by the rules below (:func:`partial`), sympy's
``diff`` only for what they do not cover: ``diff`` costs ~15 ms an expression (its Derivative machinery),
the rules ~1 ms.
"""
from __future__ import annotations

from typing import Sequence

import sympy as sp

from ...codegen.differentiate import differentiate
from ...codegen.program import Program


def partial(e, s):
    """d e / d s of a step's expression (real symbols; |x|' = sign(x), sign' = 0 away from its jump)."""
    if s not in e.free_symbols:
        return sp.Integer(0)
    if e == s:
        return sp.Integer(1)
    if e.is_Add:
        return sp.Add(*[partial(a, s) for a in e.args])
    if e.is_Mul:
        args = e.args
        terms = []
        for i, a in enumerate(args):
            d = partial(a, s)
            if d != 0:
                terms.append(sp.Mul(*(args[:i] + (d,) + args[i + 1:])))
        return sp.Add(*terms)
    if e.is_Pow:
        b, x = e.args
        if s not in x.free_symbols:
            return x * b ** (x - 1) * partial(b, s)
        if s not in b.free_symbols:
            return e * sp.log(b) * partial(x, s)
        return e * (partial(x, s) * sp.log(b) + x * partial(b, s) / b)
    if isinstance(e, sp.Function) and len(e.args) == 1:
        a = e.args[0]
        da = partial(a, s)
        if da == 0:
            return sp.Integer(0)
        f = type(e)
        if f is sp.sin:
            return sp.cos(a) * da
        if f is sp.cos:
            return -sp.sin(a) * da
        if f is sp.tan:
            return (1 + sp.tan(a) ** 2) * da
        if f is sp.exp:
            return e * da
        if f is sp.log:
            return da / a
        if f is sp.tanh:
            return (1 - sp.tanh(a) ** 2) * da
        if f is sp.atan:
            return da / (1 + a**2)
        if f is sp.sign or f is sp.floor:
            return sp.Integer(0)
        if f is sp.Abs or getattr(f, "is_real_abs", False):
            return sp.sign(a) * da
    if isinstance(e, sp.atan2):
        y, x = e.args
        return (x * partial(y, s) - y * partial(x, s)) / (x**2 + y**2)
    if isinstance(e, sp.Piecewise) and all(s not in c.free_symbols for _, c in e.args):
        return sp.Piecewise(*[(partial(v, s), c) for v, c in e.args])
    return sp.diff(e, s)


def jacobian(program: Program, exprs: Sequence, wrt: Sequence, out: Program) -> sp.Matrix:
    """d exprs / d wrt (len(exprs) x len(wrt)) over the assignments of ``program``, steps appended to ``out``:
    :func:`fmugen.codegen.differentiate.differentiate` with :func:`partial` for each step's derivatives."""
    return differentiate([program], exprs, wrt, out, partial=partial)
