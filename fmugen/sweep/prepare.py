"""What a sweep needs before any point runs: the FMUs, built once, and each point's start values.

A point changes parameters (``joint.J``) or start values of states
(``joint.theta``), never the FMUs: the scene is built once with the swept
parameters kept settable (:meth:`fmugen.scene.Scene.keeping`: not folded
even where their value is zero), and a point's values become FMU start
values -- ``inst.param`` is FMU variable ``scene.fmu_name(inst, param)`` of
FMU ``scene.group_of(inst)``.  A swept name that the built FMU does not hold
as a settable parameter (folded by ``fixed``, a robot's structural zero,
pruned with a locked joint) is refused before anything runs.

Initial state.  In a scene with ``initial = "equilibrium"`` the state of rest
depends on the parameters (the load pressure that holds a heavier link), so
it is solved again **on the client**, per point, from the monolithic model
(Newton with its exact Jacobian, :func:`fmugen.scene.equilibrium.solve_equilibrium`,
one compiled evaluator whose parameter vector changes per point: milliseconds).
A point without a state of rest is recorded as an error with the reason and
never submitted.  With ``initial = "given"`` the start values are the
scene's, or the point's for swept states.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np

from ..scene import SceneError, load_scene
from .errors import PointRefused, SweepError

def run_options(settings: Mapping[str, object], overrides: Optional[Mapping[str, object]] = None) -> dict:
    """Keywords of :func:`fmugen.cosim.master.run` from a scene's ``[cosim]`` table, then ``overrides``:
    resolved and checked as by every other command (:func:`fmugen.cosim.settings.resolve`)."""
    from ..cosim.settings import resolve

    return resolve(settings, **dict(overrides or {})).keywords()


@dataclass(frozen=True)
class PointTask:
    """One point, ready to run anywhere: its start values per FMU and what its reference needs."""

    index: int  # position in the sweep
    key: str  # :func:`fmugen.sweep.points.point_key`
    values: dict  # scene name -> value (what the user swept)
    starts: dict = field(default_factory=dict)  # FMU (group) -> {FMI variable: value}
    x0: Optional[np.ndarray] = None  # initial state of the monolithic model (for the reference)
    parameter_values: dict = field(default_factory=dict)  # monolithic parameter name -> value


class SweepPlan:
    """The scene for a sweep over ``names``, checked; :meth:`build` builds its FMUs once and
    :meth:`task` makes each point's :class:`PointTask`.

    scene: path of the scene file; names: swept scene names (``joint.J``);
    sets: ``--set`` overrides of the base scene; fmu_dir: where the FMUs go.
    """

    def __init__(self, scene_path, names: Sequence[str], fmu_dir, sets=None, progress=None,
                 allow_factories: bool = False):
        self.scene_path = Path(scene_path)
        base = load_scene(self.scene_path, set=sets, allow_factories=allow_factories)
        self.names = tuple(names)
        params, states = [], []
        for name in self.names:
            inst, var = name.split(".", 1)
            if inst not in base.spec.instances:
                raise SweepError(f"{self.scene_path}: {name}: no instance {inst!r}; instances: "
                                 f"{', '.join(base.spec.instances)}")
            m = base.base_models[inst]
            if var in {v.name for v in m.parameters}:
                params.append(name)
            elif var in {v.name for v in m.states}:
                states.append(name)
            else:
                hint = (" (a zero in a robot file is a structural zero, not a parameter)"
                        if base.spec.instances[inst].kind == "robot" else "")
                raise SweepError(f"{self.scene_path}: {name}: {inst} has no parameter or state {var!r}{hint}; "
                                 f"parameters: {', '.join(v.name for v in m.parameters)}")
        self.parameters, self.states = tuple(params), tuple(states)
        self.equilibrium = base.spec.initial == "equilibrium"
        self._evaluator = None
        self._arms = {}  # robot instance -> Robot description (for the point checks)
        try:
            self.scene = base.keeping(params)
        except SceneError as exc:
            raise SweepError(str(exc)) from None
        self.columns = tuple(self.scene.spec.record)
        self.fmu_dir, self._progress = Path(fmu_dir), progress
        self.system = None

    def build(self) -> "SweepPlan":
        """Build the FMUs (once; from the cache when nothing changed) and check every swept name is settable."""
        self.built = self.scene.build(self.fmu_dir, progress=self._progress)
        self.system = self.built.system
        self.targets = {}  # scene name -> (group, FMI variable)
        for name in self.names:
            inst, var = name.split(".", 1)
            group, fmi = self.scene.group_of(inst), self.scene.fmu_name(inst, var)
            self._check_settable(name, group, fmi, name in self.states)
            self.targets[name] = (group, fmi)
        self.digest = hashlib.sha256(b"".join(Path(u.path).read_bytes() for u in self.system.units)).hexdigest()
        return self

    def _check_settable(self, name, group, fmi, is_state) -> None:
        from fmpy import read_model_description

        md = read_model_description(str(self.system.unit(group).path))
        v = next((v for v in md.modelVariables if v.name == fmi), None)
        why = ""
        if v is None:
            why = "it is not a variable of the built FMU (folded into a constant or pruned)"
        elif is_state and fmi not in {d.variable.derivative.name for d in md.derivatives
                                      if d.variable.derivative is not None}:
            why = f"its FMU variable {fmi} is not a continuous state"
        elif not is_state and (v.causality != "parameter" or v.variability not in ("fixed", "tunable")):
            why = f"its FMU variable {fmi} is a {v.variability} {v.causality}, not a parameter"
        elif v.type not in ("Real", "Float64"):  # FMI 2.0's Real, FMI 3.0's Float64
            why = f"its FMU variable {fmi} is {v.type}"
        if why:
            raise SweepError(f"{self.scene_path}: cannot sweep {name}: {why} of FMU {group!r}")

    # -- per point -------------------------------------------------------------
    @property
    def reference_problem(self):
        return self.scene.reference_problem()

    def _equilibrium(self, values: Mapping[str, float]) -> dict:
        from ..codegen.evaluate import ModelEvaluator
        from ..scene.equilibrium import solve_equilibrium

        model = self.scene.initial.model
        if self._evaluator is None:
            self._evaluator = ModelEvaluator(model)
            self._p0 = self._evaluator.p.copy()
            self._pindex = {v.name: k for k, v in enumerate(model.parameters)}
        ev = self._evaluator
        ev.p = self._p0.copy()
        pv = {n: float(values[n]) for n in self.parameters}
        for n, val in pv.items():
            ev.p[self._pindex[n]] = val
        guess = {v.name: v.start if v.start is not None else 0.0 for v in model.states}
        guess.update({n: float(values[n]) for n in self.states})
        x = np.array([guess[v.name] for v in model.states], dtype=float)
        # model with the point's parameter values: the hydraulic checks read them (supply pressure)
        return solve_equilibrium(self.scene, model.with_starts(pv), x, evaluator=ev).values

    def check_point(self, index: int, values: Mapping[str, float]) -> None:
        """Refuse (:class:`PointRefused`) a point a file could not hold: each swept parameter's physical
        sign, a robot's masses, inertias and mass matrix with the point's values (:mod:`fmugen.values`),
        and a swept start value's declared sign and range.  The message names the point and the swept
        parameter(s), not every value of the model."""
        from ..robot.value_checks import robot_value_problem
        from ..values import variable_problem

        by_inst: dict = {}
        for n in self.parameters:
            inst, par = n.split(".", 1)
            by_inst.setdefault(inst, {})[par] = values[n]
        for inst, given in by_inst.items():
            m = self.scene.base_models[inst]
            pvars = {v.name: v for v in m.parameters}
            for par, val in given.items():
                problem = variable_problem(pvars[par], val)
                if problem:
                    raise PointRefused(f"refused: point {index}: {inst}.{par} = {val!r} {problem}")
            if self.scene.spec.instances[inst].kind == "robot":
                import fmugen

                if inst not in self._arms:
                    spec = self.scene.spec.instances[inst]
                    self._arms[inst] = fmugen.load_robot(spec.source, armature=spec.options.get("armature")).robot
                full = {v.name: v.start for v in m.parameters if v.start is not None}
                full.update(given)
                problem = robot_value_problem(self._arms[inst], full, named=given)
                if problem:
                    raise PointRefused(f"refused: point {index}: {inst}: {problem}")
        for n in self.states:  # a swept start value within the state's declared sign and range (min/max)
            inst, var = n.split(".", 1)
            sv = next(v for v in self.scene.base_models[inst].states if v.name == var)
            problem = variable_problem(sv, values[n])
            if problem:
                raise PointRefused(f"refused: point {index}: {n} = {values[n]!r} (start value) {problem}")

    def task(self, index: int, key: str, values: Mapping[str, float]) -> PointTask:
        """The point's start values; raises :class:`fmugen.scene.SceneError` when it has no state of rest
        and :class:`PointRefused` when its values fail the physical checks."""
        for n, v in values.items():
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise PointRefused(f"refused: point {index}: {n} = {v!r} is not a finite number")
        self.check_point(index, values)
        x0 = dict(self.scene.initial.values)
        if self.equilibrium and values:
            x0 = self._equilibrium(values)
        else:
            x0.update({n: float(values[n]) for n in self.states})
        starts = {}
        for u in self.system.units:
            s = {}
            g = self.scene.groups[u.name]
            for inst in g.members:  # the states cosim_system gave start values to, at this point's x0
                for v in self.scene.base_models[inst].states:
                    fmi = self.scene.fmu_name(inst, v.name)
                    if fmi in u.start_values and f"{inst}.{v.name}" in x0:
                        s[fmi] = float(x0[f"{inst}.{v.name}"])
            starts[u.name] = s
        for n in self.parameters:
            group, fmi = self.targets[n]
            starts[group][fmi] = float(values[n])
        model = self.scene.initial.model
        x0_vec = np.array([x0[v.name] for v in model.states], dtype=float)
        return PointTask(index, key, dict(values), starts, x0_vec, {n: float(values[n]) for n in self.parameters})


def point_system(system, task: PointTask):
    """``system`` (a CosimSystem) with the point's start values over each FMU's own."""
    units = tuple(replace(u, start_values={**dict(u.start_values), **task.starts.get(u.name, {})})
                  for u in system.units)
    return replace(system, units=units)
