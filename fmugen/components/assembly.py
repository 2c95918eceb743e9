"""Load an assembly TOML file into one SymbolicModel.

File format (all keys checked; the file is parsed by :mod:`tomllib`, never
evaluated)::

    [assembly]
    name = "single_joint_default"          # FMU model identifier (C identifier)
    parameter_set = "default"              # shipped set name, or a .toml path
                                           # (relative to this file)
    description = "..."                    # optional
    inputs = ["amp.theta_ref", "joint.tau_load"]   # optional: order of free inputs
    outputs = ["joint.theta", "joint.w"]           # optional: exposed variables
    connections = [                        # [source, target]: state/output -> input
      ["joint.theta", "amp.theta"],
      ...
    ]

    [components.amp]                       # instance name
    type = "amplifier"                     # a factory of COMPONENT_TYPES
    kind = "ideal"                         # the factory's fidelity options
    control = "P"
    parameter_set = "stiff"                # optional, per instance
    [components.amp.parameters]            # optional overrides
    K_a = 12.0

The lead's ``fmugen build FILE --fmi-type me|cs`` calls :func:`load_assembly`.
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Union

from ..codegen.model import SymbolicModel, intersect_range
from ..errors import InputFileError, check_identifier, read_text_file, toml_problem
from .amplifier import amplifier
from .connect import assemble
from .controller import controller
from .current_driver import current_driver
from .dc_motor import dc_motor
from .hydraulic_actuator import hydraulic_actuator
from .joint import joint_inertia
from .parameters import load_parameter_set
from .servo_valve import servo_valve
from .trajectory import ptp_trajectory, quintic_trajectory, table_trajectory

#: type name -> (factory, {option: allowed python type(s)})
COMPONENT_TYPES = {
    "amplifier": (amplifier, {"kind": str, "control": str, "rails": bool}),
    "current_driver": (current_driver, {"kind": str}),
    "servo_valve": (servo_valve, {"order": int, "stroke_limit": bool, "flow": str}),
    "hydraulic_actuator": (hydraulic_actuator, {"form": str, "kind": str}),
    "joint_inertia": (joint_inertia, {"kind": str}),
    "dc_motor": (dc_motor, {"current_loop": str, "elasticity": bool}),
    "controller": (controller, {"speed_loop": str}),
    "ptp_trajectory": (ptp_trajectory, {}),
    "quintic_trajectory": (quintic_trajectory, {}),
    "table_trajectory": (table_trajectory, {"times": list, "values": list, "kind": str, "output": str,
                                            "unit": str}),
}

_ASSEMBLY_KEYS = {"name", "parameter_set", "description", "inputs", "outputs", "connections"}


def _str_list(val, where):
    if not isinstance(val, list) or not all(isinstance(s, str) for s in val):
        raise InputFileError(f"{where} must be a list of strings")
    return val


def _check_units(model: SymbolicModel, where: str) -> None:
    """Every unit must be one modelDescription.xml can declare: refused here,
    with the file and the component, not at build time."""
    from ..fmi.units import base_units

    for v in model.states + model.inputs + model.outputs + model.parameters:
        if v.unit:
            try:
                base_units(v.unit)
            except ValueError as exc:
                raise InputFileError(f"{where}: variable {v.name}: {exc}") from None


def load_assembly(path: Union[str, Path]) -> SymbolicModel:
    """Read an assembly file and return the assembled SymbolicModel."""
    path = Path(path)
    src = str(path)
    try:
        data = tomllib.loads(read_text_file(path, "assembly file"))
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise InputFileError(f"{src}: {toml_problem(exc)}") from None
    extra = sorted(set(data) - {"assembly", "components"})
    if extra:
        raise InputFileError(f"{src}: unknown top-level key(s) {', '.join(extra)}; expected [assembly] and [components.*]")
    asm = data.get("assembly")
    if not isinstance(asm, dict):
        raise InputFileError(f"{src}: missing [assembly] table")
    bad = sorted(set(asm) - _ASSEMBLY_KEYS)
    if bad:
        raise InputFileError(f"{src}: [assembly] has unknown key(s) {', '.join(bad)}; known: {', '.join(sorted(_ASSEMBLY_KEYS))}")
    # the name becomes the model identifier, C identifiers and file names: ASCII, bounded
    name = check_identifier(asm.get("name"), f"{src}: [assembly] name")
    pset_name = asm.get("parameter_set", "default")
    if not isinstance(pset_name, str):
        raise InputFileError(f"{src}: [assembly] parameter_set must be a string")

    def pset_of(value, where):
        if value.endswith(".toml"):
            p = Path(value)
            value = str(p if p.is_absolute() else path.parent / p)
        try:
            return load_parameter_set(value)
        except (ValueError, FileNotFoundError) as exc:
            raise InputFileError(f"{src}: {where}: {exc}") from None

    default_set = pset_of(pset_name, "[assembly] parameter_set")
    comps_tab = data.get("components")
    if not isinstance(comps_tab, dict) or not comps_tab:
        raise InputFileError(f"{src}: no [components.<name>] tables")
    components = {}
    for inst, spec in comps_tab.items():
        where = f"[components.{inst}]"
        # instance names prefix every variable name ("valve.x_v") and C identifier
        check_identifier(inst, f"{src}: {where}: the instance name")
        if not isinstance(spec, dict):
            raise InputFileError(f"{src}: {where} must be a table")
        typ = spec.get("type")
        if isinstance(typ, str) and typ.startswith(("file:", "lib:")):  # a component file (equations/)
            components[inst] = _file_component(typ, spec, inst, path, where, src)
            continue
        if not isinstance(typ, str) or typ not in COMPONENT_TYPES:
            raise InputFileError(f"{src}: {where} type = {typ!r} is not a component type; "
                             f"known: {', '.join(COMPONENT_TYPES)}")
        factory, options = COMPONENT_TYPES[typ]
        kwargs = {}
        for key, val in spec.items():
            if key in ("type", "parameter_set", "parameters"):
                continue
            if key not in options:
                raise InputFileError(f"{src}: {where} has unknown option {key!r} for type {typ}; "
                                 f"known: {', '.join(options) or '-'}")
            want = options[key]
            if isinstance(val, bool) != (want is bool) or not isinstance(val, want):
                raise InputFileError(f"{src}: {where} {key} = {val!r} must be of type {want.__name__}")
            kwargs[key] = val
        if typ != "table_trajectory":
            pset = default_set
            if "parameter_set" in spec:
                if not isinstance(spec["parameter_set"], str):
                    raise InputFileError(f"{src}: {where} parameter_set must be a string")
                pset = pset_of(spec["parameter_set"], f"{where} parameter_set")
            kwargs["parameter_set"] = pset
            over = spec.get("parameters", {})
            if not isinstance(over, dict):
                raise InputFileError(f"{src}: {where}.parameters must be a table of numbers")
            for key, val in over.items():
                if isinstance(val, bool) or not isinstance(val, (int, float)):
                    raise InputFileError(f"{src}: {where}.parameters: {key} = {val!r} is not a number")
                if not math.isfinite(val):  # TOML has nan and inf literals
                    raise InputFileError(f"{src}: {where}.parameters: {key}: non-finite value {val!r}")
            kwargs["overrides"] = over
        elif "parameters" in spec or "parameter_set" in spec:
            raise InputFileError(f"{src}: {where}: a table_trajectory has no parameters (its knots are data)")
        try:
            components[inst] = factory(name=inst, **kwargs)
        except (ValueError, KeyError, TypeError) as exc:
            text = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
            raise InputFileError(f"{src}: {where}: {text}") from None
        _check_units(components[inst], f"{src}: {where}")
    conns = asm.get("connections", [])
    if not isinstance(conns, list):
        raise InputFileError(f"{src}: [assembly] connections must be a list of [source, target] pairs")
    inputs = _str_list(asm["inputs"], f"{src}: [assembly] inputs") if "inputs" in asm else None
    outputs = _str_list(asm["outputs"], f"{src}: [assembly] outputs") if "outputs" in asm else None
    pairs = [tuple(c) if isinstance(c, list) else c for c in conns]
    model = assemble(name, components, pairs, inputs=inputs, outputs=outputs,
                     description=asm.get("description", ""), where=src)
    return carry_input_ranges(model, components, pairs)


def _file_component(typ, spec, inst, path: Path, where, src) -> SymbolicModel:
    """``type = "file:x.toml"`` (relative to the assembly) or ``"lib:<name>"``, with parameter_set and parameters."""
    from .equations import load_component

    bad = sorted(set(spec) - {"type", "parameter_set", "parameters"})
    if bad:
        raise InputFileError(f"{src}: {where} has unknown key(s) {', '.join(bad)} for a component file")
    ref = typ if typ.startswith("lib:") else (Path(typ[5:]) if Path(typ[5:]).is_absolute() else path.parent / typ[5:])
    pset = spec.get("parameter_set")
    if pset is not None and (not isinstance(pset, str) or not pset):
        raise InputFileError(f"{src}: {where} parameter_set must be a string")
    if pset is not None and pset.endswith(".toml") and not Path(pset).is_absolute():
        pset = str(path.parent / pset)
    over = spec.get("parameters", {})
    if not isinstance(over, dict):
        raise InputFileError(f"{src}: {where}.parameters must be a table of numbers")
    try:
        return load_component(ref, name=inst, parameter_set=pset, overrides=over)
    except ValueError as exc:
        raise InputFileError(f"{src}: {where} type = {typ!r}: {exc}") from None


def carry_input_ranges(model: SymbolicModel, components: dict, connections) -> SymbolicModel:
    """Give a connected state or output the validity range of the input it
    drives (the intersection, when it drives several).

    A connected input disappears from the assembly, and with it the range its
    component declared (the two-chamber actuator's position, within which its
    chamber volumes stay positive); the source carries it instead, so that the
    FMU still reports leaving it.  Only plain ``[source, target]`` connections
    (no conversion factor) carry a range.
    """
    limits: dict = {}
    for conn in connections:
        if not isinstance(conn, tuple) or len(conn) != 2 or not all(isinstance(c, str) for c in conn):
            continue
        source, target = conn
        inst, _, var_name = target.partition(".")
        comp = components.get(inst)
        if comp is None:
            continue
        for v in comp.inputs:
            if v.name == var_name and (v.min is not None or v.max is not None):
                limits[source] = intersect_range(limits.get(source, (None, None)), (v.min, v.max))
    return model.with_ranges_narrowed(limits)
