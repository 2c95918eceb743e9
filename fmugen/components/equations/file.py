"""Read a component file (TOML) into a SymbolicModel: declare, check dimensions, generate.

The format, key by key, is in ``fmugen/components/README.md`` ("Component
files"; a hybrid file's ``[discrete]``, ``[indicators]`` and ``[[when]]``:
"Events: discrete states, indicators, when clauses", they become the model's
:class:`~fmugen.codegen.model.Events`).  Every key is checked where it is read; errors are
:class:`fmugen.errors.InputFileError` naming the file, the table or equation
and the reason.  The file is parsed by :mod:`tomllib`; equations go through
:mod:`.language` (never evaluated) and :mod:`.dimensions`.
"""
from __future__ import annotations

import ast
import keyword
import math
import tomllib
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Mapping, Optional

import sympy as sp

from ...codegen.model import Clock, EventClause, Events, SymbolicModel
from ...errors import InputFileError, check_identifier, read_text_file, toml_problem
from ...robot.expressions import ExpressionError
from ..base import TIME, var
from . import language
from .dimensions import ANY, DIMENSIONLESS, DimensionError, SECOND, check_equation, dimension, dimension_of_unit, show, sub

TOP_KEYS = {"component", "parameters", "inputs", "states", "intermediates", "outputs", "sets", "connectors",
            "discrete", "indicators", "when", "clocks"}
COMPONENT_KEYS = {"name", "description", "equations", "provenance"}
PARAMETER_KEYS = {"value", "unit", "min", "max", "description"}
INPUT_KEYS = {"unit", "start", "min", "max", "description"}
STATE_KEYS = {"unit", "start", "nominal", "min", "max", "description", "output"}
INTERMEDIATE_KEYS = {"unit", "description"}
OUTPUT_KEYS = {"unit", "min", "max", "description"}
DISCRETE_KEYS = {"unit", "start", "min", "max", "description", "output"}
WHEN_KEYS = {"condition", "set", "name", "description", "clock"}
CLOCK_KEYS = {"period", "offset", "description"}
MAX_CLOCKS = 10
MAX_DECLARATIONS = 200  # per table: a component file is a component, not a model of everything
MAX_INTERMEDIATES = 5000  # [intermediates]: named steps of one straight-line program (linear cost each)
MAX_EQUATIONS = 6000
MAX_INDICATORS = 100
MAX_CLAUSES = 100


@dataclass(frozen=True)
class Declared:
    name: str
    kind: str  # parameter, input, state, discrete, intermediate, output
    unit: str
    description: str = ""
    value: Optional[float] = None  # parameter value / start value
    nominal: Optional[float] = None
    min: Optional[float] = None
    max: Optional[float] = None
    output: bool = True


@dataclass
class ComponentFile:
    """The checked declarations and equations of one file (before parameter values are chosen)."""

    path: Path
    name: str
    description: str
    provenance: str
    declared: dict  # name -> Declared, in file order
    equations: dict  # lhs name (state for der) -> (lhs text, rhs text, tree, python text)
    order: list  # intermediates and outputs in dependency order
    sets: dict  # set name -> {parameter: value}
    connectors: dict = field(default_factory=dict)  # name -> (type, {connector var: variable}), checked
    kinks: list = field(default_factory=list)  # (equation, text, function, [distances], eps): smoothed kinks
    indicators: list = field(default_factory=list)  # (name, Parsed), one per [indicators] entry
    clauses: list = field(default_factory=list)  # Clause, one per [[when]] table, in file order
    clocks: list = field(default_factory=list)  # SampleClock, one per [clocks.<name>] table
    widths: list = field(default_factory=list)  # (equation, site text, eps): widths checked with the values
    built: Optional[tuple] = field(default=None, repr=False, compare=False)  # _build_all's, value-free

    def of_kind(self, kind: str) -> list:
        return [d for d in self.declared.values() if d.kind == kind]

    @property
    def hybrid(self) -> bool:
        """Whether the file declares events (discrete states, indicators, when clauses)."""
        return bool(self.indicators or self.clauses or self.clocks or self.of_kind("discrete"))


@dataclass(frozen=True)
class Parsed:
    """One expression of the events: where it is (for messages), its text, checked tree, Python text."""

    where: str
    text: str
    tree: object
    python: str


@dataclass(frozen=True)
class Clause:
    """A ``[[when]]`` table: ``name`` (given or ``when<k>``), its condition and its ``set`` entries."""

    name: str
    where: str  # "[[when]] 2 (stick)" for messages
    description: str
    condition: Optional[Parsed]  # None: a clocked clause without a condition (fires at every tick)
    assign: tuple  # ((target name, Parsed value), ...) in file order
    clock: Optional[str] = None  # the [clocks.<name>] whose ticks it is guarded by


@dataclass(frozen=True)
class SampleClock:
    """A ``[clocks.<name>]`` table: ticks at offset + j period; its tick flag is the hidden discrete state
    ``tick`` (``<name>.tick``, start 0), set by the runtime for the first round at each instant."""

    name: str
    where: str
    description: str
    period: Parsed
    offset: Parsed
    tick: str  # the FMI name of the tick flag


def tick_name(clock: str) -> str:
    """The FMI name of a clock's tick flag (a discrete state the file cannot read or set)."""
    return f"{clock}.tick"


def last_name(clock: str) -> str:
    """The FMI name of a clock's last sample time (a discrete state the file cannot read or set)."""
    return f"{clock}.last"


