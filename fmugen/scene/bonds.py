"""Power and energy per bond of a run (the bonds a scene's ``connect`` made, fmugen/scene/connect.py).

A bond's power is effort x flow of its connector type (tau w, f v, p Q, v i),
from the recorded columns of the two variables that carry them
(``[scene] record_bonds = true`` records them).  The energy is its
trapezoidal integral over the communication points: what one side delivered
to the other.  In a co-simulation both variables are values the master
exchanged, so a bond's energy is what crossed the coupling -- compare it
with the reference's to see the energy a coupling scheme created or lost.
"""
from __future__ import annotations

import numpy as np


def bond_variables(bonds) -> list:
    """The ``inst.var`` columns that carry the bonds' power (effort, flow), in bond order, once each."""
    out = []
    for b in bonds:
        out += [v for v in b.power if v not in out]
    return out


def bond_power(bonds, time, column) -> list:
    """[(bond, power array, energy array)] for the bonds whose effort and flow were recorded.

    ``column(name)`` returns a recorded column or raises KeyError.
    """
    out = []
    t = np.asarray(time, dtype=float)
    for b in bonds:
        if not b.power:
            continue
        try:
            e, f = np.asarray(column(b.power[0])), np.asarray(column(b.power[1]))
        except KeyError:
            continue
        p = e * f
        energy = np.concatenate([[0.0], np.cumsum(np.diff(t) * (p[1:] + p[:-1]) / 2)]) if len(t) > 1 else p * 0
        out.append((b, p, energy))
    return out


def bond_lines(bonds, time, column) -> list:
    """One line per bond: energy delivered and peak power (for summaries)."""
    lines = []
    for b, p, energy in bond_power(bonds, time, column):
        lines.append(f"bond {b}: {b.power[0]} x {b.power[1]}: energy {energy[-1]:.6g} J, "
                     f"peak power {np.max(np.abs(p)):.6g} W")
    return lines
