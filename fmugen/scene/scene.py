"""A scene: instances, connections, FMU groups, recorded outputs, one run.

``Scene`` is the one description every later step reads: the build (one
FMU per group, :mod:`fmugen.scene.build`), the co-simulation system
(:meth:`Scene.cosim_system`), the monolithic model and the reference
problem, the consistent initial state (:mod:`fmugen.scene.equilibrium`).

Names: a scene variable is ``instance.variable`` (``arm.q[2]``,
``valve1.x_v``).  Inside an FMU of one instance the instance's own names
are kept (``q[2]``, ``theta``); an FMU of several instances uses
``instance.variable``.
"""
from __future__ import annotations

import os
from dataclasses import replace
from functools import cached_property
from pathlib import Path
from typing import Optional

import numpy as np

from ..codegen.model import SymbolicModel, intersect_range
from ..components.connect import assemble, same_unit
from .errors import SceneError, did_you_mean
from .file import GroupSpec, SOLVERS, apply_sets, parse_scene, read_toml
from .instances import instance_model
from .repeat import expand_repeats
from .settings import parse_sets

#: instance kinds whose FMU integrates torques into motion: first in Gauss-Seidel
_MECHANICAL_TYPES = {"joint_inertia", "dc_motor"}


def load_scene(path, set=None, allow_factories: bool = False) -> "Scene":
    """Read a scene file; ``set`` holds ``--set`` overrides (``{"joint.J": 5}`` or ``["joint.J=5"]``).

    A scene file is data: an instance with ``factory = "module:function"``
    imports and runs Python code, so it is refused unless the caller allows
    it (``allow_factories=True``, ``--allow-factories``, or the environment
    variable ``FMUGEN_ALLOW_FACTORIES=1``).
    """
    path = Path(path)
    sets = parse_sets(set)
    data = expand_repeats(read_toml(path), str(path))
    deferred = apply_sets(data, sets, str(path))
    spec = parse_scene(data, path)
    return Scene(spec, deferred, allow_factories=allow_factories)


