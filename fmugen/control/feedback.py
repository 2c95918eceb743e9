"""State feedback u = u_ff - K (x - x_ref) as a component file, from a python-control design.

A gain designed on ``fmugen linearize`` (``control.lqr``, ``control.place``)
is closed around the *nonlinear* scene without a Python factory: this writes
a component file (``fmugen/components/README.md``, "Component files") whose
inputs are the measured states, whose outputs are the plant's inputs and
whose parameters are the gains, the reference state and the feed-forward
(so ``--set fb.K_1_2=...`` retunes it), with units derived from the plant's
(``K_j_i`` in [unit of u_j / unit of x_i]), dimension-checked on reading::

    lm = fmugen.linearize(plant, op)                     # or the .npz of fmugen linearize
    K, _, _ = control.lqr(lm, Q, R)
    fmugen.control.state_feedback_file("lqr.toml", K, plant, states, inputs, x_ref=op.x, u_ff=op.u)

and in the scene ``fb = { type = "file:lqr.toml" }`` with connections
``["arm.q[2]", "fb.arm_q_2"]``, ... ``["fb.drive_u", "drive.u"]``
(:func:`variable_name` gives the names).
"""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from ..errors import FmugenError
from ..fmi.units import BASE, base_units

TERMS_PER_LINE = 12  # keeps every equation far below the parser's 200-node limit


def variable_name(fmi_name: str) -> str:
    """The component-file name of a plant variable: ``arm.q[2]`` -> ``arm_q_2``."""
    name = re.sub(r"[^A-Za-z0-9]+", "_", fmi_name).strip("_")
    return name if name[:1].isalpha() else "v_" + name


def _ratio_unit(num: str, den: str) -> str:
    """The unit of num/den in base-unit exponents (``kg.m2.s-2.rad-1``), valid Modelica unit syntax."""
    a, b = base_units(num or "1"), base_units(den or "1")
    if a.factor != 1.0 or b.factor != 1.0:
        raise FmugenError(f"state feedback: units {num!r}, {den!r} carry scale factors; use coherent SI units")
    parts = []
    for k in BASE:
        e = getattr(a, k) - getattr(b, k)
        if e:
            parts.append(k if e == 1 else f"{k}{e}")
    return ".".join(parts) or "1"


def read_gain(path) -> np.ndarray:
    """A gain matrix from a file: ``.npy``, ``.npz`` (array ``K``) or ``.csv`` (rows = inputs)."""
    p = Path(path)
    try:
        if p.suffix == ".npy":
            return np.load(p, allow_pickle=False)
        if p.suffix == ".npz":
            with np.load(p, allow_pickle=False) as z:
                if "K" not in z:
                    raise FmugenError(f"{p}: no array 'K' (arrays: {', '.join(z.files)})")
                return z["K"]
        if p.suffix == ".csv":
            return np.loadtxt(p, delimiter=",", ndmin=2)
    except (OSError, ValueError) as exc:
        raise FmugenError(f"{p}: cannot read the gain matrix: {exc}") from None
    raise FmugenError(f"{p}: a gain matrix is a .npy, .npz (array K) or .csv file")