#: the start of ``<clock>.last``: before any sample instant
NEVER = -1e300


def tick_symbol(clock: str) -> str:
    """The C-safe symbol of a clock's tick flag (``tick_<clock>``; a declared name of that spelling is
    refused)."""
    return f"tick_{clock}"


def _err(src, msg):
    # one line whatever the file holds: a key "a\nb" or a value with a line separator is shown escaped
    msg = "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(msg))
    return InputFileError(f"{src}: {msg}")


def _name_problem(name) -> Optional[str]:
    if not isinstance(name, str) or not language_identifier(name):
        return "must be an identifier (ASCII letters, digits and single '_', starting with a letter, at most 64)"
    if keyword.iskeyword(name) or keyword.issoftkeyword(name):
        return "is a Python keyword"
    if name in language.RESERVED:
        return "is a function or reserved name of the equation language"
    return None


def language_identifier(name: str) -> bool:
    return (name.isascii() and name.isidentifier() and name[0].isalpha() and "__" not in name
            and len(name) <= 64)


def _number(v, where, src) -> float:
    try:
        return language.finite(v, where)
    except ExpressionError as exc:
        raise _err(src, str(exc)) from None


def read_component_file(path) -> ComponentFile:
    """Parse and check ``path`` (declarations, equations, dimensions); no parameter values chosen yet."""
    path = Path(path)
    src = str(path)
    try:
        data = tomllib.loads(read_text_file(path, "component file"))
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise _err(src, toml_problem(exc)) from None
    extra = sorted(set(data) - TOP_KEYS)
    if extra:
        raise _err(src, f"unknown top-level key(s) {', '.join(extra)}; a component file has "
                        f"{', '.join(f'[{k}]' for k in sorted(TOP_KEYS))}")
    comp = data.get("component")
    if not isinstance(comp, dict):
        raise _err(src, "missing [component] table (name, description, equations)")
    bad = sorted(set(comp) - COMPONENT_KEYS)
    if bad:
        raise _err(src, f"[component] has unknown key(s) {', '.join(bad)}; known: {', '.join(sorted(COMPONENT_KEYS))}")
    name = check_identifier(comp.get("name", path.stem), f"{src}: [component] name")
    desc, prov = comp.get("description", ""), comp.get("provenance", "")
    if not isinstance(desc, str) or not isinstance(prov, str):
        raise _err(src, "[component] description and provenance must be strings")

    declared: dict = {}
    specs = (("parameters", "parameter", PARAMETER_KEYS), ("inputs", "input", INPUT_KEYS),
             ("states", "state", STATE_KEYS), ("discrete", "discrete", DISCRETE_KEYS),
             ("intermediates", "intermediate", INTERMEDIATE_KEYS),
             ("outputs", "output", OUTPUT_KEYS))
    for table, kind, keys in specs:
        tab = data.get(table, {})
        if not isinstance(tab, dict):
            raise _err(src, f"[{table}] must be a table of {{ unit = ..., ... }} entries")
        limit = MAX_INTERMEDIATES if table == "intermediates" else MAX_DECLARATIONS
        if len(tab) > limit:
            raise _err(src, f"[{table}] declares {len(tab)} names; at most {limit}")
        for vname, entry in tab.items():
            where = f"[{table}] {vname}"
            problem = _name_problem(vname)
            if problem:
                raise _err(src, f"{where}: the name {problem}")
            if vname in declared:
                raise _err(src, f"{where}: {vname!r} is declared twice (also in the {declared[vname].kind}s)")
            if not isinstance(entry, dict):
                raise _err(src, f"{where} must be a table like {{ unit = \"N.m\", ... }}")
            bad = sorted(set(entry) - keys)
            if bad:
                raise _err(src, f"{where} has unknown key(s) {', '.join(bad)}; known: {', '.join(sorted(keys))}")
            unit = entry.get("unit", "1")
            if not isinstance(unit, str):
                raise _err(src, f"{where} unit must be a string")
            try:
                dimension_of_unit(unit)
            except ValueError as exc:
                raise _err(src, f"{where}: {exc}") from None
            d = entry.get("description", "")
            if not isinstance(d, str):
                raise _err(src, f"{where} description must be a string")
            vals = {k: _number(entry[k], f"{where} {k}", src) for k in ("value", "start", "nominal", "min", "max")
                    if k in entry}
            if kind == "parameter" and "value" not in vals:
                raise _err(src, f"{where}: a parameter needs a value")
            if kind == "discrete" and "start" not in vals:
                raise _err(src, f"{where}: a discrete state needs a start value (its value until the first "
                                f"[[when]] clause sets it)")
            if "nominal" in vals and vals["nominal"] <= 0:
                raise _err(src, f"{where} nominal must be positive")
            lo, hi = vals.get("min"), vals.get("max")
            if lo is not None and hi is not None and lo > hi:
                raise _err(src, f"{where}: min ({lo}) is above max ({hi})")
            value = vals.get("value", vals.get("start", 0.0 if kind == "state" else None))
            if value is not None and ((lo is not None and value < lo) or (hi is not None and value > hi)):
                raise _err(src, f"{where}: {'value' if kind == 'parameter' else 'start'} {value} is outside "
                                f"[{lo}, {hi}]")
            out = entry.get("output", True)
            if not isinstance(out, bool):
                raise _err(src, f"{where} output must be true or false")
            declared[vname] = Declared(vname, kind, unit, d, value, vals.get("nominal"), lo, hi, out)
    if not any(d.kind in ("state", "output") for d in declared.values()):
        raise _err(src, "declares no [states] and no [outputs]: nothing to compute")

    equations = _equations(comp.get("equations"), declared, src)
    order = _order_intermediates(equations, declared, src)
    sets = _sets(data.get("sets", {}), declared, src)
    connectors = data.get("connectors", {})
    if not isinstance(connectors, dict):
        raise _err(src, "[connectors] must hold tables [connectors.<name>]")
    from ..connectors import check_file_connectors

    connectors = check_file_connectors(connectors, declared, src)
    clocks = _clocks(data.get("clocks", {}), declared, src)
    indicators, clauses = _events(data, declared, src, clocks)
    cf = ComponentFile(path, name, desc, prov, declared, equations, order, sets, connectors,
                       indicators=indicators, clauses=clauses, clocks=clocks)
    cf.built = _build_all(cf, cf.kinks, cf.widths)  # the language's refusals first (they say what is wrong with the text) ...
    _check_dimensions(cf)  # ... then the dimensions of what it says
    return cf


