"""The expression language of component files: the robot files' safe parser, extended.

An equation's right-hand side is text.  It is tokenised, the Modelica
conditional ``if C then A else B`` (``elseif`` chains too) is rewritten into
Python's conditional expression, and the result is parsed by :mod:`ast`
(``mode="eval"``) and walked against a whitelist that builds sympy objects
directly -- the same walk, limits and refusals as
:mod:`fmugen.robot.expressions` (:data:`~fmugen.robot.expressions.MAX_DEPTH`,
:data:`~fmugen.robot.expressions.MAX_NODES`, at most
:data:`~fmugen.robot.expressions.MAX_TEXT_LENGTH` characters, no attribute,
subscript, lambda, string or call of anything outside the table below).
Nothing is ever passed to ``eval``, ``exec`` or ``sympify``.

Functions
---------
Smooth everywhere: ``sqrt sin cos tan exp log tanh atan`` (one argument),
``atan2(y, x)`` (a jump of 2 pi across y = 0, x < 0: keep the argument away
from that cut).

Staircases: ``round(x)`` (half up: ``floor(x + 1/2)``) and ``floor(x)``, exact; only in a
``[[when]]`` value (sampled once at an event: an encoder's counts ``q_step*round(x/q_step)`` at a
sample instant) or on parameters and discrete states -- on a state, input or time in an equation or
an indicator they are refused (a jump at every step).

Kinked (a corner or a jump): ``abs(x)``, ``sign(x)``, ``min(a, b)``,
``max(a, b)``, ``sat(x, lo, hi)`` (saturation), ``deadzone(x, lo, hi)``,
``step(d)`` (0 below 0, 1 above).  Each takes an optional last argument
``eps > 0``, the width of its smooth band:

* with ``eps`` the C^1 branch-free form of :mod:`fmugen.components.smooth`
  is used -- exact outside ``|kink| >= eps`` (``abs`` is the Huber function,
  ``min``/``max``/``sat``/``deadzone`` are built from the C^1 ramp,
  ``step`` is the cubic smoothstep of ``clip(d/eps, -1, 1)``), except
  ``sign(x, eps) = x/sqrt(x^2 + eps^2)``, the C-infinity Coulomb form;
* without ``eps`` the exact function is used, and this is **refused when
  its arguments depend on a state, an input or time**: a corner in f makes
  the exact Jacobian jump and a jump makes f itself jump, so RODAS3's
  Newton iteration (which reuses one Jacobian across the step), the master's
  Newton coupling and the equilibrium solver lose their convergence at the
  switch, and nothing stops the solver there (unless the switch is made an
  event: a discrete state set by ``[[when]]`` clauses).  On parameters,
  discrete states and constants (fixed between events) the exact form is kept.

Conditionals
------------
``if C then A else B``.  An ``if`` starts an expression: the whole right-hand
side, a parenthesised group or a function argument
(``1 + (if x > 0 then a else b)``).  A condition is made of comparisons
``<``, ``<=``, ``>``, ``>=``, ``==``, ``!=`` (chained ``a < b <= c`` means
``a < b and b <= c``) joined by ``and``, ``or``, ``not`` and parentheses
(:meth:`EquationBuilder.condition`); nothing else is one (``w``, ``not v``,
``x in ...``, ``is``: refused).

* On parameters, discrete states and constants: exact, any condition (a
  ternary in C; constant between events).
* On a state, input or time the switch must be smooth, and the condition one
  comparison ``l > r`` (``<``, ``>=``, ``<=``): write
  ``if smooth(l > r, eps) then A else B``, which is
  ``B + (A - B) step(l - r, eps)``: exactly A for l - r >= eps, exactly B for
  l - r <= -eps, a C^1 blend in between.  A plain comparison there is refused
  (why: as above).

Events
------
The same language writes a hybrid file's ``[indicators]`` (context
``"indicator"``: continuous between events, so a corner is kept exact but a
jump on a state, input or time is refused), and its ``[[when]]`` conditions
and assigned values (context ``"event"``: evaluated once at an event, so
every function and ``if`` is exact; ``==``/``!=`` on a state, input or time
is refused there -- never met exactly just after a crossing).

Kinks in disguise
-----------------
In an equation, on a state, input or time: a root, a fractional power below 1, a ``log`` or a power with
a non-number exponent of an expression that can be 0 (from the signs its parts can take,
:meth:`EquationBuilder.sign`: ``sqrt(w**2)`` is ``abs(w)``, ``(w + sqrt(w**2))/2`` is ``max(w, 0)``) is
refused like an exact kink; so is a smoothing width that is not a constant > 0 (``0``, ``1e-400``,
``abs(w, w)``, a width of a state, input or time).  Widths of parameters are checked with the values
(:func:`fmugen.components.equations.file.component_model`).

Numbers
-------
Decimal literals only (:data:`NUMBER_LITERAL`): ``12``, ``0.5``, ``.5``, ``3.``, ``1e-3``; no ``_``, no
``0x``/``0o``/``0b``, no ``j``, no leading zeros.

Names: ``time`` is the model time [s]; ``pi``; every declared parameter,
input, state, discrete state and intermediate.  Other names are refused with
the list of declared ones.
"""
from __future__ import annotations

