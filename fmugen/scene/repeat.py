"""``[repeat.<name>]``: declare similar chains once (six joints, one table).

::

    [repeat.joint]
    values = { k = [1, 2, 3], q_end = [0.5, -0.1, 0.2] }   # one entry per copy, lists of equal length
    connect = [["act{k}.flange", "arm.joint[{k}]"], ...]    # appended to [scene] connect
    connections = [...]                                     # appended to [scene] connections
    record = ["act{k}.tau"]                                 # appended to [scene] record
    fmus = { "joint{k}" = { members = ["amp{k}", "act{k}"] } }
    [repeat.joint.instances]
    "act{k}" = { type = "hydraulic_actuator", parameter_set = "puma_joint{k}" }
    "path{k}" = { type = "ptp_trajectory", parameters = { q_end = "{q_end}" } }

Each copy substitutes ``{name}`` in every key and string by that copy's
value; a string that is exactly ``"{name}"`` takes the value itself (a
number stays a number).  Copies are appended in the order of the values,
after what the file declares itself, so a repeated scene is the same scene
as the one written out.  This is plain data expansion before the scene is
read: every key is then checked as if written by hand (and ``--set`` names
the expanded instances: ``--set path2.q_end=0.3``).
"""
from __future__ import annotations

import re

from .errors import SceneError

REPEAT_KEYS = {"values", "instances", "connect", "connections", "record", "fmus"}
MAX_COPIES = 256
_PLACEHOLDER = re.compile(r"\{([A-Za-z_][A-Za-z0-9_]*)\}")


def expand_repeats(data: dict, src: str) -> dict:
    """``data`` with every ``[repeat.<name>]`` expanded into instances, connections, record and FMUs."""
    rep = data.pop("repeat", None)
    if rep is None:
        return data
    if not isinstance(rep, dict):
        raise SceneError(f"{src}: [repeat] must hold tables [repeat.<name>]")
    for rname, tab in rep.items():
        where = f"{src}: [repeat.{rname}]"
        if not isinstance(tab, dict):
            raise SceneError(f"{where} must be a table")
        bad = sorted(set(tab) - REPEAT_KEYS)
        if bad:
            raise SceneError(f"{where} has unknown key(s) {', '.join(bad)}; known: {', '.join(sorted(REPEAT_KEYS))}")
        values = tab.get("values")
        if not isinstance(values, dict) or not values or not all(isinstance(v, list) for v in values.values()):
            raise SceneError(f"{where} values must be a table of equal-length lists, e.g. {{ k = [1, 2, 3] }}")
        n = {len(v) for v in values.values()}
        if len(n) != 1 or not 0 < next(iter(n)) <= MAX_COPIES:
            raise SceneError(f"{where} values: the lists must have one equal length (1..{MAX_COPIES}), got "
                             f"{', '.join(f'{k}: {len(v)}' for k, v in values.items())}")
        for j in range(next(iter(n))):
            env = {k: v[j] for k, v in values.items()}
            copy = _substitute({k: v for k, v in tab.items() if k != "values"}, env, where)
            sc = data.setdefault("scene", {})
            for key in ("connect", "connections", "record"):
                if key in copy:
                    if not isinstance(copy[key], list) or not isinstance(sc.get(key, []), list):
                        raise SceneError(f"{where} {key} must be a list")
                    sc[key] = list(sc.get(key, [])) + copy[key]
            for key in ("instances", "fmus"):
                if key in copy:
                    if not isinstance(copy[key], dict):
                        raise SceneError(f"{where} {key} must be a table")
                    target = data.setdefault(key, {})
                    for name, spec in copy[key].items():
                        if name in target:
                            raise SceneError(f"{where} {key}: {name!r} exists already (copy {j + 1})")
                        target[name] = spec
    return data


def _substitute(obj, env: dict, where: str):
    if isinstance(obj, str):
        m = _PLACEHOLDER.fullmatch(obj)
        if m and m.group(1) in env:
            return env[m.group(1)]

        def one(m):
            if m.group(1) not in env:
                raise SceneError(f"{where}: {{{m.group(1)}}} in {obj!r} is not one of the values "
                                 f"({', '.join(env)})")
            return str(env[m.group(1)])
        return _PLACEHOLDER.sub(one, obj)
    if isinstance(obj, list):
        return [_substitute(x, env, where) for x in obj]
    if isinstance(obj, dict):
        return {str(_substitute(k, env, where)): _substitute(v, env, where) for k, v in obj.items()}
    return obj
