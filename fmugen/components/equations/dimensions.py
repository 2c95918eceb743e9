"""Dimensional analysis of component equations (what Modelica tools check).

Every declared quantity has a unit string (:mod:`fmugen.fmi.units` syntax,
coherent SI: factor 1, so ``bar``, ``mm`` or ``deg`` are refused in a component
file -- a scale factor inside an equation would be silently wrong).  Its
dimension is the vector of exponents of the seven SI base dimensions kg, m, s,
A, K, mol and cd.  The radian is the SI's dimensionless derived unit (m/m), so
an equation may mix ``rad`` and ``1`` (``J dw/dt = tau``: kg.m2.rad/s2 against
N.m); connections between components still keep rad apart (FMI 2.0 units:
``rad/s`` never meets ``1/s`` on a wire, see fmugen/scene).
The checker walks the expression tree as written (before sympy simplifies
anything) and refuses:

* a sum, difference, ``min``/``max``/``sat``/``deadzone``/``abs`` whose
  operands differ, or an ``if`` whose branches differ;
* a comparison whose sides differ (also in the conditions of ``[[when]]``
  clauses; ``a < b < c`` is ``a < b and b < c``), a smoothing width ``eps``
  of another dimension than what it smooths;
* ``exp``, ``log``, ``tanh``, ``sin``, ``cos``, ``tan``, ``atan`` of anything
  but a pure number (an angle is one); a dimensioned base raised to a
  non-constant power;
* an equation whose two sides differ (``der(x)`` has x's dimension / s), an
  event's assigned value of another dimension than its target.

The literal ``0`` has every dimension; other numbers are pure numbers
(write a parameter with its unit instead of a bare constant of a dimension).
``atan``, ``atan2``, ``sign`` and ``step`` give a pure number.
"""
from __future__ import annotations

import ast
from fractions import Fraction

from ...fmi.units import BASE, base_units

SI_BASE = tuple(b for b in BASE if b != "rad")  # the seven SI base dimensions
Dim = tuple  # len(SI_BASE) Fractions
DIMENSIONLESS: Dim = tuple(Fraction(0) for _ in SI_BASE)
ANY = None  # the literal 0: fits every dimension
BOOLEAN = "boolean"  # a condition (comparisons, and/or/not): no dimension
SECOND = tuple(Fraction(1 if b == "s" else 0) for b in SI_BASE)


class DimensionError(ValueError):
    """An expression or equation that is not dimensionally consistent (message says where)."""


def dimension_of_unit(unit: str) -> Dim:
    """The dimension of a unit string; a unit with a scale factor is refused (coherent SI only)."""
    u = base_units(unit or "1")
    if abs(u.factor - 1.0) > 1e-15 or u.offset:
        raise ValueError(f"unit {unit!r} has a scale factor {u.factor:g}: component files use coherent SI "
                         f"units (factor 1), e.g. Pa rather than bar, m rather than mm, rad rather than deg")
    return tuple(Fraction(getattr(u, b)) for b in SI_BASE)


def show(d: Dim) -> str:
    """A dimension as a unit string, e.g. ``kg.m-1.s-2`` (``1`` for a pure number, ``any`` for 0)."""
    if d is ANY:
        return "any"
    parts = []
    for b, e in zip(SI_BASE, d):
        if e == 0:
            continue
        parts.append(b if e == 1 else f"{b}{e}" if e.denominator == 1 else f"{b}^({e})")
    return ".".join(parts) or "1"


def add(a: Dim, b: Dim) -> Dim:
    return ANY if a is ANY or b is ANY else tuple(x + y for x, y in zip(a, b))


def sub(a: Dim, b: Dim) -> Dim:
    return ANY if a is ANY or b is ANY else tuple(x - y for x, y in zip(a, b))


def scale(a: Dim, k: Fraction) -> Dim:
    return ANY if a is ANY else tuple(x * k for x in a)


class _Unparser(ast._Unparser):
    """ast.unparse, with a conditional written the way the file writes it (``if C then A else B``)."""

    def visit_IfExp(self, node):
        with self.require_parens(ast._Precedence.TEST, node):
            self.write("if ")
            self.traverse(node.test)
            self.write(" then ")
            self.traverse(node.body)
            self.write(" else ")
            self.traverse(node.orelse)


def unparse(node) -> str:
    """A sub-expression as text for messages (from the tree: the file's spacing is not kept)."""
    try:
        return _Unparser().visit(node)
    except Exception:  # a private helper of the standard library: never let a message fail
        return ast.unparse(node)


