"""Safe parser for the quantities written in robot files.

A quantity in a robot file is a TOML number or a string holding a number, a
symbol name, or an arithmetic expression such as ``"m*l**2/12"`` or
``"-pi/2"``.  The string is parsed with Python's :mod:`ast` (``mode="eval"``)
and the tree is walked against a whitelist, building sympy objects directly;
no text is ever passed to ``eval``, ``exec`` or ``sympify``.

Accepted grammar
----------------
* numbers: plain decimal literals only (:data:`fmugen.values.DECIMAL_LITERAL`: ``12``,
  ``0.5``, ``.5``, ``1e-3``); Python's ``1_5``, ``0x10``, ``0o17``, ``0b11`` are refused;
  integer literals become ``sympy.Integer``; decimal literals inside
  a string (``"0.5"``, ``"1e-3"``) become the *exact* ``sympy.Rational`` of
  the decimal text (``"0.5*m"`` is ``m/2``), because the text is exact;
* binary ``+ - * / **``, unary ``+ -``, parentheses;
* the constant ``pi`` and the functions ``sqrt sin cos tan exp log abs``
  (one argument each; ``abs`` is ``sympy.Abs``);
* ASCII text only: Python reads identifiers after NFKC normalisation, so ``"ｍ"`` (full-width)
  or ``"𝐦"`` would silently be the parameter ``m``;
* symbol names matching ``[A-Za-z_][A-Za-z0-9_]*`` that are not reserved
  (:func:`symbol_name_problem`: Python keywords and builtins, C keywords, the
  function names and ``pi``, names starting with ``_`` -- kept for generated
  code -- and the model's own variables ``q_i``, ``qd_i``, ``qdd_i``,
  ``tau_i``, ``f_ext_i_x`` ...); each becomes ``sympy.Symbol(name, real=True)``.

TOML floats (already binary numbers when the file is read) become
``sympy.Float``; an *angle* that lies within 1e-12 rad of a multiple of pi/2
is snapped to that exact multiple (:func:`snap_angle`) so that sin and cos of
+-90 degrees are exact structural zeros and ones.
"""
from __future__ import annotations

import ast
import builtins
import keyword
import math
import re
import sys

import sympy as sp

from ..errors import FmugenError
from ..values import DECIMAL_LITERAL

FUNCTIONS = {
    "sqrt": sp.sqrt,
    "sin": sp.sin,
    "cos": sp.cos,
    "tan": sp.tan,
    "exp": sp.exp,
    "log": sp.log,
    "abs": sp.Abs,
}
CONSTANTS = {"pi": sp.pi}

NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")

# Names a symbol may not take.  Python builtins (eval, open, __import__, ...)
# are refused so that a file cannot even look like it calls them; C keywords
# are refused because parameter names end up as identifiers in generated C.
_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern "
    "float for goto if inline int long register restrict return short signed "
    "sizeof static struct switch typedef union unsigned void volatile while".split()
)
_BUILTINS = frozenset(n for n in dir(builtins) if not n.startswith("_")) | {"__import__"}

# Names of the model's own variables (joint coordinates, inputs, outputs in
# fmugen.dynamics.manipulator): a parameter of that name would silently become
# the same sympy symbol.
_MODEL_VARIABLE = re.compile(r"(q|qd|qdd|tau|qdd_out|p_ee)_[0-9]+\Z|(f_ext|t_ext)_[0-9]+_[xyz]\Z")

MAX_TEXT_LENGTH = 2000  # a robot quantity longer than this is not a quantity
# Bounds on the parsed tree, checked before anything recursive (the builder,
# sympy) sees it: 999 '+' terms or 1500 nested unary minus signs fit in 2000
# characters but would exhaust Python's recursion limit downstream.
MAX_DEPTH = 50  # nesting of operators, calls and parentheses
MAX_NODES = 200  # operators, operands and calls in one quantity
MAX_EXPONENT = 64  # refuse 10**10**10 and friends before sympy tries them
ANGLE_SNAP_TOLERANCE = 1e-12  # rad


class ExpressionError(FmugenError):
    """A quantity's text is not an accepted expression (message says why)."""


def symbol_name_problem(name: str) -> str | None:
    """Why ``name`` cannot be a symbol name, or None when it can."""
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        return f"{name!r} is not a valid identifier ([A-Za-z_][A-Za-z0-9_]*)"
    if name.startswith("_"):
        return f"{name!r}: names starting with '_' are reserved for generated code"
    if _MODEL_VARIABLE.match(name):
        return f"{name!r} is reserved for a variable of the model (joint coordinates, torques, outputs)"
    if keyword.iskeyword(name) or keyword.issoftkeyword(name):
        return f"{name!r} is a Python keyword"
    if name in FUNCTIONS or name in CONSTANTS:
        return f"{name!r} is a reserved function/constant name of the expression language"
    if name in _BUILTINS:
        return f"{name!r} is a Python builtin name and is refused as a symbol"
    if name in _C_KEYWORDS:
        return f"{name!r} is a C keyword (parameter names become C identifiers)"
    return None


