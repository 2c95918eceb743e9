"""Immutable description of a manipulator: a tree of rigid bodies moved by joints.

A :class:`Robot` is what a robot file says, after parsing and checking, and
nothing more: every quantity is a sympy expression (a number, a parameter
symbol, or an arithmetic expression in parameters).  The dynamics modules read
it; nothing mutates it.

The joint model (every robot, whatever file it came from)
---------------------------------------------------------
``Robot.bodies`` is a tuple of :class:`Body`, in topological order (a body's
parent comes before it).  Body i (0-based) hangs from body ``parent`` (-1:
the base, Featherstone's and Pinocchio's lambda(i)) by the joint that moves
it, written as a fixed *placement* followed by a *motion*:

    ^{parent}T_i(q_i) = [R, p] * M(axis, q_i + offset)

* ``rotation`` R (3x3) and ``translation`` p (3) place the *joint frame* in
  the parent body's frame (URDF ``<origin xyz rpy>``; for the base, in the
  base frame);
* the motion M is a rotation by ``q_i + offset`` about the unit ``axis``
  (revolute; URDF revolute and continuous) or a translation by ``q_i +
  offset`` along it (prismatic), with ``axis`` expressed in the joint frame
  (URDF ``<axis xyz>``), so the axis is the same vector before and after the
  motion.  ``offset`` is 0 for URDF; a DH file's theta (revolute) or d
  (prismatic) lands here;
* the *body frame* of body i is the joint frame after the motion.  Its
  ``mass``, centre of mass ``com`` and inertia ``inertia_com`` about the
  centre of mass (tensor convention: off-diagonal entries are the negated
  products of inertia, I_xy = -int(x*y dm)) are given in the body frame.

Rotor inertia ``Ia`` adds Ia qdd_i, viscous ``damping`` b adds b qd_i and
Coulomb ``friction`` F_c adds the smooth F_c tanh(qd_i / v_c) (v_c:
``friction_velocity``) to the joint's generalized force (torque about, or
force along, the axis).

``Robot.frames`` are named frames rigidly attached to a body (or to the base,
parent -1): :class:`Frame` ``(name, parent, rotation, translation)``, the
frame's pose in the body frame.  URDF fixed joints (tool flanges, sensor
frames, merged links) and the Denavit-Hartenberg link frames become frames;
forward kinematics and Jacobians can be asked for any body or frame by name.
``Robot.end_frame`` names the frame whose origin is the FMU output ``p_ee``.

Denavit-Hartenberg files are one way of writing this model
----------------------------------------------------------
A TOML robot file keeps its DH parameters in ``Robot.links`` (tuple of
:class:`Link`) and ``convention``; the bodies and frames are derived from them
by :func:`dh_to_joints` when the Robot is made (and re-derived whenever
``dataclasses.replace`` changes the links), so both views always agree:

* standard (thesis eq. 1) ``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``;
  joint i moves frame i relative to frame i-1 about/along z_{i-1};
* modified (Craig) ``A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)``,
  storing on link i the a and alpha that precede its joint;

both are products ``... X_i J_i(q_i) X_{i+1} ...`` of constant transforms
X = Tx(a) Rx(alpha) and joint transforms J = Rz(theta) Tz(d), so the joint
frame F_i (joint i about/along z) is placed in F_{i-1} by
``Tx(a') Rx(alpha')`` -- (a', alpha') of the previous link (standard) or of
link i (modified) -- followed by ``Rz(theta_i) Tz(d_i)``:

* revolute:  R = Rx(alpha'), p = [a', -sin(alpha') d_i, cos(alpha') d_i],
  axis z, offset theta_i;
* prismatic: R = Rx(alpha') Rz(theta_i), p = [a', 0, 0], axis z, offset d_i.

Link i's inertial data, given in its DH frame L_i = F_i Tx(a_i) Rx(alpha_i)
(standard; L_i = F_i for modified), are moved into F_i; the DH frames are
kept as frames ``frame1`` .. ``frameN`` (``end_frame`` = ``frameN``); a
payload (the thesis's PLYLD) is merged into the last body.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional

import sympy as sp

REVOLUTE = "revolute"
PRISMATIC = "prismatic"
STANDARD = "standard"
MODIFIED = "modified"
JOINTS = "joints"  # a robot written joint by joint (URDF), not in DH parameters

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
    """One link of a Denavit-Hartenberg file and the joint that moves it (joint i moves link i).

    Inertial data (``mass``, ``com``, ``inertia_com`` about the COM) are in the
    link's DH frame i.
    """

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
    # Coulomb friction F_c (smooth: F_c tanh(qd / friction_velocity)) and the joint's range [lower, upper]
    friction: sp.Expr = sp.Integer(0)
    friction_velocity: sp.Expr = sp.Integer(0)
    limits: Optional["Limits"] = None


@dataclass(frozen=True)
class Payload:
    """A point mass rigidly attached to the last link (the thesis's PLYLD)."""

    mass: sp.Expr
    com: Vector3  # in the last link's frame


@dataclass(frozen=True)
class Limits:
    """Validity ranges of one joint (None: unbounded), from a URDF ``<limit>`` or a DH link's ``limits``.

    ``lower``/``upper`` bound q [rad or m], ``effort`` bounds |tau| [N.m or N],
    ``velocity`` bounds |qd|.  They are ranges in which the model is valid,
    not forces: the dynamics do not read them -- unless the state-space model
    is asked for ``limits="stops"`` (then ``lower``/``upper`` are end stops,
    :meth:`fmugen.dynamics.manipulator.Manipulator.state_space_model`).
    """

    lower: Optional[float] = None
    upper: Optional[float] = None
    effort: Optional[float] = None
    velocity: Optional[float] = None


@dataclass(frozen=True)
class Body:
    """Body i and the joint that moves it (see the module docstring)."""

    name: str  # the body (URDF link) name
    joint: str  # REVOLUTE or PRISMATIC
    parent: int  # index of the parent body, -1 = base
    rotation: Matrix3  # R of the joint frame in the parent body frame
    translation: Vector3  # p of the joint frame in the parent body frame
    axis: Vector3  # unit axis of the motion, joint frame
    mass: sp.Expr
    com: Vector3  # body frame
    inertia_com: Matrix3  # about the COM, body-frame axes
    rotor_inertia: sp.Expr = sp.Integer(0)
    damping: sp.Expr = sp.Integer(0)
    external_wrench: bool = False  # adds inputs f_ext/t_ext acting at the COM
    offset: sp.Expr = sp.Integer(0)  # constant added to q in the motion
    joint_name: str = ""  # the joint's own name (URDF); "" = the body's name
    limits: Optional[Limits] = None
    friction: sp.Expr = sp.Integer(0)  # Coulomb level F_c of the smooth term F_c tanh(qd / friction_velocity)
    friction_velocity: sp.Expr = sp.Integer(0)
    # a tied mimic joint: (leader body index, multiplier, offset), q = multiplier q_leader + offset; None: independent
    mimic: Optional[tuple] = None


@dataclass(frozen=True)
class Frame:
    """A named frame fixed to body ``parent`` (-1: the base): its pose in that body's frame."""

    name: str
    parent: int
    rotation: Matrix3
    translation: Vector3


@dataclass(frozen=True)
class Robot:
    name: str
    convention: str  # STANDARD or MODIFIED (DH files), JOINTS (written as joints: URDF)
    links: tuple  # tuple[Link, ...] of a DH file; () for a robot written as joints
    gravity: Vector3  # gravitational acceleration in base coordinates, m/s^2
    parameters: tuple = ()  # tuple[Parameter, ...], every free symbol above
    payload: Optional[Payload] = None
    description: str = ""
    source: str = ""  # path of the file it came from, for messages
    bodies: tuple = ()  # tuple[Body, ...]; derived from ``links`` when they are given
    frames: tuple = ()  # tuple[Frame, ...]; derived from ``links`` when they are given
    end_frame: str = ""  # the frame whose origin is p_ee; derived from ``links`` when given

    def __post_init__(self):
        if self.links:
            bodies, frames = dh_to_joints(self.links, self.convention, self.payload)
            object.__setattr__(self, "bodies", bodies)
            object.__setattr__(self, "frames", frames)
            object.__setattr__(self, "end_frame", frames[-1].name)
        elif not self.bodies:
            raise ValueError(f"robot {self.name!r}: no links and no bodies")
        for i, b in enumerate(self.bodies):
            if not (-1 <= b.parent < i):
                raise ValueError(f"robot {self.name!r}: body {i} ({b.name}) has parent {b.parent}; "
                                 "bodies must come after their parent (topological order)")

    @property
    def n(self) -> int:
        return len(self.bodies)

    @property
    def is_chain(self) -> bool:
        """Every body hangs from the one before it (a serial chain)."""
        return all(b.parent == i - 1 for i, b in enumerate(self.bodies))

    def children(self, i: int) -> tuple:
        """Indices of the bodies whose parent is ``i`` (-1: the base)."""
        return tuple(k for k, b in enumerate(self.bodies) if b.parent == i)

    def ancestors(self, i: int) -> tuple:
        """Body ``i`` and the bodies between it and the base, ``i`` first (the joints that move it)."""
        out = []
        while i >= 0:
            out.append(i)
            i = self.bodies[i].parent
        return tuple(out)

    def frame_names(self) -> tuple:
        """Every name ``locate`` knows: bodies, then frames."""
        return tuple(b.name for b in self.bodies) + tuple(f.name for f in self.frames)

    def locate(self, name: str) -> tuple:
        """``(parent body, rotation, translation)`` of the body or frame ``name``.

        A body is itself with the identity placement.  KeyError lists the names.
        """
        for i, b in enumerate(self.bodies):
            if b.name == name:
                return i, IDENTITY3, ZERO_VECTOR
        for f in self.frames:
            if f.name == name:
                return f.parent, f.rotation, f.translation
        raise KeyError(f"robot {self.name!r} has no body or frame {name!r}; "
                       f"known: {', '.join(self.frame_names())}")

    def parameter_values(self) -> dict:
        """Default values of the parameters that have one, keyed by symbol."""
        return {p.symbol: p.value for p in self.parameters if p.value is not None}

    def parameter(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"robot {self.name!r} has no parameter {name!r}")


_Z, _ONE = sp.Integer(0), sp.Integer(1)
IDENTITY3 = ((_ONE, _Z, _Z), (_Z, _ONE, _Z), (_Z, _Z, _ONE))
ZERO_VECTOR = (_Z, _Z, _Z)
Z_AXIS = (_Z, _Z, _ONE)


def _rx(alpha) -> sp.Matrix:
    c, s = sp.cos(alpha), sp.sin(alpha)
    return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rz(theta) -> sp.Matrix:
    c, s = sp.cos(theta), sp.sin(theta)
    return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _rows(M: sp.Matrix) -> tuple:
    return tuple(tuple(M.row(r)) for r in range(M.rows))


def dh_to_joints(links, convention: str, payload=None) -> tuple:
    """``(bodies, frames)`` of a Denavit-Hartenberg chain (module docstring, last section).

    The payload, if any, is merged into the last body; the DH frame of link i
    becomes the frame ``frame{i}`` on body i-1 (0-based).
    """
    if convention not in (STANDARD, MODIFIED):
        raise ValueError(f"unknown DH convention {convention!r}")
    links = _merged_payload(tuple(links), payload)
    bodies, frames = [], []
    for i, L in enumerate(links):
        if convention == STANDARD:
            prev = links[i - 1] if i > 0 else None
            alpha_in = prev.alpha if prev else _Z
            a_in = prev.a if prev else _Z
            end_a, end_alpha = L.a, L.alpha
        else:
            alpha_in, a_in = L.alpha, L.a
            end_a, end_alpha = _Z, _Z
        Rx = _rx(alpha_in)
        if L.joint == PRISMATIC:
            R, p, offset = Rx * _rz(L.theta), (sp.sympify(a_in), _Z, _Z), sp.sympify(L.d)
        else:
            d = sp.sympify(L.d)
            R, p, offset = Rx, (sp.sympify(a_in), -sp.sin(alpha_in) * d, sp.cos(alpha_in) * d), sp.sympify(L.theta)
        # data given in L_i = F_i Tx(end_a) Rx(end_alpha): r_F = [end_a, 0, 0] + Rx r_L
        Re = _rx(end_alpha)
        com = Re * sp.Matrix(L.com) + sp.Matrix([end_a, 0, 0])
        inertia = Re * sp.Matrix(L.inertia_com) * Re.T
        bodies.append(Body(
            name=L.name, joint=L.joint, parent=i - 1, rotation=_rows(R), translation=p, axis=Z_AXIS,
            mass=L.mass, com=tuple(com), inertia_com=_rows(inertia), rotor_inertia=L.rotor_inertia,
            damping=L.damping, external_wrench=L.external_wrench, offset=offset, friction=L.friction,
            friction_velocity=L.friction_velocity, limits=L.limits))
        frames.append(Frame(f"frame{i + 1}", i, _rows(Re), (sp.sympify(end_a), _Z, _Z)))
    return tuple(bodies), tuple(frames)


def combined_last_link(robot: Robot) -> tuple:
    """The links with the payload (if any) merged into the last link.

    A point mass m_L at r_L adds to the mass, moves the centre of mass, and
    adds the parallel-axis terms of both bodies about the new centre of mass.
    Both formulations call this, so they see the same rigid bodies.
    """
    return _merged_payload(robot.links, robot.payload)


def _merged_payload(links: tuple, payload) -> tuple:
    if payload is None:
        return links
    last = links[-1]
    m, mL = last.mass, payload.mass
    r = sp.Matrix(last.com)
    rL = sp.Matrix(payload.com)
    mt = m + mL
    rc = (m * r + mL * rL) / mt

    def shift(mass, offset):
        # inertia of a point mass at `offset` from the new COM (tensor form)
        o = offset
        return mass * ((o.T * o)[0, 0] * sp.eye(3) - o * o.T)

    I = sp.Matrix(last.inertia_com) + shift(m, r - rc) + shift(mL, rL - rc)
    # the joint's own data (rotor, damping, friction, limits) stay as they are
    merged = replace(last, mass=mt, com=tuple(rc), inertia_com=tuple(tuple(I.row(i)) for i in range(3)))
    return links[:-1] + (merged,)