class Checker:
    """Dimensions of the nodes of one equation's tree.

    ``dims``: name -> Dim of every declared name; ``constant_value(node)``:
    the exact number of a constant sub-tree, or None (for exponents).
    """

    def __init__(self, text: str, dims: dict, constant_value):
        self.text = text
        self.dims = dims
        self.constant_value = constant_value

    def src(self, node) -> str:
        return unparse(node)

    def fail(self, node, msg) -> None:
        raise DimensionError(f"{msg} (in {self.src(node)!r})")

    def same(self, node, *children) -> Dim:
        """The common dimension of ``children`` (0 fits any), or an error naming the two that differ."""
        found, first = ANY, None
        for c in children:
            d = self.dim(c)
            if d is ANY:
                continue
            if found is ANY:
                found, first = d, c
            elif d != found:
                self.fail(node, f"{self.src(first)!r} is [{show(found)}] but {self.src(c)!r} is [{show(d)}]")
        return found

    def dim(self, node) -> Dim:
        method = getattr(self, "_" + type(node).__name__, None)
        if method is None:  # the builder refused it already; be safe
            self.fail(node, f"cannot check the dimension of {type(node).__name__}")
        return method(node)

    def _Constant(self, node):
        return ANY if node.value == 0 else DIMENSIONLESS

    def _Name(self, node):
        if node.id == "pi":
            return DIMENSIONLESS
        if node.id == "time":
            return SECOND
        return self.dims[node.id]

    def _UnaryOp(self, node):
        if isinstance(node.op, ast.Not):
            self.dim(node.operand)
            return BOOLEAN
        return self.dim(node.operand)

    def _Compare(self, node):  # a condition: the two sides of each comparison (a < b < c: a, b and b, c) agree
        sides = [node.left, *node.comparators]
        for a, b in zip(sides, sides[1:]):
            self.same(node, a, b)
        return BOOLEAN

    def _BoolOp(self, node):
        for v in node.values:
            self.dim(v)
        return BOOLEAN

    def _BinOp(self, node):
        if isinstance(node.op, (ast.Add, ast.Sub)):
            return self.same(node, node.left, node.right)
        a, b = self.dim(node.left), self.dim(node.right)
        if isinstance(node.op, ast.Mult):
            return add(a, b)
        if isinstance(node.op, ast.Div):
            return sub(a, b)
        # power: a pure-number exponent; a dimensioned base needs a constant one
        if b is not ANY and b != DIMENSIONLESS:
            self.fail(node, f"the exponent {self.src(node.right)!r} is [{show(b)}], not a pure number")
        if a is ANY or a == DIMENSIONLESS:
            return a
        k = self.constant_value(node.right)
        if k is None:
            self.fail(node, f"{self.src(node.left)!r} is [{show(a)}]: a dimensioned quantity needs a constant "
                            f"exponent, not {self.src(node.right)!r}")
        return scale(a, k)

    def _Call(self, node):
        name = node.func.id
        args = node.args
        if name == "sqrt":
            return scale(self.dim(args[0]), Fraction(1, 2))
        if name in ("sin", "cos", "tan", "exp", "log", "tanh", "atan", "round", "floor"):
            d = self.dim(args[0])
            if d is not ANY and d != DIMENSIONLESS:
                self.fail(node, f"the argument of {name} must be a pure number, but {self.src(args[0])!r} "
                                f"is [{show(d)}]")
            return DIMENSIONLESS
        if name in ("sign", "step", "atan2"):
            self.same(node, *args)  # x and eps
            return DIMENSIONLESS
        return self.same(node, *args)  # abs, min, max, sat, deadzone (and eps)

    def _IfExp(self, node):
        test = node.test
        if isinstance(test, ast.Call):  # smooth(l > r, eps)
            test = test.args[0]
            self.same(node.test, test.left, test.comparators[0], node.test.args[1])
        else:
            self.dim(test)
        return self.same(node, node.body, node.orelse)


def dimension(text: str, tree, dims: dict, constant_value) -> Dim:
    """The dimension of an expression (an event indicator), or :data:`BOOLEAN` for a condition; an
    inconsistent one is refused (:class:`DimensionError`)."""
    return Checker(text, dims, constant_value).dim(tree)


def check_equation(text: str, tree, lhs_text: str, lhs_dim: Dim, dims: dict, constant_value) -> None:
    """Refuse ``lhs = text`` unless both sides have one dimension (messages give both)."""
    rhs = Checker(text, dims, constant_value).dim(tree)
    if rhs is not ANY and rhs != lhs_dim:
        raise DimensionError(f"the left side {lhs_text} is [{show(lhs_dim)}] but the right side is [{show(rhs)}]")
