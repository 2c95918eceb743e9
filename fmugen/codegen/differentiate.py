"""Exact derivatives of straight-line programs (forward mode, symbolic).

For the implicit solver, directional derivatives and linearisation the FMUs
need df/dx and df/du.  Differentiating a closed form would re-create the
swell the programs avoid, so the chain rule is applied step by step instead:
for ``s = e(a, b, ...)`` the derivative program gets
``ds/dw = de/da * da/dw + de/db * db/dw + ...`` for every w the step depends
on, each term bound to a fresh symbol.  The size of the result is bounded by
(program length) x (number of w), and structural independence is exploited:
a step that depends on no w produces nothing.
"""
from __future__ import annotations

from typing import Sequence

import sympy as sp

from .program import Assign, Program


def differentiate(
    sources: Sequence[Program],
    exprs: Sequence[sp.Expr],
    wrt: Sequence[sp.Symbol],
    out: Program,
) -> sp.Matrix:
    """Jacobian d exprs / d wrt (len(exprs) x len(wrt)), with steps appended to ``out``.

    ``sources`` are the programs that define the symbols in ``exprs`` (in
    execution order).  Solution symbols of linear solves are treated as
    independent quantities (the caller wants partial derivatives at fixed
    solution, e.g. d ID / d q at fixed qdd).
    """
    wrt = list(wrt)
    wset = set(wrt)
    steps = [st for P in sources for st in P.steps if isinstance(st, Assign)]
    # which steps are needed by the outputs (walking back through assignments only)
    needed = set()
    for e in exprs:
        needed |= sp.sympify(e).free_symbols
    for st in reversed(steps):
        if st.symbol in needed:
            needed |= st.expr.free_symbols
    deriv: dict = {}  # symbol -> {w: derivative expression}

    def grad(expr) -> dict:
        expr = sp.sympify(expr)
        total: dict = {}
        for s in expr.free_symbols:
            if s in wset:
                ds = {s: sp.Integer(1)}
            elif s in deriv:
                ds = deriv[s]
            else:
                continue
            partial = expr.diff(s)
            if partial == 0:
                continue
            if len(ds) > 1:
                partial = out.let(partial, "p")
            for w, dw in ds.items():
                total[w] = total.get(w, 0) + partial * dw
        return {w: out.let(v, "d") for w, v in total.items() if v != 0}

    for st in steps:
        if st.symbol in needed:
            g = grad(st.expr)
            if g:
                deriv[st.symbol] = g
    J = sp.zeros(len(exprs), len(wrt))
    for i, e in enumerate(exprs):
        g = grad(e)
        for j, w in enumerate(wrt):
            if w in g:
                J[i, j] = g[w]
    return J