import ast
import io
import math
import re
import tokenize

from typing import Optional

import sympy as sp

from ...robot.expressions import (MAX_DEPTH, MAX_TEXT_LENGTH, ExpressionError, _Builder, _check_size,
                                  _short, check_double)
from ..base import TIME
from ..smooth import huber, smooth_relu, smooth_sign
from .dimensions import unparse

#: one-argument functions that are smooth everywhere
SMOOTH_FUNCTIONS = {"sqrt": sp.sqrt, "sin": sp.sin, "cos": sp.cos, "tan": sp.tan, "exp": sp.exp, "log": sp.log,
                    "tanh": sp.tanh, "atan": sp.atan}
#: kinked functions: name -> number of arguments without the optional eps
KINKED_FUNCTIONS = {"abs": 1, "sign": 1, "min": 2, "max": 2, "sat": 3, "deadzone": 3, "step": 1}
#: staircases (quantisation): exact, and only where no solver integrates across their jumps -- in a
#: [[when]] value (sampled at an event: an encoder's counts at a sample instant) or on constants
STAIR_FUNCTIONS = {"round": lambda x: sp.floor(x + sp.Rational(1, 2)), "floor": sp.floor}
#: every callable name of the language (``smooth`` only as an if-condition)
FUNCTION_NAMES = (frozenset(SMOOTH_FUNCTIONS) | frozenset(KINKED_FUNCTIONS) | frozenset(STAIR_FUNCTIONS)
                  | {"atan2", "smooth", "der"})
RESERVED = FUNCTION_NAMES | {"pi", "time", "t", "if", "then", "else", "elseif", "and", "or", "not"}

#: the literal grammar (README "The expression language"): digits, an optional fraction, an optional exponent
#: -- ``0 | [1-9][0-9]*`` before the point (no leading zeros), no ``_``, no ``0x``/``0o``/``0b``, no ``j``
NUMBER_LITERAL = re.compile(r"(?:(?:0|[1-9][0-9]*)(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")

# -- signs, for the kinks in disguise: the set of signs (-1, 0, +1) an expression can take -----------
POS, NEG, ZERO = frozenset({1}), frozenset({-1}), frozenset({0})
NONNEG, NONPOS, NONZERO, ANYSIGN = frozenset({0, 1}), frozenset({-1, 0}), frozenset({-1, 1}), frozenset({-1, 0, 1})


def _sign_add(a, b):
    out = set()
    for x in a:
        for y in b:
            out |= {x} if x == y or y == 0 else {y} if x == 0 else {-1, 0, 1}
    return frozenset(out) or ANYSIGN


def _sign_mul(a, b):
    return frozenset(x * y for x in a for y in b) or ANYSIGN


def _sign_flip(a):
    return frozenset(-x for x in a)


def _sign_square(a):
    return frozenset(abs(x) for x in a)


def _sign_root(a):
    """The signs of a non-integer power of a base of signs ``a`` (real only for a base >= 0)."""
    return frozenset(x for x in a if x >= 0) or ANYSIGN


def sign_of_bounds(lo, hi, constant: bool) -> frozenset:
    """The signs a declared quantity takes in its range [lo, hi].  A constant (parameter, discrete state) is
    taken as non-zero (generic values; a smoothing width of value 0 is refused when the values are chosen)."""
    if lo is not None and (lo > 0 or (constant and lo >= 0)):
        return POS
    if hi is not None and (hi < 0 or (constant and hi <= 0)):
        return NEG
    if lo is not None and lo >= 0:
        return NONNEG
    if hi is not None and hi <= 0:
        return NONPOS
    return NONZERO if constant else ANYSIGN


