"""The generic symbolic model that the code generator and the FMU builder take.

Every component fmugen exports -- a manipulator, an actuator, a controller --
is first a :class:`SymbolicModel`:

    x' = f(x, u, p),   y = g(x, u, p)

with states x, inputs u, parameters p and (computed) outputs y.  ``program``
is a straight-line program (:mod:`fmugen.codegen.program`) after which the
expressions ``derivatives`` (one per state) and ``outputs`` (one per output
variable) can be read.  ``jacobian`` (optional) is a second program whose
results ``dfdx, dfdu, dgdx, dgdu`` give the exact partial derivatives; it may
use the symbols of ``program`` (it runs after it).

States can also be outputs (``Variable.output``), which is how the arm exposes
q and qd for co-simulation without direct feedthrough.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, replace
from typing import Optional, Sequence

import sympy as sp

from .chain import ChainDynamics, chain_ops
from .program import Assign, Program
from ..errors import FmugenError


#: ``min`` of a quantity that must be > 0 (a mass, a time constant): the smallest
#: positive normal double, since FMI's min is inclusive
POSITIVE_MIN = sys.float_info.min


@dataclass(frozen=True)
class Variable:
    """A model variable: FMI name, C/sympy symbol, unit, description, start."""

    name: str  # FMI name, e.g. "q[1]"
    symbol: sp.Symbol  # identifier used in generated code, e.g. q_1
    unit: str = ""
    description: str = ""
    start: Optional[float] = None
    nominal: Optional[float] = None
    min: Optional[float] = None
    max: Optional[float] = None
    output: bool = False  # for states: also exposed as an output
    # parameters: their physical sign, ">0" (an inertia, a time constant) or ">=0" (a leakage); every
    # value given later (with_starts: --set, start tables, sweep points) is checked against it
    sign: str = ""
    # a second FMI name for the same value (an FMI 2.0 alias: same value reference), e.g. a URDF joint's
    # "shoulder_pan_joint.q" for q[1]; "" = none (fmi/model_description.py writes it)
    alias: str = ""


def physical_range(v: Variable) -> tuple:
    """``(min, max)`` of a parameter with its physical sign applied (``">0"``: at least
    :data:`POSITIVE_MIN`, ``">=0"``: at least 0): the range its FMU declares and enforces."""
    lo = v.min
    floor = POSITIVE_MIN if v.sign == ">0" else 0.0 if v.sign == ">=0" else None
    if floor is not None and (lo is None or float(lo) < floor):
        lo = floor
    return lo, v.max


@dataclass(frozen=True)
class EventClause:
    """One guarded assignment of a hybrid model: at an event, when ``guard`` holds, every
    ``(target, expr)`` of ``assign`` is applied -- a discrete state takes a new value, or a state is
    re-initialised (Modelica's ``reinit``).

    ``guard`` and the values are sympy expressions of the states, inputs, parameters, discrete states,
    time ``t`` and the symbols of the model's program (a robot's constraint torque), evaluated with the
    values at the event; all clauses of one round are evaluated first and then applied in order (a later
    clause wins a shared target).
    """

    guard: sp.Basic
    assign: tuple  # ((target symbol, value expression), ...)
    name: str = ""  # for messages: the file's name of the clause


@dataclass(frozen=True)
class Clock:
    """A sample clock of a hybrid model: ticks at t = offset + j period (j = 0, 1, ...), time events.

    ``period``, ``offset``: expressions of the parameters (numbers or parameter symbols); ``tick``: a
    discrete state of the model's :class:`Events` (start 0) that the runtime sets to 1 for the first round
    of the event iteration at each tick, so that a clause guarded by ``tick > 0`` fires once per sample
    instant (a sampled controller's update)."""

    period: sp.Basic
    offset: sp.Basic
    tick: Variable


@dataclass(frozen=True)
class Events:
    """What makes a model hybrid (FMI 2.0 events; see c_runtime/README.md "Events").

    ``discrete``: Variables of the discrete states (start values required), constant between events;
    the continuous equations read them like parameters.  ``indicators``: ``(name, expr)`` pairs, a state
    event when one changes its domain expr > 0 <-> expr <= 0.  ``clauses``: the :class:`EventClause`
    list run at every event, round after round, until no discrete state and no state changes (the event
    iteration).  Indicators and clauses may read the program's symbols: the generated ``indicators`` and
    ``update`` run the program steps they need.
    """

    discrete: tuple = ()
    indicators: tuple = ()
    clauses: tuple = ()
    clocks: tuple = ()  # of Clock: sampled updates (time events)

    def expressions(self) -> list:
        """Every expression the events evaluate (indicators, guards, assigned values, clock timing)."""
        out = [sp.sympify(e) for _, e in self.indicators]
        for c in self.clauses:
            out.append(c.guard)
            out += [sp.sympify(e) for _, e in c.assign]
        for k in self.clocks:
            out += [sp.sympify(k.period), sp.sympify(k.offset)]
        return out

    def substituted(self, env: dict) -> "Events":
        """A copy with ``env`` (symbol -> expression) replaced everywhere."""
        sub = lambda e: sp.sympify(e).xreplace(env)  # noqa: E731
        return Events(self.discrete, tuple((n, sub(e)) for n, e in self.indicators),
                      tuple(EventClause(sub(c.guard), tuple((t, sub(e)) for t, e in c.assign), c.name)
                            for c in self.clauses),
                      tuple(Clock(sub(k.period), sub(k.offset), k.tick) for k in self.clocks))


@dataclass(frozen=True)
class SymbolicModel:
    name: str
    description: str
    states: tuple
    inputs: tuple
    parameters: tuple
    outputs: tuple
    program: Program
    derivatives: tuple  # expressions, one per state
    output_exprs: tuple  # expressions, one per output
    jacobian: Optional[Program] = None
    dfdx: Optional[sp.Matrix] = None
    dfdu: Optional[sp.Matrix] = None
    dgdx: Optional[sp.Matrix] = None
    dgdu: Optional[sp.Matrix] = None
    # where the equations come from, printed in generated files
    provenance: str = ""
    # a hybrid model's discrete states, event indicators and event clauses (None: smooth)
    events: Optional[Events] = None

    # -- construction ----------------------------------------------------
    @staticmethod
    def from_equations(
        name: str,
        states: Sequence[Variable],
        inputs: Sequence[Variable],
        parameters: Sequence[Variable],
        derivatives: Sequence[sp.Expr],
        outputs: Sequence[Variable] = (),
        output_exprs: Sequence[sp.Expr] = (),
        description: str = "",
        provenance: str = "",
        events: Optional[Events] = None,
    ) -> "SymbolicModel":
        """An explicit ODE model from plain expressions (small components).

        The Jacobians are obtained by symbolic differentiation (a discrete state of ``events`` is a
        constant to it: the Jacobian of the mode the model is in).
        """
        states, inputs = tuple(states), tuple(inputs)
        f = sp.Matrix([sp.sympify(e) for e in derivatives])
        g = sp.Matrix([sp.sympify(e) for e in output_exprs]) if outputs else sp.zeros(0, 1)
        if len(f) != len(states):
            raise ValueError(f"{name}: {len(f)} derivative expressions for {len(states)} states")
        if len(g) != len(outputs):
            raise ValueError(f"{name}: {len(g)} output expressions for {len(outputs)} outputs")
        xs = [v.symbol for v in states]
        us = [v.symbol for v in inputs]
        prog = Program("_w")
        fd = tuple(prog.let(e, "f") for e in f)
        gd = tuple(prog.let(e, "g") for e in g)
        jac = Program("_j")

        def jm(exprs, wrt):
            if not wrt or len(exprs) == 0:
                return sp.zeros(len(exprs), len(wrt))
            return sp.Matrix(len(exprs), len(wrt), lambda i, j: jac.let(_finite_signs(sp.diff(exprs[i], wrt[j]))))

        return SymbolicModel(
            name=name,
            description=description,
            states=states,
            inputs=inputs,
            parameters=tuple(parameters),
            outputs=tuple(outputs),
            program=prog,
            derivatives=fd,
            output_exprs=gd,
            jacobian=jac,
            dfdx=jm(f, xs),
            dfdu=jm(f, us),
            dgdx=jm(g, xs),
            dgdu=jm(g, us),
            provenance=provenance,
            events=events if events is not None and (events.discrete or events.indicators or events.clauses
                                                     or events.clocks) else None,
        )

    # -- queries -----------------------------------------------------------
    @property
    def nx(self) -> int:
        return len(self.states)

    @property
    def nu(self) -> int:
        return len(self.inputs)

    @property
    def ny(self) -> int:
        return len(self.outputs)

    @property
    def np(self) -> int:
        return len(self.parameters)

    def dependencies(self, knowns: Optional[Sequence[sp.Symbol]] = None) -> dict:
        """Exact structural dependencies of derivatives and outputs.

        Returns ``{"derivatives": [set, ...], "outputs": [set, ...]}`` where
        each set holds the symbols among ``knowns`` (default: states and
        inputs; add parameters for the InitialUnknowns) the quantity depends
        on, propagated through the program (a linear solve couples all its
        unknowns with everything in A and B).
        """
        if knowns is None:
            knowns = [v.symbol for v in self.states] + [v.symbol for v in self.inputs]
        knowns = set(knowns)
        deps: dict = {}

        def of(expr) -> set:
            out = set()
            for s in sp.sympify(expr).free_symbols:
                if s in knowns:
                    out.add(s)
                elif s in deps:
                    out |= deps[s]
            return out

        for st in self.program.steps:
            if isinstance(st, Assign):
                deps[st.symbol] = of(st.expr)
            else:
                d = set()
                for e in list(st.A) + list(st.B):
                    d |= of(e)
                for x in st.X:
                    deps[x] = d
        return {
            "derivatives": [of(e) for e in self.derivatives],
            "outputs": [of(e) for e in self.output_exprs],
        }

    def parameter_values(self) -> dict:
        return {v.symbol: v.start for v in self.parameters if v.start is not None}

    def with_parameters_folded(self, names: Optional[Sequence[str]] = None) -> "SymbolicModel":
        """A copy in which parameters (all, or those named) become constants.

        Folding lets the generator simplify with the numbers (zeros vanish,
        products of constants are computed once); the folded parameters are
        no longer settable in the FMU.
        """
        chosen = [v for v in self.parameters if names is None or v.name in names]
        missing = [v.name for v in chosen if v.start is None]
        if missing:
            raise ValueError(f"{self.name}: cannot fold parameters without a value: {', '.join(missing)}")
        values = {v.symbol: _number(v.start) for v in chosen}
        kept = tuple(v for v in self.parameters if v not in chosen)
        return replace(self._with_constants(values), parameters=kept)

    def _with_constants(self, values: dict) -> "SymbolicModel":
        """Every symbol of ``values`` replaced by its number, constants propagated.

        A step whose expression becomes a number disappears into the
        environment, so zeros vanish from everything downstream.
        """
        def fold_program(prog: Optional[Program], env: dict) -> tuple:
            if prog is None:
                return None, env
            env = dict(env)
            out = Program(prog.prefix)
            out._count = prog._count
            for st in prog.steps:
                if isinstance(st, Assign):
                    e = st.expr.xreplace(env)
                    if e.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
                        _undefined(self.name, st.symbol, e, values)
                    if e.is_Number:
                        env[st.symbol] = e
                    else:
                        out.steps.append(Assign(st.symbol, e))
                else:
                    # replace() keeps the step's class (a ChainDynamics stays a chain call)
                    out.steps.append(replace(st, A=st.A.xreplace(env), B=st.B.xreplace(env)))
            return out, env

        # the Jacobian program runs after the main one and sees its folded constants
        prog, env = fold_program(self.program, values)
        jprog, full = fold_program(self.jacobian, env)
        def sub(e):
            r = sp.sympify(e).xreplace(full)
            if r.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
                _undefined(self.name, "an equation", r, values)
            return r

        subm = lambda m: None if m is None else m.xreplace(full)  # noqa: E731
        return replace(
            self,
            program=prog,
            derivatives=tuple(sub(e) for e in self.derivatives),
            output_exprs=tuple(sub(e) for e in self.output_exprs),
            jacobian=jprog,
            dfdx=subm(self.dfdx),
            dfdu=subm(self.dfdu),
            dgdx=subm(self.dgdx),
            dgdu=subm(self.dgdu),
            events=None if self.events is None else self.events.substituted(full),
        )

    # -- scene-driven reductions ---------------------------------------------
    def with_inputs_fixed(self, values: dict) -> "SymbolicModel":
        """A copy in which the inputs named in ``values`` are constants.

        An input nothing drives is a constant of the scene: folding it (most
        often to zero, e.g. external wrenches) removes the terms it feeds.
        The Jacobian columns of those inputs are dropped.
        """
        by_name = {v.name: v for v in self.inputs}
        unknown = sorted(set(values) - set(by_name))
        if unknown:
            raise ValueError(f"{self.name}: {', '.join(unknown)} not inputs (inputs: {', '.join(by_name) or '-'})")
        consts = {by_name[n].symbol: _number(x) for n, x in values.items()}
        keep = [k for k, v in enumerate(self.inputs) if v.name not in values]
        m = self._with_constants(consts)
        cols = lambda M: None if M is None else M.extract(list(range(M.rows)), keep)  # noqa: E731
        return replace(m, inputs=tuple(self.inputs[k] for k in keep), dfdu=cols(m.dfdu), dgdu=cols(m.dgdu))

    def with_outputs(self, names: Sequence[str]) -> "SymbolicModel":
        """A copy with only the outputs named (in that order), programs pruned.

        States stay; a state named in ``names`` is flagged as an output.
        """
        outs = {v.name: k for k, v in enumerate(self.outputs)}
        states = {v.name for v in self.states}
        unknown = [n for n in names if n not in outs and n not in states]
        if unknown:
            raise ValueError(f"{self.name}: {', '.join(unknown)} neither outputs nor states "
                             f"(outputs: {', '.join(outs) or '-'})")
        rows = [outs[n] for n in names if n in outs]
        st = tuple(replace(v, output=True) if v.name in names else v for v in self.states)
        pick = lambda M: None if M is None else M.extract(rows, list(range(M.cols)))  # noqa: E731
        m = replace(self, states=st, outputs=tuple(self.outputs[k] for k in rows),
                    output_exprs=tuple(self.output_exprs[k] for k in rows),
                    dgdx=pick(self.dgdx), dgdu=pick(self.dgdu))
        return m.pruned()

    def without_jacobian(self) -> "SymbolicModel":
        """A copy without the Jacobian program (FMU: providesDirectionalDerivative=false)."""
        return replace(self, jacobian=None, dfdx=None, dfdu=None, dgdx=None, dgdu=None).pruned()

    def with_starts(self, values: dict) -> "SymbolicModel":
        """A copy whose states, inputs or parameters named in ``values`` have new start values."""
        from ..values import as_number, variable_problem

        for v in self.parameters:  # the same physical check whatever path the value took
            if v.name in values:
                problem = variable_problem(v, values[v.name])
                if problem:
                    shown = repr(values[v.name])
                    shown = shown if len(shown) <= 40 else shown[:20] + "..."
                    raise FmugenError(f"{self.name}: parameter {v.name} = {shown} {problem}")
        groups = {}
        for g in ("states", "inputs", "parameters"):
            groups[g] = tuple(replace(v, start=as_number(values[v.name], f"{self.name}: {v.name}"))
                              if v.name in values else v for v in getattr(self, g))
        events = self.events
        if events is not None:  # a discrete state's start: the mode the model starts in
            events = replace(events, discrete=tuple(
                replace(v, start=as_number(values[v.name], f"{self.name}: {v.name}")) if v.name in values else v
                for v in events.discrete))
        known = {v.name for g in groups.values() for v in g} | {v.name for v in (events.discrete if events else ())}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"{self.name}: {', '.join(unknown)} not a state, input, parameter or discrete state")
        return replace(self, events=events, **groups)

    def with_ranges_narrowed(self, ranges: dict) -> "SymbolicModel":
        """A copy whose states and outputs named in ``ranges`` ({name: (min, max)}, None = open) keep
        only the intersection of their own validity range and the one given."""
        if not ranges:
            return self

        def narrowed(v):
            if v.name not in ranges:
                return v
            lo, hi = intersect_range((v.min, v.max), ranges[v.name])
            return replace(v, min=lo, max=hi)

        return replace(self, states=tuple(map(narrowed, self.states)), outputs=tuple(map(narrowed, self.outputs)))

    def pruned(self) -> "SymbolicModel":
        """A copy whose programs hold only the steps the results need."""
        jac_needs = []
        if self.jacobian is not None:
            mats = [M for M in (self.dfdx, self.dfdu, self.dgdx, self.dgdu) if M is not None]
            jac_needs = [e for M in mats for e in M]
            jprog = self.jacobian.pruned(jac_needs)
            reads = set()
            for stp in jprog.steps:
                if isinstance(stp, Assign):
                    reads |= stp.expr.free_symbols
                else:
                    for e in list(stp.A) + list(stp.B):
                        reads |= sp.sympify(e).free_symbols
            jac_needs = list(reads) + jac_needs
        else:
            jprog = None
        ev_needs = self.events.expressions() if self.events is not None else []
        prog = self.program.pruned(list(self.derivatives) + list(self.output_exprs) + jac_needs + ev_needs)
        return replace(self, program=prog, jacobian=jprog)

    def operation_count(self) -> int:
        """Number of operations of the programs (sympy's count_ops), a size measure for reports."""
        n = 0
        for prog in (self.program, self.jacobian):
            if prog is None:
                continue
            for stp in prog.steps:
                if isinstance(stp, Assign):
                    n += sp.count_ops(stp.expr)
                elif isinstance(stp, ChainDynamics):  # the runtime's loops
                    ops = chain_ops(stp.n, stp.kind, len(stp.external))
                    n += ops.mul + ops.add + ops.div + ops.n_calls
                else:
                    n += stp.X.rows ** 3 // 3 + stp.X.rows ** 2 * stp.X.cols
        return n


