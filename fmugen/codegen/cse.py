"""Common subexpressions of a straight-line program by hash-consing (no rebuilt expressions).

The programs fmugen prints are already lists of named intermediates
(:mod:`fmugen.codegen.program`): each expression is the size of one step of
a recursion.  What is left to share between them are repeated subtrees
(``sin(q1)`` in the kinematics, the dynamics and the end-effector position)
and products with common factors (``a*b*c`` and ``a*b*d``).  sympy's global
:func:`sympy.cse` finds both, but rebuilds every expression of the program
(Mul/Add flattening, the cache, sorting): 3.4 s of a 9.5 s PUMA build.

This module finds the same two things without building a single new
expression except one product per shared group of factors:

1. one walk over the pool indexes every distinct subtree (sympy's structural
   hash is the hash-consing key) in first-visit order, which is deterministic
   because sympy keeps the arguments of Add and Mul in canonical order;
2. products sharing two or more factors are split greedily (smallest product
   first, like sympy's ``match_common_args``): the common factors become one
   product that both use;
3. a second walk counts references as :func:`sympy.cse`'s ``tree_cse`` does
   (a subtree met a second time is repeated; its children are not counted
   again) and names every repeated expression, and every non-symbol base of
   a small integer power (``sin(a)**2`` must not call sin twice).

The result is a list of temporaries and a list of reduced roots, each a
:class:`Ref` (the original expression plus the symbols it reads directly:
program symbols and other temporaries), which the C printer prints with the
names substituted (:class:`fmugen.codegen.c_code._Printer` consults
:attr:`CSE.named` and :attr:`CSE.factors`).
"""
from __future__ import annotations

from collections import defaultdict
from typing import Callable, Iterator, Sequence

import sympy as sp

__all__ = ["CSE", "Ref", "common_subexpressions"]


class Ref:
    """An expression printed with the temporaries of a :class:`CSE` substituted.

    ``free_symbols`` are the symbols it reads directly (program symbols,
    states/inputs/parameters and temporaries), as for a reduced sympy
    expression.
    """

    __slots__ = ("expr", "free_symbols")

    def __init__(self, expr, free_symbols):
        self.expr = expr
        self.free_symbols = free_symbols


def _unnamed(e) -> bool:
    """Expressions never worth a temporary: atoms and negated symbols."""
    if e.is_Atom or not isinstance(e, sp.Expr):
        return True
    if e.is_Mul and len(e.args) == 2:
        a, b = e.args
        return a.is_Number and b.is_Symbol
    return False


def _small_power(e, max_power: int) -> bool:
    return e.is_Pow and e.exp.is_Integer and 2 <= abs(int(e.exp)) <= max_power