_COMPARE = {ast.Gt: sp.Gt, ast.GtE: sp.Ge, ast.Lt: sp.Lt, ast.LtE: sp.Le}
_EQUALITY = {ast.Eq: sp.Eq, ast.NotEq: sp.Ne}
_OPERATOR_NAMES = {ast.In: "in", ast.NotIn: "not in", ast.Is: "is", ast.IsNot: "is not"}


# --------------------------------------------------------------------------
# text -> Python expression tree
# --------------------------------------------------------------------------
def parse_tree(text: str) -> tuple:
    """(checked :mod:`ast` tree, the Python text it was parsed from) of a right-hand side (``if`` rewritten)."""
    if not isinstance(text, str):
        raise ExpressionError(f"expected an expression string, got {type(text).__name__}")
    if len(text) > MAX_TEXT_LENGTH:
        raise ExpressionError(f"expression longer than {MAX_TEXT_LENGTH} characters")
    if not text.strip():
        raise ExpressionError("empty expression")
    if any(ord(c) < 32 or ord(c) == 127 for c in text):
        raise ExpressionError(f"control character (newline, tab, ...) in {_short(text)}; write one line")
    if not text.isascii():  # Python reads names after NFKC: full-width 'ｘ_d' would be the declared x_d
        bad = next(c for c in text if not c.isascii())
        raise ExpressionError(f"non-ASCII character {bad!r} (U+{ord(bad):04X}) in {_short(text)}: the language "
                              f"is ASCII (names are declared in ASCII; look-alike letters are not them)")
    python = _rewrite_conditionals(text)
    try:
        tree = ast.parse(python, mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"syntax error in {_short(text)}: {exc.msg}") from None
    except (RecursionError, MemoryError):
        raise ExpressionError(f"expression nested too deeply in {_short(text)}") from None
    _check_size(tree.body, text)
    return tree.body, python


def _tokens(text: str) -> list:
    out = []
    try:
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type in (tokenize.NEWLINE, tokenize.NL, tokenize.INDENT, tokenize.DEDENT, tokenize.ENDMARKER):
                continue
            if tok.type == tokenize.COMMENT:
                raise ExpressionError(f"'#' is not allowed in {_short(text)}")
            if tok.type == tokenize.ERRORTOKEN and not tok.string.isspace():
                raise ExpressionError(f"cannot read {tok.string!r} in {_short(text)}")
            if tok.type == tokenize.NUMBER and not NUMBER_LITERAL.fullmatch(tok.string):
                raise ExpressionError(
                    f"the number {tok.string!r} in {_short(text)} is not a literal of the language: write decimal "
                    f"digits with an optional fraction and exponent (12, 0.5, .5, 3., 1e-3, 2.5E+6); no '_' "
                    f"separators, no 0x/0o/0b prefixes, no leading zeros, no imaginary 'j'")
            out.append(tok.string)
    except (tokenize.TokenError, IndentationError, SyntaxError) as exc:
        raise ExpressionError(f"syntax error in {_short(text)}: {exc.args[0] if exc.args else exc}") from None
    return out + [""]  # "" is the end