def split_equation(text: str) -> tuple:
    """``"lhs = rhs"`` split at the one '=' that is not part of ==, <=, >= or !=."""
    for i, c in enumerate(text):
        if c == "=" and (i == 0 or text[i - 1] not in "<>=!") and (i + 1 == len(text) or text[i + 1] != "="):
            return text[:i].strip(), text[i + 1:].strip()
    raise ValueError("is not 'lhs = rhs'")


def _equations(raw, declared, src) -> dict:
    if not isinstance(raw, list) or not all(isinstance(e, str) for e in raw):
        raise _err(src, "[component] equations must be a list of strings \"der(x) = ...\" / \"y = ...\"")
    if len(raw) > MAX_EQUATIONS:
        raise _err(src, f"[component] equations: {len(raw)} equations; at most {MAX_EQUATIONS}")
    out = {}
    for k, text in enumerate(raw):
        where = f"equation {k + 1} {language._short(text)}"
        if not text.isascii():  # the left side too: str.strip() would drop a no-break space around der(x)
            bad = next(c for c in text if not c.isascii())
            raise _err(src, f"{where}: non-ASCII character {bad!r} (U+{ord(bad):04X}); equations are ASCII")
        try:
            lhs, rhs = split_equation(text)
        except ValueError as exc:
            raise _err(src, f"{where} {exc}") from None
        if lhs.startswith("der(") and lhs.endswith(")"):
            target, want = lhs[4:-1].strip(), ("state",)
        else:
            target, want = lhs, ("output", "intermediate")
        d = declared.get(target)
        if d is None or d.kind not in want:
            what = "der() of a declared state" if want == ("state",) else "a declared output or intermediate"
            kind = f" ({target!r} is {'an' if d and d.kind[0] in 'aeiou' else 'a'} {d.kind})" if d else ""
            raise _err(src, f"{where}: the left side must be {what}{kind}; write der(x) = ... for a state x, "
                            f"y = ... for an output or intermediate y")
        if target in out:
            raise _err(src, f"{where}: a second equation for {lhs} (the first: {out[target][0]} = {out[target][1]})")
        tree, python = _parse(rhs, where, declared, src)
        out[target] = (lhs, rhs, tree, python)
    missing = [("der(" + d.name + ")" if d.kind == "state" else d.name) for d in declared.values()
               if d.kind in ("state", "output", "intermediate") and d.name not in out]
    if missing:
        raise _err(src, f"no equation for {', '.join(missing)}: every state needs der(x) = ..., every output "
                        f"and intermediate y = ...")
    return out


def _parse(text, where, declared, src) -> tuple:
    """(checked tree, Python text) of an expression, every name declared (else one line naming ``where``)."""
    try:
        tree, python = language.parse_tree(text)
    except ExpressionError as exc:
        raise _err(src, f"{where}: {exc}") from None
    unknown = sorted(language.names_in(tree) - set(declared) - {"pi", "time"} - language.FUNCTION_NAMES)
    if unknown:
        raise _err(src, f"{where}: unknown name(s) {', '.join(unknown)}; declared: {', '.join(declared)}, "
                        f"time, pi")
    return tree, python


def _value_text(v, where, src) -> str:
    """A ``set`` value: an expression string, or a TOML number written as one."""
    if isinstance(v, str):
        return v
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return repr(_number(v, where, src))
    raise _err(src, f"{where} must be an expression string or a number, got {type(v).__name__} {v!r}")


