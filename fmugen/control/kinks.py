"""Is an operating point inside a smoothed kink?  (``fmugen linearize`` warns.)

A component file's kinks are linearised in their smooth form
(fmugen/components/README.md, "Kinks"): inside the band |d| < eps the slope
is of order 1/eps.  At rest a regularised Coulomb term sign(w, eps) acts as a
viscous damper T/eps -- huge, and not what the real plant does for small
motions -- so an LQR designed there can differ from the nonlinear response by
the whole step.  :func:`kink_warnings` finds every smoothed kink of every
component-file instance of a scene whose argument lies inside its band at the
operating point, and says what the two choices are: the smooth form (what was
linearised), or the plant without the kink -- for a smoothed sign whose width
is a parameter, ``--set inst.eps=1e12`` makes x/sqrt(x^2 + eps^2) vanish with
its slope (the friction-free plant); otherwise an operating point outside the
band (``--at``).
"""
from __future__ import annotations

import numpy as np
import sympy as sp


KINK_OFF = 1e9  # a width this large is the user switching the kink off (the choice offered below)


def kink_warnings(scene, model, op) -> list:
    """One line per smoothed kink whose band holds the operating point ``op`` of ``model`` (a scene model)."""
    from ..components.equations import read_cached
    from .linearize import as_model

    m = as_model(model)
    x = {v.name: float(op.x[k]) for k, v in enumerate(m.states)}
    u = {v.name: float(op.u[k]) for k, v in enumerate(m.inputs)}
    params = {v.name: v.start for v in m.parameters}
    src = {f"{ti}.{tv}": (si, sv) for si, sv, ti, tv, f in scene.connections}
    factor = {f"{ti}.{tv}": (1.0 if f is None else f) for si, sv, ti, tv, f in scene.connections}
    memo: dict = {}

    def value(inst, var, depth=0):
        key = f"{inst}.{var}"
        if key in x:
            return x[key]
        if key in u:
            return u[key]
        if key in memo:
            return memo[key]
        if depth > 50:
            raise RecursionError(key)
        bm = scene.base_models[inst]
        if key in src:  # a connected input: its source's value
            si, sv = src[key]
            memo[key] = factor[key] * value(si, sv, depth + 1)
        elif any(v.name == var for v in bm.inputs):  # an undriven input: its start value
            memo[key] = next(v.start or 0.0 for v in bm.inputs if v.name == var)
        elif any(v.name == var for v in bm.states):  # a state pruned from the model: its start
            memo[key] = next(v.start or 0.0 for v in bm.states if v.name == var)
        else:  # an output: evaluate the instance
            from ..codegen.evaluate import ModelEvaluator

            ev = ModelEvaluator(bm)
            xs = [value(inst, v.name, depth + 1) for v in bm.states]
            us = [value(inst, v.name, depth + 1) for v in bm.inputs]
            for v, g in zip(bm.outputs, ev.g(op.t if hasattr(op, "t") else 0.0, xs, us)):
                memo[f"{inst}.{v.name}"] = float(g)
        return memo[key]

    lines = []
    for inst, ins in scene.spec.instances.items():
        if ins.kind != "file" or inst not in scene.base_models:
            continue
        cf = read_cached(ins.source)
        bm = scene.base_models[inst]
        env = {}
        for v in list(bm.parameters):
            env[v.symbol] = params.get(f"{inst}.{v.name}", v.start)
        for v in list(bm.states) + list(bm.inputs):
            try:
                env[v.symbol] = value(inst, v.name)
            except (KeyError, RecursionError, StopIteration):
                env = None
                break
        if env is None:
            continue
        lines += _site_lines(cf, env, f"{inst}.", f"{inst}: ")
    return lines


def _site_lines(cf, env: dict, set_prefix: str, where_prefix: str) -> list:
    """The warning lines of a component file's kinks at the values ``env`` (symbol -> number)."""
    lines = []
    for eq, text, name, dists, eps in cf.kinks:
        e = float(sp.sympify(eps).xreplace(env))
        d = min(abs(float(sp.sympify(dd).xreplace(env))) for dd in dists)
        if not np.isfinite(d) or d >= abs(e) or abs(e) >= KINK_OFF:
            continue
        hint = ("the plant without it: " + f"--set {set_prefix}{eps}=1e12 (the smoothed sign and its slope vanish)"
                if name == "sign" and isinstance(eps, sp.Symbol) else
                "the plant beside it: an operating point outside the band (--at)")
        lines.append(f"warning: {where_prefix}{text} in '{eq}': the operating point is inside its smooth band "
                     f"(distance {d:.3g} < eps = {e:.3g}): the linearisation sees the smoothed kink's slope "
                     f"(~1/eps), not the kink; choose the smooth form (linearised here) or {hint}")
    return lines


def component_kink_warnings(path, model, op) -> list:
    """:func:`kink_warnings` for a component file linearised on its own (``fmugen linearize x.toml``)."""
    from ..components.equations import read_cached

    env = {v.symbol: v.start for v in model.parameters}
    env.update({v.symbol: float(op.x[k]) for k, v in enumerate(model.states)})
    env.update({v.symbol: float(op.u[k]) for k, v in enumerate(model.inputs)})
    return _site_lines(read_cached(path), env, "", "")
