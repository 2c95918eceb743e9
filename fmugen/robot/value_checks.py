"""Parameter values given to a robot after its file was read (``--set``, scene instances, sweep
points, arm sizing): the robot file's own physical checks applied to the new numbers.

Here, in the robot package, because the checks are the readers' (:mod:`fmugen.robot.checks`, the URDF
reader's composite-body test); :mod:`fmugen.values` holds what every reader shares and imports nothing
of the robot's.
"""
from __future__ import annotations

import math
from typing import Mapping, Optional

import numpy as np
import sympy as sp

from .checks import RobotFileError, inertia_problems, singular_joint
from .description import MODIFIED, PRISMATIC
from .urdf import _Reader

__all__ = ["robot_value_problem"]


def robot_value_problem(robot, values: Mapping[str, float], named=None) -> Optional[str]:
    """Why ``robot`` with parameter ``values`` (name -> float, over the file's own) is not a
    physical arm -- the robot-file checks applied to the new numbers -- or None.

    ``named``: the names of ``values`` the message shows as the cause (a sweep point passes every
    parameter's value but names the swept ones); all of them by default."""
    if not values:
        return None
    base = {p.symbol: p.value for p in robot.parameters if p.value is not None}
    new = dict(base)
    by_name = {p.name: p.symbol for p in robot.parameters}
    for k, v in values.items():
        if k in by_name:
            new[by_name[k]] = float(v)

    def num(e, subs):
        e = sp.sympify(e)
        if e.free_symbols - set(subs):
            return None
        with np.errstate(all="ignore"):
            x = e.xreplace(subs)
            try:
                f = float(x)
            except (TypeError, ValueError, OverflowError):
                return math.nan  # zoo, nan: a division by zero
        return f

    shown = set(values if named is None else named)
    changed = ", ".join(f"{k} = {v!r}" for k, v in values.items() if k in by_name and k in shown) or "these values"
    data, complete = [], True
    dh = bool(robot.links)  # a DH file (links), or a robot written as joints (bodies: URDF)
    for i, L in enumerate(robot.links or robot.bodies, start=1):
        label = f"{'link' if dh else 'body'} {i} ({L.name})"
        fields = {"mass": L.mass, "rotor_inertia": L.rotor_inertia, "damping": L.damping}
        if dh:
            fields.update(a=L.a, d=L.d)
        else:
            fields.update({f"translation[{k}]": e for k, e in enumerate(L.translation)}, offset=L.offset)
        vals = {}
        for field, e in fields.items():
            x = num(e, new)
            if x is not None and not math.isfinite(x):
                return f"{label}: {field} = {e} is not a finite number with {changed} (a division by zero?)"
            vals[field] = x
        com = [num(e, new) for e in L.com]
        I = [[num(e, new) for e in row] for row in L.inertia_com]
        for x in com + [y for row in I for y in row]:
            if x is not None and not math.isfinite(x):
                return f"{label}: its centre of mass or inertia is not finite with {changed}"
        m = vals["mass"]
        if m is not None and m <= 0 and not (sp.sympify(L.mass) == 0):
            return f"{label}: mass = {L.mass} = {m:g} kg with {changed}; a body's mass must be positive"
        for field in ("rotor_inertia", "damping"):
            if vals[field] is not None and vals[field] < 0:
                return f"{label}: {field} = {fields[field]} = {vals[field]:g} is negative with {changed}"
        if m is None or None in com or any(y is None for row in I for y in row) or None in vals.values():
            complete = False
            continue
        I = np.array(I)
        for r in range(3):
            if I[r, r] < 0:
                return f"{label}: moment of inertia [{r}][{r}] = {I[r, r]:g} kg m^2 is negative with {changed}"
        problems = inertia_problems(m, I)
        if problems:
            I0 = [[num(e, base) for e in row] for row in L.inertia_com]
            m0 = num(L.mass, base)
            was_ok = m0 is not None and all(y is not None for row in I0 for y in row) \
                and not inertia_problems(m0, np.array(I0, dtype=float))
            if was_ok:  # the file's values made a rigid body: an override may not unmake it
                return f"{label}: not a realisable rigid body with {changed}: {'; '.join(problems)}"
        if not dh:
            continue
        th = num(L.theta, new)
        al = num(L.alpha, new)
        if th is None or al is None:
            complete = False
            continue
        data.append(dict(prismatic=L.joint == PRISMATIC, a=vals["a"], alpha=al, d=vals["d"], theta=th, mass=m,
                         com=com, inertia=I, rotor=vals["rotor_inertia"]))
    payload = None
    if robot.payload is not None:
        pm = num(robot.payload.mass, new)
        pc = [num(e, new) for e in robot.payload.com]
        if pm is not None and (not math.isfinite(pm) or pm < 0):
            return f"payload: mass = {robot.payload.mass} = {pm:g} kg with {changed}; must be >= 0 and finite"
        if pm is None or None in pc:
            complete = False
        elif not all(map(math.isfinite, pc)):
            return f"payload: com is not finite with {changed}"
        payload = (pm, pc)
    for k, g in enumerate(robot.gravity):
        x = num(g, new)
        if x is not None and not math.isfinite(x):
            return f"gravity[{k}] = {g} is not finite with {changed}"
    if complete and not dh and robot.bodies:  # a robot written as joints: M's diagonal by composite bodies
        source = robot.source or "robot"
        try:
            _Reader(source)._check_moves_something(robot.bodies, new)
        except RobotFileError as exc:
            return f"{str(exc).removeprefix(source + ': ')} with {changed}"
        except (TypeError, ValueError):  # a quantity left symbolic: not judged here (the build judges it)
            pass
    if complete and data:
        found = singular_joint(data, robot.convention == MODIFIED, payload)
        if found is not None:
            j, _ = found
            if j < 0:
                return f"the mass matrix overflows double precision with {changed}"
            return (f"link {j + 1} ({robot.links[j].name}): the mass matrix is singular with {changed}: joint "
                    f"{j + 1} moves no mass, no inertia about its axis and no rotor inertia")
    return None