def _rewrite_conditionals(text: str) -> str:
    """``if C then A elseif D then B else E`` -> ``((A) if (C) else ((B) if (D) else (E)))``."""
    toks = _tokens(text)

    def fail(msg):
        raise ExpressionError(f"{msg} in {_short(text)}")

    def expr(i, stops, depth):
        if depth > MAX_DEPTH:
            fail(f"expression nested too deeply (more than {MAX_DEPTH} levels)")
        if toks[i] == "if":
            cond, i = expr(i + 1, {"then"}, depth + 1)
            if toks[i] != "then":
                fail("'if' without 'then'")
            a, i = expr(i + 1, {"else", "elseif"}, depth + 1)
            if toks[i] == "elseif":
                toks[i] = "if"
                b, i = expr(i, stops, depth + 1)
            elif toks[i] == "else":
                b, i = expr(i + 1, stops, depth + 1)
            else:
                fail("'if ... then' without 'else'")
            return f"(({a}) if ({cond}) else ({b}))", i
        out = []
        while True:
            t = toks[i]
            if t == "" or t in stops or t in (")", ",", "]") or t in ("then", "else", "elseif"):
                break
            if t == "if":
                fail("'if' must start an expression: write (if C then A else B)")
            if t in ("(", "["):
                close = ")" if t == "(" else "]"
                out.append(t)
                i += 1
                while toks[i] != close:
                    item, i = expr(i, set(), depth + 1)
                    out.append(item)
                    if toks[i] == ",":
                        out.append(",")
                        i += 1
                    elif toks[i] != close:
                        fail("unbalanced parentheses" if toks[i] == "" else f"unexpected {toks[i]!r}")
                out.append(close)
                i += 1
                continue
            out.append(t)
            i += 1
        if not out:
            fail(f"missing expression before {toks[i]!r}" if toks[i] else "missing expression at the end")
        return " ".join(out), i

    result, i = expr(0, set(), 1)
    if toks[i] != "":
        fail(f"unexpected {toks[i]!r}" + (" (an 'if' needs 'then' and 'else')" if toks[i] in ("then", "else") else ""))
    return result


