"""Modelica-style composition of component models into one SymbolicModel.

``assemble(name, components, connections)`` takes instances (name ->
SymbolicModel) and causal connections ``("source.var", "target.input")`` and
returns one model:

* every variable is renamed with its instance name: FMI name ``valve.x_v``,
  sympy/C symbol ``valve__x_v`` (parameters too: ``valve.P_s``); the time
  symbol ``t`` is shared and never renamed;
* a connected input is replaced by the source's expression (a state, or an
  output -- an algebraic function of its component's states and inputs);
  an output that depends on inputs which are themselves connected is resolved
  recursively, and a cycle of such direct feedthroughs (an algebraic loop)
  is an error that names the loop;
* both ends of a connection must have the same unit (compared in SI base
  units, so ``N.m`` meets ``J`` but ``m3/s`` never meets ``rad``) unless the
  connection states a conversion as a third element ``(source, target,
  factor)``: the target then receives ``factor * source``;
* unconnected inputs become the assembly's inputs;
* states keep their ``output`` flag unless ``outputs`` says otherwise; all
  component outputs become assembly outputs unless ``outputs`` chooses;
* derivatives, outputs and the exact Jacobians are rebuilt by
  :meth:`SymbolicModel.from_equations` (symbolic differentiation of the
  assembled closed forms -- the components are small).

Components whose program contains a linear solve (the arm: M qdd = tau - h)
cannot be inlined into closed form; they are composed at the program level
instead (:func:`_assemble_programs`): the programs are renamed and merged,
each connected input becomes an assignment from its source, the steps are
ordered by their dependencies (a cycle is an algebraic loop), and the exact
Jacobians are obtained by differentiating the merged program, through the
linear solves.
"""
from __future__ import annotations

import heapq
import math
from dataclasses import replace
from typing import Mapping, Optional, Sequence

import sympy as sp

from ..codegen.differentiate import differentiate
from ..codegen.model import Clock, EventClause, Events, SymbolicModel, Variable
from ..codegen.program import Assign, Program, SolveSPD
from ..fmi.units import base_units

SEP = "__"  # C-safe separator of instance and variable in symbols


def _renamed(inst: str, v: Variable, **changes) -> Variable:
    return replace(v, name=f"{inst}.{v.name}", symbol=sp.Symbol(f"{inst}{SEP}{v.symbol.name}", real=True),
                   alias=f"{inst}.{v.alias}" if v.alias else "", **changes)


def _split(endpoint, where: str):
    if not isinstance(endpoint, str) or endpoint.count(".") < 1:
        raise ValueError(f"{where}: {endpoint!r} is not of the form 'instance.variable'")
    inst, var = endpoint.split(".", 1)
    return inst, var


def connection_parts(conn, k: int, where: str) -> tuple:
    """``(source, target, factor)`` of a connection given as a pair or a triple.

    The optional third element is a stated unit conversion: the target
    receives ``factor * source``.  Without it, source and target must have
    the same unit.
    """
    if not (isinstance(conn, (list, tuple)) and len(conn) in (2, 3)):
        raise ValueError(f"{where}: connection {k} must be a pair [source, target] (or [source, target, factor]), "
                         f"got {conn!r}")
    factor = conn[2] if len(conn) == 3 else None
    if factor is not None and (isinstance(factor, bool) or not isinstance(factor, (int, float))
                               or not math.isfinite(factor) or factor == 0):
        raise ValueError(f"{where}: connection {k} ({conn[0]} -> {conn[1]}): factor must be a finite non-zero "
                         f"number, got {factor!r}")
    return conn[0], conn[1], factor


def same_unit(a: str, b: str) -> bool:
    """True when two unit strings denote the same quantity (``N.m`` and ``J``, not ``m3/s`` and ``rad``)."""
    if a == b:
        return True
    try:
        ua, ub = base_units(a or "1"), base_units(b or "1")
    except ValueError:
        return False
    return ua.exponents() == ub.exponents() and math.isclose(ua.factor, ub.factor) and ua.offset == ub.offset


