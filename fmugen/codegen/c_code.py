"""C code generation: a :class:`SymbolicModel` printed as one ``model.c``.

The generated file fills in the ``fmugen_model_def`` struct of
``c_runtime/fmugen_model.h`` and holds only the model:

* ``evaluate(p, t, x, u, dx, y)``  --  dx = f(t, x, u, p) and y = g(t, x, u, p)
  in one pass (the output-only part runs only when ``y != NULL``);
* ``jacobian(p, t, x, u, dfdx, dfdu, dgdx, dgdu)``  --  the exact partial
  derivatives, dense row-major (nx*nx, nx*nu, ny*nx, ny*nu).

Each function body is straight-line C produced from a
:class:`~fmugen.codegen.program.Program`:

1. the steps' expressions and the results (derivatives, outputs, Jacobian
   entries) go through **one joint** common-subexpression elimination
   (:mod:`fmugen.codegen.cse`: hash-consing of repeated subtrees and of
   common groups of factors, no expression rebuilt), so a quantity used by
   several steps -- sin(q1) in the kinematics, the dynamics and the
   end-effector position -- is computed once;
2. integer powers whose base is not a plain variable get their base named
   too, so ``sin(a)**2`` never evaluates ``sin(a)`` twice;
3. statements are emitted in program order, each CSE temporary just before
   its first use, dead statements dropped (no unused variables under
   ``-Wall -Wextra``);
4. a :class:`~fmugen.codegen.program.SolveSPD` step becomes two local arrays
   (lower triangle of A, and B) and a call of ``fmugen_spd_solve`` (Cholesky,
   ``c_runtime/linalg.c``), whose error code is returned on failure.

Operation counts are taken from the printed C itself (see :class:`OpCount`),
so they describe exactly the code the compiler gets.

Example (a pendulum; the count is of the C that is printed):

>>> import sympy as sp
>>> from fmugen.codegen.model import SymbolicModel, Variable
>>> phi, w, g, L = sp.symbols("phi w g L", real=True)
>>> m = SymbolicModel.from_equations(
...     "Pendulum",
...     states=[Variable("phi", phi, "rad", start=0.1), Variable("w", w, "rad/s", start=0.0)],
...     inputs=[], parameters=[Variable("g", g, "m/s2", start=9.81), Variable("L", L, "m", start=1.0)],
...     derivatives=[w, -g / L * sp.sin(phi)])
>>> gen = generate_c(m)
>>> str(gen.op_counts["evaluate"])
'1 mul, 0 add, 1 div, 1 call (sin 1)'
"""
from __future__ import annotations

import keyword
import math
import re
import uuid
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Iterable, Optional, Sequence

import sympy as sp
from sympy.printing.c import C99CodePrinter
from sympy.printing.precedence import precedence

from ..errors import FmugenError
from .model import SymbolicModel, Variable, physical_range
from .chain import ChainDynamics, chain_call_lines, chain_ops, unrolled_choice, unrolled_step_lines
from .cse import common_subexpressions
from .op_count import OpCount
from .program import Assign, Program, SolveSPD
from .runtime_parameters import runtime_starts

__all__ = [
    "OpCount",
    "FunctionOps",
    "GeneratedC",
    "generate_c",
    "count_operations",
    "c_identifier",
    "deterministic_guid",
]

#: longest C name printed for a variable (C99 guarantees 63 significant
#: characters of an internal identifier; suffixes keep names unique)
MAX_C_NAME = 48

#: Integer powers up to this exponent are printed as repeated products.
MAX_PRODUCT_POWER = 6

GUID_NAMESPACE = uuid.UUID("7b0f2f5e-2a71-5d0e-9a59-6c1f0d3f6a10")

_C_KEYWORDS = {
    "auto", "break", "case", "char", "const", "continue", "default", "do", "double", "else",
    "enum", "extern", "float", "for", "goto", "if", "inline", "int", "long", "register",
    "restrict", "return", "short", "signed", "sizeof", "static", "struct", "switch", "typedef",
    "union", "unsigned", "void", "volatile", "while", "_Bool", "_Complex", "_Imaginary",
    "NULL", "main",
}
_C_MATH = {
    "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh",
    "acosh", "atanh", "exp", "exp2", "expm1", "log", "log10", "log2", "log1p", "pow", "sqrt",
    "cbrt", "hypot", "fabs", "floor", "ceil", "fmod", "fmin", "fmax", "copysign", "erf", "erfc",
    "tgamma", "lgamma", "round", "trunc", "isfinite", "isnan", "isinf", "signbit", "memset",
    "M_PI", "M_E", "INFINITY", "NAN", "HUGE_VAL",
}
#: keywords of every C standard (C89 to C23) and of the GNU dialects that
#: ``gcc``/``clang`` compile by default (``fmpy compile`` passes no ``-std``):
#: a parameter called ``asm`` or ``typeof`` is a syntax error there even
#: though ``-std=c99`` accepts it
_C_ALL_KEYWORDS = {
    # C23 keywords without underscore
    "alignas", "alignof", "bool", "constexpr", "false", "nullptr", "static_assert", "thread_local", "true",
    "typeof", "typeof_unqual",
    # GNU and common compiler extensions (gcc, clang, MSVC/MinGW spellings without leading underscores)
    "asm", "fortran", "cdecl", "pascal", "far", "near", "huge", "stdcall", "fastcall", "thiscall", "vectorcall",
    "declspec", "restrict", "complex", "imaginary", "noreturn", "atomic", "generic",
    # C++ keywords: the headers are also read by C++ importers
    "and", "and_eq", "bitand", "bitor", "catch", "char8_t", "char16_t", "char32_t", "class", "compl", "concept",
    "consteval", "constinit", "const_cast", "co_await", "co_return", "co_yield", "decltype", "delete",
    "dynamic_cast", "explicit", "export", "friend", "mutable", "namespace", "new", "noexcept", "not", "not_eq",
    "operator", "or", "or_eq", "private", "protected", "public", "reflexpr", "reinterpret_cast", "requires",
    "static_cast", "template", "this", "throw", "try", "typeid", "typename", "using", "virtual", "wchar_t",
    "xor", "xor_eq",
}
#: object-like macros without a leading underscore that a compiler predefines
#: in its GNU dialects (gcc's and clang's ``builtin_define_std``: ``linux`` is
#: ``1`` under ``-std=gnu11``) on the platforms FMUs are built for, and that
#: the headers the generated code includes define there (math.h, stddef.h,
#: string.h, stdlib.h of glibc, musl, macOS and MinGW): a variable of that name
#: would be replaced by the preprocessor
_PREDEFINED_MACROS = {
    "linux", "unix", "i386", "i486", "i586", "i686", "sun", "sparc", "mips", "mipsel", "MIPSEB", "MIPSEL",
    "R3000", "R4000", "hppa", "hp9000", "hpux", "vax", "pdp11", "m68k", "mc68000", "mc68010", "mc68020",
    "mc68030", "mc68040", "mc68060", "m88k", "ns32000", "pyr", "sequent", "sgi", "host_mips", "alpha", "arm",
    "thumb", "powerpc", "ppc", "PPC", "POWERPC", "ibm", "aix", "AIX", "sh", "bfin", "BFIN", "cris", "CRIS",
    "GNU_CRIS", "tune_i386", "amd64", "x86_64", "ia64", "WIN32", "WIN64", "WINNT", "MSDOS", "CYGWIN32",
    "MINGW32", "OBJC_NEW_PROPERTIES", "APPLE", "MACH", "NeXT", "BSD", "SVR4", "svr4", "sysV", "osf", "OSF1",
    "vms", "VMS", "embedded", "gnu_linux", "ELF", "elf",
    # header macros (glibc in GNU mode, musl, macOS, MinGW)
    "BIG_ENDIAN", "LITTLE_ENDIAN", "PDP_ENDIAN", "BYTE_ORDER", "EXIT_FAILURE", "EXIT_SUCCESS", "FD_SETSIZE",
    "NFDBITS", "MB_CUR_MAX", "RAND_MAX", "WCONTINUED", "WEXITED", "WNOHANG", "WNOWAIT", "WSTOPPED",
    "WUNTRACED", "WCOREFLAG", "HUGE", "MAXFLOAT", "DOMAIN", "SING", "OVERFLOW", "UNDERFLOW", "TLOSS", "PLOSS",
    "X_TLOSS", "math_errhandling", "MATH_ERRNO", "MATH_ERREXCEPT", "offsetof", "errno", "alloca",
    "EDOM", "ERANGE", "EILSEQ", "fpclassify", "isnormal", "isgreater", "isgreaterequal", "isless",
    "islessequal", "islessgreater", "isunordered", "iscanonical", "issignaling", "issubnormal", "iszero",
}
# names the generated functions use for themselves
_ARGS = {"p", "t", "x", "u", "dx", "y", "dfdx", "dfdu", "dgdx", "dgdu", "status",
         "evaluate", "jacobian", "x_start", "x_nominal", "u_start", "p_start",
         "x_names", "u_names", "y_names", "p_names", "fmugen_model",
         "x_min", "x_max", "u_min", "u_max", "y_min", "y_max", "p_min", "p_max", "rt_start"}
