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

from .chain import ChainDynamics
from .program import Assign, Program, SolveSPD


def _finite_signs(expr):
    """``sign(a)**-k`` -> ``sign(a)**k`` (equal where a != 0, finite at a = 0): sympy differentiates some
    nested ``Abs`` (smooth kinks of component files) into ``1/sign(a)``, 0/0 in C exactly at the kink."""
    if not expr.has(sp.sign):
        return expr
    return expr.replace(lambda e: e.is_Pow and isinstance(e.base, sp.sign) and e.exp.is_negative,
                        lambda e: e.base ** (-e.exp))


def differentiate(
    sources: Sequence[Program],
    exprs: Sequence[sp.Expr],
    wrt: Sequence[sp.Symbol],
    out: Program,
    through_solves: bool = False,
    partial=None,
) -> sp.Matrix:
    """Jacobian d exprs / d wrt (len(exprs) x len(wrt)), with steps appended to ``out``.

    ``partial(e, s)``: the partial derivative of one step's expression with respect to one symbol
    (default sympy's ``diff``; component files pass their cheaper rules,
    :func:`fmugen.components.equations.derive.partial`).

    ``sources`` are the programs that define the symbols in ``exprs`` (in
    execution order).  By default the solution symbols of linear solves are
    treated as independent quantities (the caller wants partial derivatives
    at fixed solution, e.g. d ID / d q at fixed qdd).  With
    ``through_solves`` the chain rule goes through them as well:
    X = A^{-1} B gives dX/dw = A^{-1} (dB/dw - dA/dw X), one more solve with
    the same A and one right-hand side per (column of B, w).
    """
    wrt = list(wrt)
    wset = set(wrt)
    d_of = partial or (lambda e, s: e.diff(s))
    steps = [st for P in sources for st in P.steps if through_solves or isinstance(st, Assign)]
    # which steps are needed by the outputs (walking back through the steps)
    needed = set()
    for e in exprs:
        needed |= sp.sympify(e).free_symbols
    for st in reversed(steps):
        if isinstance(st, Assign):
            if st.symbol in needed:
                needed |= st.expr.free_symbols
        elif any(x in needed for x in st.X):
            for e in list(st.A) + list(st.B):
                needed |= sp.sympify(e).free_symbols
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
            p = _finite_signs(d_of(expr, s))
            if p == 0:
                continue
            if len(ds) > 1:
                p = out.let(p, "p")
            for w, dw in ds.items():
                total[w] = total.get(w, 0) + p * dw
        return {w: out.let(v, "d") for w, v in total.items() if v != 0}

    for st in steps:
        if isinstance(st, Assign):
            if st.symbol in needed:
                g = grad(st.expr)
                if g:
                    deriv[st.symbol] = g
        elif any(x in needed for x in st.X):
            _through_solve(st, grad, deriv, out)
    J = sp.zeros(len(exprs), len(wrt))
    for i, e in enumerate(exprs):
        g = grad(e)
        for j, w in enumerate(wrt):
            if w in g:
                J[i, j] = g[w]
    return J


def _through_solve(st: SolveSPD, grad, deriv: dict, out: Program) -> None:
    """Derivatives of X = A^{-1} B: one solve with A for every (w, column of B)."""
    if isinstance(st, ChainDynamics):
        raise ValueError(f"a model with the runtime's looped dynamics of a {st.n}-link arm cannot be "
                         f"differentiated symbolically (e.g. composed with other components into one "
                         f"model); give the arm a group of its own, or derive it with "
                         f"state_space_model(strategy='straight')")
    n, k = st.B.shape
    gA = {(i, j): grad(st.A[i, j]) for i in range(n) for j in range(i + 1)}  # lower triangle is read
    gB = {(i, c): grad(st.B[i, c]) for i in range(n) for c in range(k)}
    ws = []
    for g in list(gA.values()) + list(gB.values()):
        ws += [w for w in g if w not in ws]
    if not ws:
        return

    def a(i, j, w):  # dA/dw, symmetric
        return gA[(i, j) if j <= i else (j, i)].get(w, 0)

    rhs = sp.zeros(n, k * len(ws))
    for m, w in enumerate(ws):
        for c in range(k):
            for i in range(n):
                e = gB[(i, c)].get(w, 0) - sum(a(i, j, w) * st.X[j, c] for j in range(n))
                rhs[i, m * k + c] = out.let(e, "r")
    Y = out.solve_spd(st.A, rhs, "dx")
    for m, w in enumerate(ws):
        for c in range(k):
            for i in range(n):
                deriv.setdefault(st.X[i, c], {})[w] = Y[i, m * k + c]