def _validated_connections(info: dict, connections: Sequence, where: str) -> dict:
    """(target instance, input name) -> (source instance, variable name, "state"|"output", factor or None)."""
    source_of = {}
    for k, conn in enumerate(connections):
        src, dst, factor = connection_parts(conn, k, where)
        conn = (src, dst)
        (si, sv), (ti, tv) = _split(conn[0], f"{where}: connection {k}"), _split(conn[1], f"{where}: connection {k}")
        for i_, end in ((si, conn[0]), (ti, conn[1])):
            if i_ not in info:
                raise ValueError(f"{where}: connection {k} ({conn[0]} -> {conn[1]}): no component named {i_!r}; "
                                 f"components: {', '.join(info)}")
        if sv in info[si]["states"]:
            kind = "state"
        elif sv in info[si]["outputs"]:
            kind = "output"
        else:
            raise ValueError(f"{where}: connection {k}: {conn[0]} is neither a state nor an output of {si} "
                             f"(states: {', '.join(info[si]['states']) or '-'}; "
                             f"outputs: {', '.join(info[si]['outputs']) or '-'})")
        if tv not in info[ti]["inputs"]:
            raise ValueError(f"{where}: connection {k}: {conn[1]} is not an input of {ti} "
                             f"(inputs: {', '.join(info[ti]['inputs']) or '-'})")
        if (ti, tv) in source_of:
            a = source_of[(ti, tv)]
            raise ValueError(f"{where}: input {conn[1]} is connected twice (from {a[0]}.{a[1]} and {conn[0]})")
        src_var = info[si]["states"][sv] if kind == "state" else info[si]["model"].outputs[info[si]["outputs"][sv]]
        dst_var = info[ti]["inputs"][tv]
        if factor is None and not same_unit(src_var.unit, dst_var.unit):
            raise ValueError(f"{where}: connection {k}: unit mismatch: {conn[0]} is in [{src_var.unit or '1'}] but "
                             f"{conn[1]} expects [{dst_var.unit or '1'}]; connect variables of the same unit, or "
                             f"state the conversion as a third element (factor: target = factor * source)")
        source_of[(ti, tv)] = (si, sv, kind, factor)
    return source_of


def assemble(name: str, components: Mapping[str, SymbolicModel], connections: Sequence,
             inputs: Optional[Sequence[str]] = None, outputs: Optional[Sequence[str]] = None,
             description: str = "", provenance: str = "", where: str = "assemble") -> SymbolicModel:
    """One SymbolicModel from connected components (see module docstring).

    ``inputs`` (optional) orders the unconnected inputs and must list all of
    them; ``outputs`` (optional) lists the exposed variables (states or
    outputs, ``"inst.var"``).  ``where`` prefixes error messages (a file name).

    >>> from fmugen.components import joint_inertia, hydraulic_actuator
    >>> m = assemble("a", {"act": hydraulic_actuator(), "joint": joint_inertia()},
    ...              [("act.tau", "joint.tau"), ("joint.w", "act.w")])
    >>> [v.name for v in m.states], [v.name for v in m.inputs]
    (['act.P_L', 'joint.theta', 'joint.w'], ['act.Q_L', 'joint.tau_load'])
    """
    for inst in components:
        if not inst.isidentifier() or SEP in inst:
            raise ValueError(f"{where}: instance name {inst!r} must be an identifier without '{SEP}'")
    if any(not isinstance(st, Assign) for m in components.values() for st in m.program.steps):
        return _assemble_programs(name, components, connections, inputs, outputs, description, provenance, where)
    # --- closed forms of every component, renamed ----------------------------
    info = {}
    for inst, m in components.items():
        ren = {}
        for group in (m.states, m.inputs, m.parameters, m.outputs, _discrete(m)):
            for v in group:
                ren[v.symbol] = sp.Symbol(f"{inst}{SEP}{v.symbol.name}", real=True)
        closed = m.program.inline(list(m.derivatives) + list(m.output_exprs))
        closed = [sp.sympify(e).xreplace(ren) for e in closed]
        info[inst] = dict(
            model=m, ren=ren,
            f=closed[:m.nx], g=closed[m.nx:],
            states={v.name: v for v in m.states}, inputs={v.name: v for v in m.inputs},
            outputs={v.name: k for k, v in enumerate(m.outputs)},
        )

    source_of = _validated_connections(info, connections, where)

    # --- resolve connected inputs (depth first, detecting algebraic loops) --------
    resolved = {}  # renamed input symbol -> expression in states / free inputs / parameters / t
    in_progress = []

    def input_symbol(inst, vname):
        return info[inst]["ren"][info[inst]["inputs"][vname].symbol]

    def resolve(inst, vname):
        sym = input_symbol(inst, vname)
        if sym in resolved:
            return resolved[sym]
        if (inst, vname) not in source_of:
            return sym  # a free input of the assembly
        if (inst, vname) in in_progress:
            loop = in_progress[in_progress.index((inst, vname)):] + [(inst, vname)]
            raise ValueError(f"{where}: algebraic loop through inputs {' -> '.join(f'{a}.{b}' for a, b in loop)} "
                             "(every output on it depends directly on its input); break it with a state")
        in_progress.append((inst, vname))
        si, sv, kind, factor = source_of[(inst, vname)]
        if kind == "state":
            expr = info[si]["ren"][info[si]["states"][sv].symbol]
        else:
            expr = info[si]["g"][info[si]["outputs"][sv]]
            sub = {}
            for iv in info[si]["inputs"].values():
                isym = info[si]["ren"][iv.symbol]
                if isym in expr.free_symbols:
                    sub[isym] = resolve(si, iv.name)
            expr = expr.xreplace(sub)
        if factor is not None:
            expr = sp.Float(factor) * expr
        in_progress.pop()
        resolved[sym] = expr
        return expr

    for (ti, tv) in source_of:
        resolve(ti, tv)

    v = _assembled_variables(info, source_of, inputs, outputs, description, provenance, where, resolved)
    states, free, params, ders, outs, out_exprs, desc, prov = v
    events = _assembled_events(components, info, lambda m, e: m.program.inline([e])[0], resolved)
    return SymbolicModel.from_equations(name, states, free, params, ders, outs, out_exprs,
                                        description=desc, provenance=prov, events=events)