def _clocks(raw, declared, src) -> list:
    """The checked ``[clocks.<name>]`` tables: period and offset, expressions of parameters and numbers."""
    if not isinstance(raw, dict):
        raise _err(src, "[clocks] must hold tables [clocks.<name>] with period = \"T_s\" (a parameter or a "
                        "number of seconds)")
    if len(raw) > MAX_CLOCKS:
        raise _err(src, f"[clocks] declares {len(raw)} clocks; at most {MAX_CLOCKS}")
    params = {n for n, d in declared.items() if d.kind == "parameter"}
    out = []
    for cname, tab in raw.items():
        where = f"[clocks.{cname}]"
        problem = _name_problem(cname)
        if problem:
            raise _err(src, f"{where}: the name {problem}")
        if cname in declared:
            raise _err(src, f"{where}: {cname!r} is also a declared {declared[cname].kind}; give the clock a name "
                            f"of its own")
        for hidden in (tick_symbol(cname), f"last_{cname}"):
            if hidden in declared:
                raise _err(src, f"{where}: the name {hidden!r} is the clock's own (its tick flag or last sample "
                                f"time); rename the {declared[hidden].kind} {hidden!r}")
        if not isinstance(tab, dict):
            raise _err(src, f"{where} must be a table like {{ period = \"T_s\", offset = \"0\" }}")
        bad = sorted(set(tab) - CLOCK_KEYS)
        if bad:
            raise _err(src, f"{where} has unknown key(s) {', '.join(bad)}; known: {', '.join(sorted(CLOCK_KEYS))}"
                       + (" (a one-sample computation delay is written in the clause: see the README, "
                          "\"Sample clocks\")" if "delay" in bad else ""))
        desc = tab.get("description", "")
        if not isinstance(desc, str):
            raise _err(src, f"{where} description must be a string")
        if "period" not in tab:
            raise _err(src, f"{where} needs period = \"T_s\": a parameter of unit s, or a number of seconds")
        parts = []
        for key, default in (("period", None), ("offset", "0")):
            value = tab.get(key, default)
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                value = repr(_number(value, f"{where} {key}", src))
            if not isinstance(value, str):
                raise _err(src, f"{where} {key} must be a parameter name, a number or an expression string of "
                                f"parameters, got {type(value).__name__} {value!r}")
            kwhere = f"{where} {key} = {language._short(value)}"
            tree, python = _parse(value, kwhere, declared, src)
            other = sorted(language.names_in(tree) - params - language.FUNCTION_NAMES - {"pi"})
            if other:
                raise _err(src, f"{kwhere}: a clock's timing is fixed for the run: it may read parameters and "
                                f"numbers only, not {', '.join(other)}")
            parts.append(Parsed(kwhere, value, tree, python))
        out.append(SampleClock(cname, where, desc, parts[0], parts[1], tick_name(cname)))
    return out


def _events(data, declared, src, clocks=()) -> tuple:
    """The checked ``[indicators]`` and ``[[when]]`` tables: ([(name, Parsed)], [Clause])."""
    raw = data.get("indicators", {})
    if not isinstance(raw, dict):
        raise _err(src, "[indicators] must be a table of name = \"expression\" entries")
    if len(raw) > MAX_INDICATORS:
        raise _err(src, f"[indicators] declares {len(raw)} indicators; at most {MAX_INDICATORS}")
    indicators = []
    for iname, text in raw.items():
        where = f"[indicators] {iname}"
        problem = _name_problem(iname)
        if problem:
            raise _err(src, f"{where}: the name {problem}")
        if iname in declared:
            raise _err(src, f"{where}: {iname!r} is also a declared {declared[iname].kind}; give the indicator a "
                            f"name of its own")
        if not isinstance(text, str):
            raise _err(src, f"{where} must be an expression string whose sign change is the event, like \"h\" "
                            f"or \"T_s - abs(tau)\"")
        tree, python = _parse(text, f"{where} = {language._short(text)}", declared, src)
        if isinstance(tree, (ast.Compare, ast.BoolOp)) or (isinstance(tree, ast.UnaryOp)
                                                           and isinstance(tree.op, ast.Not)):
            raise _err(src, f"{where} = {language._short(text)}: an indicator is a quantity, not a condition: the "
                            f"event is its sign change (write \"h\", not \"h <= 0\")")
        indicators.append((iname, Parsed(f"{where} = {language._short(text)}", text, tree, python)))

    raw = data.get("when", [])
    if isinstance(raw, dict):
        raise _err(src, "[when] must be an array of tables: write [[when]] (two brackets) for each clause")
    if not isinstance(raw, list) or not all(isinstance(c, dict) for c in raw):
        raise _err(src, "[[when]] clauses must be tables [[when]] with condition = \"...\" and set = { ... }")
    if len(raw) > MAX_CLAUSES:
        raise _err(src, f"{len(raw)} [[when]] clauses; at most {MAX_CLAUSES}")
    clauses, seen = [], {}
    for k, tab in enumerate(raw, 1):
        cname = tab.get("name", f"when{k}")
        where = f"[[when]] {k}" + (f" ({cname})" if "name" in tab else "")
        bad = sorted(set(tab) - WHEN_KEYS)
        if bad:
            raise _err(src, f"{where} has unknown key(s) {', '.join(bad)}; known: {', '.join(sorted(WHEN_KEYS))}")
        problem = _name_problem(cname)
        if problem:
            raise _err(src, f"{where}: the name {problem}")
        if cname in seen:
            raise _err(src, f"{where}: the name {cname!r} is also {seen[cname]}'s")
        seen[cname] = where
        desc = tab.get("description", "")
        if not isinstance(desc, str):
            raise _err(src, f"{where} description must be a string")
        clock = tab.get("clock")
        names = [c.name for c in clocks]
        if clock is not None and clock not in names:
            raise _err(src, f"{where} clock = {clock!r}: "
                            + (f"not a declared clock; declared: {', '.join(names)}" if names and isinstance(clock, str)
                               else "must name a [clocks.<name>] table" if names
                               else "no [clocks.<name>] table declares it"))
        cond = tab.get("condition")
        if cond is None and clock is not None:
            condition = None
        else:
            if not isinstance(cond, str):
                raise _err(src, f"{where} needs condition = \"...\", a string (comparisons joined by and, or, not)"
                                + (f", not {type(cond).__name__} {cond!r}" if cond is not None else "")
                                + (", or clock = \"<name>\" of a [clocks.<name>] table" if cond is None else ""))
            cwhere = f"{where} condition {language._short(cond)}"
            tree, python = _parse(cond, cwhere, declared, src)
            condition = Parsed(cwhere, cond, tree, python)
        sets = tab.get("set")
        if not isinstance(sets, dict) or not sets:
            raise _err(src, f"{where} needs set = {{ target = \"value\", ... }}, the discrete states and states "
                            f"it assigns")
        assign = []
        for target, value in sets.items():
            swhere = f"{where} set {target}"
            d = declared.get(target)
            if d is None or d.kind not in ("discrete", "state"):
                what = f"is {'an' if d.kind[0] in 'aeiou' else 'a'} {d.kind}" if d else "is not declared"
                targets = [n for n, e in declared.items() if e.kind in ("discrete", "state")]
                raise _err(src, f"{swhere}: unknown target: {target!r} {what}; a clause sets a [discrete] state "
                                f"or re-initialises a [states] state ({', '.join(targets) or 'none declared'})")
            text = _value_text(value, swhere, src)
            vwhere = f"{swhere} = {language._short(text)}"
            tree, python = _parse(text, vwhere, declared, src)
            assign.append((target, Parsed(vwhere, text, tree, python)))
        clauses.append(Clause(cname, where, desc, condition, tuple(assign), clock))

    discrete = [n for n, d in declared.items() if d.kind == "discrete"]
    assigned = {t for c in clauses for t, _ in c.assign}
    never = [n for n in discrete if n not in assigned]
    if never:
        raise _err(src, f"[discrete] {', '.join(never)}: never set by a [[when]] clause, so constant: make "
                        f"{'it a parameter' if len(never) == 1 else 'them parameters'}")
    if clauses and not indicators and not clocks:
        raise _err(src, "[[when]] clauses but no [indicators] and no [clocks]: no event would ever run them after "
                        "the start; declare the quantities whose sign change is an event, or a sample clock")
    unused = [c.name for c in clocks if not any(cl.clock == c.name for cl in clauses)]
    if unused:
        raise _err(src, f"[clocks.{unused[0]}]: no [[when]] clause has clock = {unused[0]!r}: its ticks would "
                        f"do nothing; add the clause that samples, or remove the clock")
    if indicators and not clauses:
        raise _err(src, "[indicators] but no [[when]] clause: an event would change nothing; add the clauses "
                        "that act at the events")
    return indicators, clauses