def intersect_range(a: tuple, b: tuple) -> tuple:
    """Intersection of two (min, max) ranges in which None means unbounded."""
    lo = a[0] if b[0] is None else (b[0] if a[0] is None else max(a[0], b[0]))
    hi = a[1] if b[1] is None else (b[1] if a[1] is None else min(a[1], b[1]))
    return lo, hi


def _finite_signs(expr):
    """``sign(a)**-k`` -> ``sign(a)**k``: equal wherever a != 0, and finite at a = 0.

    sympy's derivatives of nested ``Abs`` (the smooth rails and stroke limits)
    can come out as ``1/sign(a)``, which is 0/0 in C exactly at the kink
    (a spool resting on its stroke limit).
    """
    return expr.replace(lambda e: e.is_Pow and isinstance(e.base, sp.sign) and e.exp.is_negative,
                        lambda e: e.base ** (-e.exp))


def _undefined(model: str, where, expr, values: dict) -> None:
    """Folding constants made ``expr`` undefined (a division by zero): name the values, never emit it as C."""
    zeros = [f"{s} = 0" for s, v in values.items() if v == 0]
    raise FmugenError(f"{model}: with {', '.join(zeros) or 'the values folded into constants'} the equations "
                      f"divide by zero ({where} becomes {expr}); give {'these' if len(zeros) > 1 else 'it'} a "
                      f"non-zero value")


def _number(x) -> sp.Expr:
    x = float(x)
    return sp.Integer(int(x)) if x.is_integer() else sp.Float(x)