RESERVED_NAMES = frozenset(_C_KEYWORDS | _C_MATH | _ARGS)
#: user-derived names that get :data:`SAFE_PREFIX` in front (``asm`` ->
#: ``v_asm``): every keyword and predefined macro above
PREFIXED_NAMES = frozenset(_C_KEYWORDS | _C_ALL_KEYWORDS | _PREDEFINED_MACROS)
#: prefixes of names the runtime header, the FMI headers and the C library
#: (math.h, stddef.h, string.h) may define as macros or identifiers: a model
#: variable called ``FMUGEN_OK`` or ``M_PI2`` would otherwise be expanded by
#: the preprocessor.  Such names get :data:`SAFE_PREFIX` in front.
RESERVED_PREFIXES = ("FMUGEN", "fmugen", "fmi2", "FMI2", "FP_", "M_", "HUGE_VAL", "MATH_ERR",
                     "math_err", "FLT_", "DBL_", "INFINITY", "NAN")
SAFE_PREFIX = "v_"


# --------------------------------------------------------------------------
# operation counts
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class FunctionOps:
    """Operation count of one generated function.

    ``expressions`` is the straight-line code; ``linear_solve`` the Cholesky
    solves (:func:`cholesky_solve_ops`), counted apart because they are loops
    in the runtime, not generated code.
    """

    expressions: OpCount = OpCount()
    linear_solve: OpCount = OpCount()
    #: the looped chain dynamics of the runtime (:func:`fmugen.codegen.chain.chain_ops`)
    loops: OpCount = OpCount()

    @property
    def total(self) -> OpCount:
        return self.expressions + self.linear_solve + self.loops

    @property
    def mul(self) -> int:
        return self.total.mul

    @property
    def add(self) -> int:
        return self.total.add

    def __str__(self) -> str:
        s = str(self.expressions)
        if self.linear_solve != OpCount():
            s += f"; linear solve: {self.linear_solve}"
        if self.loops != OpCount():
            s += f"; runtime loops: {self.loops}"
        return s


def cholesky_solve_ops(n: int, k: int) -> OpCount:
    """Exact counts of ``fmugen_spd_solve(n, k, A, B)`` (c_runtime/linalg.c).

    Factorisation A = L L^T: sum_j j (n - j) = (n^3 - n)/6 multiplications and
    as many subtractions, n(n-1)/2 divisions, n square roots.  Each of the k
    right-hand sides: forward and back substitution, n(n-1) multiplications,
    n(n-1) subtractions, 2n divisions.
    """
    chol = (n ** 3 - n) // 6
    return OpCount(
        mul=chol + k * n * (n - 1),
        add=chol + k * n * (n - 1),
        div=n * (n - 1) // 2 + 2 * n * k,
        calls=(("sqrt", n),) if n else (),
    )


_TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+\.\d*|\.\d+|\d+)(?:[eE][+-]?\d+)?)|(?P<id>[A-Za-z_]\w*)|(?P<op>\S))"
)


def count_c_expression(code: str) -> OpCount:
    """Count the operations of one printed C expression (rules in :class:`OpCount`)."""
    mul = add = div = 0
    calls: Counter = Counter()
    prev = None  # kind of previous token: "val" (operand or ')') or "op"
    pos = 0
    toks = []
    while pos < len(code):
        m = _TOKEN.match(code, pos)
        if m is None or m.end() == pos:
            break
        pos = m.end()
        if m.group("num"):
            toks.append(("num", m.group("num")))
        elif m.group("id"):
            toks.append(("id", m.group("id")))
        else:
            toks.append(("op", m.group("op")))
    for i, (kind, text) in enumerate(toks):
        if kind == "id":
            if i + 1 < len(toks) and toks[i + 1] == ("op", "("):
                calls[text] += 1
                prev = "op"
            else:
                prev = "val"
        elif kind == "num":
            prev = "val"
        else:
            if text in "+-":
                if prev == "val":
                    add += 1
            elif text == "*":
                mul += 1
            elif text == "/":
                div += 1
            prev = "val" if text in ")]" else "op"
    return OpCount(mul, add, div, tuple(sorted(calls.items())))