def _discrete(m: SymbolicModel) -> tuple:
    return tuple(m.events.discrete) if m.events is not None else ()


def _assembled_events(components, info, closed, resolved) -> Optional[Events]:
    """The components' events, renamed like their variables: discrete states ``inst.name``, indicators
    ``inst: name``; ``closed(model, expr)`` gives an event expression in the assembly's terms (the
    closed-form path inlines the component's program; the program path keeps program symbols, renamed),
    and connected inputs are replaced by ``resolved`` (empty on the program path, where they are
    assignments of the program)."""
    discrete, indicators, clauses, clocks = [], [], [], []
    for inst, m in components.items():
        if m.events is None:
            continue
        ren = info[inst]["ren"]

        def term(e):
            return sp.sympify(closed(m, sp.sympify(e))).xreplace(ren).xreplace(resolved)

        renamed = {v.symbol: _renamed(inst, v) for v in m.events.discrete}
        discrete += list(renamed.values())
        indicators += [(f"{inst}: {n}", term(e)) for n, e in m.events.indicators]
        clauses += [EventClause(term(c.guard), tuple((ren[t], term(e)) for t, e in c.assign),
                                f"{inst}: {c.name}" if c.name else inst) for c in m.events.clauses]
        # sample clocks: timing of the parameters, the tick flag the renamed discrete state
        clocks += [Clock(term(k.period), term(k.offset), renamed[k.tick.symbol])
                   for k in getattr(m.events, "clocks", ())]
    if not (discrete or indicators or clauses):
        return None
    return Events(tuple(discrete), tuple(indicators), tuple(clauses), tuple(clocks))


def _assembled_variables(info, source_of, inputs, outputs, description, provenance, where, resolved):
    """States, free inputs, parameters, derivatives, outputs of an assembly, renamed.

    ``resolved`` substitutes connected inputs in closed forms (empty for the
    program-level path, where connections are assignments in the program).
    Returns (states, free inputs, parameters, derivatives, outputs, output
    expressions, description, provenance).
    """
    chosen = None if outputs is None else list(outputs)
    chosen_set = set(chosen or [])
    for o in chosen_set:
        oi, ov = _split(o, f"{where}: outputs")
        if oi not in info or (ov not in info[oi]["states"] and ov not in info[oi]["outputs"]):
            raise ValueError(f"{where}: outputs: {o} is neither a state nor an output of a component")
    states, ders, free, params, outs, out_exprs = [], [], [], [], [], []
    for inst, d in info.items():
        m = d["model"]
        for v, f in zip(m.states, d["f"]):
            flag = v.output if chosen is None else f"{inst}.{v.name}" in chosen_set
            states.append(_renamed(inst, v, output=flag))
            ders.append(f.xreplace(resolved))
        for v in m.inputs:
            if (inst, v.name) not in source_of:
                free.append(_renamed(inst, v))
        params += [_renamed(inst, v) for v in m.parameters]
    # outputs in the order asked for (or component order)
    order = chosen if chosen is not None else [f"{i}.{v.name}" for i, d in info.items() for v in d["model"].outputs]
    for o in order:
        oi, ov = o.split(".", 1)
        if ov in info[oi]["outputs"]:
            k = info[oi]["outputs"][ov]
            outs.append(_renamed(oi, info[oi]["model"].outputs[k]))
            out_exprs.append(info[oi]["g"][k].xreplace(resolved))
    if inputs is not None:
        by_name = {v.name: v for v in free}
        missing = sorted(set(by_name) - set(inputs))
        extra = sorted(set(inputs) - set(by_name))
        if missing or extra:
            raise ValueError(f"{where}: inputs must list every unconnected input exactly; "
                             f"missing: {', '.join(missing) or '-'}; not unconnected inputs: {', '.join(extra) or '-'}")
        free = [by_name[n] for n in inputs]
    desc = description or "assembly of " + ", ".join(f"{i} ({d['model'].description})" for i, d in info.items())
    prov = provenance or "; ".join(f"{i}: {d['model'].provenance}" for i, d in info.items() if d["model"].provenance)
    return states, free, params, ders, outs, out_exprs, desc, prov


