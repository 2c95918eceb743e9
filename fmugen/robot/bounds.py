"""Physical ranges of a robot's parameters, for the FMU.

A parameter that *is* a physical quantity of a link -- the file writes
``mass = "m1"`` or ``inertia = ["Ixx", ...]`` -- can take only the values that
quantity can: a link mass > 0, a rotor inertia, a damping, a principal
moment of inertia and a payload mass >= 0.  The FMU declares them as the
parameter's min (modelDescription.xml) and its runtime refuses a value
outside them in ``fmi2SetReal``, so an importer cannot give the arm a
negative mass that the robot file itself would have been refused for.

A parameter that only enters a quantity through an expression (``mass =
"m1 + m2"``) keeps an open range: its own sign says nothing.
"""
from __future__ import annotations

import sympy as sp

from ..codegen.model import POSITIVE_MIN
from .description import Robot

__all__ = ["parameter_bounds"]


def parameter_bounds(robot: Robot) -> dict:
    """``{parameter name: lowest allowed value}`` of the parameters that are a
    link's or the payload's quantity themselves (:data:`POSITIVE_MIN` for > 0)."""
    lows: dict = {}

    def at_least(expr, low):
        if isinstance(expr, sp.Symbol):
            lows[expr.name] = max(lows.get(expr.name, low), low)

    # a DH file's own quantities are its links'; a URDF robot's are its bodies' (a merged body's mass is a
    # sum, not a parameter, and keeps an open range)
    for link in robot.links or robot.bodies:
        at_least(link.mass, POSITIVE_MIN)
        at_least(link.rotor_inertia, 0.0)
        at_least(link.damping, 0.0)
        at_least(getattr(link, "friction", 0), 0.0)
        for k in range(3):
            at_least(link.inertia_com[k][k], 0.0)
    if robot.payload is not None:
        at_least(robot.payload.mass, 0.0)
    # a URDF keeps its published numbers (a rounding-level -5e-20 moment of inertia is read with a
    # warning): a range the file's own value falls outside is not imposed
    values = {p.name: p.value for p in robot.parameters}
    return {k: v for k, v in lows.items() if values.get(k) is None or values[k] >= v}