# --------------------------------------------------------------------------
# printing
# --------------------------------------------------------------------------
class _Printer(C99CodePrinter):
    """C99 printer with named symbols, double literals and cheap powers."""

    def __init__(self, names: dict, cse=None):
        # order "none": the terms of a sum in sympy's canonical argument order
        # (deterministic, and no sorting at print time)
        super().__init__({"strict": False, "order": "none"})
        self._names = names
        self._cse = cse  # a fmugen.codegen.cse.CSE: its temporaries are printed by name
        self._root = None
        self._not_supported = set()

    def print_ref(self, ref) -> str:
        """C of a reduced expression (:class:`~fmugen.codegen.cse.Ref`) or of a symbol."""
        if isinstance(ref, sp.Symbol):
            return self._print_Symbol(ref)
        self._root = ref.expr
        self._not_supported = set()
        code = self._print(ref.expr)
        if self._not_supported:
            raise ValueError(f"cannot print {', '.join(sorted(map(str, self._not_supported)))} as C")
        return code

    def _temp(self, expr):
        """The temporary that stands for ``expr`` here, or None."""
        if self._cse is None or expr is self._root or expr.is_Atom:
            return None
        return self._cse.named.get(expr)

    def _print(self, expr, **kwargs):
        t = self._temp(expr) if isinstance(expr, sp.Basic) else None
        if t is not None:
            return self._names[t]
        return super()._print(expr, **kwargs)

    def _print_Add(self, expr, order=None):
        prec = 40  # sympy's precedence of Add
        parts = []
        for term in expr.args:
            named = self._temp(term) is not None
            t = self._print(term)
            if t.startswith("-") and not named and not term.is_Add:
                sign, t = "-", t[1:]
            else:
                sign = "+"
            if not named and (term.is_Add or precedence(term) < prec):
                t = f"({t})"
            parts += [sign, t]
        sign = parts.pop(0)
        return ("" if sign == "+" else sign) + " ".join(parts)

    def _print_Symbol(self, expr):
        try:
            return self._names[expr]
        except KeyError:
            raise ValueError(f"symbol {expr} has no C name (not a state, input, parameter, "
                             f"time or program symbol)") from None

    def _print_Integer(self, expr):
        return f"{int(expr)}.0"

    def _print_Rational(self, expr):
        return repr(float(expr))

    def _print_Float(self, expr):
        return repr(float(expr))

    def _print_NumberSymbol(self, expr):
        # pi, E, ... as double literals: strict C99 <math.h> has no M_PI
        return repr(float(expr))

    def parenthesize(self, item, level, strict=False):
        if isinstance(item, sp.Basic) and self._temp(item) is not None:
            return self._print(item)  # a name
        # A small integer power is printed as a product or a quotient, so it
        # binds like a Mul, not like a power: a/L**2 must become a/(L*L).
        if isinstance(item, sp.Pow) and item.exp.is_Integer and item.exp != 1 \
                and abs(int(item.exp)) <= MAX_PRODUCT_POWER:
            text = self._print(item)
            return f"({text})" if level >= 50 else text
        if isinstance(item, (sp.Rational, sp.Float)) and item > 0:
            return self._print(item)  # a literal needs no parentheses
        return super().parenthesize(item, level, strict)

    def _print_Mul(self, expr):
        # sign, then numerator factors, then one '/' for all denominator
        # factors (so a/(b*c) costs one division, not two)
        c, rest = expr.as_coeff_Mul()
        sign = ""
        if c < 0:
            sign, c = "-", -c
        split = self._cse.factors.get(expr) if self._cse is not None else None
        # factors in sympy's canonical argument order, or the CSE's grouping of them
        # (which holds the size of the coefficient)
        if split is not None:
            factors = list(split)
        else:
            factors = ([] if c == 1 else [c]) + list(sp.Mul.make_args(rest))
        factors = [f for f in factors if f != 1]
        num, den = [], []
        for f in factors:
            if f.is_Pow and f.exp.is_Rational and f.exp.is_negative and self._temp(f) is None:
                den.append(f.base if f.exp == -1 else sp.Pow(f.base, -f.exp, evaluate=False))
            else:
                num.append(f)
        mul = 50  # sympy's precedence of Mul

        def factor(f):
            if f.is_Pow and f.exp.is_Integer and 1 < int(f.exp) <= MAX_PRODUCT_POWER:
                return self._print(f)  # a product inside a product needs no parentheses
            return self.parenthesize(f, mul)

        text = "*".join(factor(f) for f in num) if num else "1.0"
        if den:
            ds = [self.parenthesize(f, mul) for f in den]
            text += "/" + (ds[0] if len(ds) == 1 else "(" + "*".join(ds) + ")")
        return sign + text

    def _print_Pow(self, expr):
        base, e = expr.base, expr.exp
        b = self.parenthesize(base, 50)  # above Mul precedence: parenthesise sums
        if e.is_Integer:
            n = int(e)
            if 1 <= n <= MAX_PRODUCT_POWER:
                return "*".join([b] * n)
            if -MAX_PRODUCT_POWER <= n <= -1:
                prod = "*".join([b] * -n)
                return f"1.0/{prod}" if n == -1 else f"1.0/({prod})"
        if e == sp.Rational(1, 2) or (e.is_Float and float(e) == 0.5):
            return f"sqrt({self._print(base)})"
        if e == -sp.Rational(1, 2) or (e.is_Float and float(e) == -0.5):
            return f"1.0/sqrt({self._print(base)})"
        return f"pow({self._print(base)}, {self._print(e)})"


def c_identifier(name: str) -> str:
    """A valid C identifier from an arbitrary name (``"PUMA 560"`` -> ``PUMA_560``)."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", name.strip())
    s = re.sub(r"_+", "_", s).strip("_") or "model"
    if s[0].isdigit():
        s = "m_" + s
    # (the model identifier reaches C only inside a string literal and as a file name: a macro or GNU
    # keyword name is harmless there, unlike a variable's)
    if s in _C_KEYWORDS or keyword.iskeyword(s):
        s += "_"
    return s


def _reserved(name: str) -> bool:
    """True for names in the runtime's or the C library's name space
    (:data:`RESERVED_PREFIXES`); single reserved names are kept apart by
    :data:`RESERVED_NAMES` in :class:`_Names`."""
    return name.startswith("_") or name.startswith(RESERVED_PREFIXES) or name in PREFIXED_NAMES


def _number_or_none(e) -> Optional[float]:
    """The value of a reduced expression (sympy or a CSE Ref) that is a number, else None."""
    x = getattr(e, "expr", e)
    return float(x) if getattr(x, "is_Number", False) else None


_UNROLLED_STATEMENT = re.compile(r"^\s*const double t\d+ = (.*);$", re.M)


def _function_ops_of(source: str) -> OpCount:
    """The operations of one unrolled step's C (its statements; a sine-cosine pair counts as sin and cos)."""
    total = OpCount()
    for m in _UNROLLED_STATEMENT.finditer(source):
        total = total + count_c_expression(m.group(1))
    pairs = source.count("FMUGEN_UNROLLED_SINCOS(") - 1  # the macro's own definition
    if pairs > 0:
        total = total + OpCount(calls=(("cos", pairs), ("sin", pairs)))
    return total


class _Names:
    """Unique C names for sympy symbols."""

    def __init__(self):
        self.map: dict = {}
        self.used: set = set(RESERVED_NAMES)
        self.support: dict = {}  # file-scope functions the bodies call: name -> C source (unrolled dynamics)

    def add(self, sym: sp.Symbol, preferred: Optional[str] = None) -> str:
        if sym in self.map:
            return self.map[sym]
        # a whitelist: ASCII letters, digits and '_' only; bounded length
        base = preferred or re.sub(r"[^A-Za-z0-9_]", "_", sym.name)[:MAX_C_NAME] or "v"
        # leading underscores are reserved in C (program symbols use them to
        # stay apart from parameter names; uniqueness is kept below)
        base = base.lstrip("_") or "v"
        if base[0].isdigit() or _reserved(base):
            base = SAFE_PREFIX + base
        name, k = base, 2
        while name in self.used:
            name = f"{base}_{k}"
            k += 1
        self.used.add(name)
        self.map[sym] = name
        return name


# --------------------------------------------------------------------------
# lowering: program + results -> C statements
# --------------------------------------------------------------------------
@dataclass
class Sink:
    """A result stored into an output array: ``array[index] = expr``."""

    array: str
    index: int
    expr: sp.Expr