def _order_intermediates(equations, declared, src) -> list:
    # outputs may be read by other equations too: both are ordered by their dependencies
    inter = [d.name for d in declared.values() if d.kind in ("intermediate", "output")]
    deps = {n: sorted(language.names_in(equations[n][2]) & set(inter)) for n in inter}
    state, order, path = {}, [], []

    def visit(n):
        if state.get(n) == 2:
            return
        if state.get(n) == 1:
            cycle = path[path.index(n):] + [n]
            raise _err(src, f"the intermediates/outputs {' -> '.join(cycle)} depend on each other in a cycle "
                            f"(an algebraic loop): make one of them a state or solve the loop by hand")
        state[n] = 1
        path.append(n)
        for m in deps[n]:
            visit(m)
        path.pop()
        state[n] = 2
        order.append(n)

    for n in inter:
        visit(n)
    return order


def _sets(raw, declared, src) -> dict:
    if not isinstance(raw, dict):
        raise _err(src, "[sets] must hold tables [sets.<name>] of parameter values")
    out = {}
    params = {d.name: d for d in declared.values() if d.kind == "parameter"}
    for sname, tab in raw.items():
        if not isinstance(tab, dict):
            raise _err(src, f"[sets.{sname}] must be a table of parameter values")
        out[sname] = _check_values(tab, params, f"{src}: [sets.{sname}]")
    return out


def _check_values(values: Mapping, params: dict, where: str) -> dict:
    out = {}
    for k, v in values.items():
        d = params.get(k)
        if d is None:
            raise InputFileError(f"{where}: {k!r} is not a parameter; parameters: {', '.join(params) or '-'}")
        try:
            x = language.finite(v, f"{where}: {k}")
        except ExpressionError as exc:
            raise InputFileError(str(exc)) from None
        if (d.min is not None and x < d.min) or (d.max is not None and x > d.max):
            raise InputFileError(f"{where}: {k} = {x} is outside its range [{d.min}, {d.max}]")
        out[k] = x
    return out


def _constant_value(python: str):
    """The exact value of a constant sub-tree (for exponents), or None."""
    def value(node):
        try:
            e = language.EquationBuilder(python, {}, set()).build(node)
        except ExpressionError:
            return None
        return Fraction(int(e.p), int(e.q)) if e.is_Rational else None
    return value