# --------------------------------------------------------------------------
# tree -> sympy
# --------------------------------------------------------------------------
class EquationBuilder(_Builder):
    """Builds sympy from a checked tree; names resolve through ``names``.

    ``names``: name -> sympy expression (parameters and variables their
    symbols, intermediates their already-built expressions).  ``constant``:
    symbols fixed between events (the parameters and the discrete states): a
    kinked function or an ``if`` on them is kept exact, anything else must be
    smooth.

    ``context``: what the expression is --

    * ``"equation"`` (default): a right-hand side, integrated by the solvers:
      the rules above;
    * ``"indicator"``: an event indicator, whose zero the runtime locates by
      root finding: it must be continuous between events, so a corner
      (``abs min max sat deadzone``) is kept exact but a jump (``sign``,
      ``step``, an ``if``) must be on constants;
    * ``"event"``: a ``[[when]]`` condition or assigned value, evaluated once
      at an event (never integrated, never differentiated): every function
      and ``if`` is exact.
    """

    CONTEXTS = ("equation", "indicator", "event")

    def __init__(self, text: str, names: dict, constant: set, context: str = "equation",
                 signs: Optional[dict] = None):
        super().__init__(text)
        if context not in self.CONTEXTS:
            raise ValueError(f"context {context!r}; one of {self.CONTEXTS}")
        self.names = names
        self.constant = constant
        self.context = context
        self.signs = signs if signs is not None else {}  # name -> the signs it can take (None: any)
        self.kinks = []  # (text, name, [distances to the kink], eps): where a smoothed kink sits
        self.widths = []  # (text, eps): every smoothing width that is not a number (checked with the values)
        self._sign_memo = {}
        self._built = {}  # id(node) -> its sympy expression (a sub-tree is built once: sites recorded once)

    def build(self, node):
        key = id(node)
        if key not in self._built:
            self._built[key] = (node, super().build(node))  # the node is kept: its id stays its own
        return self._built[key][1]

    # -- kinks in disguise -------------------------------------------------
    def sign(self, node) -> frozenset:
        """The signs (subset of {-1, 0, 1}) the sub-tree can take, from its structure: sums, products and even
        powers of the declared ranges, exp > 0, the smooth abs >= eps/2 > 0, ... (sound, not complete)."""
        key = id(node)
        if key not in self._sign_memo:
            self._sign_memo[key] = self._sign(node)
        return self._sign_memo[key]

    def _sign(self, node) -> frozenset:
        if isinstance(node, ast.Constant):
            v = node.value
            return ANYSIGN if not isinstance(v, (int, float)) else POS if v > 0 else NEG if v < 0 else ZERO
        if isinstance(node, ast.Name):
            if node.id == "pi":
                return POS
            if node.id == "time":
                return NONNEG
            return self.signs.get(node.id) or ANYSIGN
        if isinstance(node, ast.UnaryOp):
            a = self.sign(node.operand)
            return _sign_flip(a) if isinstance(node.op, ast.USub) else a if isinstance(node.op, ast.UAdd) else ANYSIGN
        if isinstance(node, ast.BinOp):
            a, b = self.sign(node.left), self.sign(node.right)
            if isinstance(node.op, ast.Add):
                return _sign_add(a, b)
            if isinstance(node.op, ast.Sub):
                return _sign_add(a, _sign_flip(b))
            if isinstance(node.op, ast.Mult):
                return _sign_mul(a, b)
            if isinstance(node.op, ast.Div):
                return _sign_mul(a, b - ZERO or ANYSIGN)
            if isinstance(node.op, ast.Pow):
                k = self._number(node.right)
                if k is not None and k.is_integer:
                    return POS if k == 0 else _sign_square(a) if k.is_even else a
                if k is not None:
                    return _sign_root(a)
                return POS if a == POS else ANYSIGN
            return ANYSIGN
        if isinstance(node, ast.IfExp):
            return self.sign(node.body) | self.sign(node.orelse)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            name, args = node.func.id, node.args
            signs = [self.sign(x) for x in args]
            if not signs:
                return ANYSIGN
            if name == "exp":
                return POS
            if name == "sqrt":
                return _sign_root(signs[0])
            if name in ("tanh", "atan"):
                return signs[0]
            if name == "abs":
                return POS if len(args) == 2 else _sign_square(signs[0])  # the smooth abs is >= eps/2
            if name == "sign":
                return signs[0] if len(args) == 2 else signs[0]
            if name == "step":
                return NONNEG
            if name == "max" and len(args) >= 2:  # the smooth max is >= the exact one
                return POS if POS in (signs[0], signs[1]) else ANYSIGN
            if name == "min" and len(args) == 2:
                return POS if signs[0] == signs[1] == POS else NEG if NEG in (signs[0], signs[1]) else ANYSIGN
        return ANYSIGN

    def _number(self, node):
        """The exact value of a constant sub-tree (a sympy number), or None."""
        try:
            e = self.build(node)
        except ExpressionError:
            return None
        return e if e.is_number and e.is_real else None

    def _varies(self, node) -> bool:
        """Whether the sub-tree depends on a state, an input or time."""
        return not self._is_constant(self.build(node))

    def _disguise(self, node, base, what: str) -> None:
        """Refuse a root/fractional power/log of ``base`` on a state, input or time that can vanish."""
        if self.context != "equation" or not self._varies(base) or 0 not in self.sign(base):
            return
        b = unparse(base)
        raise ExpressionError(
            f"{unparse(node)} in {self.text!r} is {what} of {b!r}, which can be 0 on a state, input or time: a "
            f"non-differentiable point in disguise (sqrt(x**2) is abs(x), (x + sqrt(x**2))/2 is max(x, 0); a root "
            f"has an infinite slope at 0), refused by the kink rule like an exact abs/max: write the kink with "
            f"its width (abs(x, eps), max(x, 0, eps)), or keep the argument away from 0 (sqrt(x**2 + eps**2), "
            f"a declared min > 0)")

    def _width(self, node, eps_node, eps) -> None:
        """A smoothing width must be a constant > 0: not 0, not negative, not a state, input or time."""
        text = unparse(eps_node)
        if not self._is_constant(eps):
            raise ExpressionError(
                f"the smoothing width {text!r} of {unparse(node)} in {self.text!r} depends on a state, input or "
                f"time: a width is a constant > 0 (a parameter or a number); a width that moves with the state "
                f"is no band at all (abs(w, w) is exactly |w|: the corner at 0 is kept), refused by the kink rule")
        if eps.is_number:
            try:
                v = float(eps)
            except (TypeError, ValueError, OverflowError):
                v = math.nan
            if not (math.isfinite(v) and v > 0):
                raise ExpressionError(
                    f"the smoothing width {text!r} of {unparse(node)} in {self.text!r} is "
                    f"{'0' if v == 0 else 'not positive' if math.isfinite(v) else 'not finite'} (as a double: "
                    f"{v!r}): a width is a constant > 0; with 0 the kink is exact (and the smooth form divides "
                    f"by 0), refused by the kink rule")
            return
        if self.sign(eps_node) <= NONPOS:  # else checked with the parameter values (file.component_model)
            raise ExpressionError(
                f"the smoothing width {text!r} of {unparse(node)} in {self.text!r} is never positive (from the "
                f"declared ranges): a width is a constant > 0, refused by the kink rule")
        self.widths.append((f"{unparse(node)}", eps))

    def _site(self, node, name, distances, eps):
        self.kinks.append((ast.unparse(node), name, distances, eps))

    def _is_constant(self, expr) -> bool:
        return expr.free_symbols <= self.constant

    def _Name(self, node):
        name = node.id
        if name == "pi":
            return sp.pi
        if name == "time":
            return TIME
        if name in FUNCTION_NAMES:
            raise ExpressionError(f"function {name!r} used without a call in {self.text!r}")
        if name not in self.names:
            known = ", ".join(sorted(self.names)) or "-"
            raise ExpressionError(f"unknown name {name!r} in {self.text!r}; declared: {known}, time, pi")
        return self.names[name]

    def _UnaryOp(self, node):
        if isinstance(node.op, ast.Not):
            raise ExpressionError(f"'not' is only in a condition (of an if or a [[when]] clause) in {self.text!r}")
        return super()._UnaryOp(node)

    def _Call(self, node):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTION_NAMES - {"smooth", "der"}:
            callee = node.func.id if isinstance(node.func, ast.Name) else type(node.func).__name__
            hint = (" (smooth(...) is only an if-condition: if smooth(x > c, eps) then ...)" if callee == "smooth"
                    else " (der(x) is only a left-hand side)" if callee == "der" else "")
            raise ExpressionError(f"call of {callee!r} is not allowed in {self.text!r}{hint}; functions: "
                                  f"{', '.join(sorted(FUNCTION_NAMES - {'smooth', 'der'}))}")
        name = node.func.id
        if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
            raise ExpressionError(f"{name}() takes plain positional arguments in {self.text!r}")
        args = [self.build(a) for a in node.args]
        if name in SMOOTH_FUNCTIONS:
            self._arity(name, args, 1)
            if name == "sqrt":
                self._disguise(node, node.args[0], "a square root")
            elif name == "log":
                self._disguise(node, node.args[0], "the logarithm (exp(log(x**2)/2) is abs(x))")
            return SMOOTH_FUNCTIONS[name](args[0])
        if name == "atan2":
            self._arity(name, args, 2)
            return sp.atan2(args[0], args[1])
        if name in STAIR_FUNCTIONS:
            self._arity(name, args, 1)
            if self.context == "event" or self._is_constant(args[0]):
                return STAIR_FUNCTIONS[name](args[0])
            raise ExpressionError(
                f"{name}({args[0]}) in {self.text!r} is a staircase on a state, input or time: it jumps at "
                f"every step, which no solver may integrate across and no indicator may hold; use it in a "
                f"[[when]] value (evaluated once at an event, e.g. a sensor quantised at each sample instant of "
                f"a [clocks] clock) or on parameters and discrete states")
        n = KINKED_FUNCTIONS[name]
        if len(args) not in (n, n + 1):
            raise ExpressionError(f"{name}() takes {n} argument{'s' if n > 1 else ''} and an optional "
                                  f"smoothing width eps, got {len(args)} in {self.text!r}")
        if len(args) == n + 1:
            self._width(node, node.args[n], args[n])
            a = args
            dist = ([a[0] - a[1]] if name in ("min", "max") else [a[0] - a[1], a[0] - a[2]]
                    if name in ("sat", "deadzone") else [a[0]])
            if self.context == "equation":
                self._site(node, name, dist, a[n])
            return _smooth_form(name, args[:n], args[n])
        jump = name in ("sign", "step")
        if self.context == "event" or (self.context == "indicator" and not jump) \
                or all(self._is_constant(a) for a in args):
            return _exact_form(name, args)
        if self.context == "indicator":
            raise ExpressionError(
                f"{name}({', '.join(map(str, args))}) in {self.text!r} jumps on a state, input or time: an "
                f"indicator must be continuous between events (the runtime locates its zero by root finding); "
                f"use the quantity itself (its sign changes where {name}() jumps)")
        raise ExpressionError(
            f"{name}({', '.join(map(str, args))}) in {self.text!r} has a "
            f"{'jump' if jump else 'corner'} on a state, input or time: give the width "
            f"of its smooth band as a last argument, {name}(..., eps) (an exact kink breaks the exact "
            f"Jacobian and the Newton iterations of the implicit solvers), or make the switch an event "
            f"(a [discrete] mode set by [[when]] clauses)")

    @staticmethod
    def _arity(name, args, n):
        if len(args) != n:
            raise ExpressionError(f"{name}() takes exactly {n} argument{'s' if n > 1 else ''}, got {len(args)}")

    # -- conditions -------------------------------------------------------
    def condition(self, node) -> sp.Basic:
        """A sympy Boolean of a condition tree: comparisons (``<, <=, >, >=, ==, !=``, chained
        ``a < b < c`` meaning ``a < b and b < c``) joined by ``and``, ``or``, ``not``.

        ``==`` and ``!=`` compare quantities constant between events (parameters, discrete states,
        numbers) only in an event condition: a state or input meets a value exactly only by chance.
        """
        if isinstance(node, ast.BoolOp):
            parts = [self.condition(v) for v in node.values]
            return sp.And(*parts) if isinstance(node.op, ast.And) else sp.Or(*parts)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            return sp.Not(self.condition(node.operand))
        if isinstance(node, ast.Compare):
            for op in node.ops:
                if type(op) not in _COMPARE and type(op) not in _EQUALITY:
                    raise ExpressionError(f"the comparison {_OPERATOR_NAMES.get(type(op), type(op).__name__)!r} "
                                          f"is not allowed in {self.text!r}; compare with <, <=, >, >=, ==, !=")
            sides = [self.build(node.left)] + [self.build(c) for c in node.comparators]
            rels = []
            for op, lhs, rhs in zip(node.ops, sides, sides[1:]):
                cls = _COMPARE.get(type(op)) or _EQUALITY.get(type(op))
                if cls in (sp.Eq, sp.Ne) and self.context != "equation" and not (
                        self._is_constant(lhs) and self._is_constant(rhs)):
                    raise ExpressionError(
                        f"{lhs} {'==' if cls is sp.Eq else '!='} {rhs} compares a state, input or time for "
                        f"equality in {self.text!r}: the runtime stops just after a crossing, where such a value "
                        f"is never exactly met; use <, <=, >, >= (== and != are for parameters and discrete states)")
                rels.append(cls(lhs, rhs))
            return sp.And(*rels)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "smooth":
            raise ExpressionError(f"smooth(...) is only the whole condition of an if in an equation "
                                  f"(if smooth(l > r, eps) then ...) in {self.text!r}")
        raise ExpressionError(f"a condition must be a comparison (<, <=, >, >=, ==, !=) or comparisons joined by "
                              f"and, or, not; {ast.unparse(node)!r} is not one (in {self.text!r})")

    def _IfExp(self, node):
        test, eps = node.test, None
        if isinstance(test, ast.Call) and isinstance(test.func, ast.Name) and test.func.id == "smooth":
            if len(test.args) != 2 or test.keywords:
                raise ExpressionError(f"smooth(condition, eps) takes a comparison and a width in {self.text!r}")
            self._width(test, test.args[1], self.build(test.args[1]))
            test, eps = test.args[0], self.build(test.args[1])
            if not isinstance(test, ast.Compare) or len(test.ops) != 1 or type(test.ops[0]) not in _COMPARE:
                raise ExpressionError(f"the condition of smooth(condition, eps) is one comparison l > r, l < r, "
                                      f"l >= r or l <= r in {self.text!r}")
            lhs, rhs = self.build(test.left), self.build(test.comparators[0])
            a, b = self.build(node.body), self.build(node.orelse)
            greater = isinstance(test.ops[0], (ast.Gt, ast.GtE))
            d = lhs - rhs if greater else rhs - lhs
            if self.context == "equation":
                self._site(node.test, "if", [d], eps)
            return b + (a - b) * _smooth_form("step", [d], eps)
        cond = self.condition(test)
        a, b = self.build(node.body), self.build(node.orelse)
        if self.context == "event" or cond.free_symbols <= self.constant:
            return sp.Piecewise((a, cond), (b, True))
        if self.context == "indicator":
            raise ExpressionError(
                f"if-condition on a state, input or time in {self.text!r}: an indicator must be continuous "
                f"between events (the runtime locates its zero by root finding); an if on parameters and "
                f"discrete states is fine (constant between events)")
        if not isinstance(test, ast.Compare) or len(test.ops) != 1 or type(test.ops[0]) not in _COMPARE:
            raise ExpressionError(f"an if-condition on a state, input or time is one comparison l > r, l < r, "
                                  f"l >= r or l <= r written smooth(l > r, eps) in {self.text!r} (conditions "
                                  f"with ==, !=, and, or, not are for parameters and discrete states)")
        raise ExpressionError(
            f"if-condition on a state, input or time in {self.text!r}: a switch there makes f or its Jacobian "
            f"jump, which the implicit solvers' Newton iterations cannot follow between events; write "
            f"if smooth(l > r, eps) then A else B (a C^1 blend over |l - r| < eps), or make the switch an "
            f"event (a [discrete] mode set by [[when]] clauses)")

    def _BinOp(self, node):
        if isinstance(node.op, ast.Pow):
            k = self._number(node.right)
            if k is None:
                self._disguise(node, node.left, "a power with a non-constant exponent")
            elif not k.is_integer and k < 1:
                self._disguise(node, node.left, f"a fractional power ({k} < 1)")
        return super()._BinOp(node)

    def _Compare(self, node):
        raise ExpressionError(f"a comparison is only an if-condition or a [[when]] condition in {self.text!r}")

    def _BoolOp(self, node):
        raise ExpressionError(f"'and'/'or' join conditions only (of an if or a [[when]] clause) in {self.text!r}")