@dataclass
class SinkGroup:
    """Results stored together, under ``if (guard)`` when guard is given.

    With ``own_block`` the statements needed only by this group are emitted
    inside the guarded block, so their work is skipped when the guard fails.
    ``preamble`` lines open the guarded block (e.g. a memset of zeros).
    """

    guard: Optional[str]
    sinks: list
    own_block: bool = False
    preamble: tuple = ()


@dataclass
class Body:
    """Emitted C statements of one function body and what they cost."""

    lines: list = field(default_factory=list)
    ops: OpCount = OpCount()
    solve_ops: OpCount = OpCount()
    loop_ops: OpCount = OpCount()
    reads: set = field(default_factory=set)  # known symbols read (x, u, p, t)
    n_solves: int = 0
    n_chains: int = 0  # calls of the looped chain dynamics (c_runtime/chain_dynamics.c)
    cleanup: list = field(default_factory=list)  # lines before the final return (free())

    @property
    def function_ops(self) -> FunctionOps:
        return FunctionOps(self.ops, self.solve_ops, self.loop_ops)


_ELEMENT = re.compile(r"([A-Za-z_]\w*)\[(\d+)\]")


def _block_copies(copies: list, ind: str, shortest: int = 4) -> list:
    """``array[index] = code;`` statements, with runs of plain element copies
    (``dfdx[k] = w[j]``, ``dfdx[k+1] = w[j+1]``, ...) of at least ``shortest``
    entries written as one memcpy: a looped model's Jacobian is O(n^2) such
    copies, which would otherwise be the largest part of its model.c."""
    out, k = [], 0
    while k < len(copies):
        arr, idx, code = copies[k]
        m = _ELEMENT.fullmatch(code)
        run = 1
        if m:
            src, j = m.group(1), int(m.group(2))
            while k + run < len(copies):
                a2, i2, c2 = copies[k + run]
                if a2 != arr or i2 != idx + run or c2 != f"{src}[{j + run}]":
                    break
                run += 1
        if run >= shortest:
            out.append(f"{ind}memcpy({arr} + {idx}, {m.group(1)} + {int(m.group(2))}, {run} * sizeof(double));")
        else:
            run = 1
            out.append(f"{ind}{arr}[{idx}] = {code};")
        k += run
    return out


def _cse_prefix(pool_symbols: Iterable[sp.Symbol], names: "_Names", prefix: str) -> str:
    """A prefix whose numbered symbols collide with no symbol of the pool.

    (sympy identifies symbols by name and assumptions, so a CSE temporary
    ``c0`` would silently *be* a program symbol ``c0``.)
    """
    taken = set(names.used) | {s.name for s in pool_symbols}
    while any(re.fullmatch(re.escape(prefix) + r"\d+", t) for t in taken):
        prefix += "c"
    return prefix


def lower(
    steps: Sequence,
    groups: Sequence[SinkGroup],
    names: "_Names",
    known: set,
    indent: str = "    ",
) -> Body:
    """C statements for a straight-line program followed by stores of results.

    One joint CSE runs over every expression (step right-hand sides, the
    lower triangles of the SPD matrices, right-hand sides of solves, results).
    Statements follow program order; each CSE temporary is emitted just
    before its first use; steps no result needs are dropped.  ``known`` are
    the symbols readable without a statement (states, inputs, parameters,
    time).
    """
    # 1. the pool of expressions, in order
    pool: list = []
    layout: list = []  # ("assign", step, idx) | ("solve", step, [(i, j, idx)], [(i, j, idx)])
    for st in steps:
        if isinstance(st, Assign):
            layout.append(("assign", st, len(pool)))
            pool.append(sp.sympify(st.expr))
        elif isinstance(st, ChainDynamics):  # a SolveSPD too: test it first
            b_idx = list(range(len(pool), len(pool) + len(st.B)))
            pool.extend(sp.sympify(e) for e in st.B)
            layout.append(("chain", st, [], [(i, 0, idx) for i, idx in enumerate(b_idx)]))
        elif isinstance(st, SolveSPD):
            n, k = st.B.shape
            if st.A.shape != (n, n) or st.X.shape != (n, k):
                raise ValueError(f"SolveSPD with A {st.A.shape}, B {st.B.shape}, X {st.X.shape}")
            a_idx, b_idx = [], []
            for i in range(n):
                for j in range(i + 1):
                    a_idx.append((i, j, len(pool)))
                    pool.append(sp.sympify(st.A[i, j]))
            for i in range(n):
                for j in range(k):
                    b_idx.append((i, j, len(pool)))
                    pool.append(sp.sympify(st.B[i, j]))
            layout.append(("solve", st, a_idx, b_idx))
        else:
            raise TypeError(f"unknown program step {type(st).__name__}")
    group_start = []
    for g in groups:
        group_start.append(len(pool))
        pool.extend(sp.sympify(s.expr) for s in g.sinks)

    cse = common_subexpressions(
        pool, lambda pool_symbols: sp.numbered_symbols(_cse_prefix(pool_symbols, names, "c"), real=True),
        MAX_PRODUCT_POWER)
    temps, reduced = dict(cse.temps), cse.reduced

    # 2. liveness, backwards from each group's results
    def closure(syms: Iterable) -> set:
        out, stack = set(), list(syms)
        while stack:
            s = stack.pop()
            if s not in out:
                out.add(s)
                if s in temps:
                    stack.extend(temps[s].free_symbols)
        return out

    def live_steps(need: set) -> tuple:
        need = closure(need)
        live = set()
        for li in range(len(layout) - 1, -1, -1):
            ent = layout[li]
            if ent[0] == "assign":
                if ent[1].symbol in need:
                    live.add(li)
                    need |= closure(reduced[ent[2]].free_symbols)
            elif any(xs in need for xs in ent[1].X):
                live.add(li)
                for _, _, idx in ent[2] + ent[3]:
                    need |= closure(reduced[idx].free_symbols)
        return live, need

    lives, all_need = [], set()
    for g, start in zip(groups, group_start):
        need = set()
        for i in range(len(g.sinks)):
            need |= reduced[start + i].free_symbols
        live, need = live_steps(need)
        lives.append(live)
        all_need |= need

    # 3. emission
    printer = _Printer(names.map, cse)
    body = Body()
    defined: set = set(known)
    cost = [OpCount(), OpCount()]  # expressions, linear solves

    def code_of(e) -> str:
        code = printer.print_ref(e)
        cost[0] = cost[0] + count_c_expression(code)
        return code

    def emit_temps_for(e, out, ind):
        for s in sorted(e.free_symbols, key=lambda z: z.name):
            if s in temps and s not in defined:
                emit_temps_for(temps[s], out, ind)
                out.append(f"{ind}const double {names.add(s)} = {code_of(temps[s])};")
                defined.add(s)

    def emit_expr(e, out, ind) -> str:
        emit_temps_for(e, out, ind)
        return code_of(e)

    def emit_step(ent, out, ind):
        if ent[0] == "assign":
            st = ent[1]
            code = emit_expr(reduced[ent[2]], out, ind)
            out.append(f"{ind}const double {names.add(st.symbol)} = {code};")
            defined.add(st.symbol)
            return
        st = ent[1]
        if ent[0] == "chain":
            codes = [emit_expr(reduced[idx], out, ind) for _, _, idx in ent[3]]
            consts = [reduced[idx] for _, _, idx in ent[3][3 * st.n:]]
            numbers = [_number_or_none(e) for e in consts]
            unrolled = unrolled_step_lines(st, body.n_solves, numbers, codes[:3 * st.n], ind) \
                if unrolled_choice(st, numbers) else None  # the robot's numbers are known: code of its own
            if unrolled is not None:
                lines, arr, fn, source = unrolled
                names.support[fn] = source
                offset, free_line = 0, None
                body.n_solves += 1
                body.ops = body.ops + _function_ops_of(source)
            else:
                lines, arr, offset, free_line = chain_call_lines(st, body.n_solves, codes, ind)
                body.n_solves += 1
                body.n_chains += 1
                body.loop_ops = body.loop_ops + chain_ops(st.n, st.kind, len(st.external))
            out.extend(lines)
            # the results stay in the call's array: X[i] prints as arr[offset + i] (no copies;
            # stores of consecutive entries become memcpy, see _block_copies)
            for i, xs in enumerate(st.X):
                names.map[xs] = f"{arr}[{offset + i}]"
                defined.add(xs)
            if free_line:
                body.cleanup.append(free_line)
            return
        n, k = st.B.shape
        a, b = f"spd_A{body.n_solves}", f"spd_B{body.n_solves}"
        body.n_solves += 1
        fills = []
        for i, j, idx in ent[2]:
            fills.append(f"{ind}{a}[{i * n + j}] = {emit_expr(reduced[idx], out, ind)};")
        for i, j, idx in ent[3]:
            fills.append(f"{ind}{b}[{i * k + j}] = {emit_expr(reduced[idx], out, ind)};")
        out.append(f"{ind}/* X = A^-1 B by Cholesky: A {n}x{n} symmetric positive definite "
                   f"(lower triangle filled), B {n}x{k} */")
        out.append(f"{ind}double {a}[{n * n}], {b}[{n * k}];")
        out.extend(fills)
        out.append(f"{ind}status = fmugen_spd_solve({n}, {k}, {a}, {b});")
        out.append(f"{ind}if (status != FMUGEN_OK) return status;")
        cost[1] = cost[1] + cholesky_solve_ops(n, k)
        for i in range(n):
            for j in range(k):
                xs = st.X[i, j]
                if xs in all_need:
                    out.append(f"{ind}const double {names.add(xs)} = {b}[{i * k + j}];")
                    defined.add(xs)

    emitted: set = set()
    for g, start, live in zip(groups, group_start, lives):
        inner = indent * 2 if g.guard else indent
        work = [] if (g.own_block and g.guard) else body.lines
        work_ind = inner if work is not body.lines else indent
        for li in sorted(live):
            if li not in emitted:
                emitted.add(li)
                emit_step(layout[li], work, work_ind)
        copies = []
        for i, s in enumerate(g.sinks):
            code = emit_expr(reduced[start + i], work, work_ind)
            copies.append((s.array, s.index, code))
        stores = _block_copies(copies, inner)
        if g.guard:
            if not (stores or g.preamble or work is not body.lines):
                continue
            body.lines.append(f"{indent}if ({g.guard}) {{")
            body.lines.extend(f"{inner}{p}" for p in g.preamble)
            if work is not body.lines:
                body.lines.extend(work)
            body.lines.extend(stores)
            body.lines.append(f"{indent}}}")
        else:
            body.lines.extend(f"{indent}{p}" for p in g.preamble)
            body.lines.extend(stores)
    body.ops, body.solve_ops = cost
    body.reads = {s for s in all_need if s in known}
    return body


