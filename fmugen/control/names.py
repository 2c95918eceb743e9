"""One naming rule for states, inputs and outputs, and name look-up.

The names of a model's variables are its **FMI names**: ``q[1]``, ``tau[2]``
for an arm, ``valve.x_v`` inside an assembly, ``arm.q[2]`` inside a scene.
They are what the FMU, the ``.npz`` files of ``fmugen linearize`` and every
fmugen API take and return.

python-control reserves ``'.'`` (it separates system and signal in
``interconnect`` specifications such as ``"plant.y"``) and refuses it in
signal names.  So the **python-control signal name** of a variable is its FMI
name with every ``'.'`` written ``'_'`` -- for arms (``q[1]`` stays ``q[1]``)
and components (``valve.x_v`` -> ``valve_x_v``) alike.  The result keeps
python-control's vector conventions: ``"arm_q"`` selects every ``arm_q[i]``,
``"arm_q[1:3]"`` a slice.  Because the rule is not one-to-one in general, a
model in which two names would collide is refused.

Every look-up here accepts either spelling, and a *base name* (``q``,
``arm.q``) standing for all its elements ``q[1]``, ``q[2]``, ...

>>> signal_name("valve.x_v"), signal_name("arm.q[2]"), signal_name("q[1]")
('valve_x_v', 'arm_q[2]', 'q[1]')
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Sequence

try:  # the project's error classes (fmugen/errors.py); ValueError subclasses
    from ..errors import FmugenError
except ImportError:  # pragma: no cover - older trees without fmugen.errors
    FmugenError = ValueError

_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")


class UnknownNameError(FmugenError):
    """A name that is not a state, input or output of the model."""


def signal_name(fmi_name: str) -> str:
    """python-control signal name of an FMI variable name ('.' -> '_')."""
    return fmi_name.replace(".", "_")


@dataclass(frozen=True)
class Signal:
    """A model variable found by name: kind ("state", "input", "output"), index, FMI name."""

    kind: str
    index: int
    name: str


def model_names(model) -> dict:
    """{"state": [...], "input": [...], "output": [...]} FMI names of a SymbolicModel.

    "output" lists the computed outputs y = g(x, u) only; states exposed as
    outputs are found as states.
    """
    return {"state": [v.name for v in model.states], "input": [v.name for v in model.inputs],
            "output": [v.name for v in model.outputs]}


def signals(model, kind: str) -> list:
    """Every :class:`Signal` of one kind ("state", "input", "output"), in model order."""
    return [Signal(kind, i, n) for i, n in enumerate(model_names(model)[kind])]


def check_signal_names(model) -> None:
    """Refuse a model whose python-control names would collide (see module doc)."""
    seen = {}
    for kind, names in model_names(model).items():
        for n in names:
            s = signal_name(n)
            if s in seen and seen[s] != n:
                raise FmugenError(f"{model.name}: {kind} {n!r} and {seen[s]!r} have the same "
                                  f"python-control signal name {s!r}; rename one")
            seen[s] = n


def lookup(model, name: str, kinds: Sequence[str] = ("state", "input", "output")) -> list:
    """The :class:`Signal` s that ``name`` stands for, in index order.

    ``name``: an FMI name, a python-control signal name, or a base name of
    vector elements (``q`` for ``q[1]`` ... ``q[n]``).  An unknown name is an
    error listing what the model has.
    """
    names = model_names(model)
    found = []
    for kind in kinds:
        for i, n in enumerate(names[kind]):
            if name in (n, signal_name(n)):
                found.append(Signal(kind, i, n))
    if found:
        return found
    for kind in kinds:  # base name of a vector: every element, in index order
        elems = []
        for i, n in enumerate(names[kind]):
            m = _ELEMENT.match(n)
            if m and name in (m.group(1), signal_name(m.group(1))):
                elems.append((int(m.group(2)), Signal(kind, i, n)))
        found += [s for _, s in sorted(elems)]
    if not found:
        have = "; ".join(f"{k}s: {', '.join(_compact(names[k])) or '-'}" for k in kinds)
        raise UnknownNameError(f"{model.name}: no {'/'.join(kinds)} named {name!r} ({have})")
    return found


def _compact(names: Sequence[str]) -> list:
    """['q[1]', ..., 'q[6]', 'x'] -> ['q[1..6]', 'x'] for messages."""
    out, groups = [], {}
    for n in names:
        m = _ELEMENT.match(n)
        if m:
            if m.group(1) not in groups:
                groups[m.group(1)] = []
                out.append(m.group(1))
            groups[m.group(1)].append(int(m.group(2)))
        else:
            out.append(n)
    return [f"{n}[{min(groups[n])}..{max(groups[n])}]" if n in groups else n for n in out]