def _check_dimensions(cf: ComponentFile) -> None:
    dims = {n: dimension_of_unit(d.unit) for n, d in cf.declared.items()}
    for target, (lhs, rhs, tree, python) in cf.equations.items():
        lhs_dim = sub(dims[target], SECOND) if cf.declared[target].kind == "state" else dims[target]
        try:
            check_equation(python, tree, lhs, lhs_dim, dims, _constant_value(python))
        except DimensionError as exc:
            units = ", ".join(f"{n} [{cf.declared[n].unit}]" for n in sorted(language.names_in(tree) & set(dims)))
            raise _err(cf.path, f"equation '{lhs} = {rhs}' is dimensionally inconsistent: {exc}; units: "
                                f"{lhs.removeprefix('der(').removesuffix(')')} [{cf.declared[target].unit}]"
                                f"{', ' + units if units else ''}") from None

    def units(tree, first=""):
        names = sorted(language.names_in(tree) & set(dims) - {first})
        shown = ([f"{first} [{cf.declared[first].unit}]"] if first else []) + [f"{n} [{cf.declared[n].unit}]"
                                                                                 for n in names]
        return f"; units: {', '.join(shown)}" if shown else ""

    def dim_of(p: Parsed):
        try:
            return dimension(p.python, p.tree, dims, _constant_value(p.python))
        except DimensionError as exc:
            raise _err(cf.path, f"{p.where} is dimensionally inconsistent: {exc}{units(p.tree)}") from None

    for _, ind in cf.indicators:
        dim_of(ind)
    for k in cf.clocks:
        for p in (k.period, k.offset):
            d = dim_of(p)
            number = d == DIMENSIONLESS and not (language.names_in(p.tree) & set(dims))  # seconds as a number
            if d is not ANY and d != SECOND and not number:
                raise _err(cf.path, f"{p.where} is [{show(d)}]: a clock's period and offset are times [s] (a "
                                    f"parameter of unit s, or a plain number of seconds){units(p.tree)}")
    for c in cf.clauses:
        if c.condition is not None:
            dim_of(c.condition)
        for target, p in c.assign:
            d = dim_of(p)
            if d is not ANY and d != dims[target]:
                raise _err(cf.path, f"{p.where}: the value is [{show(d)}] but {target} is in "
                                    f"[{cf.declared[target].unit}] ([{show(dims[target])}]): a clause must assign "
                                    f"a value of its target's unit{units(p.tree, target)}")


def component_model(cf: ComponentFile, name: Optional[str] = None, parameter_set=None,
                    overrides: Optional[Mapping[str, float]] = None, strict_set: bool = True) -> SymbolicModel:
    """The SymbolicModel of a checked file with chosen parameter values.

    ``parameter_set``: a name of the file's ``[sets.<name>]``, or a ``.toml``
    path holding a ``[<component name>]`` table of values; ``strict_set=False``
    (a scene's default set) ignores a set name the file does not define.
    ``overrides``: parameter values, checked against the declared ranges.
    """
    src = str(cf.path)
    params = {d.name: d for d in cf.of_kind("parameter")}
    values = {n: d.value for n, d in params.items()}
    if parameter_set is not None:
        ps = str(parameter_set)
        if ps.endswith(".toml"):
            try:
                tab = tomllib.loads(read_text_file(Path(ps), "parameter set")).get(cf.name)
            except (tomllib.TOMLDecodeError, RecursionError) as exc:
                raise InputFileError(f"{ps}: {toml_problem(exc)}") from None
            if not isinstance(tab, dict):
                raise InputFileError(f"{ps}: no [{cf.name}] table of parameter values for component file {src}")
            values.update(_check_values(tab, params, f"{ps}: [{cf.name}]"))
        elif ps in cf.sets:
            values.update(cf.sets[ps])
        elif strict_set:
            raise InputFileError(f"{src}: no parameter set {ps!r}; the file defines "
                                 f"{', '.join(cf.sets) or 'none'} ([sets.<name>])")
    values.update(_check_values(dict(overrides or {}), params, f"{src}: parameter override"))

    ders, outs, events, program = cf.built if cf.built is not None else _build_all(cf)
    program = _copy(program)  # explicit_model appends its f and g steps
    env = {sp.Symbol(n, real=True): values[n] for n in params}
    env.update({sp.Symbol(d.name, real=True): d.value for d in cf.of_kind("discrete")})
    for eq, site, eps in cf.widths:  # the widths that are parameters: > 0 with the chosen values
        try:
            x = float(sp.sympify(eps).xreplace(env))
        except (TypeError, ValueError, OverflowError):
            x = math.nan
        if not (math.isfinite(x) and x > 0):
            raise _err(src, f"equation '{eq}': the smoothing width {eps} of {site} is {x:g} with these parameter "
                            f"values: a width is a constant > 0 (with 0 the kink is exact and its smooth form "
                            f"divides by 0), refused by the kink rule")

    def v(d, start):
        return var(d.name, d.unit, d.description, start=start, nominal=d.nominal, min=d.min, max=d.max,
                   output=d.kind in ("state", "discrete") and d.output)

    if events is not None:
        ticks = [var(k.tick, "1", f"tick flag of the sample clock {k.name} (1 for the first round of the event "
                                  f"iteration at each of its instants, else 0)", start=0.0, symbol=tick_symbol(k.name),
                     min=0.0, max=1.0) for k in cf.clocks]
        lasts = [var(last_name(k.name), "s", f"time of the last sample instant of the clock {k.name}",
                     start=NEVER, symbol=f"last_{k.name}") for k in cf.clocks]
        clocks = tuple(Clock(period, offset, tick) for (period, offset), tick in zip(events[2], ticks))
        env = {sp.Symbol(n, real=True): values[n] for n in params}
        for k, c in zip(cf.clocks, clocks):
            for what, e, ok in (("period", c.period, lambda x: x > 0), ("offset", c.offset, lambda x: x >= 0)):
                x = sp.sympify(sp.sympify(e).xreplace(env))
                if not (x.is_number and math.isfinite(float(x)) and ok(float(x))):
                    raise _err(src, f"{k.where} {what} = {getattr(k, what).text} is {x} with these parameter values: "
                                    f"a clock's period must be positive and its offset >= 0 (finite, in s)")
        events = Events(discrete=tuple(v(d, d.value) for d in cf.of_kind("discrete")) + tuple(ticks) + tuple(lasts),
                        indicators=events[0], clauses=events[1], clocks=clocks)

    try:
        return explicit_model(
            name or cf.name,
            [v(d, d.value) for d in cf.of_kind("state")],
            [v(d, d.value) for d in cf.of_kind("input")],
            [v(d, values[d.name]) for d in params.values()],
            ders, [v(d, None) for d in cf.of_kind("output")], outs,
            description=cf.description or f"component file {cf.path.name}",
            provenance=cf.provenance or f"component file {cf.path.name}", events=events, program=program)
    except ValueError as exc:
        raise _err(src, str(exc)) from None