# --------------------------------------------------------------------------
# the model file
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class GeneratedC:
    """``source`` of model.c and the operation count of each function."""

    source: str
    op_counts: dict  # "evaluate" / "jacobian" -> FunctionOps
    model_identifier: str
    guid: str


def deterministic_guid(*texts: str) -> str:
    """A GUID that depends only on the given texts (uuid5), in FMI's braces."""
    return "{" + str(uuid.uuid5(GUID_NAMESPACE, "\n".join(texts))) + "}"


GUID_PLACEHOLDER = "@FMUGEN_GUID@"


def _c_string(s: str) -> str:
    """A C string literal of ``s`` in printable ASCII only.

    ``"`` and ``\\`` are escaped, ``?`` is written ``\\?`` (so ``??/`` can never
    form a trigraph), and every other character outside 0x20..0x7e is written
    as octal escapes of its UTF-8 bytes (three digits each: an octal escape
    cannot swallow the character after it, a hex escape could).
    """
    out = []
    for ch in s:
        if ch in ('"', "\\", "?"):
            out.append("\\" + ch)
        elif " " <= ch <= "~":
            out.append(ch)
        else:
            out.extend(f"\\{b:03o}" for b in ch.encode("utf-8", "surrogatepass"))
    return '"' + "".join(out) + '"'


def _c_double(v: float) -> str:
    v = float(v)
    if v != v or v in (float("inf"), float("-inf")):
        raise ValueError(f"non-finite start/nominal value {v}")
    return repr(v)


def _comment_safe(s) -> str:
    """``s`` reduced to text that cannot leave (or disturb) a C block comment.

    The C preprocessor replaces trigraphs and splices backslash-newlines
    *before* it looks for the end of a comment, so ``*\\`` + newline + ``/``
    or ``*??/`` + newline + ``/`` would close the comment and let the rest of
    a description be compiled.  Hence: every character outside printable
    ASCII (newlines, tabs, control and non-ASCII characters) becomes ``?``
    -- except that no two ``?`` may touch (``?_?``), backslashes become
    ``|``, and ``*/`` and ``/*`` (-Wcomment) are split with a space.
    """
    s = "".join(ch if " " <= ch <= "~" else "?" for ch in str(s))
    s = s.replace("\\", "|")
    s = re.sub(r"\?(?=\?)", "?_", s)
    while "*/" in s or "/*" in s:
        s = s.replace("*/", "* /").replace("/*", "/ *")
    return s


def _time_symbol(model: SymbolicModel, known: set) -> Optional[sp.Symbol]:
    """The symbol standing for time: any free symbol named ``t`` that is not
    a state, input, parameter or program symbol.  Any other unknown symbol
    is an error."""
    assigned = model.program.assigned_symbols()
    if model.jacobian is not None:
        assigned |= model.jacobian.assigned_symbols()
    free: set = set()
    progs = [model.program] + ([model.jacobian] if model.jacobian is not None else [])
    for prog in progs:
        for st in prog.steps:
            if isinstance(st, Assign):
                free |= sp.sympify(st.expr).free_symbols
            else:
                free |= st.A.free_symbols | st.B.free_symbols
    for e in list(model.derivatives) + list(model.output_exprs):
        free |= sp.sympify(e).free_symbols
    if model.events is not None:
        for e in model.events.expressions():
            free |= e.free_symbols
        free |= {t for c in model.events.clauses for t, _ in c.assign}
    for m in (model.dfdx, model.dfdu, model.dgdx, model.dgdu):
        if m is not None:
            free |= m.free_symbols
    unknown = free - known - assigned
    time = [s for s in unknown if s.name == "t"]
    other = sorted(s.name for s in unknown if s.name != "t")
    if other:
        raise ValueError(f"model {model.name!r}: symbols {', '.join(other)} are neither states, "
                         f"inputs, parameters, time t, nor assigned by the program")
    if len(time) > 1:
        raise ValueError(f"model {model.name!r}: more than one symbol named t")
    return time[0] if time else None