class CSE:
    """Common subexpressions of ``pool`` (see the module docstring).

    Attributes: ``named`` {expression: temporary symbol}; ``temps`` [(symbol,
    :class:`Ref`)] in first-visit order; ``reduced``
    one :class:`Ref` (or a temporary symbol, when the whole root is shared)
    per pool entry; ``factors`` {product: [factor expressions]} for products
    rewritten with a common group of factors (the size of the numeric
    coefficient among them, its sign the product's own); ``symbols`` every symbol of the pool.
    """

    def __init__(self, pool: Sequence, symbols: Callable[[set], Iterator[sp.Symbol]], max_power: int = 6):
        self.pool = [sp.sympify(e) for e in pool]
        self.order: dict = {}  # distinct non-atom subtree -> first-visit index
        self.symbols: set = set()
        for e in self.pool:
            self._index(e)
        self.factors = self._split_products()
        self.named = self._repeated(max_power)
        # temporaries in post-order (children first), deterministic names
        # temporaries numbered in first-visit order (deterministic)
        ordered = sorted(self.named, key=self.order.__getitem__)
        symbols = symbols(self.symbols)
        self.named = {e: next(symbols) for e in ordered}
        self.temps = [(self.named[e], Ref(e, self._reads(e))) for e in ordered]
        self.reduced = [self.named[e] if e in self.named else Ref(e, self._reads(e)) for e in self.pool]

    # -- 1. index ------------------------------------------------------------
    def _index(self, e) -> None:
        stack = [e]
        order, syms = self.order, self.symbols
        while stack:
            x = stack.pop()
            if x.is_Atom:
                if x.is_Symbol:
                    syms.add(x)
                continue
            if x in order:
                continue
            order[x] = len(order)
            stack.extend(reversed(x.args))

    def _children(self, e):
        f = self.factors.get(e)
        return f if f is not None else e.args

    # -- 2. products with common factors -----------------------------------------
    def _split_products(self) -> dict:
        order = self.order
        muls = [m for m in order if m.is_Mul and isinstance(m, sp.Expr) and m.is_commutative]
        cur: dict = {}
        for m in muls:
            # the factors, and the size of the numeric coefficient (folded parameters make
            # 0.5*c1*x and 0.5*c1*y share 0.5*c1); its sign stays the product's own
            c = m.as_coeff_Mul()[0]
            fs = [f for f in m.args if not f.is_Number] + ([abs(c)] if abs(c) != 1 else [])
            if len(fs) >= 2:
                cur[m] = set(fs)
        if len(cur) < 2:
            return {}
        index = defaultdict(list)  # factor -> products holding it (in index order)
        items = sorted(cur, key=lambda m: (len(cur[m]), order[m]))
        pos = {m: k for k, m in enumerate(items)}
        for m in items:
            for f in cur[m]:
                index[f].append(m)
        changed = set()
        for m in items:
            fs = cur[m]
            if len(fs) < 2:
                continue
            counts: dict = defaultdict(int)
            for f in fs:
                for other in index[f]:
                    if pos[other] > pos[m]:
                        counts[other] += 1
            for other in sorted((o for o, c in counts.items() if c >= 2), key=pos.__getitem__):
                common = cur[m] & cur[other]
                if len(common) < 2:
                    continue
                # a product that is a part of the other is used there as it is (if its
                # numeric coefficient is 1: the coefficient stays the product's own)
                if common == cur[m] and m.as_coeff_Mul()[0] > 0:
                    group = m
                elif common == cur[other] and other.as_coeff_Mul()[0] > 0:
                    group = other
                else:
                    group = sp.Mul(*sorted(common, key=self._key))
                    if group in (m, other):
                        continue
                    if group not in order:
                        order[group] = len(order)
                    if group not in cur:  # a new product: printed from its factors
                        cur[group] = set(common)
                        changed.add(group)
                for prod in (m, other):
                    if prod is group:
                        continue
                    cur[prod] = (cur[prod] - common) | {group}
                    changed.add(prod)
                    for f in common:
                        index[f].remove(prod)
                    index[group].append(prod)
                if len(cur[m]) < 2:
                    break
        return {m: sorted(cur[m], key=self._key) for m in changed}

    def _key(self, e):
        """Deterministic order of factors: atoms by name/value, subtrees by first visit."""
        if e.is_Number:
            return (0, "", 0)
        if e.is_Atom:
            return (1, str(e), 0)
        return (2, "", self.order[e])

    # -- 3. references ------------------------------------------------------------
    def _repeated(self, max_power: int) -> set:
        seen, named = set(), set()
        stack = list(reversed(self.pool))
        while stack:
            x = stack.pop()
            if x.is_Atom:
                continue
            if x in seen:
                if not _unnamed(x):
                    named.add(x)
                continue
            seen.add(x)
            if _small_power(x, max_power) and not x.base.is_Atom:
                named.add(x.base)
            stack.extend(self._children(x))
        return named

    def _reads(self, root) -> set:
        """Symbols and temporaries ``root`` reads directly."""
        if root.is_Atom:
            return {root} if root.is_Symbol else set()
        out, named, seen = set(), self.named, set()
        stack = list(self._children(root))
        while stack:
            x = stack.pop()
            if x.is_Atom:
                if x.is_Symbol:
                    out.add(x)
                continue
            t = named.get(x)
            if t is not None:
                out.add(t)
                continue
            if x in seen:
                continue
            seen.add(x)
            stack.extend(self._children(x))
        return out


def common_subexpressions(pool: Sequence, symbols: Callable[[set], Iterator[sp.Symbol]], max_power: int = 6) -> CSE:
    """:class:`CSE` of ``pool``; ``symbols(pool_symbols)`` gives the temporaries' symbols (names that
    collide with none of the pool's symbols)."""
    return CSE(pool, symbols, max_power)