def _signs(cf) -> dict:
    """name -> the signs (of -1, 0, 1) a declared quantity takes, from its declared range (kinks in disguise)."""
    return {n: language.sign_of_bounds(d.min, d.max, d.kind in ("parameter", "discrete"))
            for n, d in cf.declared.items() if d.kind in ("parameter", "input", "state", "discrete")}


def _build_all(cf: ComponentFile, kinks: Optional[list] = None, widths: Optional[list] = None) -> tuple:
    """(derivative expressions, output expressions, events, program); parameters symbolic.

    Every intermediate and output is a named step of one straight-line :class:`Program` (``_w<name>_<k>``):
    the equations read its symbol, never its expression, so nothing is expanded (a chain of intermediates
    each reading the previous one k times costs k operations a link, not k**n), and the Jacobians are the
    chain rule over the program (:func:`.derive.jacobian`, the algorithm of
    :func:`fmugen.codegen.differentiate.differentiate`, in :func:`explicit_model`).  An intermediate of parameters and discrete states only is a constant to
    the kink rules.  ``events``: None for a smooth file, else (indicators, clauses, timing) with the
    intermediates inlined (the events read states, inputs, parameters, discrete states, t).
    """
    from ...codegen.program import Program

    symbols = {n: sp.Symbol(n, real=True) for n in cf.declared
               if cf.declared[n].kind in ("parameter", "input", "state", "discrete")}
    ticks = {k.name: sp.Symbol(tick_symbol(k.name), real=True) for k in cf.clocks}
    lasts = {k.name: sp.Symbol(f"last_{k.name}", real=True) for k in cf.clocks}
    # constant between events: a kink or an exact if on these is no kink of the integrated equations
    constant = {symbols[d.name] for d in cf.of_kind("parameter") + cf.of_kind("discrete")}
    names = dict(symbols)
    signs = _signs(cf)
    program = Program("_w")
    for n in cf.order:  # intermediates and outputs, each after what it reads
        expr, sign = _build(cf, n, names, constant, kinks, signs, widths)
        s = program.let(expr, f"{n}_")
        names[n] = s
        signs[n] = sign
        if s.is_Symbol and expr.free_symbols <= constant:
            constant.add(s)
    ders = [_build(cf, d.name, names, constant, kinks, signs, widths)[0] for d in cf.of_kind("state")]
    outs = [names[d.name] for d in cf.of_kind("output")]
    inline = _Inliner(program)
    if kinks:  # the distances to the kinks, for fmugen linearize: of states, inputs and parameters only
        kinks[:] = [k[:3] + ([inline(d) for d in k[3]], inline(k[4])) for k in kinks]
    if widths:
        widths[:] = [(eq, site, inline(e)) for eq, site, e in widths]
    if not cf.hybrid:
        return ders, outs, None, program
    inlined = _Inlined(names, inline)  # the events read closed forms, built for what they read only
    indicators = tuple((n, _build_event(cf, p, inlined, constant, "indicator")) for n, p in cf.indicators)
    timing = tuple(tuple(_build_event(cf, p, inlined, constant, "event") for p in (k.period, k.offset))
                   for k in cf.clocks)
    period = {k.name: t[0] for k, t in zip(cf.clocks, timing)}

    def guard(c):
        cond = None if c.condition is None else _build_event(cf, c.condition, inlined, constant, "condition")
        if c.clock is None:
            return cond
        # the tick, and at most once per sample instant: a tick repeated within half a period (a
        # Co-Simulation step ending a rounding error past the instant it already sampled) is ignored
        tick = sp.And(sp.Gt(ticks[c.clock], 0), sp.Gt(TIME - lasts[c.clock], period[c.clock] / 2))
        return tick if cond is None else sp.And(tick, cond)

    def assign(c):
        out = tuple((symbols[t], _build_event(cf, p, inlined, constant, "event")) for t, p in c.assign)
        return out + (((lasts[c.clock], TIME),) if c.clock is not None else ())

    clauses = tuple(EventClause(guard(c), assign(c), c.name) for c in cf.clauses)
    return ders, outs, (indicators, clauses, timing), program


def _copy(program):
    from ...codegen.program import Program

    out = Program(program.prefix)
    out.steps, out._count = list(program.steps), program._count
    return out


class _Inlined(dict):
    """``names`` with every value read through ``inline`` (on demand: only the names an event reads)."""

    def __init__(self, names, inline):
        super().__init__(names)
        self.inline = inline

    def __getitem__(self, key):
        return self.inline(super().__getitem__(key))