def _check_model(model: SymbolicModel) -> None:
    if len(model.derivatives) != model.nx:
        raise ValueError(f"model {model.name!r}: {len(model.derivatives)} derivatives for {model.nx} states")
    if len(model.output_exprs) != model.ny:
        raise ValueError(f"model {model.name!r}: {len(model.output_exprs)} output expressions for "
                         f"{model.ny} outputs")
    syms = [v.symbol for v in model.states + model.inputs + model.parameters]
    dup = sorted({s.name for s in syms if syms.count(s) > 1})
    if dup:
        raise ValueError(f"model {model.name!r}: symbols used by more than one variable: {', '.join(dup)}")
    if model.jacobian is not None:
        shapes = {"dfdx": (model.nx, model.nx), "dfdu": (model.nx, model.nu),
                  "dgdx": (model.ny, model.nx), "dgdu": (model.ny, model.nu)}
        for attr, shape in shapes.items():
            m = getattr(model, attr)
            if m is None:
                raise ValueError(f"model {model.name!r}: has a jacobian program but {attr} is missing")
            if tuple(m.shape) != shape:
                raise ValueError(f"model {model.name!r}: {attr} is {m.shape[0]}x{m.shape[1]}, "
                                 f"expected {shape[0]}x{shape[1]}")


def _declare_reads(body: Body, names: "_Names", model: SymbolicModel, time) -> list:
    """``const double q_1 = x[0];`` for every state/input/parameter read."""
    lines = []
    # a hybrid model's discrete states follow the parameters in p (c_runtime/fmugen_model.h)
    for arr, vars_ in (("x", model.states), ("u", model.inputs), ("p", model.parameters + _discrete(model))):
        for i, v in enumerate(vars_):
            if v.symbol in body.reads:
                lines.append(f"    const double {names.map[v.symbol]} = {arr}[{i}]; "
                             f"/* {_comment_safe(v.name)} */")
    if time is not None and time in body.reads:
        lines.append(f"    const double {names.map[time]} = t;")
    return lines


def _function(signature: str, args: Sequence[str], body: Body, reads: list) -> str:
    out = [f"static int {signature}", "{"]
    out.append("    " + " ".join(f"(void){a};" for a in args))
    if body.n_solves:
        out.append("    int status;")
    out.extend(reads)
    out.extend(body.lines)
    out.extend(body.cleanup)
    out.append("    return FMUGEN_OK;")
    out.append("}")
    return "\n".join(out)


def _discrete(model: SymbolicModel) -> tuple:
    """The discrete states of a hybrid model (none for a smooth one)."""
    return tuple(model.events.discrete) if model.events is not None else ()


def _event_functions(model: SymbolicModel, names: "_Names", known: set, time) -> tuple:
    """(C source of ``indicators`` and ``update``, declarations, struct fields) of a hybrid model.

    ``update`` writes guard[k] = 1 when clause k fires and value[a] for every assignment a, all from the
    values before the event; the tables ``assign_clause``/``assign_target`` tell the runtime where each
    value goes (target k < nd: discrete state k; nd + j: state j)."""
    ev = model.events
    disc = _discrete(model)
    nd = len(disc)
    d_index = {v.symbol: k for k, v in enumerate(disc)}
    x_index = {v.symbol: j for j, v in enumerate(model.states)}
    parts, decls, fields = [], [], []
    nz = len(ev.indicators)
    if nz:
        zb = lower(model.program.steps,
                   [SinkGroup(None, [Sink("z", i, sp.sympify(e)) for i, (_, e) in enumerate(ev.indicators)])],
                   names, known)
        parts.append("/* event indicators: a state event when z[i] changes its domain z > 0 <-> z <= 0 */\n"
                     + _function("indicators(const double *p, double t, const double *x, const double *u, double *z)",
                                 ["p", "t", "x", "u", "z"], zb, _declare_reads(zb, names, model, time)))
        decls.append(_array("char *const", "z_names", [_c_string(n) for n, _ in ev.indicators]))
        fields += [f"    .nz = {nz}, .z_names = z_names, .indicators = indicators,"]
    clauses = list(ev.clauses)
    if clauses:
        sinks, a_clause, a_target = [], [], []
        for k, c in enumerate(clauses):
            sinks.append(Sink("guard", k, sp.Piecewise((sp.Float(1.0), c.guard), (sp.Float(0.0), True))))
        a = 0
        for k, c in enumerate(clauses):
            for target, e in c.assign:
                if target in d_index:
                    a_target.append(d_index[target])
                elif target in x_index:
                    a_target.append(nd + x_index[target])
                else:
                    raise ValueError(f"model {model.name!r}: event clause {c.name or k + 1} assigns {target}, "
                                     f"neither a discrete state nor a state")
                a_clause.append(k)
                sinks.append(Sink("value", a, sp.sympify(e)))
                a += 1
        ub = lower(model.program.steps, [SinkGroup(None, sinks)], names, known)
        parts.append("/* the event clauses: guard[k] = 1 when clause k fires, value[a] the value of assignment a\n"
                     " * (from the values before the event; the runtime applies them) */\n"
                     + _function("update(const double *p, double t, const double *x, const double *u, "
                                 "double *guard, double *value)",
                                 ["p", "t", "x", "u", "guard", "value"], ub, _declare_reads(ub, names, model, time)))
        decls += [_array("int", "assign_clause", [str(i) for i in a_clause]),
                  _array("int", "assign_target", [str(i) for i in a_target])]
        fields += [f"    .ng = {len(clauses)}, .na = {a}, .update = update,",
                   f"    .assign_clause = {'assign_clause' if a else 'NULL'}, "
                   f".assign_target = {'assign_target' if a else 'NULL'},"]
    if ev.clocks:
        cb = lower([], [SinkGroup(None, [Sink("period", k, sp.sympify(c.period)) for k, c in enumerate(ev.clocks)]
                                  + [Sink("offset", k, sp.sympify(c.offset)) for k, c in enumerate(ev.clocks)])],
                   names, known)
        parts.append("/* sample clocks: ticks at offset[k] + j period[k] (time events) */\n"
                     + _function("clocks(const double *p, double *period, double *offset)", ["p", "period", "offset"],
                                 cb, _declare_reads(cb, names, model, None)))
        ticks = []
        for c in ev.clocks:
            if c.tick.symbol not in d_index:
                raise ValueError(f"model {model.name!r}: a clock's tick flag {c.tick.name!r} is not a discrete state")
            ticks.append(str(d_index[c.tick.symbol]))
        decls.append(_array("int", "clock_tick", ticks))
        fields += [f"    .ns = {len(ev.clocks)}, .clocks = clocks, .clock_tick = clock_tick,"]
    if nd:
        decls += [_array("double", "d_start", [_c_double(v.start) for v in disc]),
                  _array("char *const", "d_names", [_c_string(v.name) for v in disc])]
        fields += [f"    .nd = {nd}, .d_start = d_start, .d_names = d_names,"]
    return parts, decls, fields


