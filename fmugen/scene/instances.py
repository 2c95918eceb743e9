"""Scene instances -> SymbolicModels (robots, shipped components, user factories).

A robot file becomes the arm's state-space model (free joints only when
joints are locked); a component type calls the factory of
:data:`fmugen.components.assembly.COMPONENT_TYPES` with its fidelity
options, parameter set and overrides; a user factory is imported by its
module path and called with the instance's options -- never evaluated text.
``--set`` values for an instance land here: a parameter's value, or the
start value of a state or an input.
"""
from __future__ import annotations

import importlib
from typing import Optional, Sequence

from ..codegen.model import SymbolicModel
from ..errors import FmugenError
from ..values import as_number, check_model_values
from ..components.assembly import COMPONENT_TYPES
from .errors import SceneError, did_you_mean
from .file import InstanceSpec


def instance_model(spec: InstanceSpec, default_set: str, src: str, sets: Optional[dict] = None,
                   robot_outputs: Sequence[str] = (), strategy: str = "straight") -> SymbolicModel:
    """The instance's model with the scene's parameters and start values (nothing folded yet).

    ``strategy`` (robots): "straight" -- straight-line code that composition
    can differentiate through (monolithic models, groups of several
    instances) -- or "auto", which lets an arm in an FMU of its own use the
    runtime's looped dynamics past the size where they win.
    """
    where = f"{src}: [instances.{spec.name}]"
    sets = dict(sets or {})
    overrides = dict(spec.parameters)
    arm = None
    if spec.kind == "robot":
        model, arm = _robot_model(spec, where, robot_outputs, strategy)
    else:
        model = _component(spec, default_set, where, overrides)
        params = {v.name for v in model.parameters}
        late = {k: v for k, v in sets.items() if k in params}
        if late:  # parameters change derived start values too: make the model again
            try:  # named as the user wrote it, before the model is made again
                check_model_values(model, late, lambda k: f"--set {spec.name}.{k}")
            except FmugenError as exc:
                raise SceneError(str(exc)) from None
            for k, v in late.items():
                overrides[k] = _float(v, f"--set {spec.name}.{k}")
                sets.pop(k)
            model = _component(spec, default_set, where, overrides)
    values = dict(overrides) if spec.kind == "robot" else {}
    origin = {k: f"{where} parameters.{k}" for k in values}
    values.update(spec.start)
    origin.update({k: f"{where} start.{k}" for k in spec.start})
    for k, v in sets.items():
        values[k] = _float(v, f"--set {spec.name}.{k}")
        origin[k] = f"--set {spec.name}.{k}"
    # the physical checks a file value gets, for a value from parameters, start or --set
    if arm is not None:  # the robot's own checks first: they name the link and the quantity
        from ..robot.value_checks import robot_value_problem  # (a robot is loaded: its reader's imports are paid)

        pnames = {v.name for v in model.parameters}
        given = {k: v for k, v in values.items() if k in pnames}
        problem = robot_value_problem(arm.robot, given)
        if problem:
            raise SceneError(f"{where} ({', '.join(origin[k] for k in given)}): {problem}")
    try:
        check_model_values(model, values, origin.get)
    except FmugenError as exc:
        raise SceneError(str(exc)) from None
    discrete = tuple(model.events.discrete) if model.events is not None else ()
    known = {v.name for g in (model.states, model.inputs, model.parameters, discrete) for v in g}
    for k in values:
        if k not in known:
            raise SceneError(f"{where}: {k!r} is not a parameter, state, input or discrete state of {spec.name}"
                             f"{did_you_mean(k, known)}; parameters: "
                             f"{', '.join(v.name for v in model.parameters) or '-'}")
    model = model.with_starts(values)
    missing = [v.name for v in model.parameters if v.start is None]
    if missing:
        raise SceneError(f"{where}: parameter(s) {', '.join(missing)} have no value; give them in "
                         f"[instances.{spec.name}] parameters or on the command line, e.g. "
                         f"--set {spec.name}.{missing[0]}=VALUE")
    for h in spec.hold:
        if h not in {v.name for v in model.states}:
            raise SceneError(f"{where} hold: {h!r} is not a state of {spec.name}"
                             f"{did_you_mean(h, [v.name for v in model.states])}")
    return model


def _float(v, where) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise SceneError(f"{where}: {v!r} must be a number")
    try:
        return as_number(v, where)
    except FmugenError as exc:
        raise SceneError(str(exc)) from None


def _robot_model(spec: InstanceSpec, where: str, outputs, strategy: str = "straight") -> SymbolicModel:
    import fmugen

    try:
        arm = fmugen.load_robot(spec.source, spec.options.get("formulation", "newton_euler"),
                                mimic=spec.options.get("mimic", "independent"),
                                armature=spec.options.get("armature"))
        if spec.locked:
            strategy = "straight"  # the looped dynamics have no locked joints
        events = {k: spec.options[k] for k in ("friction", "limits") if k in spec.options}
        if events:
            strategy = "straight"  # events need the straight-line derivation (the loops have none)
        return arm.state_space_model(outputs=tuple(outputs), name=spec.name, locked=spec.locked or None,
                                     strategy=strategy, **events), arm
    except SceneError:
        raise
    except (ValueError, KeyError) as exc:
        raise SceneError(f"{where}: {exc}") from None


def _component(spec: InstanceSpec, default_set: str, where: str, overrides: dict) -> SymbolicModel:
    if spec.kind == "file":  # a component file: its own [sets.<name>]; the scene's default only if defined
        from ..components.equations import load_component

        try:
            return load_component(spec.source, name=spec.name, parameter_set=spec.parameter_set or default_set,
                                  overrides=overrides, strict_set=spec.parameter_set is not None)
        except ValueError as exc:
            raise SceneError(f"{where}: {exc}") from None
    if spec.kind == "factory":
        module_name, func_name = spec.source.split(":", 1)
        try:
            factory = getattr(importlib.import_module(module_name), func_name)
        except (ImportError, AttributeError) as exc:
            raise SceneError(f"{where} factory = {spec.source!r}: cannot import: {exc}") from None
        kwargs = dict(spec.options)
        if spec.parameter_set is not None:
            kwargs["parameter_set"] = spec.parameter_set
        if overrides:
            kwargs["overrides"] = overrides
        try:
            model = factory(name=spec.name, **kwargs)
        except (ValueError, KeyError, TypeError) as exc:
            raise SceneError(f"{where}: {spec.source}: {exc}") from None
        if not isinstance(model, SymbolicModel):
            raise SceneError(f"{where}: factory {spec.source} returned {type(model).__name__}, not a SymbolicModel")
        return model
    factory, _ = COMPONENT_TYPES[spec.source]
    kwargs = dict(spec.options)
    if spec.source != "table_trajectory":
        kwargs["parameter_set"] = spec.parameter_set or default_set
        kwargs["overrides"] = overrides
    try:
        return factory(name=spec.name, **kwargs)
    except (ValueError, KeyError, TypeError, FileNotFoundError) as exc:
        raise SceneError(f"{where}: {exc}") from None