def _assemble_programs(name, components, connections, inputs, outputs, description, provenance, where):
    """Program-level composition (see the module docstring)."""
    info, steps = {}, []
    for inst, m in components.items():
        ren = {}
        for group in (m.states, m.inputs, m.parameters, m.outputs, _discrete(m)):
            for v in group:
                ren[v.symbol] = sp.Symbol(f"{inst}{SEP}{v.symbol.name}", real=True)
        for sym in m.program.assigned_symbols():
            ren[sym] = sp.Symbol(f"_{inst}{SEP}{sym.name.lstrip('_')}", real=True)
        for st in m.program.steps:
            if isinstance(st, Assign):
                steps.append(Assign(ren[st.symbol], st.expr.xreplace(ren)))
            else:
                steps.append(SolveSPD(st.X.xreplace(ren), st.A.xreplace(ren), st.B.xreplace(ren)))
        info[inst] = dict(
            model=m, ren=ren,
            f=[sp.sympify(e).xreplace(ren) for e in m.derivatives],
            g=[sp.sympify(e).xreplace(ren) for e in m.output_exprs],
            states={v.name: v for v in m.states}, inputs={v.name: v for v in m.inputs},
            outputs={v.name: k for k, v in enumerate(m.outputs)},
        )
    source_of = _validated_connections(info, connections, where)
    for (ti, tv), (si, sv, kind, factor) in source_of.items():
        target = info[ti]["ren"][info[ti]["inputs"][tv].symbol]
        src = (info[si]["ren"][info[si]["states"][sv].symbol] if kind == "state"
               else info[si]["g"][info[si]["outputs"][sv]])
        steps.append(Assign(target, src if factor is None else sp.Float(factor) * src))
    program = Program("_a")
    program.steps = _ordered(steps, source_of, info, where)

    v = _assembled_variables(info, source_of, inputs, outputs, description, provenance, where, {})
    states, free, params, ders, outs, out_exprs, desc, prov = v
    xs, us = [v.symbol for v in states], [v.symbol for v in free]
    jac = Program("_b")
    F = differentiate([program], ders, xs + us, jac, through_solves=True)
    G = differentiate([program], out_exprs, xs + us, jac, through_solves=True) if out_exprs else sp.zeros(0, len(xs + us))
    nx = len(xs)
    return SymbolicModel(
        name=name, description=desc, states=tuple(states), inputs=tuple(free), parameters=tuple(params),
        outputs=tuple(outs), program=program, derivatives=tuple(ders), output_exprs=tuple(out_exprs),
        jacobian=jac, dfdx=F[:, :nx], dfdu=F[:, nx:], dgdx=G[:, :nx], dgdu=G[:, nx:], provenance=prov,
        events=_assembled_events(components, info, lambda m, e: e, {}),
    )


def _ordered(steps, source_of, info, where) -> list:
    """Steps in an order where every symbol is assigned before it is read.

    Kahn's algorithm, keeping the given order where it is free; a cycle
    means an algebraic loop through connected inputs, named in the error.
    """
    defines = {}
    for k, st in enumerate(steps):
        for s_ in ([st.symbol] if isinstance(st, Assign) else list(st.X)):
            defines[s_] = k

    def reads(st):
        if isinstance(st, Assign):
            return st.expr.free_symbols
        out = set()
        for e in list(st.A) + list(st.B):
            out |= sp.sympify(e).free_symbols
        return out

    deps = [{defines[s_] for s_ in reads(st) if s_ in defines} for st in steps]
    users = [[] for _ in steps]
    for k, ds in enumerate(deps):
        for d in ds:
            users[d].append(k)
    waiting = [len(ds) for ds in deps]
    ready = [k for k, w in enumerate(waiting) if w == 0]
    heapq.heapify(ready)
    order = []
    while ready:
        k = heapq.heappop(ready)
        order.append(k)
        for u in users[k]:
            waiting[u] -= 1
            if waiting[u] == 0:
                heapq.heappush(ready, u)
    if len(order) < len(steps):
        stuck = {k for k, w in enumerate(waiting) if w > 0}
        names = []
        for (ti, tv) in source_of:
            sym = info[ti]["ren"][info[ti]["inputs"][tv].symbol]
            if defines.get(sym) in stuck:
                names.append(f"{ti}.{tv}")
        raise ValueError(f"{where}: algebraic loop through inputs {', '.join(sorted(names))} "
                         "(outputs that depend directly on their inputs form a cycle); break it with a state")
    return [steps[k] for k in order]