def _new_names(model: SymbolicModel, time) -> _Names:
    names = _Names()
    for v in model.states + model.inputs + model.parameters + _discrete(model):
        names.add(v.symbol)
    if time is not None:
        # time is read as the argument t; its local copy needs another name
        names.add(time, "time" if time.name == "t" else None)
    return names


def _bound(v, side: float) -> str:
    """A validity-range bound as C: the number, or -HUGE_VAL/HUGE_VAL when open."""
    if v is None or math.isinf(float(v)):
        return ("-HUGE_VAL" if side < 0 else "HUGE_VAL") if v is None else (
            "-HUGE_VAL" if float(v) < 0 else "HUGE_VAL")
    return _c_double(v)


def _range_arrays(prefix: str, vars_) -> tuple:
    """``(declarations, min pointer, max pointer)`` of the validity ranges of
    ``vars_`` (Variable.min/max); NULL pointers when none has a range."""
    if not any(v.min is not None or v.max is not None for v in vars_):
        return [], "NULL", "NULL"
    for v in vars_:
        if v.min is not None and v.max is not None and not float(v.min) <= float(v.max):
            raise ValueError(f"variable {v.name!r}: validity range min = {v.min!r} > max = {v.max!r}")
    lo = _array("double", f"{prefix}_min", [_bound(v.min, -1) for v in vars_])
    hi = _array("double", f"{prefix}_max", [_bound(v.max, 1) for v in vars_])
    return [lo, hi], f"{prefix}_min", f"{prefix}_max"


def _array(ctype: str, name: str, values: list) -> str:
    if not values:
        return ""
    return f"static const {ctype} {name}[{len(values)}] = {{{', '.join(values)}}};"


def _variable_table(model: SymbolicModel) -> list:
    rows = []
    nx, nu, ny = model.nx, model.nu, model.ny
    vr = 0

    def row(kind, i, v: Variable, vref):
        unit = _comment_safe(v.unit or "-")
        desc = _comment_safe(v.description)
        return f" *   {vref:4d}  {kind:<10s} {i:3d}  {_comment_safe(v.name):<22s} {unit:<10s} {desc}"

    for i, v in enumerate(model.states):
        rows.append(row("state", i, v, vr + i))
    vr += 2 * nx
    for i, v in enumerate(model.inputs):
        rows.append(row("input", i, v, vr + i))
    vr += nu
    for i, v in enumerate(model.outputs):
        rows.append(row("output", i, v, vr + i))
    vr += ny
    for i, v in enumerate(model.parameters):
        rows.append(row("parameter", i, v, vr + i))
    return rows


#: the runtime's Real parameters in FMUGEN_RT_* order (c_runtime/fmugen_model.h)
RT_START_ORDER = ("solver.rtol", "solver.atol", "solver.max_step", "solver.fixed_step")


def _runtime_start_fields(runtime_start) -> list:
    if not runtime_start:
        return []
    return ["    .rt_start = rt_start,", f"    .solver_start = {int(runtime_start['solver.method'])},"]


