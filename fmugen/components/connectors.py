"""Connectors: the physical ports of components, after the Modelica Standard Library's flanges and pins.

A connector type names the variables a physical bond carries -- potential
("across") variables and the flow/effort the bond transmits -- with their
units:

=============  ========================  ==============  =================
type           potential                 flow            power
=============  ========================  ==============  =================
rotational     phi [rad], w [rad/s]      tau [N.m]       tau w
translational  s [m], v [m/s]            f [N]           f v
hydraulic      p [Pa]                    Q [m3/s]        p Q
electrical     v [V]                     i [A]           v i
=============  ========================  ==============  =================

A component's connector maps these names to its own variables
(``{"w": "w", "tau": "tau"}`` for the hydraulic actuator's flange); a name it
leaves out is not part of its port.  Which side computes a variable is read
from the variable itself: a state or output computes it, an input needs it.
Our components are causal (explicit ODEs), so the bond is a pair of signals
-- the arm computes the joint's phi and w, the actuator its torque -- and
``connect`` (fmugen/scene/connect.py) turns a bond into those signal
connections with their direction checked.  The value computed on one side is
copied to the other (the torque an actuator outputs is the torque the joint
receives), as the scene's own ``connections`` do.

Built-in types declare their connectors in :data:`BUILTIN`; a component file
in its ``[connectors.<name>]`` tables (checked by :func:`check_file_connectors`);
an arm has ``joint[k]`` (rotational for a revolute joint, translational for a
prismatic one: q[k], qd[k], tau[k]).
"""
from __future__ import annotations

#: type -> ((potential names), (flow names), (effort name, flow name) of the power)
TYPES = {
    "rotational": {"vars": {"phi": "rad", "w": "rad/s", "tau": "N.m"}, "power": ("tau", "w")},
    "translational": {"vars": {"s": "m", "v": "m/s", "f": "N"}, "power": ("f", "v")},
    "hydraulic": {"vars": {"p": "Pa", "Q": "m3/s"}, "power": ("p", "Q")},
    "electrical": {"vars": {"v": "V", "i": "A"}, "power": ("v", "i")},
}

#: built-in component type -> {connector: (type, {connector variable: component variable})}
BUILTIN = {
    "hydraulic_actuator": {
        "flange": ("rotational", {"phi": "theta", "w": "w", "tau": "tau"}),
        "port": ("hydraulic", {"p": "P_L", "Q": "Q_L"}),
    },
    "servo_valve": {"port": ("hydraulic", {"p": "P_L", "Q": "Q_L"})},
    "joint_inertia": {"flange": ("rotational", {"phi": "theta", "w": "w", "tau": "tau"})},
    "dc_motor": {"flange": ("rotational", {"phi": "theta", "w": "w", "tau": "tau"})},
}


def arm_joint(k: int, revolute: bool) -> tuple:
    """The connector ``joint[k]`` of an arm."""
    if revolute:
        return "rotational", {"phi": f"q[{k}]", "w": f"qd[{k}]", "tau": f"tau[{k}]"}
    return "translational", {"s": f"q[{k}]", "v": f"qd[{k}]", "f": f"tau[{k}]"}


def check_file_connectors(raw: dict, declared: dict, src: str) -> dict:
    """A component file's ``[connectors]``: ``{name: (type, {connector var: component var})}``.

    Every mapped name must be a declared input, state or output whose unit is
    the connector variable's (so that a bond never needs a conversion).
    """
    from ..errors import InputFileError
    from .connect import same_unit

    out = {}
    for cname, tab in raw.items():
        where = f"{src}: [connectors.{cname}]"
        if not isinstance(tab, dict):
            raise InputFileError(f"{where} must be a table with type = ... and the variables it maps")
        if not (isinstance(cname, str) and cname.isascii() and cname.isidentifier()) or cname in declared:
            raise InputFileError(f"{where}: the name must be an identifier that is not a variable's name")
        ctype = tab.get("type")
        if ctype not in TYPES:
            raise InputFileError(f"{where} type = {ctype!r}; connector types: {', '.join(TYPES)}")
        known = TYPES[ctype]["vars"]
        mapping = {}
        for key, val in tab.items():
            if key == "type":
                continue
            if key not in known:
                raise InputFileError(f"{where}: {key!r} is not a variable of a {ctype} connector "
                                     f"({', '.join(known)})")
            d = declared.get(val) if isinstance(val, str) else None
            if d is None or d.kind not in ("input", "state", "output"):
                raise InputFileError(f"{where}: {key} = {val!r} must name an input, state or output of the file")
            if not same_unit(d.unit, known[key]):
                raise InputFileError(f"{where}: {key} = {val!r} is in [{d.unit}], a {ctype} connector's {key} "
                                     f"is in [{known[key]}]")
            mapping[key] = val
        if not mapping:
            raise InputFileError(f"{where} maps no variable")
        out[cname] = (ctype, mapping)
    return out