def _exact_form(name, a):
    if name == "abs":
        return sp.Abs(a[0])
    if name == "sign":
        return sp.sign(a[0])
    if name == "min":
        return sp.Min(a[0], a[1])
    if name == "max":
        return sp.Max(a[0], a[1])
    if name == "sat":
        return sp.Min(sp.Max(a[0], a[1]), a[2])
    if name == "deadzone":
        return a[0] - sp.Min(sp.Max(a[0], a[1]), a[2])
    if name == "step":
        return sp.Piecewise((1, sp.Gt(a[0], 0)), (0, True))
    raise AssertionError(name)


def _smooth_form(name, a, eps):
    """The C^1 (sign: C-infinity) branch-free forms of fmugen.components.smooth, exact for |kink| >= eps."""
    if name == "abs":
        return huber(a[0], eps)
    if name == "sign":
        return smooth_sign(a[0], eps)
    if name == "min":
        return a[0] - smooth_relu(a[0] - a[1], eps)
    if name == "max":
        return a[0] + smooth_relu(a[1] - a[0], eps)
    if name == "sat":
        return a[1] + smooth_relu(a[0] - a[1], eps) - smooth_relu(a[0] - a[2], eps)
    if name == "deadzone":
        return a[0] - _smooth_form("sat", a, eps)
    if name == "step":
        c = (sp.Abs(a[0] / eps + 1) - sp.Abs(a[0] / eps - 1)) / 2  # clip(d/eps, -1, 1), exact
        return sp.Rational(1, 2) + sp.Rational(3, 4) * c - c**3 / 4  # smoothstep: slope 0 at c = +-1
    raise AssertionError(name)