class Scene:
    def __init__(self, spec, deferred_sets: Optional[dict] = None, allow_factories: bool = False):
        self.spec = spec
        self.src = str(spec.path)
        self._sets = deferred_sets or {}
        allowed = allow_factories or os.environ.get("FMUGEN_ALLOW_FACTORIES") == "1"
        for name, ins in spec.instances.items():
            if ins.kind == "factory" and not allowed:
                raise SceneError(f"{self.src}: [instances.{name}] factory = {ins.source!r} runs Python code from "
                                 f"your environment; allow it with --allow-factories (API: allow_factories=True, "
                                 f"or FMUGEN_ALLOW_FACTORIES=1) if you trust this file")
        if spec.connect:  # bonds -> signal connections (checked below like any other); done once per spec
            from .connect import expand_connect

            extra, bonds = expand_connect(self, spec.connect)
            self.spec = spec = replace(spec, connections=spec.connections + tuple(extra), connect=(), bonds=bonds)
            if spec.record_bonds:
                from .bonds import bond_variables

                self.spec = spec = replace(spec, record=tuple(dict.fromkeys(spec.record + tuple(bond_variables(bonds)))))
        self.connections = self._checked_connections()
        self._check_record()
        self._check_loops()
        self._check_undriven_inputs()
        self._check_exposed_inputs()
        self.external = None  # [external]: an SSP's components beside the instances (scene/external.py)
        if spec.external is not None:
            from .external import read_external

            self.external = read_external(self, spec.external)

    # ------------------------------------------------------------------ basics
    @property
    def name(self) -> str:
        return self.spec.name

    @cached_property
    def base_models(self) -> dict:
        """instance -> SymbolicModel with every robot output the scene may use."""
        out = {}
        for name, ins in self.spec.instances.items():
            outs = ("p_ee", "qdd") + _frame_outputs(ins) if ins.kind == "robot" else ()
            out[name] = instance_model(ins, self.spec.parameter_set, self.src, self._sets.get(name), outs)
        return out

    def _var(self, inst: str, var: str, where: str):
        """(kind, Variable) of ``inst.var``: kind is "state", "input" or "output"."""
        m = self.base_models[inst]
        for kind, group in (("state", m.states), ("input", m.inputs), ("output", m.outputs)):
            for v in group:
                if v.name == var:
                    return kind, v
        names = [v.name for g in (m.states, m.inputs, m.outputs) for v in g]
        raise SceneError(f"{where}: {inst} has no variable {var!r}{did_you_mean(var, names)}; "
                         f"variables: {', '.join(names)}")

    def _endpoint(self, text: str, where: str) -> tuple:
        if "." not in text:
            raise SceneError(f"{where}: {text!r} is not 'instance.variable'")
        inst, var = text.split(".", 1)
        if inst not in self.spec.instances:
            raise SceneError(f"{where}: no instance {inst!r}{did_you_mean(inst, self.spec.instances)}; "
                             f"instances: {', '.join(self.spec.instances)}")
        return inst, var

    def _checked_connections(self) -> list:
        """[(source inst, var, target inst, input, factor)]: existence, direction, units, fan-in."""
        out, seen = [], {}
        for k, (s, t, factor) in enumerate(self.spec.connections):
            where = f"{self.src}: [scene] connections[{k}] ({s} -> {t})"
            si, sv = self._endpoint(s, where)
            ti, tv = self._endpoint(t, where)
            skind, svar = self._var(si, sv, where)
            tkind, tvar = self._var(ti, tv, where)
            if skind == "input":
                raise SceneError(f"{where}: wrong direction: {s} is an input; a connection goes from a state "
                                 f"or output to an input")
            if tkind != "input":
                raise SceneError(f"{where}: wrong direction: {t} is a {tkind}, not an input")
            if factor is None and not same_unit(svar.unit, tvar.unit):
                raise SceneError(f"{where}: unit mismatch: {s} is in [{svar.unit or '1'}] but {t} expects "
                                 f"[{tvar.unit or '1'}]; state a conversion with "
                                 f"{{ from = \"{s}\", to = \"{t}\", factor = ... }}")
            if (ti, tv) in seen:
                raise SceneError(f"{where}: input {t} is already driven by {seen[(ti, tv)]}")
            seen[(ti, tv)] = s
            out.append((si, sv, ti, tv, factor))
        return out

    def _check_record(self) -> None:
        for r in self.spec.record:
            inst, var = self._endpoint(r, f"{self.src}: [scene] record")
            kind, _ = self._var(inst, var, f"{self.src}: [scene] record")
            if kind == "input":
                raise SceneError(f"{self.src}: [scene] record: {r} is an input; record the state or output "
                                 f"that drives it")

    def _check_undriven_inputs(self) -> None:
        """An input nothing drives needs a value: its default (start) or one the scene gives."""
        for inst in self.spec.instances:
            for v in self.undriven_inputs(inst):
                if v.start is None:
                    raise SceneError(f"{self.src}: [instances.{inst}]: input {v.name} is not connected and has no "
                                     f"default; connect it or give start = {{ {v.name} = ... }}")

    def _check_exposed_inputs(self) -> None:
        """``[scene] inputs``: undriven inputs that stay inputs of their FMU (of the system)."""
        seen = set()
        driven = {(ti, tv) for _, _, ti, tv, _ in self.connections}
        for name in self.spec.inputs:
            where = f"{self.src}: [scene] inputs"
            inst, var = self._endpoint(name, where)
            kind, _ = self._var(inst, var, where)
            if kind != "input":
                raise SceneError(f"{where}: {name} is a {kind}, not an input")
            if (inst, var) in driven:
                raise SceneError(f"{where}: {name} is driven by a connection; only undriven inputs can be inputs "
                                 f"of the system")
            if name in seen:
                raise SceneError(f"{where}: {name} is listed twice")
            seen.add(name)

    def system_inputs(self, prune: Optional[bool] = None) -> list:
        """Undriven inputs that stay inputs of the built FMUs ("inst.var"): all of them without pruning,
        else those ``[scene] inputs`` lists (the others are fixed at their start values)."""
        prune = self.spec.prune if prune is None else prune
        outside = self._externally_driven()
        out = []
        for inst in self.spec.instances:
            for v in self.undriven_inputs(inst):
                name = f"{inst}.{v.name}"
                if name not in outside and (not prune or name in self.spec.inputs):
                    out.append(name)
        return out

    def _externally_driven(self) -> set:
        """Scene inputs an SSP component drives ("inst.var"): they stay inputs of their FMU."""
        return {f"{i}.{v}" for _, _, i, v, _ in self.external.to_scene} if self.external else set()

    def external_links(self, members) -> list:
        """[external] connections touching ``members`` (for the build's cache key)."""
        if not self.external:
            return []
        return [list(map(str, c)) for c in self.external.to_scene if c[2] in members] + \
            [list(map(str, c)) for c in self.external.from_scene if c[0] in members]

    @cached_property
    def rest_inputs(self) -> dict:
        """Value of every connected input at the initial state ("inst.var" -> value), from
        :meth:`input_values`.  Baked into the FMUs as the inputs' start values, so an FMU run alone or by
        another importer starts where the scene starts (the arm's torques at the holding torques)."""
        return self.input_values(self.initial.values, self.spec.start)

    def input_values(self, values: dict, t: float) -> dict:
        """Every connected input's value ("inst.var") with the scene's states at ``values``: its source's
        value (times the connection's factor), evaluated instance by instance in the order of the
        connections' dependencies (the scene has no algebraic loop); undriven inputs at their starts."""
        from ..codegen.evaluate import ModelEvaluator

        known = {k: float(v) for k, v in values.items()}
        for inst in self.spec.instances:
            for v in self.undriven_inputs(inst):
                known[f"{inst}.{v.name}"] = float(v.start if v.start is not None else 0.0)
        driver = {f"{ti}.{tv}": (f"{si}.{sv}", 1.0 if f is None else f) for si, sv, ti, tv, f in self.connections}
        evaluators = {}

        def value(name, depth=0):
            # only the instances whose computed outputs feed a connection are evaluated (not the arm,
            # whose connected outputs are its states)
            if name in known:
                return known[name]
            if depth > 4 * len(driver) + 8:  # cannot happen without an algebraic loop (refused on reading)
                raise SceneError(f"{self.src}: no value for {name} at t = {t:g}")
            if name in driver:
                s_, f = driver[name]
                known[name] = f * value(s_, depth + 1)
                return known[name]
            inst = name.split(".", 1)[0]
            m = self.base_models[inst]
            x = np.array([value(f"{inst}.{v.name}", depth + 1) for v in m.states])
            u = np.array([value(f"{inst}.{v.name}", depth + 1) for v in m.inputs])
            ev = evaluators.setdefault(inst, ModelEvaluator(m))
            for v, y in zip(m.outputs, ev.g(t, x, u)):
                known[f"{inst}.{v.name}"] = float(y)
            return known[name]

        return {name: value(name) for name in driver}

    def _check_loops(self) -> None:
        """An algebraic loop: a cycle of outputs that depend directly on connected inputs."""
        feeds = {}  # (inst, output) -> inputs of inst it depends on directly
        for inst, m in self.base_models.items():
            if not m.outputs:
                continue
            deps = m.dependencies()["outputs"]
            by_sym = {v.symbol: v.name for v in m.inputs}
            for v, d in zip(m.outputs, deps):
                feeds[(inst, v.name)] = [by_sym[s] for s in d if s in by_sym]
        driver = {(ti, tv): (si, sv) for si, sv, ti, tv, _ in self.connections}
        state, path = {}, []

        def visit(node):  # node: (inst, input)
            if state.get(node) == 2:
                return
            if state.get(node) == 1:
                loop = path[path.index(node):] + [node]
                raise SceneError(f"{self.src}: algebraic loop through {' -> '.join(f'{a}.{b}' for a, b in loop)}: "
                                 f"every output on it depends directly on its input; put a state in the loop")
            state[node] = 1
            path.append(node)
            src = driver.get(node)
            if src is not None:
                for inp in feeds.get(src, []):
                    visit((src[0], inp))
            path.pop()
            state[node] = 2

        for node in driver:
            visit(node)

    # ------------------------------------------------------------------ groups
    @property
    def groups(self) -> dict:
        """name -> GroupSpec; a monolithic scene is one group named after the scene."""
        if self.spec.monolithic:
            g = next(iter(self.spec.groups.values()), None)
            return {self.name: GroupSpec(self.name, tuple(self.spec.instances), g.fmi_type if g else "cs",
                                         g.solver if g else "rodas3", g.tolerance if g else None,
                                         g.jacobian if g else "auto")}
        return dict(self.spec.groups)

    def group_of(self, inst: str) -> str:
        for g in self.groups.values():
            if inst in g.members:
                return g.name
        raise SceneError(f"{self.src}: instance {inst} is in no FMU")

    def fmu_name(self, inst: str, var: str) -> str:
        """The FMI name of scene variable ``inst.var`` inside its FMU."""
        return var if len(self.groups[self.group_of(inst)].members) == 1 else f"{inst}.{var}"

    def undriven_inputs(self, inst: str) -> list:
        driven = {tv for _, _, ti, tv, _ in self.connections if ti == inst}
        return [v for v in self.base_models[inst].inputs if v.name not in driven]

    def read_variables(self, inst: str) -> list:
        """Variables of ``inst`` that something reads: a connection or the record."""
        names = [sv for si, sv, _, _, _ in self.connections if si == inst]
        names += [r.split(".", 1)[1] for r in self.spec.record if r.split(".", 1)[0] == inst]
        if self.external:  # read by an SSP component
            names += [v for i, v, _, _, _ in self.external.from_scene if i == inst]
        return list(dict.fromkeys(names))

    def robot_outputs(self, inst: str, prune: bool = True) -> tuple:
        ins = self.spec.instances[inst]
        if not prune:
            return ("p_ee", "qdd") + _frame_outputs(ins)
        used = set(ins.options.get("outputs", ()))
        for v in self.read_variables(inst):
            stem = v.split("[", 1)[0]
            if stem in ("p_ee", "qdd"):
                used.add(stem)
        return tuple(o for o in ("p_ee", "qdd") if o in used) + _frame_outputs(ins)

    def needs_jacobian(self, group: GroupSpec) -> bool:
        if group.jacobian != "auto":
            return bool(group.jacobian)
        scheme = str(self.spec.cosim.get("scheme", ""))
        hermite = scheme == "iterative" and str(self.spec.cosim.get("extrapolation", "")) in ("quadratic", "cubic")
        # Newton: interface Jacobians; Hermite inputs: slopes of computed outputs (dg/dx f + dg/du du)
        return group.fmi_type == "me" or group.solver == "rodas3" or scheme == "newton" or hermite

    # ------------------------------------------------------------------ models
    def instance_model(self, inst: str, prune: bool = True) -> tuple:
        """(model, [what pruning removed]) for one instance, parameters fixed as the scene says."""
        ins = self.spec.instances[inst]
        removed = []
        if ins.kind == "robot":
            outs = self.robot_outputs(inst, prune)
            alone = len(self.groups[self.group_of(inst)].members) == 1
            m = instance_model(ins, self.spec.parameter_set, self.src, self._sets.get(inst), outs,
                               strategy="auto" if alone else "straight")
            dropped = [o for o in ("p_ee", "qdd") if o not in outs]
            if dropped:
                removed.append(f"{inst}: outputs {', '.join(dropped)} (nothing reads them)")
            if ins.locked:
                removed.append(f"{inst}: joints {', '.join(f'q[{j}]' for j in sorted(ins.locked))} locked "
                               f"({2 * len(ins.locked)} states)")
        else:
            m = self.base_models[inst]
        fold = [v.name for v in m.parameters] if ins.fixed == "all" else list(ins.fixed)
        unknown = [n for n in fold if n not in {v.name for v in m.parameters}]
        if unknown:
            raise SceneError(f"{self.src}: [instances.{inst}] fixed: {', '.join(unknown)} not parameters of {inst}"
                             f"{did_you_mean(unknown[0], [v.name for v in m.parameters])}")
        if prune:
            zeros = [v.name for v in m.parameters if v.start == 0.0 and v.name not in fold and v.name not in ins.keep]
            if zeros:
                removed.append(f"{inst}: terms of zero-valued parameters {', '.join(zeros)} (folded)")
            fold += zeros
        if fold:
            m = m.with_parameters_folded(fold)
        if prune:
            kept = set(self.spec.inputs) | self._externally_driven()
            undriven = {v.name: v.start if v.start is not None else 0.0 for v in self.undriven_inputs(inst)
                        if f"{inst}.{v.name}" not in kept}
            if undriven:
                m = m.with_inputs_fixed(undriven)
                removed.append(f"{inst}: inputs {', '.join(undriven)} (nothing drives them; fixed at their values; "
                               f"list them in [scene] inputs to keep them)")
        return m, removed

    def group_model(self, group: str, prune: bool = True, x0: Optional[dict] = None,
                    u0: Optional[dict] = None) -> tuple:
        """(SymbolicModel of the FMU, [what pruning removed]).  ``x0``: scene state name -> initial value;
        ``u0``: scene input name -> its value at rest (:attr:`rest_inputs`), the start values of the FMU's
        inputs."""
        g = self.groups[group]
        members = list(g.members)
        models, removed = {}, []
        for inst in members:
            models[inst], rem = self.instance_model(inst, prune)
            removed += rem
        inside = set(members)
        exposed = []  # FMU-level names read from outside or recorded
        for inst in members:
            for v in self.read_variables(inst):
                if any(si == inst and sv == v and ti not in inside for si, sv, ti, _, _ in self.connections) \
                        or f"{inst}.{v}" in self.spec.record:
                    exposed.append((inst, v))
        if len(members) == 1:
            inst = members[0]
            m = models[inst]
            if prune:
                m = m.with_outputs([v for i, v in exposed if any(o.name == v for o in m.outputs)]
                                   + [v for i, v in exposed if any(s.name == v for s in m.states)])
            m = replace(m, name=group)
        else:
            internal = [(f"{si}.{sv}", f"{ti}.{tv}") + ((f,) if f is not None else ())
                        for si, sv, ti, tv, f in self.connections if si in inside and ti in inside]
            outputs = None
            if prune:
                outputs = [f"{i}.{v}" for i, v in exposed]
            m = assemble(group, models, internal, outputs=outputs,
                         description=self.spec.description or f"{group} of scene {self.name}",
                         where=f"{self.src}: [fmus.{group}]")
        m = self._with_input_ranges(m, members)
        if prune and not self.needs_jacobian(g):
            m = m.without_jacobian()
            removed.append(f"{group}: Jacobian program (explicit internal solver, no directional derivatives)")
        if x0:
            starts = {}
            for inst in members:
                for v in self.base_models[inst].states:
                    key = f"{inst}.{v.name}"
                    if key in x0:
                        starts[self.fmu_name(inst, v.name)] = x0[key]
            starts = {k: v for k, v in starts.items() if k in {s.name for s in m.states}}
            m = m.with_starts(starts)
        if u0:
            starts = {}
            for inst in members:
                for v in self.base_models[inst].inputs:
                    if f"{inst}.{v.name}" in u0:
                        starts[self.fmu_name(inst, v.name)] = u0[f"{inst}.{v.name}"]
            starts = {k: v for k, v in starts.items() if k in {i.name for i in m.inputs}}
            if starts:
                m = m.with_starts(starts)
        return m, removed

    def _with_input_ranges(self, m: SymbolicModel, members) -> SymbolicModel:
        """A state or output that drives inputs carries their validity ranges (the intersection).

        The input vanishes into the connection, possibly into another FMU; its
        source keeps the range (e.g. the arm's joint angle, the stroke within
        which a two-chamber actuator's volumes stay positive), so the FMU that
        owns the source reports leaving it.  Connections with a conversion
        factor carry none.
        """
        limits = {}
        for si, sv, ti, tv, factor in self.connections:
            if si not in members or factor is not None:
                continue
            v = self._var(ti, tv, self.src)[1]
            if v.min is not None or v.max is not None:
                key = self.fmu_name(si, sv)
                limits[key] = intersect_range(limits.get(key, (None, None)), (v.min, v.max))
        return m.with_ranges_narrowed(limits)

    def monolithic_model(self) -> SymbolicModel:
        """The whole scene as one model (names ``instance.variable``), nothing pruned or folded."""
        models = {inst: self.base_models[inst] for inst in self.spec.instances}
        conns = [(f"{si}.{sv}", f"{ti}.{tv}") + ((f,) if f is not None else ())
                 for si, sv, ti, tv, f in self.connections]
        outs = [r for r in self.spec.record]
        states = {f"{i}.{v.name}" for i, m in models.items() for v in m.states}
        outs = list(dict.fromkeys(outs + [f"{i}.{v.name}" for i, m in models.items() for v in m.states]))
        outs = [o for o in outs if o in states or o in self.spec.record]
        return assemble(self.name, models, conns, outputs=outs,
                        description=self.spec.description or f"scene {self.name}", where=self.src)

    # ------------------------------------------------------------------ initial state
    @cached_property
    def initial(self):
        """:class:`fmugen.scene.equilibrium.InitialState` of the scene (given or at rest)."""
        from .equilibrium import initial_state

        return initial_state(self)

    # ------------------------------------------------------------------ downstream
    def keeping(self, names) -> "Scene":
        """This scene with the parameters ``names`` (``inst.param``) never folded as zero-valued.

        A parameter sweep builds the FMUs once and sets the swept values as
        start values per run, so those parameters must stay parameters of the
        FMU even where the scene's value is zero.  A parameter the scene lists
        under ``fixed`` is refused: the file says it is a constant.
        """
        keep = {}
        for name in names:
            inst, par = self._endpoint(str(name), f"{self.src}: keep parameter {name!r}")
            params = {v.name: v.start for v in self.base_models[inst].parameters}
            if par not in params:
                raise SceneError(f"{self.src}: {name}: {inst} has no parameter {par!r}{did_you_mean(par, params)}")
            fixed = self.spec.instances[inst].fixed
            if fixed == "all" or par in fixed:
                raise SceneError(f"{self.src}: [instances.{inst}] fixed: {par} is folded into a constant, so "
                                 f"{name} cannot change per run; remove it from 'fixed' to vary it")
            if params[par] == 0.0:  # only zeros are folded: other FMUs stay those of the scene (and its cache)
                keep.setdefault(inst, []).append(par)
        if not keep:
            return self
        instances = {i: replace(ins, keep=tuple(dict.fromkeys(ins.keep + tuple(keep.get(i, ())))))
                     for i, ins in self.spec.instances.items()}
        # this scene was accepted already (factories included), so its copy is too
        return Scene(replace(self.spec, instances=instances), self._sets, allow_factories=True)

    def build(self, out_dir, prune: Optional[bool] = None, progress=None, use_cache: bool = True):
        """One FMU per group into ``out_dir`` (see :func:`fmugen.scene.build.build_scene`);
        ``prune`` None: the scene's ``[scene] prune``."""
        from .build import build_scene

        return build_scene(self, out_dir, prune=prune, progress=progress, use_cache=use_cache)

    def gauss_seidel_order(self) -> tuple:
        """Mechanical groups (arm, joint) first, then the rest in scene order."""
        def mechanical(g):
            return any(self.spec.instances[i].kind == "robot" or self.spec.instances[i].source in _MECHANICAL_TYPES
                       for i in self.groups[g].members)
        names = list(self.groups)
        return tuple([g for g in names if mechanical(g)] + [g for g in names if not mechanical(g)])

    def cosim_system(self, paths: dict):
        """The :class:`fmugen.cosim.system.CosimSystem` of the built FMUs (``paths``: group -> .fmu)."""
        from ..cosim.system import CosimSystem, Coupling, Recorded, Unit

        x0 = self.initial.values
        units = []
        for gname, g in self.groups.items():
            starts = {}
            for inst in g.members:
                for v in self.base_models[inst].states:
                    key = f"{inst}.{v.name}"
                    if key in x0:
                        starts[self.fmu_name(inst, v.name)] = float(x0[key])
            if g.fmi_type == "cs":
                tol = g.tolerance or self.spec.tolerance
                starts.update({"solver.method": SOLVERS[g.solver], "solver.rtol": tol, "solver.atol": tol})
            units.append(Unit(gname, Path(paths[gname]), g.fmi_type, starts, self.needs_jacobian(g), g.members))
        couplings = []
        for si, sv, ti, tv, f in self.connections:
            gs, gt = self.group_of(si), self.group_of(ti)
            if gs != gt:
                unit = self._var(ti, tv, self.src)[1].unit
                couplings.append(Coupling((gs, self.fmu_name(si, sv)), (gt, self.fmu_name(ti, tv)),
                                          1.0 if f is None else f, unit))
        recorded = []
        for r in self.spec.record:
            inst, var = r.split(".", 1)
            _, v = self._var(inst, var, self.src)
            recorded.append(Recorded(r, self.group_of(inst), self.fmu_name(inst, var), v.unit))
        system = CosimSystem(self.name, tuple(units), tuple(couplings), tuple(recorded), self.spec.start,
                             self.spec.stop, self.spec.step, self.gauss_seidel_order(), dict(self.spec.cosim),
                             tuple(getattr(self.initial, "unstable", ())))
        if self.external:  # an SSP's components beside the scene's FMUs
            from .external import extend_system

            system = extend_system(self, system)
        return system

    def reference_problem(self):
        """:class:`fmugen.cosim.system.ReferenceProblem`: the monolithic model from the scene's initial state."""
        from ..cosim.system import ReferenceProblem

        if self.external:
            raise SceneError(f"{self.src}: [external] components (an SSP's FMUs) have no symbolic model, so the "
                             f"scene has no reference solution; export it (fmugen ssp) and run fmugen report on "
                             f"the .ssp for a self-convergence reference")

        m = self.initial.model
        x0 = np.array([self.initial.values[v.name] for v in m.states])
        u = np.array([v.start if v.start is not None else 0.0 for v in m.inputs])
        nominals = np.array([abs(v.nominal) if v.nominal else max(1.0, abs(x)) for v, x in zip(m.states, x0)])
        return ReferenceProblem(m, x0, u, tuple(self.spec.record), self.spec.start, self.spec.stop, nominals)


def _frame_outputs(ins) -> tuple:
    """A robot instance's declared frame outputs ("p:tool0", "J:left_gripper", ...): always built."""
    return tuple(o for o in ins.options.get("outputs", ()) if ":" in o)