def make_symbol(name: str) -> sp.Symbol:
    problem = symbol_name_problem(name)
    if problem:
        raise ExpressionError(problem)
    return sp.Symbol(name, real=True)


def parse_expression(text: str) -> sp.Expr:
    """Parse ``text`` (an arithmetic expression) into a sympy expression.

    >>> parse_expression("m*l**2/12")
    l**2*m/12
    """
    if not isinstance(text, str):
        raise ExpressionError(f"expected a string, got {type(text).__name__}")
    if len(text) > MAX_TEXT_LENGTH:
        raise ExpressionError(f"expression longer than {MAX_TEXT_LENGTH} characters")
    if not text.strip():
        raise ExpressionError("empty expression")
    if not text.isascii():
        bad = next(c for c in text if not c.isascii())
        raise ExpressionError(f"non-ASCII character {bad!r} (U+{ord(bad):04X}) in {_short(text)}: an expression "
                              f"is ASCII arithmetic (Python would read full-width or styled letters and "
                              f"digits as plain ones)")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        if "too many nested" in str(exc.msg):  # the parser's own limit (200 parentheses)
            raise ExpressionError(f"expression nested too deeply (more than {MAX_DEPTH} levels) "
                                  f"in {_short(text)}") from None
        raise ExpressionError(f"syntax error in {_short(text)}: {exc.msg}") from None
    except (RecursionError, MemoryError):  # the parser's own nesting limit
        raise ExpressionError(f"expression nested too deeply (more than {MAX_DEPTH} levels) "
                              f"in {_short(text)}") from None
    _check_size(tree.body, text)
    return _Builder(text.strip()).build(tree.body)


def _short(text: str, n: int = 60) -> str:
    """``repr`` of ``text``, cut to ``n`` characters for messages."""
    return repr(text) if len(text) <= n else repr(text[:n]) + f"... ({len(text)} characters)"


def _check_size(root, text: str) -> None:
    """Refuse a tree deeper than :data:`MAX_DEPTH` or larger than
    :data:`MAX_NODES` (walked with an explicit stack, so never a RecursionError)."""
    stack, nodes = [(root, 1)], 0
    while stack:
        node, depth = stack.pop()
        if isinstance(node, (ast.operator, ast.unaryop, ast.expr_context)):
            continue
        nodes += 1
        if depth > MAX_DEPTH:
            raise ExpressionError(f"expression nested too deeply (more than {MAX_DEPTH} levels of "
                                  f"operators, calls or parentheses) in {_short(text)}")
        if nodes > MAX_NODES:
            raise ExpressionError(f"expression too long: more than {MAX_NODES} terms, operators and "
                                  f"calls in {_short(text)}; name intermediate quantities in [parameters]")
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))


def quantity(value) -> sp.Expr:
    """A TOML value (int, float or expression string) as a sympy expression.

    Booleans, tables and arrays are refused.  Non-finite results (``inf``,
    ``nan``, ``"1/0"``) are refused.
    """
    if isinstance(value, bool):
        raise ExpressionError(f"expected a number or an expression string, got the boolean {value}")
    if isinstance(value, int):
        expr = sp.Integer(value)
    elif isinstance(value, float):
        if not math.isfinite(value):
            raise ExpressionError(f"non-finite number {value!r}")
        expr = sp.Float(value)
    elif isinstance(value, str):
        expr = parse_expression(value)
    else:
        raise ExpressionError(
            f"expected a number or an expression string, got {type(value).__name__} {value!r}"
        )
    if expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        raise ExpressionError(f"non-finite value {value!r}")
    if not expr.free_symbols:
        if not expr.is_real:
            raise ExpressionError(f"{value!r} is not a real number")
        # exact sympy numbers such as 1e308*10 or exp(1000) are finite
        # symbolically but not as doubles, which is what the C code computes
        check_double(expr, repr(value))
    return expr


def check_double(expr, text: str) -> float:
    """``float(expr)``, or an :class:`ExpressionError` when that is not a finite double."""
    try:
        v = float(expr)
    except (OverflowError, TypeError, ValueError):
        v = math.inf
    if not math.isfinite(v):
        raise ExpressionError(f"{text} is not a finite double-precision number "
                              f"(|value| > {sys.float_info.max:.3g} or undefined)")
    return v