def build(text: str, names: dict, constant: set) -> sp.Expr:
    """Parse ``text`` and build its sympy expression (see :class:`EquationBuilder`); non-finite refused."""
    tree, python = parse_tree(text)
    expr = EquationBuilder(python, names, constant).build(tree)
    check_finite_constants(expr, text)
    return expr


def check_finite_constants(expr, text: str) -> None:
    """Every constant sub-expression must be a finite double (``1/0``, ``log(0)``, ``exp(1000)`` refused)."""
    if expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        raise ExpressionError(f"non-finite value in {_short(text)}")
    stack = [expr]
    while stack:
        e = stack.pop()
        if isinstance(e, sp.Basic) and not e.free_symbols and not isinstance(e, sp.logic.boolalg.BooleanAtom) \
                and not e.is_Relational and isinstance(e, sp.Expr):
            shown = str(e) if len(str(e)) <= 40 else f"{str(e)[:20]}... ({len(str(e))} characters)"
            check_double(e, f"{shown} in {_short(text)}")
            continue
        stack.extend(a for a in getattr(e, "args", ()) if isinstance(a, sp.Basic))


def names_in(tree) -> set:
    """Every name the tree reads (to order intermediates by their dependencies)."""
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}


def finite(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ExpressionError(f"{where} must be a finite number, got {value!r}")
    return float(value)