def generate_c(
    model: SymbolicModel,
    model_identifier: Optional[str] = None,
    guid: Optional[str] = None,
    runtime_start: Optional[dict] = None,
) -> GeneratedC:
    """Print ``model`` as the ``model.c`` of the fmugen runtime.

    ``model_identifier`` defaults to :func:`c_identifier` of the model name;
    ``guid`` to a hash of the generated text (identical models give identical
    files).  Pass :data:`GUID_PLACEHOLDER` to get a source to hash together
    with the modelDescription.xml, then substitute (what the FMU builder does).
    ``runtime_start``: start values of the runtime's own parameters
    (``solver.method``, ``solver.rtol``, ...) that differ from its defaults
    (:func:`fmugen.codegen.runtime_parameters.runtime_starts` checks and completes them).
    """
    _check_model(model)
    ident = model_identifier or c_identifier(model.name)
    if c_identifier(ident) != ident:
        raise ValueError(f"model identifier {ident!r} is not a valid C identifier")
    origin = f" (from {model.provenance})" if model.provenance else ""
    for v in model.states:
        if v.start is None:
            raise ValueError(f"model {model.name!r}{origin}: state {v.name!r} has no start value")
    for kind, vars_ in (("state", model.states), ("input", model.inputs), ("parameter", model.parameters)):
        for v in vars_:
            for what in ("start", "nominal", "min", "max"):
                val = getattr(v, what)
                if val is None or (what in ("min", "max") and math.isinf(float(val))):
                    continue  # an infinite bound is an open side
                if not math.isfinite(float(val)):
                    raise ValueError(f"model {model.name!r}{origin}: {kind} {v.name!r}: non-finite {what} value "
                                     f"{float(val)!r}")
    for v in _discrete(model):
        if v.start is None or not math.isfinite(float(v.start)):
            raise ValueError(f"model {model.name!r}{origin}: discrete state {v.name!r} needs a finite start value")
    known = {v.symbol for v in model.states + model.inputs + model.parameters + _discrete(model)}
    time = _time_symbol(model, known)
    if time is not None:
        known.add(time)
    names = _new_names(model, time)
    nx, nu, ny = model.nx, model.nu, model.ny

    # evaluate(): derivatives, then the output-only work under if (y)
    ev = lower(
        model.program.steps,
        [SinkGroup("dx != NULL", [Sink("dx", i, e) for i, e in enumerate(model.derivatives)]),
         SinkGroup("y != NULL", [Sink("y", i, e) for i, e in enumerate(model.output_exprs)],
                   own_block=True)],
        names, known)
    evaluate = _function(
        "evaluate(const double *p, double t, const double *x, const double *u, double *dx, double *y)",
        ["p", "t", "x", "u", "dx", "y"], ev, _declare_reads(ev, names, model, time))
    op_counts = {"evaluate": ev.function_ops}

    jac_src = ""
    has_jac = model.jacobian is not None
    if has_jac:
        groups = []
        for arr, m in (("dfdx", model.dfdx), ("dfdu", model.dfdu),
                       ("dgdx", model.dgdx), ("dgdu", model.dgdu)):
            rows, cols = m.shape
            if rows * cols == 0:
                continue
            entries = [(r * cols + c, m[r, c]) for r in range(rows) for c in range(cols)]
            nz = [Sink(arr, k, e) for k, e in entries if not (sp.sympify(e).is_zero is True)]
            pre = ()
            if len(nz) < len(entries):  # structural zeros, written once by memset
                pre = (f"memset({arr}, 0, {len(entries)} * sizeof(double));",)
            groups.append(SinkGroup(f"{arr} != NULL", nz, preamble=pre))
        # the Jacobian program may read program symbols: run both, pruned by lower()
        jb = lower(list(model.program.steps) + list(model.jacobian.steps), groups, names, known)
        jac_src = _function(
            "jacobian(const double *p, double t, const double *x, const double *u,\n"
            "                    double *dfdx, double *dfdu, double *dgdx, double *dgdu)",
            ["p", "t", "x", "u", "dfdx", "dfdu", "dgdx", "dgdu"], jb,
            _declare_reads(jb, names, model, time))
        op_counts["jacobian"] = jb.function_ops

    ev_parts, ev_decls, ev_fields = _event_functions(model, names, known, time) if model.events else ([], [], [])

    guid_text = GUID_PLACEHOLDER if guid is None else guid
    header = [
        "/*",
        f" * model.c -- {_comment_safe(model.name)}: generated by fmugen, do not edit.",
        " *",
    ]
    if model.description:
        header += [f" * {_comment_safe(line)}" for line in model.description.splitlines()] + [" *"]
    if model.provenance:
        header += [" * Provenance:"] + [f" *   {_comment_safe(line)}"
                                        for line in model.provenance.splitlines()] + [" *"]
    header += [
        f" * dx/dt = f(t, x, u, p), y = g(t, x, u, p) with nx = {nx}, nu = {nu}, ny = {ny}, "
        f"np = {model.np}.",
        " * Variables (value reference, kind, index in x/u/y/p, FMI name, unit, description):",
        *_variable_table(model),
        " *",
        " * Operation counts (binary * + - / and calls in the code below; unary minus free;",
        " * Cholesky solves in the runtime counted separately):",
    ]
    for fn, oc in op_counts.items():
        header.append(f" *   {fn}: {_comment_safe(str(oc.expressions))}")
        if oc.linear_solve != OpCount():
            header.append(f" *   {' ' * len(fn)}  linear solve: {oc.linear_solve}")
        if oc.loops != OpCount():
            header.append(f" *   {' ' * len(fn)}  runtime loops (c_runtime/chain_dynamics.c): {oc.loops}")
    header += [" */"]

    def names_array(name, vars_):
        return _array("char *const", name, [_c_string(v.name) for v in vars_])

    if runtime_start:
        runtime_start = runtime_starts(runtime_start)
    decls = [
        # sized by the runtime's count: a runtime with more parameters zero-fills, never over-reads
        *([_array("double", "rt_start", [_c_double(runtime_start[n]) for n in RT_START_ORDER])
           .replace(f"rt_start[{len(RT_START_ORDER)}]", "rt_start[FMUGEN_RT_COUNT]")]
          if runtime_start else []),
        _array("double", "x_start", [_c_double(v.start) for v in model.states]),
        _array("double", "x_nominal", [_c_double(v.nominal if v.nominal else 1.0) for v in model.states]),
        _array("double", "u_start", [_c_double(v.start if v.start is not None else 0.0)
                                     for v in model.inputs]),
        _array("double", "p_start", [_c_double(v.start if v.start is not None else 0.0)
                                     for v in model.parameters]),
        names_array("x_names", model.states),
        names_array("u_names", model.inputs),
        names_array("y_names", model.outputs),
        names_array("p_names", model.parameters),
    ]
    ranges = {}
    params = [replace(v, min=physical_range(v)[0]) for v in model.parameters]  # the sign is a bound too
    for v in params:  # a start value the FMU itself would refuse (fmi2SetReal) is no default
        if v.start is not None and ((v.min is not None and float(v.start) < float(v.min))
                                    or (v.max is not None and float(v.start) > float(v.max))):
            raise FmugenError(f"model {model.name!r}{origin}: parameter {v.name!r} = {float(v.start)!r} is outside "
                              f"its physical range [{v.min if v.min is not None else '-inf'}, "
                              f"{v.max if v.max is not None else 'inf'}]")
    for prefix, vars_ in (("x", model.states), ("u", model.inputs), ("y", model.outputs), ("p", params)):
        arrays, lo, hi = _range_arrays(prefix, vars_)
        decls += arrays
        ranges[prefix] = (lo, hi)

    def ptr(name, n):
        return name if n else "NULL"

    struct = [
        "const fmugen_model_def fmugen_model = {",
        f"    .model_identifier = {_c_string(ident)},",
        f"    .guid = {_c_string(guid_text)},",
        f"    .nx = {nx}, .nu = {nu}, .ny = {ny}, .np = {model.np},",
        f"    .x_start = {ptr('x_start', nx)},",
        f"    .x_nominal = {ptr('x_nominal', nx)},",
        f"    .u_start = {ptr('u_start', nu)},",
        f"    .p_start = {ptr('p_start', model.np)},",
        f"    .x_names = {ptr('x_names', nx)},",
        f"    .u_names = {ptr('u_names', nu)},",
        f"    .y_names = {ptr('y_names', ny)},",
        f"    .p_names = {ptr('p_names', model.np)},",
        f"    .has_jacobian = {1 if has_jac else 0},",
        "    .evaluate = evaluate,",
        f"    .jacobian = {'jacobian' if has_jac else 'NULL'},",
        *(f"    .{k}_min = {lo}, .{k}_max = {hi}," for k, (lo, hi) in ranges.items()),
        *_runtime_start_fields(runtime_start),
        *ev_fields,
        "};",
    ]
    looped = ev.n_chains + (jb.n_chains if has_jac else 0)
    parts = ["\n".join(header), "#include <math.h>\n#include <stddef.h>\n#include <string.h>\n"
             + ("#include <stdlib.h>\n" if looped else "")
             + '#include "fmugen_model.h"' + ('\n#include "chain_dynamics.h"' if looped else ""),
             "\n".join(d for d in decls if d),
             *names.support.values(),
             "/* dx = f(t, x, u, p) and y = g(t, x, u, p) in one pass */\n" + evaluate]
    if has_jac:
        parts.append("/* exact partial derivatives, dense row-major */\n" + jac_src)
    if ev_decls:
        parts.append("\n".join(d for d in ev_decls if d))
    parts += ev_parts
    parts.append("\n".join(struct))
    source = "\n\n".join(parts) + "\n"
    if guid is None:
        guid = deterministic_guid(source)
        source = source.replace(GUID_PLACEHOLDER, guid)
    return GeneratedC(source=source, op_counts=op_counts, model_identifier=ident, guid=guid)


def count_operations(
    outputs: Sequence[sp.Expr],
    program: Optional[Program] = None,
) -> FunctionOps:
    """Operations of C code computing ``outputs`` after ``program``.

    The same lowering as :func:`generate_c` (joint CSE, dead steps dropped,
    the counting rules of :class:`OpCount`), so the counts of e.g. the
    inverse dynamics or the mass matrix alone are comparable with the counts
    of the generated functions.  Every free symbol that the program does not
    assign is an input.

    >>> import sympy as sp
    >>> a, b = sp.symbols("a b")
    >>> str(count_operations([sp.sin(a) * b + sp.sin(a) / b]))
    '1 mul, 1 add, 1 div, 1 call (sin 1)'
    """
    outputs = [sp.sympify(e) for e in (outputs.tolist() if hasattr(outputs, "tolist") else outputs)]
    outputs = [e for row in outputs for e in (row if isinstance(row, list) else [row])]
    steps = list(program.steps) if program is not None else []
    assigned = program.assigned_symbols() if program is not None else set()
    free: set = set()
    for e in outputs:
        free |= e.free_symbols
    for st in steps:
        if isinstance(st, Assign):
            free |= sp.sympify(st.expr).free_symbols
        else:
            free |= st.A.free_symbols | st.B.free_symbols
    known = free - assigned
    names = _Names()
    for s in sorted(known, key=lambda z: z.name):
        names.add(s)
    body = lower(steps, [SinkGroup(None, [Sink("out", i, e) for i, e in enumerate(outputs)])],
                 names, known)
    return body.function_ops
