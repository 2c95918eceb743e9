"""Immutable description of a serial manipulator.

A :class:`Robot` is what a robot file says, after parsing and checking, and
nothing more: every quantity is a sympy expression (a number, a parameter
symbol, or an arithmetic expression in parameters).  The dynamics modules read
it; nothing mutates it.

Conventions (SI units throughout)
---------------------------------
* Denavit-Hartenberg parameters (a, alpha, d, theta) in the *standard*
  convention of the McGalliard thesis, eq. (1):
  ``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``; joint i moves frame i
  relative to frame i-1 about/along z_{i-1}.  The *modified* (Craig)
  convention ``A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)`` stores
  on link i the a and alpha that precede its joint; the joint moves about/along
  z_i.
* For a revolute joint ``theta`` is a constant offset added to q_i; for a
  prismatic joint ``d`` is a constant offset added to q_i.
* Inertial data of link i are expressed in frame i: mass ``mass``, centre of
  mass ``com`` (3-vector), and the inertia tensor ``inertia_com`` about the
  centre of mass (3x3, symmetric, tensor convention: off-diagonal entries are
  the negated products of inertia, I_xy = -int(x*y dm)).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import sympy as sp

REVOLUTE = "revolute"
PRISMATIC = "prismatic"
STANDARD = "standard"
MODIFIED = "modified"

Vector3 = tuple  # tuple of three sympy expressions
Matrix3 = tuple  # tuple of three rows, each a tuple of three sympy expressions


@dataclass(frozen=True)
class Parameter:
    """A named symbolic quantity of the model (becomes an FMU parameter).

    ``value`` is the default (start) value; ``None`` means the file leaves the
    quantity purely symbolic (numeric evaluation then needs a value).
    """

    name: str
    symbol: sp.Symbol
    value: Optional[float]
    unit: str = ""
    description: str = ""


@dataclass(frozen=True)
class Link:
    """One link and the joint that moves it (joint i moves link i)."""

    name: str
    joint: str  # REVOLUTE or PRISMATIC
    a: sp.Expr
    alpha: sp.Expr
    d: sp.Expr
    theta: sp.Expr
    mass: sp.Expr
    com: Vector3
    inertia_com: Matrix3
    rotor_inertia: sp.Expr = sp.Integer(0)
    damping: sp.Expr = sp.Integer(0)
    external_wrench: bool = False  # adds inputs f_ext/t_ext acting at the COM


@dataclass(frozen=True)
class Payload:
    """A point mass rigidly attached to the last link (the thesis's PLYLD)."""

    mass: sp.Expr
    com: Vector3  # in the last link's frame


@dataclass(frozen=True)
class Robot:
    name: str
    convention: str  # STANDARD or MODIFIED
    links: tuple  # tuple[Link, ...]
    gravity: Vector3  # gravitational acceleration in base coordinates, m/s^2
    parameters: tuple = ()  # tuple[Parameter, ...], every free symbol above
    payload: Optional[Payload] = None
    description: str = ""
    source: str = ""  # path of the file it came from, for messages

    @property
    def n(self) -> int:
        return len(self.links)

    def parameter_values(self) -> dict:
        """Default values of the parameters that have one, keyed by symbol."""
        return {p.symbol: p.value for p in self.parameters if p.value is not None}

    def parameter(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"robot {self.name!r} has no parameter {name!r}")


def combined_last_link(robot: Robot) -> tuple:
    """The links with the payload (if any) merged into the last link.

    A point mass m_L at r_L adds to the mass, moves the centre of mass, and
    adds the parallel-axis terms of both bodies about the new centre of mass.
    Both formulations call this, so they see the same rigid bodies.
    """
    links = robot.links
    if robot.payload is None:
        return links
    last = links[-1]
    m, mL = last.mass, robot.payload.mass
    r = sp.Matrix(last.com)
    rL = sp.Matrix(robot.payload.com)
    mt = m + mL
    rc = (m * r + mL * rL) / mt

    def shift(mass, offset):
        # inertia of a point mass at `offset` from the new COM (tensor form)
        o = offset
        return mass * ((o.T * o)[0, 0] * sp.eye(3) - o * o.T)

    I = sp.Matrix(last.inertia_com) + shift(m, r - rc) + shift(mL, rL - rc)
    merged = Link(
        name=last.name,
        joint=last.joint,
        a=last.a,
        alpha=last.alpha,
        d=last.d,
        theta=last.theta,
        mass=mt,
        com=tuple(rc),
        inertia_com=tuple(tuple(I.row(i)) for i in range(3)),
        rotor_inertia=last.rotor_inertia,
        damping=last.damping,
        external_wrench=last.external_wrench,
    )
    return links[:-1] + (merged,)
