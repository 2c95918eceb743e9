"""Straight-line programs: named intermediate quantities instead of closed forms.

Symbolic expression swell is avoided by never building a large expression:
every non-trivial intermediate result of a recursion is bound to a fresh
symbol (:meth:`Program.let`), so each expression stays the size of one step of
the algorithm and the whole program grows linearly with the work done.  A
:class:`Program` is a list of steps; a step is either

* :class:`Assign` -- ``symbol = expr`` where expr uses earlier symbols and the
  program's inputs, or
* :class:`SolveSPD` -- ``X = A^{-1} B`` for a symmetric positive-definite A
  (the mass matrix), solved at run time by a Cholesky factorisation, never a
  symbolic inverse.

The same program is printed as C (:mod:`fmugen.codegen.c_code`) and as Python
for the numeric evaluators (:mod:`fmugen.codegen.python_code`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Sequence

import sympy as sp


@dataclass(frozen=True)
class Assign:
    symbol: sp.Symbol
    expr: sp.Expr


@dataclass(frozen=True)
class SolveSPD:
    """X = A^{-1} B with A symmetric positive definite (n x n), B and X n x k.

    ``A`` and ``B`` hold expressions (usually program symbols); ``X`` holds the
    fresh symbols that receive the solution.  Only the lower triangle of A is
    read.
    """

    X: sp.Matrix
    A: sp.Matrix
    B: sp.Matrix


def is_trivial(expr: sp.Expr) -> bool:
    """Expressions not worth a name: numbers, symbols and their negations."""
    if expr.is_Number or expr.is_Symbol:
        return True
    if expr.is_Mul and len(expr.args) == 2:
        a, b = expr.args
        return (a == -1 and b.is_Symbol) or (b == -1 and a.is_Symbol)
    return False


class Program:
    """A growing straight-line program with fresh-symbol naming.

    Prefixes start with an underscore: robot files may not name parameters
    so (the loader reserves them), hence intermediates never alias a user's
    symbol.

    >>> import sympy as sp
    >>> x, y = sp.symbols("x y")
    >>> p = Program("_t")
    >>> s = p.let(sp.sin(x) * y)
    >>> s, p.let(s + 0), len(p.steps)
    (_t0, _t0, 1)
    """

    def __init__(self, prefix: str = "_t"):
        self.prefix = prefix
        self.steps: list = []
        self._count = 0

    def fresh(self, hint: str = "") -> sp.Symbol:
        name = f"{self.prefix}{hint}{self._count}"
        self._count += 1
        return sp.Symbol(name, real=True)

    def let(self, expr, hint: str = "") -> sp.Expr:
        """Bind ``expr`` to a fresh symbol unless it is trivial; return it."""
        expr = sp.sympify(expr)
        if is_trivial(expr):
            return expr
        s = self.fresh(hint)
        self.steps.append(Assign(s, expr))
        return s

    def let_vec(self, exprs: Iterable, hint: str = "") -> list:
        return [self.let(e, hint) for e in exprs]

    def solve_spd(self, A: sp.Matrix, B: sp.Matrix, hint: str = "x") -> sp.Matrix:
        """Append X = A^{-1} B; returns the matrix of solution symbols."""
        n, k = B.shape
        X = sp.Matrix(n, k, lambda i, j: self.fresh(hint))
        self.steps.append(SolveSPD(X, sp.Matrix(A), sp.Matrix(B)))
        return X

    def extend(self, other: "Program") -> None:
        self.steps.extend(other.steps)

    # --- inspection -----------------------------------------------------
    def assigned_symbols(self) -> set:
        out = set()
        for st in self.steps:
            if isinstance(st, Assign):
                out.add(st.symbol)
            else:
                out.update(st.X)
        return out

    def inline(self, exprs: Sequence[sp.Expr]) -> list:
        """Substitute every intermediate back: closed forms (for tests only).

        Raises if the program contains a linear solve.
        """
        env: dict = {}
        for st in self.steps:
            if not isinstance(st, Assign):
                raise ValueError("cannot inline a program with a linear solve")
            env[st.symbol] = st.expr.xreplace(env)
        return [sp.sympify(e).xreplace(env) for e in exprs]

    def pruned(self, outputs: Iterable[sp.Expr]) -> "Program":
        """A copy without the steps that no output depends on."""
        needed = set()
        for e in outputs:
            needed |= sp.sympify(e).free_symbols
        kept = []
        for st in reversed(self.steps):
            if isinstance(st, Assign):
                if st.symbol in needed:
                    kept.append(st)
                    needed |= st.expr.free_symbols
            else:
                if any(x in needed for x in st.X):
                    kept.append(st)
                    for e in list(st.A) + list(st.B):
                        needed |= sp.sympify(e).free_symbols
        p = Program(self.prefix)
        p._count = self._count
        p.steps = list(reversed(kept))
        return p