def state_feedback_file(path, K, model, states: Sequence[str], inputs: Sequence[str],
                        x_ref: Optional[Sequence[float]] = None, u_ff: Optional[Sequence[float]] = None,
                        name: str = "state_feedback", description: str = "",
                        sample_period: Optional[float] = None) -> Path:
    """Write ``u = u_ff - K (x - x_ref)`` as a component file; returns its path.

    ``K``: the (inputs x states) gain, or a file holding it (:func:`read_gain`);
    ``model``: the plant (SymbolicModel or scene) whose ``states`` and
    ``inputs`` (FMI names) K was designed for -- their units give the file's.
    ``sample_period``: None for the continuous law; a period T_s [s] for the sampled one
    ``u[k] = u_ff - K (x[k] - x_ref)``, computed at every instant k T_s and held (zero-order hold) --
    K from ``control.dlqr`` on the plant discretised at T_s (:func:`fmugen.control.c2d`); the file's
    parameter ``T_s`` is the period (``[clocks.sample]``, README "Sample clocks").
    """
    from .linearize import as_model

    m = as_model(model)
    K = np.atleast_2d(np.asarray(read_gain(K) if isinstance(K, (str, Path)) else K, dtype=float))
    if K.shape != (len(inputs), len(states)):
        raise FmugenError(f"state feedback: K is {K.shape[0]}x{K.shape[1]}, expected {len(inputs)}x{len(states)} "
                          f"(inputs x states)")
    if not np.all(np.isfinite(K)):
        raise FmugenError("state feedback: K has non-finite entries")
    units = {v.name: v.unit for g in (m.states, m.inputs, m.outputs) for v in g}
    for n in list(states) + list(inputs):
        if n not in units:
            raise FmugenError(f"state feedback: {n!r} is not a variable of {m.name}")
    x_ref = np.zeros(len(states)) if x_ref is None else np.asarray(x_ref, dtype=float)
    u_ff = np.zeros(len(inputs)) if u_ff is None else np.asarray(u_ff, dtype=float)
    xs, us = [variable_name(s) for s in states], [variable_name(u) for u in inputs]
    if len(set(xs + us)) != len(xs) + len(us):
        raise FmugenError("state feedback: two plant variables map to one file name; rename them")
    eqs, lines = [], []
    for j, u in enumerate(us):
        terms = [f"K_{j + 1}_{i + 1}*({x} - ref_{x})" for i, x in enumerate(xs) if K[j, i] != 0.0]
        chunks = [terms[c:c + TERMS_PER_LINE] for c in range(0, len(terms), TERMS_PER_LINE)] or [["0"]]
        parts = []
        for c, chunk in enumerate(chunks):
            if len(chunks) == 1:
                parts.append("(" + " + ".join(chunk) + ")")
            else:
                eqs.append(f"s_{j + 1}_{c + 1} = " + " + ".join(chunk))
                parts.append(f"s_{j + 1}_{c + 1}")
        law = f"ff_{u} - " + (" - ".join(parts) if len(chunks) == 1 else "(" + " + ".join(parts) + ")")
        eqs.append(f"{u} = {law}" if sample_period is None else f"v_{u} = {law}")
    sampled = sample_period is not None
    if sampled:
        T = float(sample_period)
        if not np.isfinite(T) or T <= 0:
            raise FmugenError(f"state feedback: sample_period {sample_period!r} must be a positive number of seconds")
        eqs += [f"{u} = {u}_k" for u in us]
    law = "u[k] = u_ff - K (x[k] - x_ref), sampled every T_s and held" if sampled else "u = u_ff - K (x - x_ref)"
    lines += [f"# State feedback {law}, written by fmugen.control.state_feedback_file.",
              "[component]", f"name = {json.dumps(name)}",
              f"description = {json.dumps(description or 'state feedback ' + law)}",
              "equations = ["] + [f'  "{e}",' for e in eqs] + ["]", "", "[parameters]"]
    if sampled:
        lines.append(f'T_s = {{ value = {T!r}, unit = "s", min = 1e-12, description = "sample period" }}')
    for j, u in enumerate(us):
        for i, x in enumerate(xs):
            if K[j, i] != 0.0:
                lines.append(f'K_{j + 1}_{i + 1} = {{ value = {float(K[j, i])!r}, unit = "{_ratio_unit(units[inputs[j]], units[states[i]])}", '
                             f'description = "gain from {states[i]} to {inputs[j]}" }}')
    for i, x in enumerate(xs):
        lines.append(f'ref_{x} = {{ value = {float(x_ref[i])!r}, unit = "{units[states[i]] or "1"}", '
                     f'description = "reference of {states[i]}" }}')
    for j, u in enumerate(us):
        lines.append(f'ff_{u} = {{ value = {float(u_ff[j])!r}, unit = "{units[inputs[j]] or "1"}", '
                     f'description = "feed-forward of {inputs[j]}" }}')
    lines += ["", "[inputs]"] + [f'{x} = {{ unit = "{units[s] or "1"}", start = {float(r)!r}, description = "measured {s}" }}'
                                 for x, s, r in zip(xs, states, x_ref)]
    lines += ["", "[outputs]"] + [f'{u} = {{ unit = "{units[s] or "1"}", description = "command of {s}'
                                  f'{" (held between samples)" if sampled else ""}" }}' for u, s in zip(us, inputs)]
    inter = [e.split(" = ", 1)[0] for e in eqs if e.startswith("s_")]
    if inter or sampled:
        lines += ["", "[intermediates]"] + [f'{s} = {{ unit = "{units[inputs[int(s.split("_")[1]) - 1]] or "1"}" }}'
                                            for s in inter]
    if sampled:
        lines += [f'v_{u} = {{ unit = "{units[s] or "1"}", description = "the law at the sample instant" }}'
                  for u, s in zip(us, inputs)]
        lines += ["", "[discrete]"] + [f'{u}_k = {{ start = {float(f)!r}, unit = "{units[s] or "1"}", '
                                       f'description = "held command of {s}" }}' for u, s, f in zip(us, inputs, u_ff)]
        lines += ["", "[clocks.sample]", 'period = "T_s"', "", "[[when]]", 'name = "sample"', 'clock = "sample"',
                  "set = { " + ", ".join(f'{u}_k = "v_{u}"' for u in us) + " }"]
    p = Path(path)
    p.write_text("\n".join(lines) + "\n")
    from ..components.equations import read_component_file

    read_component_file(p)  # what was written reads back, dimensions checked
    return p