def snap_angle(expr: sp.Expr) -> sp.Expr:
    """Replace a numeric angle within 1e-12 rad of k*pi/2 by the exact k*pi/2.

    Symbolic angles and angles away from a multiple of pi/2 are returned
    unchanged.  ``snap_angle(sp.Float(-1.5707963267948966)) == -pi/2``.
    """
    if expr.free_symbols:
        return expr
    v = float(expr)
    k = round(v / (math.pi / 2))
    if abs(v - k * math.pi / 2) <= ANGLE_SNAP_TOLERANCE:
        return sp.Integer(k) * sp.pi / 2
    return expr


class _Builder:
    """Walks a whitelisted Python expression tree into sympy objects."""

    _BINARY = {
        ast.Add: lambda a, b: a + b,
        ast.Sub: lambda a, b: a - b,
        ast.Mult: lambda a, b: a * b,
        ast.Div: lambda a, b: a / b,
        ast.Pow: lambda a, b: a**b,
    }

    def __init__(self, text: str):
        self.text = text

    def build(self, node):
        method = getattr(self, "_" + type(node).__name__, None)
        if method is None:
            raise ExpressionError(f"{_describe(node)} is not allowed in {self.text!r}")
        return method(node)

    def _Constant(self, node):
        v = node.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ExpressionError(f"constant {v!r} is not a real number in {self.text!r}")
        segment = ast.get_source_segment(self.text, node)
        if segment is not None and not DECIMAL_LITERAL.fullmatch(segment):
            raise ExpressionError(f"the number {segment!r} in {_short(self.text)} is not a decimal literal: write "
                                  f"ASCII digits with an optional '.' and exponent (12, 0.5, .5, 1e-3); no '_' "
                                  f"separators, no 0x/0o/0b prefixes")
        if isinstance(v, int):
            return sp.Integer(v)
        if not math.isfinite(v):
            raise ExpressionError(f"non-finite number in {self.text!r}")
        # exact value of the decimal text as written (e.g. "0.1" -> 1/10)
        segment = ast.get_source_segment(self.text, node)
        return sp.Rational(segment) if segment else sp.Float(v)

    def _Name(self, node):
        name = node.id
        if name in CONSTANTS:
            return CONSTANTS[name]
        if name in FUNCTIONS:
            raise ExpressionError(f"function {name!r} used without a call in {self.text!r}")
        problem = symbol_name_problem(name)
        if problem:
            raise ExpressionError(f"{problem} (in {self.text!r})")
        return sp.Symbol(name, real=True)

    def _UnaryOp(self, node):
        operand = self.build(node.operand)
        if isinstance(node.op, ast.USub):
            return -operand
        if isinstance(node.op, ast.UAdd):
            return operand
        raise ExpressionError(f"operator {type(node.op).__name__} is not allowed in {self.text!r}")

    def _BinOp(self, node):
        op = self._BINARY.get(type(node.op))
        if op is None:
            raise ExpressionError(f"operator {type(node.op).__name__} is not allowed in {self.text!r}")
        left, right = self.build(node.left), self.build(node.right)
        if isinstance(node.op, ast.Pow) and right.is_number:
            # refuse 10**10**10 and ((10**60)**60)**60 before sympy expands them
            try:
                too_big = abs(float(right)) > MAX_EXPONENT
                if not too_big and left.is_number and left != 0:
                    too_big = abs(float(right)) * abs(math.log10(abs(float(left)))) > 300
            except (OverflowError, TypeError, ValueError):
                too_big = True
            if too_big:
                raise ExpressionError(f"power too large in {self.text!r}")
        return op(left, right)

    def _Call(self, node):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            callee = node.func.id if isinstance(node.func, ast.Name) else _describe(node.func)
            raise ExpressionError(
                f"call of {callee!r} is not allowed in {self.text!r} "
                f"(allowed functions: {', '.join(sorted(FUNCTIONS))})"
            )
        if node.keywords or len(node.args) != 1 or isinstance(node.args[0], ast.Starred):
            raise ExpressionError(f"{node.func.id}() takes exactly one argument in {self.text!r}")
        return FUNCTIONS[node.func.id](self.build(node.args[0]))


def _describe(node) -> str:
    names = {
        "Attribute": "attribute access",
        "Subscript": "subscripting",
        "Lambda": "a lambda",
        "Compare": "a comparison",
        "BoolOp": "a boolean operator",
        "IfExp": "a conditional expression",
        "List": "a list",
        "Tuple": "a tuple",
        "Dict": "a dict",
        "Set": "a set",
        "JoinedStr": "an f-string",
        "ListComp": "a comprehension",
        "GeneratorExp": "a generator",
        "NamedExpr": "an assignment expression",
        "Starred": "star-unpacking",
    }
    return names.get(type(node).__name__, f"syntax {type(node).__name__}")