class _Inliner:
    """An expression with the program's symbols replaced by their closed forms (memoised, on demand)."""

    def __init__(self, program):
        self.steps = {st.symbol: st.expr for st in program.steps}
        self.memo = {}

    def __call__(self, expr):
        expr = sp.sympify(expr)
        todo = [s for s in expr.free_symbols if s in self.steps and s not in self.memo]
        while todo:  # depth first, without recursion (a chain of 1000 intermediates)
            s = todo[-1]
            need = [t for t in self.steps[s].free_symbols if t in self.steps and t not in self.memo]
            if need:
                todo += need
                continue
            todo.pop()
            if s not in self.memo:
                self.memo[s] = self.steps[s].xreplace(self.memo)
        return expr.xreplace(self.memo) if self.memo else expr


def _build_event(cf, p: Parsed, names, constant, what):
    """An indicator (``what = "indicator"``), a condition (``"condition"``) or an assigned value (``"event"``)."""
    try:
        builder = language.EquationBuilder(p.python, names, constant, "indicator" if what == "indicator" else "event")
        expr = builder.condition(p.tree) if what == "condition" else builder.build(p.tree)
        language.check_finite_constants(expr, p.text)
    except ExpressionError as exc:
        raise _err(cf.path, f"{p.where}: {str(exc).replace(repr(p.python), repr(p.text))}") from None
    if what == "condition" and expr in (sp.true, sp.false):
        raise _err(cf.path, f"{p.where} is always {'true' if expr == sp.true else 'false'}: a condition must "
                            f"depend on the model's values (a clause whose condition stays true after its "
                            f"assignment would repeat at every round of the event iteration)")
    if what == "indicator" and expr.free_symbols <= constant:
        raise _err(cf.path, f"{p.where} depends on no state, input or time: it never changes sign between "
                            f"events, so it is never an event")
    return expr


def _build(cf, target, names, constant, kinks=None, signs=None, widths=None):
    """(expression, the signs it can take) of the right-hand side of ``target``'s equation."""
    lhs, rhs, tree, python = cf.equations[target]
    try:
        builder = language.EquationBuilder(python, names, constant, signs=signs)
        expr = builder.build(tree)
        if kinks is not None:
            kinks += [(f"{lhs} = {rhs}",) + k for k in builder.kinks]
        if widths is not None:
            widths += [(f"{lhs} = {rhs}",) + w for w in builder.widths]
        language.check_finite_constants(expr, rhs)
        sign = builder.sign(tree)
    except ExpressionError as exc:
        raise _err(cf.path, f"equation '{lhs} = {rhs}': {str(exc).replace(repr(python), repr(rhs))}") from None
    return expr, sign


class _RealAbs(sp.Function):
    """|x| of a real x, differentiated as sign(x) dx.

    sympy's own Abs falls back to re/im parts and a division by |x| when it
    cannot prove a nested argument real (the smooth forms nest Abs), which is
    0/0 in C exactly at a kink; this one is swapped in for the derivation only.
    """

    is_real = True
    is_real_abs = True

    def fdiff(self, argindex=1):
        return sp.sign(self.args[0])


def explicit_model(name, states, inputs, parameters, derivatives, outputs, output_exprs, description,
                   provenance, events: Optional[Events] = None, program=None) -> SymbolicModel:
    """A SymbolicModel of explicit equations; |x| differentiated as sign(x) dx.

    ``program``: the named intermediates the expressions read (a :class:`Program`, steps in order).  The
    Jacobians are the chain rule over its steps (:func:`.derive.jacobian`, the algorithm of
    :func:`fmugen.codegen.differentiate.differentiate`: one derivative step per (step, state or input it
    depends on), each a fresh symbol), never a closed form: the cost grows linearly with the number of
    intermediates.  The one CSE runs when the C is written.
    """
    from ...codegen.model import _finite_signs
    from ...codegen.program import Assign, Program
    from .derive import jacobian

    def plain(e):
        e = sp.sympify(e)
        return _finite_signs(e.replace(_RealAbs, sp.Abs) if e.has(_RealAbs) else e)

    prog = Program("_w") if program is None else program
    intermediates = Program(prog.prefix)
    intermediates.steps = [st for st in prog.steps if isinstance(st, Assign)]
    f = [sp.sympify(e) for e in derivatives]
    g = [sp.sympify(e) for e in output_exprs]
    xs, us = [v.symbol for v in states], [v.symbol for v in inputs]
    fd = tuple(prog.let(plain(e), "f") for e in f)
    gd = tuple(prog.let(plain(e), "g") for e in g)
    jac = Program("_j")
    nx, nu = len(xs), len(us)

    def jm(exprs):
        if not exprs or not xs + us:
            return sp.zeros(len(exprs), nx), sp.zeros(len(exprs), nu)
        J = jacobian(intermediates, exprs, xs + us, jac)
        return J[:, :nx], J[:, nx:]

    (dfdx, dfdu), (dgdx, dgdu) = jm(f), jm(g)
    jac.steps = [Assign(st.symbol, plain(st.expr)) for st in jac.steps]
    return SymbolicModel(name=name, description=description, states=tuple(states), inputs=tuple(inputs),
                         parameters=tuple(parameters), outputs=tuple(outputs), program=prog, derivatives=fd,
                         output_exprs=gd, jacobian=jac, dfdx=dfdx, dfdu=dfdu, dgdx=dgdx, dgdu=dgdu,
                         provenance=provenance, events=events)
