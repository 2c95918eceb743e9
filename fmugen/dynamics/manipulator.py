"""A manipulator's equations of motion, symbolic and numeric.

    tau = M(q) qdd + h(q, qd)        (thesis eq. 40; DYNAMAN eq. 17 with B = M)

``Manipulator`` derives, for either formulation,

* ``inverse_dynamics``  tau(q, qd, qdd)       -- one recursion
* ``mass_matrix``       M(q), n x n            -- the recursion with qd = 0, g = 0
                                                  and qdd = e_j, column by column
                                                  (the thesis's ARM2, eqs. 41-42)
* ``bias``              h(q, qd)               -- the recursion with qdd = 0
* ``forward_dynamics``  qdd = M^{-1}(tau - h)  -- Cholesky solve, never an inverse
* ``fk`` / ``jacobian`` pose and 6 x n geometric Jacobian of the last frame

as straight-line programs, numeric evaluators (numpy in, numpy out), and the
state-space :class:`~fmugen.codegen.model.SymbolicModel` that becomes an FMU.

Symbols: q_i, qd_i, qdd_i, tau_i (i = 1..n); external wrenches on a link k
that asks for them: f_ext_k_x.., t_ext_k_x.. (base coordinates, force at the
link's centre of mass).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from typing import Mapping, Optional, Sequence

import numpy as np
import sympy as sp

from ..codegen.chain import LOOP_MIN_LINKS, ChainDynamics, robot_tree
from ..codegen.differentiate import differentiate
from ..codegen.model import EventClause, Events, SymbolicModel, Variable
from ..codegen.program import Program
from ..codegen.python_code import compile_program
from ..robot.bounds import parameter_bounds
from ..robot.description import REVOLUTE, Robot
from . import crba, kinematics
from .lagrange import RecursiveLagrange
from .newton_euler import NestedBodyInverseDynamics
from .trig import TrigCache


def robot_parameters(robot: Robot) -> tuple:
    """The robot's parameters as model Variables, with the physical ranges of
    those that are a link's quantity themselves (:func:`fmugen.robot.bounds.parameter_bounds`)."""
    lows = parameter_bounds(robot)
    return tuple(Variable(p.name, p.symbol, p.unit, p.description, start=p.value, min=lows.get(p.name))
                 for p in robot.parameters)

FORMULATIONS = ("newton_euler", "lagrange")
#: ``state_space_model(friction=...)``: the smooth tanh Coulomb term, or stick and slip modes (events)
FRICTION_MODES = ("smooth", "stick-slip")
#: ``state_space_model(limits=...)``: joint ranges as validity ranges, or as end stops (events)
LIMIT_MODES = ("range", "stops")


def _real(name):
    return sp.Symbol(name, real=True)


def _joint_label(body) -> str:
    """A joint as its file names it: the URDF joint name, or the DH link name."""
    return body.joint_name or body.name


def _frame_tag(name: str) -> str:
    """A frame name as part of an FMI variable name: an identifier (never "ee": p_ee is taken)."""
    tag = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return "ee_frame" if tag == "ee" else tag


def _joint_aliases(bodies, joints) -> dict:
    """FMI 2.0 alias names of the joint variables of a URDF robot: ``{i: "<joint>"}``.

    The URDF joint name made an FMI identifier (every character outside
    ``[A-Za-z0-9_]`` becomes ``_``, a leading digit gets a ``_`` before it), so
    ``<joint>.q``, ``<joint>.qd``, ``<joint>.tau`` are structured names; two
    joints whose names clean to the same identifier get ``_2``, ``_3`` ...
    DH robots (no joint names) get none: their q[i] are the file's own names.
    """
    out, used = {}, set()
    for i in joints:
        name = bodies[i].joint_name
        if not name:
            continue
        tag = re.sub(r"[^A-Za-z0-9_]", "_", name)
        if not re.match(r"[A-Za-z_]", tag):
            tag = "_" + tag
        base, k = tag, 2
        while tag in used:
            tag, k = f"{base}_{k}", k + 1
        used.add(tag)
        out[i] = tag
    return out


def _ee_label(robot) -> str:
    """Where p_ee is, in words: "frame 6" (DH), or the frame's name."""
    if robot.links and robot.end_frame == f"frame{robot.n}":
        return f"frame {robot.n}"
    return robot.end_frame


@dataclass
class Derivation:
    """One Program with the inverse-dynamics engine that writes into it."""

    program: Program
    engine: object
    trig: TrigCache


@dataclass
class _EventJoint:
    """One free joint with stick-slip friction and/or end stops (see ``state_space_model``)."""

    k: int  # index among the free joints (the state order)
    i: int  # 0-based joint index
    label: str  # the joint as its file names it
    tag: str  # parameter-name suffix: the cleaned URDF joint name, or the 1-based DH index
    revolute: bool
    F_c: object = None  # Coulomb level (stick-slip joints)
    F_s: object = None  # breakaway parameter symbol
    slip: object = None  # discrete m_i
    lower: object = None  # stop parameter symbols (None: no stop on that side)
    upper: object = None
    e: object = None  # restitution parameter symbol
    rest: object = None  # discrete r_i
    tau_c: object = None  # constraint torque (program symbol)

    @property
    def lock(self):
        """s_i: 1 when the joint is stuck or resting on a stop, else 0 (for m_i, r_i in {-1, 0, 1})."""
        if self.slip is not None and self.rest is not None:
            return 1 - self.slip ** 2 * (1 - self.rest ** 2)
        if self.slip is not None:
            return 1 - self.slip ** 2
        return self.rest ** 2


@dataclass
class _HybridPlan:
    """The per-joint lock masks, discrete states, parameters and events of a hybrid arm model."""

    manipulator: "Manipulator"
    robot: Robot  # the robot derived: smooth friction removed from the stick-slip joints
    joints: list  # _EventJoint, in free-joint order
    parameters: tuple  # the new parameters (breakaway, stops, restitution, rest speed)
    discrete: tuple  # Variables of slip[i], rest[i]
    v_rest: object = None
    by_k: dict = field(default_factory=dict)

    def __post_init__(self):
        self.by_k = {j.k: j for j in self.joints}

    def _s(self, k):
        j = self.by_k.get(k)
        return sp.Integer(0) if j is None else j.lock

    def masked(self, P: Program, M: sp.Matrix, rhs: sp.Matrix) -> tuple:
        """(M', r') of the design: identity rows/columns and zero right-hand sides for locked joints,
        the slip friction -m_i F_c_i on the others; entries of joints without events unchanged."""
        nf = M.rows
        Mp = sp.zeros(nf, nf)
        for a in range(nf):
            for b in range(a + 1):
                sa, sb = self._s(a), self._s(b)
                if sa == 0 and sb == 0:
                    e = M[a, b]
                else:
                    e = P.let((1 - sa) * (1 - sb) * M[a, b] + (sa if a == b else 0), "Mm")
                Mp[a, b] = Mp[b, a] = e
        rp = []
        for k in range(nf):
            j = self.by_k.get(k)
            if j is None:
                rp.append(rhs[k])
                continue
            r = rhs[k] - (j.slip * j.F_c if j.slip is not None else 0)
            rp.append(P.let((1 - j.lock) * r, "rm"))
        return Mp, sp.Matrix(rp)

    def constraint_torques(self, P: Program, M: sp.Matrix, rhs: sp.Matrix, X: sp.Matrix) -> None:
        """tau_c_i = tau_i - h_i - sum_j M_ij qdd_j (full M): zero for a free joint, the negated torque
        of its lock (static friction, stop) for a locked one."""
        for j in self.joints:
            j.tau_c = P.let(rhs[j.k] - sum(M[j.k, b] * X[b] for b in range(M.cols)), "tauc")

    def masked_rows(self, Jp: Program, B: sp.Matrix) -> sp.Matrix:
        """The Jacobian's right-hand sides with the rows of locked joints multiplied by (1 - s_i)."""
        B = sp.Matrix(B)
        for j in self.joints:
            for c in range(B.cols):
                if B[j.k, c] != 0:
                    B[j.k, c] = Jp.let((1 - j.lock) * B[j.k, c], "Bm")
        return B

    def state_variables(self, states: list) -> list:
        """States of stop joints lose their validity range on q: the stops hold q (to the event location's
        accuracy), and the stop positions are parameters."""
        stopped = {self.manipulator.q[j.i] for j in self.joints if j.rest is not None}
        return [replace(v, min=None, max=None) if v.symbol in stopped else v for v in states]

    def events(self, qdd_f: list) -> Events:
        m = self.manipulator
        indicators, clauses = [], []
        one, zero = sp.Integer(1), sp.Integer(0)
        for j in self.joints:
            q, qd, qdd, tc, n = m.q[j.i], m.qd[j.i], qdd_f[j.k], j.tau_c, j.i + 1
            free_of_stops = [sp.Eq(j.rest, 0)] if j.rest is not None else []
            if j.slip is not None:
                m_ = j.slip
                stuck = (1 - m_ ** 2) * (1 - j.rest ** 2) if j.rest is not None else 1 - m_ ** 2
                indicators.append((f"stick[{n}]", m_ * qd))
                indicators.append((f"breakaway[{n}]", stuck * (j.F_s - sp.Abs(tc)) + (1 - stuck)))
                # a stuck joint given a velocity (a start value) slides that way
                clauses.append(EventClause(sp.And(sp.Eq(m_, 0), sp.Ne(qd, 0), *free_of_stops),
                                           ((m_, sp.Piecewise((one, qd > 0), (-one, True))),), f"start sliding[{n}]"))
                # a sliding joint whose velocity reached zero sticks; right after a breakaway qd = 0 with the
                # acceleration along m_i: that is no stick
                clauses.append(EventClause(sp.And(sp.Ne(m_, 0), m_ * qd <= 0, sp.Or(m_ * qd < 0, m_ * qdd <= 0)),
                                           ((m_, zero), (qd, zero)), f"stick[{n}]"))
                clauses.append(EventClause(sp.And(sp.Eq(m_, 0), sp.Abs(tc) > j.F_s, *free_of_stops),
                                           ((m_, sp.Piecewise((one, tc > 0), (-one, True))),), f"breakaway[{n}]"))
            if j.rest is not None:
                r, e, vr = j.rest, j.e, self.v_rest
                slip_after = (lambda v: ((j.slip, v),)) if j.slip is not None else (lambda v: ())
                if j.lower is not None:
                    lo = j.lower
                    indicators.append((f"lower_stop[{n}]", q - lo))
                    clauses.append(EventClause(sp.And(sp.Eq(r, 0), q <= lo, qd < 0, -e * qd >= vr),
                                               ((q, lo), (qd, -e * qd)) + slip_after(one),
                                               f"bounce at lower stop[{n}]"))
                    clauses.append(EventClause(sp.And(sp.Eq(r, 0), q <= lo, qd <= 0, sp.Or(qd < 0, qdd < 0),
                                                      -e * qd < vr),
                                               ((r, -one), (q, lo), (qd, zero)) + slip_after(zero),
                                               f"rest on lower stop[{n}]"))
                    clauses.append(EventClause(sp.And(sp.Eq(r, -1), tc >= 0), ((r, zero),), f"leave lower stop[{n}]"))
                if j.upper is not None:
                    hi = j.upper
                    indicators.append((f"upper_stop[{n}]", hi - q))
                    clauses.append(EventClause(sp.And(sp.Eq(r, 0), q >= hi, qd > 0, e * qd >= vr),
                                               ((q, hi), (qd, -e * qd)) + slip_after(-one),
                                               f"bounce at upper stop[{n}]"))
                    clauses.append(EventClause(sp.And(sp.Eq(r, 0), q >= hi, qd >= 0, sp.Or(qd > 0, qdd > 0),
                                                      e * qd < vr),
                                               ((r, one), (q, hi), (qd, zero)) + slip_after(zero),
                                               f"rest on upper stop[{n}]"))
                    clauses.append(EventClause(sp.And(sp.Eq(r, 1), tc <= 0), ((r, zero),), f"leave upper stop[{n}]"))
                # (a bounce puts q on the stop as well: the located impact is up to the event tolerance past it,
                # and an importer would see q cross the stop again, upwards, right after the bounce)
                # resting: z = -tau_c (lower) or tau_c (upper) > 0 while the stop pushes; free: 0
                indicators.append((f"leave_stop[{n}]", r * tc))
        return Events(discrete=self.discrete, indicators=tuple(indicators), clauses=tuple(clauses))

    def provenance(self) -> str:
        fr = [j.i + 1 for j in self.joints if j.slip is not None]
        st = [j.i + 1 for j in self.joints if j.rest is not None]
        return ((f"; stick-slip friction (events) on joints {fr}" if fr else "")
                + (f"; end stops (events) on joints {st}" if st else ""))


class Manipulator:
    """Equations of motion of a :class:`~fmugen.robot.description.Robot`.

    >>> from fmugen.robot.chain import n_link_chain          # doctest: +SKIP
    >>> arm = Manipulator(n_link_chain(2, seed=1))            # doctest: +SKIP
    >>> arm.mass_matrix([0.1, 0.2]).shape                     # doctest: +SKIP
    (2, 2)
    """

    def __init__(self, robot: Robot, formulation: str = "newton_euler"):
        if formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {FORMULATIONS}, not {formulation!r}")
        self.robot = robot
        self.formulation = formulation
        n = robot.n
        self.q = [_real(f"q_{i + 1}") for i in range(n)]
        self.qd = [_real(f"qd_{i + 1}") for i in range(n)]
        self.qdd = [_real(f"qdd_{i + 1}") for i in range(n)]
        self.tau = [_real(f"tau_{i + 1}") for i in range(n)]
        self.external_links = [i for i, L in enumerate(robot.bodies) if L.external_wrench]
        self.ext = {}
        for k in self.external_links:
            f = [_real(f"f_ext_{k + 1}_{c}") for c in "xyz"]
            t = [_real(f"t_ext_{k + 1}_{c}") for c in "xyz"]
            self.ext[k] = (f, t)
        self.parameter_symbols = [p.symbol for p in robot.parameters]
        self._compiled: dict = {}

    @property
    def n(self) -> int:
        return self.robot.n

    @property
    def ext_symbols(self) -> list:
        return [s for k in self.external_links for s in self.ext[k][0] + self.ext[k][1]]

    # ------------------------------------------------------------------
    # symbolic derivations
    def derivation(self, formulation: Optional[str] = None, prefix: str = "_w") -> Derivation:
        formulation = formulation or self.formulation
        P = Program(prefix)
        trig = TrigCache(P)
        if formulation == "newton_euler":
            engine = NestedBodyInverseDynamics(P, self.robot.bodies, trig)
        elif formulation == "lagrange":
            engine = RecursiveLagrange(P, self.robot, trig)
        else:
            raise ValueError(f"formulation must be one of {FORMULATIONS}, not {formulation!r}")
        return Derivation(P, engine, trig)

    def _mass_matrix_into(self, d: Derivation, q=None) -> sp.Matrix:
        """M(q): composite rigid bodies (Newton-Euler) or unit accelerations (Lagrange).

        The Lagrange formulation keeps the thesis's own method (ARM2, eqs.
        41-42): column j is the inverse dynamics with qd = 0, g = 0 and
        qdd = e_j; only the lower triangle is computed, the upper mirrors it.
        """
        q = self.q if q is None else q
        if isinstance(d.engine, NestedBodyInverseDynamics):
            return crba.mass_matrix(d.engine, q)
        n = self.n
        zeros = [sp.Integer(0)] * n
        M = sp.zeros(n, n)
        for j in range(n):
            e = [sp.Integer(int(k == j)) for k in range(n)]
            col = d.engine.torques(q, zeros, e, gravity=None, external=None, first=j)
            for i in range(j, n):
                M[i, j] = M[j, i] = col[i]
        return M

    def _bias_into(self, d: Derivation) -> list:
        zeros = [sp.Integer(0)] * self.n
        return d.engine.torques(self.q, self.qd, zeros, gravity=self.robot.gravity, external=self.ext or None)

    def inverse_dynamics_program(self, formulation=None) -> tuple:
        """(Program, [tau_i]) for tau = ID(q, qd, qdd)."""
        d = self.derivation(formulation)
        tau = d.engine.torques(self.q, self.qd, self.qdd, gravity=self.robot.gravity, external=self.ext or None)
        return d.program, tau

    def mass_matrix_program(self, formulation=None) -> tuple:
        d = self.derivation(formulation)
        return d.program, self._mass_matrix_into(d)

    def bias_program(self, formulation=None) -> tuple:
        d = self.derivation(formulation)
        return d.program, self._bias_into(d)

    def kinematics_program(self, frame: Optional[str] = None) -> tuple:
        """(Program, pose of ``frame`` as 4x4 Matrix, its J as 6 x n Matrix).

        ``frame``: any body or frame name (:meth:`Robot.frame_names`); default
        ``robot.end_frame`` (the last DH frame, the thesis's TRANSP).
        """
        P = Program("_k")
        Ts = kinematics.body_frames(P, self.robot, self.q)
        body, T = kinematics.frame_pose(P, self.robot, Ts, frame or self.robot.end_frame)
        J = kinematics.geometric_jacobian(P, self.robot, Ts, [T[r][3] for r in range(3)], body)
        return P, sp.Matrix(T), J

    # closed forms (small robots, tests and printing only)
    def closed_form(self, formulation=None) -> tuple:
        """(M, h) as closed-form sympy matrices.  Grows fast with n: n <= 3."""
        Pm, M = self.mass_matrix_program(formulation)
        Ph, h = self.bias_program(formulation)
        Mc = sp.Matrix(self.n, self.n, Pm.inline(list(M)))
        hc = sp.Matrix(Ph.inline(h))
        return Mc, hc

    # ------------------------------------------------------------------
    # the state-space model that becomes an FMU
    def state_space_model(self, outputs: Sequence[str] = ("p_ee",), formulation=None, name=None,
                          locked: Optional[Mapping[int, float]] = None,
                          strategy: str = "auto", friction: str = "smooth",
                          limits: str = "range") -> SymbolicModel:
        """x = [q, qd], u = [tau, external wrenches], x' = [qd, M^{-1}(tau - h)].

        ``strategy``: "straight" derives straight-line code (the formulation's
        recursion, symbolic, CSE'd: the fastest code for small arms, but its
        size and compile time grow with n^2..n^3); "loops" derives nothing and
        lets the generated C call the looped articulated-body algorithm and
        analytical Newton-Euler derivatives of ``c_runtime/chain_dynamics.c``
        (:mod:`fmugen.codegen.chain`: code size linear in n, for C only --
        the Python evaluators need "straight"); "auto" (default) takes
        "loops" from :data:`~fmugen.codegen.chain.LOOP_MIN_LINKS` links on,
        for arms without locked joints.

        ``outputs``: any of "p_ee" (end-effector position: the origin of
        ``robot.end_frame``, frame N of a DH robot), "qdd" (joint
        accelerations, which have direct feedthrough from tau) and, for any
        body or frame NAME (a URDF link, a link merged by a fixed joint, a DH
        ``frameI``), "p:NAME" (its origin, FMI ``p_NAME[1..3]``), "R:NAME"
        (its orientation, ``R_NAME[r,c]``) and "J:NAME" (the 6 x n geometric
        Jacobian of its origin, linear rows first, ``J_NAME[r,j]`` for each
        free joint j); only the bodies between the named frames and the base
        are computed.  q and qd are outputs as states (no direct feedthrough).

        ``locked`` ({joint number (1-based): position}) holds joints still:
        their q is the given number and their qd, qdd are zero, so the model
        keeps only the free joints (names unchanged, e.g. q[1], q[2], q[3])
        and its equations are exactly the free joints' rows of the full arm,
        M_ff qdd_f + h_f = tau_f; the locked links' mass and inertia act
        through the numbers they fold into.

        ``friction``: "smooth" (default) keeps the Coulomb friction F_c of a
        joint (URDF ``<dynamics friction>``, a DH link's ``friction``) as the
        smooth term F_c tanh(qd / v_c): a joint held against a load below F_c
        still creeps at qd = v_c atanh(load / F_c).  "stick-slip" makes it
        hybrid (FMI events): the joint sticks and stays put to round-off until
        the torque its lock has to supply exceeds the breakaway level F_s
        (parameter ``fs_<joint>``, default F_c), and slides against -sign(qd)
        F_c otherwise.  ``limits``: "range" (default) keeps a joint's range
        (URDF ``<limit lower upper>``, a DH link's ``limits``) as the validity
        range of q; "stops" makes its ends end stops: an impact reverses qd
        times the restitution e (``e_stop_<joint>``, default 0: inelastic),
        and below the rest speed (``v_rest``, 1e-3 rad/s or m/s) the joint
        rests on the stop (q := stop, qd := 0) until the stop no longer has to
        push.  Both are the straight-line strategy only.

        Hybrid design (one mode-dependent model, never 2^n modes): each event
        joint i has discrete states ``slip[i]`` m_i in {-1, 0, +1} (0: stuck)
        and/or ``rest[i]`` r_i in {-1, 0, +1} (resting on the lower/upper
        stop), and a lock s_i = 1 - m_i^2 (1 - r_i^2) (friction and stops),
        1 - m_i^2 (friction) or r_i^2 (stops).  The derivation is made
        without the tanh term of the stick-slip joints, and

            M'_ij = (1 - s_i)(1 - s_j) M_ij + s_i delta_ij,
            r'_i  = (1 - s_i)(tau_i - h_i - m_i F_c_i),   qdd = M'^{-1} r'

        is ONE symmetric positive definite solve whose entries the modes
        switch: a locked joint has qdd_i = 0 exactly (its row and column are
        the identity's, its right-hand side 0) and qd_i = 0 from the event
        that locked it, so q_i does not move, while the free joints obey the
        free rows of the full equations with the locked joints held.  The
        constraint torque tau_c_i = tau_i - h_i - sum_j M_ij qdd_j (what
        the lock or the stop supplies, negated) is a program symbol the
        indicators and clauses read.  Events: a sliding joint sticks when
        m_i qd_i crosses 0 (qd_i := 0, m_i := 0); in the next round of the
        same event iteration a stuck joint with |tau_c_i| > F_s breaks away
        (m_i := sign(tau_c_i)); the breakaway indicator F_s - |tau_c_i| is a
        constant 1 while the joint slides.  A free joint reaching a stop
        (indicators q_i - lower, upper - q_i) bounces (qd_i := -e qd_i) or
        rests (r_i := -+1, q_i := stop, qd_i := 0, m_i := 0), and leaves
        the stop when tau_c_i points away from it (indicator r_i tau_c_i).
        The exact Jacobian is the current mode's: d ID / dz at fixed qdd
        (tanh-free), rows of locked joints zeroed, solved with M'.  Locked
        joints (``locked=``) are not states and have no events; a tied mimic
        follower with friction (stick-slip) or limits (stops) is refused.
        """
        kin_outputs = self.frame_outputs(outputs)
        n, robot = self.n, self.robot
        locked = dict(locked or {})
        if strategy not in ("auto", "straight", "loops"):
            raise ValueError(f"strategy must be 'auto', 'straight' or 'loops', not {strategy!r}")
        if friction not in FRICTION_MODES:
            raise ValueError(f"friction must be one of {FRICTION_MODES}, not {friction!r}")
        if limits not in LIMIT_MODES:
            raise ValueError(f"limits must be one of {LIMIT_MODES}, not {limits!r}")
        hybrid = friction == "stick-slip" or limits == "stops"
        # the runtime's loops take any tree of the general joint model (damping and Coulomb friction too)
        followers = {i: b.mimic for i, b in enumerate(robot.bodies) if b.mimic is not None}
        loopable = not locked and not kin_outputs and not followers
        if strategy == "loops" and not loopable:
            why = "locked joints" if locked else "frame outputs" if kin_outputs else "tied mimic joints"
            raise ValueError(f"{robot.name}: strategy='loops' does not handle {why}; "
                             f"use strategy='straight'")
        if strategy == "loops" or (strategy == "auto" and loopable and n >= LOOP_MIN_LINKS):
            if hybrid:
                what = " and ".join(w for w, on in ((f"friction={friction!r}", friction != "smooth"),
                                                    (f"limits={limits!r}", limits != "range")) if on)
                how = "strategy='loops'" if strategy == "loops" else \
                    f"strategy='auto' (the runtime's loops from {LOOP_MIN_LINKS} joints on)"
                raise ValueError(f"{robot.name}: {what} needs straight-line code, and {how} derives none; "
                                 f"use strategy='straight' (its size and build time grow with n^2..n^3)")
            return self._looped_state_space_model(outputs, name)
        bad = [j for j in locked if not (isinstance(j, int) and 1 <= j <= n)]
        if bad:
            raise ValueError(f"{robot.name}: locked joint(s) {bad} do not exist (joints 1..{n})")
        tied = [f + 1 for f in followers if f + 1 in locked]
        if tied:
            raise ValueError(f"{robot.name}: joint(s) {tied} follow another joint (tied mimic joints); "
                             "lock their leader instead")
        free = [i for i in range(n) if i + 1 not in locked and i not in followers]
        if not free:
            raise ValueError(f"{robot.name}: every joint is locked; nothing moves")
        q = [sp.Float(locked[i + 1]) if i + 1 in locked else self.q[i] for i in range(n)]
        qd = [sp.Integer(0) if i + 1 in locked else self.qd[i] for i in range(n)]
        nf = len(free)
        # tied mimic joints: q_f = m q_l + o, so q = G q_free + const and the equations are
        # G^T (M G qdd_free + h) = G^T tau (the follower has no actuator of its own)
        G = sp.zeros(n, nf)
        for k, i in enumerate(free):
            G[i, k] = 1
        for f, (lead, mult, off) in sorted(followers.items()):
            q[f] = mult * q[lead] + off
            qd[f] = mult * qd[lead]
            G[f, :] = mult * G[lead, :]
        hyb = self._hybrid_plan(free, followers, friction, limits) if hybrid else None
        # stick-slip joints: derived without their smooth tanh term (the modes carry the friction)
        d = (self if hyb is None else Manipulator(hyb.robot, self.formulation)).derivation(formulation)
        P = d.program
        zeros = [sp.Integer(0)] * n
        h = d.engine.torques(q, qd, zeros, gravity=robot.gravity, external=self.ext or None)
        M_full = self._mass_matrix_into(d, q)
        if followers:
            M = (G.T * M_full * G).applyfunc(lambda e: P.let(e, "M"))
            hr = G.T * sp.Matrix(h)
            rhs = sp.Matrix([P.let(self.tau[i] - hr[k], "r") for k, i in enumerate(free)])
        else:
            M = M_full.extract(free, free)
            rhs = sp.Matrix([P.let(self.tau[i] - h[i], "r") for i in free])
        if hyb is None:
            M_solve = M
            X = P.solve_spd(M, rhs, "qdd")
        else:
            M_solve, rhs_m = hyb.masked(P, M, rhs)
            X = P.solve_spd(M_solve, rhs_m, "qdd")
            hyb.constraint_torques(P, M, rhs, X)
        qdd_f = list(X)
        qdd = [P.let(e, "qdd") for e in G * sp.Matrix(qdd_f)]
        out_vars, out_exprs = [], []
        wanted = (["p_ee"] if "p_ee" in outputs else []) + kin_outputs
        if wanted:
            transform = d.engine.rotation_translation if isinstance(d.engine, NestedBodyInverseDynamics) else None
            names = [robot.end_frame if w == "p_ee" else w[2:] for w in wanted]
            Ts = kinematics.body_frames(P, robot, q, d.trig, transform, frames=names)
            for w, frame in zip(wanted, names):
                body, T = kinematics.frame_pose(P, robot, Ts, frame)
                if w == "p_ee":
                    for r in range(3):
                        out_vars.append(Variable(f"p_ee[{r + 1}]", _real(f"p_ee_{r + 1}"), "m",
                                                 f"end-effector position (origin of {_ee_label(robot)}), "
                                                 f"base {'xyz'[r]}"))
                        out_exprs.append(T[r][3])
                    continue
                kind, tag = w[0], _frame_tag(frame)
                if kind == "p":
                    for r in range(3):
                        out_vars.append(Variable(f"p_{tag}[{r + 1}]", _real(f"out_p_{tag}_{r + 1}"), "m",
                                                 f"position of frame {frame} (origin), base {'xyz'[r]}"))
                        out_exprs.append(T[r][3])
                elif kind == "R":
                    for r in range(3):
                        for c in range(3):
                            out_vars.append(Variable(f"R_{tag}[{r + 1},{c + 1}]", _real(f"out_R_{tag}_{r + 1}_{c + 1}"),
                                                     "1", f"orientation of frame {frame}: base {'xyz'[r]} component "
                                                     f"of its {'xyz'[c]} axis"))
                            out_exprs.append(T[r][c])
                else:  # J: 6 x (free joints) geometric Jacobian of the frame origin
                    J = kinematics.geometric_jacobian(P, robot, Ts, [T[r][3] for r in range(3)], body)
                    if followers:  # columns per free joint: the followers' motion included
                        Jr = J * G
                        J = sp.zeros(6, n)
                        for k, i in enumerate(free):
                            J[:, i] = Jr[:, k].applyfunc(lambda e: P.let(e, "Jv"))
                    for r in range(6):
                        for i in free:
                            unit = ("1" if robot.bodies[i].joint == REVOLUTE else "1/m") if r >= 3 else \
                                ("m" if robot.bodies[i].joint == REVOLUTE else "1")
                            out_vars.append(Variable(f"J_{tag}[{r + 1},{i + 1}]", _real(f"out_J_{tag}_{r + 1}_{i + 1}"),
                                                     unit, f"geometric Jacobian of frame {frame}: "
                                                     f"{('linear velocity', 'angular velocity')[r // 3]} "
                                                     f"{'xyz'[r % 3]} per unit qd of joint {i + 1}"))
                            out_exprs.append(J[r, i])
        n_kin = len(out_vars)
        if "qdd" in outputs:
            for i in free:
                unit = "rad/s2" if robot.bodies[i].joint == REVOLUTE else "m/s2"
                out_vars.append(Variable(f"qdd[{i + 1}]", _real(f"qdd_out_{i + 1}"), unit,
                                         f"acceleration of joint {i + 1} ({_joint_label(robot.bodies[i])})"))
                out_exprs.append(qdd[i])

        # exact Jacobians: ID(q, qd, qdd*) = tau  =>  dqdd/dz = -M^{-1} dID/dz
        Jp = Program("_j")
        d.engine.P = Jp  # keep the shared constants and sin/cos, write new steps to Jp
        d.trig.program = Jp
        idx = d.engine.torques(q, qd, qdd, gravity=robot.gravity, external=self.ext or None)
        idx = [Jp.let(e, "tau") for e in G.T * sp.Matrix(idx)] if followers else [idx[i] for i in free]
        ext = self.ext_symbols
        qf, qdf = [self.q[i] for i in free], [self.qd[i] for i in free]
        D = differentiate([P, Jp], idx, qf + qdf + ext, Jp)
        B = sp.zeros(nf, 3 * nf + len(ext))
        B[:, : 2 * nf] = -D[:, : 2 * nf]
        B[:, 2 * nf: 3 * nf] = sp.eye(nf)
        if ext:
            B[:, 3 * nf:] = -D[:, 2 * nf:]
        if hyb is not None:  # the current mode's Jacobian: locked rows zero, solved with M'
            B = hyb.masked_rows(Jp, B)
        Y = Jp.solve_spd(M_solve, B, "y")
        nx, nu = 2 * nf, nf + len(ext)
        dfdx = sp.zeros(nx, nx)
        dfdx[:nf, nf:] = sp.eye(nf)
        dfdx[nf:, :] = Y[:, :nx]
        dfdu = sp.zeros(nx, nu)
        dfdu[nf:, :] = Y[:, nx:]
        dgdx = sp.zeros(len(out_vars), nx)
        dgdu = sp.zeros(len(out_vars), nu)
        row = 0
        if n_kin:
            dgdx[:n_kin, :nf] = differentiate([P], out_exprs[:n_kin], qf, Jp)
            row = n_kin
        if "qdd" in outputs:
            dgdx[row:row + nf, :] = Y[:, :nx]
            dgdu[row:row + nf, :] = Y[:, nx:]

        states, inputs = self._joint_variables(free)
        inputs += self._wrench_inputs()
        params = robot_parameters(robot)
        events = None
        if hyb is not None:
            states = hyb.state_variables(states)
            params += hyb.parameters
            events = hyb.events(qdd_f)
        model = SymbolicModel(
            name=name or robot.name,
            description=robot.description or f"{robot.name}: {n}-link manipulator",
            states=tuple(states),
            inputs=tuple(inputs),
            parameters=params,
            outputs=tuple(out_vars),
            program=P,
            derivatives=tuple(qdf) + tuple(qdd_f),
            output_exprs=tuple(out_exprs),
            jacobian=Jp,
            dfdx=dfdx,
            dfdu=dfdu,
            dgdx=dgdx,
            dgdu=dgdu,
            provenance=f"{robot.source or robot.name}; {formulation or self.formulation} formulation"
                       + (f"; joints {sorted(locked)} locked at {[locked[j] for j in sorted(locked)]}" if locked else "")
                       + (f"; joints {[f + 1 for f in sorted(followers)]} tied to their leaders (mimic)"
                          if followers else "")
                       + (hyb.provenance() if hyb is not None else ""),
            events=events,
        )
        # locked joints leave rows of M and h nobody reads: drop their steps
        return model.pruned() if locked or followers or hyb is not None else model

    def _hybrid_plan(self, free: list, followers: dict, friction: str, limits: str) -> _HybridPlan:
        """Which free joints get stick-slip friction and end stops, with their parameters and discrete
        states (``state_space_model``'s hybrid design); ValueError for what it cannot do."""
        robot = self.robot
        values = robot.parameter_values()
        taken = {p.name for p in robot.parameters}
        taken |= {s.name for s in self.q + self.qd + self.qdd + self.tau + self.ext_symbols}

        def unique(base: str) -> str:
            name, k = base, 2
            while name in taken:
                name, k = f"{base}_{k}", k + 1
            taken.add(name)
            return name

        def number(e):
            v = sp.sympify(e).xreplace({k: sp.Float(x) for k, x in values.items()})
            return float(v) if v.is_Number else None

        def stops_of(b):
            lim = b.limits
            return (None, None) if lim is None else (lim.lower, lim.upper)

        fric = friction == "stick-slip"
        stops = limits == "stops"
        if fric:
            bad = [_joint_label(robot.bodies[f]) for f in followers if robot.bodies[f].friction != 0]
            if bad:
                raise ValueError(f"{robot.name}: friction='stick-slip' is not supported on tied mimic joints with "
                                 f"friction of their own ({', '.join(bad)}); load the robot with "
                                 f"mimic='independent', or use friction='smooth'")
        if stops:
            bad = [_joint_label(robot.bodies[f]) for f in followers if stops_of(robot.bodies[f]) != (None, None)]
            if bad:
                raise ValueError(f"{robot.name}: limits='stops' is not supported on tied mimic joints with limits "
                                 f"of their own ({', '.join(bad)}); load the robot with mimic='independent', "
                                 f"or use limits='range'")
        with_friction = [i for i in free if robot.bodies[i].friction != 0] if fric else []
        with_stops = [i for i in free if stops_of(robot.bodies[i]) != (None, None)] if stops else []
        if fric and not with_friction:
            raise ValueError(f"{robot.name}: friction='stick-slip' but no free joint has Coulomb friction "
                             f"(URDF <dynamics friction>, a DH link's friction)")
        if stops and not with_stops:
            raise ValueError(f"{robot.name}: limits='stops' but no free joint has limits "
                             f"(URDF <limit lower upper>, a DH link's limits)")
        aliases = _joint_aliases(robot.bodies, free)
        joints, params, discrete = [], [], []
        v_rest = None
        if with_stops:
            v_rest = sp.Symbol(unique("v_rest"), real=True)
        for k, i in enumerate(free):
            if i not in with_friction and i not in with_stops:
                continue
            b = robot.bodies[i]
            rev = b.joint == REVOLUTE
            label = _joint_label(b)
            tag = aliases.get(i, str(i + 1)).lstrip("_") or str(i + 1)
            j = _EventJoint(k=k, i=i, label=label, tag=tag, revolute=rev)
            force, pos = ("N.m", "rad") if rev else ("N", "m")
            if i in with_friction:
                j.F_c = b.friction
                j.F_s = sp.Symbol(unique(f"fs_{tag}"), real=True)
                params.append(Variable(j.F_s.name, j.F_s, force,
                                       f"breakaway (static friction) level of joint {i + 1} ({label}): a stuck joint "
                                       f"slides when its constraint torque exceeds it (default: the Coulomb level)",
                                       start=number(b.friction), sign=">=0"))
                j.slip = sp.Symbol(unique(f"slip_{i + 1}"), real=True)
                discrete.append(Variable(f"slip[{i + 1}]", j.slip, "1",
                                         f"friction mode of joint {i + 1} ({label}): +1/-1 sliding with qd > 0 / "
                                         f"qd < 0, 0 stuck", start=0.0))
            if i in with_stops:
                lo, hi = stops_of(b)
                if lo is not None:
                    j.lower = sp.Symbol(unique(f"q_lower_{tag}"), real=True)
                    params.append(Variable(j.lower.name, j.lower, pos, f"lower end stop of joint {i + 1} ({label})",
                                           start=float(lo)))
                if hi is not None:
                    j.upper = sp.Symbol(unique(f"q_upper_{tag}"), real=True)
                    params.append(Variable(j.upper.name, j.upper, pos, f"upper end stop of joint {i + 1} ({label})",
                                           start=float(hi)))
                j.e = sp.Symbol(unique(f"e_stop_{tag}"), real=True)
                params.append(Variable(j.e.name, j.e, "1", f"coefficient of restitution of the end stops of joint "
                                       f"{i + 1} ({label}): qd := -e qd at an impact (0: inelastic)",
                                       start=0.0, min=0.0, max=1.0))
                j.rest = sp.Symbol(unique(f"rest_{i + 1}"), real=True)
                discrete.append(Variable(f"rest[{i + 1}]", j.rest, "1",
                                         f"end-stop mode of joint {i + 1} ({label}): -1/+1 resting on the lower/upper "
                                         f"stop, 0 free", start=0.0))
            joints.append(j)
        if v_rest is not None:
            params.append(Variable(v_rest.name, v_rest, "",
                                   "rest speed of the end stops (rad/s or m/s): an impact whose rebound e |qd| is "
                                   "below it leaves the joint resting on the stop", start=1e-3, sign=">0"))
        # the robot derived: the stick-slip joints without their smooth term
        drop = set(with_friction)
        if not drop:
            derived = robot
        elif robot.links:
            derived = replace(robot, links=tuple(
                replace(L, friction=sp.Integer(0), friction_velocity=sp.Integer(0)) if i in drop else L
                for i, L in enumerate(robot.links)))
        else:
            derived = replace(robot, bodies=tuple(
                replace(b, friction=sp.Integer(0), friction_velocity=sp.Integer(0)) if i in drop else b
                for i, b in enumerate(robot.bodies)))
        return _HybridPlan(self, derived, joints, tuple(params), tuple(discrete), v_rest)

    def _looped_state_space_model(self, outputs: Sequence[str], name=None) -> SymbolicModel:
        """The state-space model as two calls of the runtime's chain loops (strategy "loops").

        Same variables, names and Jacobian layout as the straight-line model;
        the program holds one :class:`~fmugen.codegen.chain.ChainDynamics`
        step (forward dynamics and end-effector position), the Jacobian
        program another.
        """
        n, robot = self.n, self.robot
        # the general joint model of every robot (a DH file's chain included): a tree of bodies
        rev, parents, ee_body, constants = robot_tree(robot)
        ext, ne = self.ext_symbols, len(self.external_links)
        B = sp.Matrix(self.q + self.qd + self.tau + constants + ext)
        tree = dict(revolute=rev, external=tuple(self.external_links), parent=parents, ee_body=ee_body)
        P = Program("_w")
        X = sp.Matrix([P.fresh("qdd") for _ in range(n)] + [P.fresh("pee") for _ in range(3)])
        P.steps.append(ChainDynamics(X, sp.zeros(0, 0), B, kind="fd", **tree))
        qdd, pee = list(X[:n]), list(X[n:])
        Jp = Program("_j")
        nu = n + 6 * ne
        nj = n + n * (2 * n + nu) + 3 * n
        XJ = sp.Matrix([Jp.fresh("jd") for _ in range(nj)])
        Jp.steps.append(ChainDynamics(XJ, sp.zeros(0, 0), B, kind="jacobian", **tree))
        Y = sp.Matrix(n, 2 * n + nu, list(XJ[n:n + n * (2 * n + nu)]))
        dpee = sp.Matrix(3, n, list(XJ[n + n * (2 * n + nu):]))
        out_vars, out_exprs = [], []
        if "p_ee" in outputs:
            for r in range(3):
                out_vars.append(Variable(f"p_ee[{r + 1}]", _real(f"p_ee_{r + 1}"), "m",
                                         f"end-effector position (origin of {_ee_label(robot)}), base {'xyz'[r]}"))
                out_exprs.append(pee[r])
        if "qdd" in outputs:
            for i in range(n):
                unit = "rad/s2" if robot.bodies[i].joint == REVOLUTE else "m/s2"
                out_vars.append(Variable(f"qdd[{i + 1}]", _real(f"qdd_out_{i + 1}"), unit,
                                         f"acceleration of joint {i + 1} ({_joint_label(robot.bodies[i])})"))
                out_exprs.append(qdd[i])
        dfdx = sp.zeros(2 * n, 2 * n)
        dfdx[:n, n:] = sp.eye(n)
        dfdx[n:, :] = Y[:, :2 * n]
        dfdu = sp.zeros(2 * n, nu)
        dfdu[n:, :] = Y[:, 2 * n:]
        dgdx = sp.zeros(len(out_vars), 2 * n)
        dgdu = sp.zeros(len(out_vars), nu)
        row = 0
        if "p_ee" in outputs:
            dgdx[:3, :n] = dpee
            row = 3
        if "qdd" in outputs:
            dgdx[row:row + n, :] = Y[:, :2 * n]
            dgdu[row:row + n, :] = Y[:, 2 * n:]
        states, inputs = self._joint_variables(range(n))
        inputs += self._wrench_inputs()
        params = robot_parameters(robot)
        return SymbolicModel(
            name=name or robot.name,
            description=robot.description or f"{robot.name}: {n}-link manipulator",
            states=tuple(states), inputs=tuple(inputs), parameters=params, outputs=tuple(out_vars),
            program=P, derivatives=tuple(self.qd) + tuple(qdd), output_exprs=tuple(out_exprs),
            jacobian=Jp, dfdx=dfdx, dfdu=dfdu, dgdx=dgdx, dgdu=dgdu,
            provenance=f"{robot.source or robot.name}; looped articulated-body algorithm and analytical "
                       f"Newton-Euler derivatives (c_runtime/chain_dynamics.c)",
        )

    def frame_outputs(self, outputs) -> list:
        """The frame outputs among ``outputs`` ("p:NAME", "R:NAME", "J:NAME"), checked; ValueError names the choices."""
        out = []
        for o in outputs:
            if o in ("p_ee", "qdd"):
                continue
            kind, _, frame = str(o).partition(":")
            if kind not in ("p", "R", "J") or not frame:
                raise ValueError(f"unknown output {o!r}; choose from p_ee, qdd, p:FRAME, R:FRAME, J:FRAME "
                                 f"(FRAME: a body or frame name)")
            try:
                self.robot.locate(frame)
            except KeyError as exc:
                raise ValueError(f"output {o!r}: {exc.args[0]}") from None
            if o not in out:
                out.append(o)
        return out

    def _joint_variables(self, joints) -> tuple:
        """(states q[i] then qd[i], inputs tau[i]) of the given 0-based joints.

        Names are indexed (``q[3]``, structured FMI names every scene and
        command uses); each description names the joint as its file does
        (the URDF joint name).  A URDF ``<limit>`` becomes the validity range
        of q (lower, upper) and of tau (+-effort).
        """
        states, qds, inputs = [], [], []
        aliases = _joint_aliases(self.robot.bodies, joints)
        for i in joints:
            L = self.robot.bodies[i]
            tag = aliases.get(i)
            rev = L.joint == REVOLUTE
            lim = L.limits
            lo = None if lim is None else lim.lower
            hi = None if lim is None else lim.upper
            # start at 0, or mid-range when 0 is outside the joint's range (the Panda's elbow: [-3.07, -0.07])
            start = 0.0
            if (lo is not None and lo > 0) or (hi is not None and hi < 0):
                start = 0.5 * (lo + hi) if lo is not None and hi is not None else (lo if lo is not None else hi)
            name = _joint_label(L)
            states.append(Variable(f"q[{i + 1}]", self.q[i], "rad" if rev else "m",
                                   f"position of joint {i + 1} ({name}, {L.joint})", start=start, output=True,
                                   min=lo, max=hi, alias=f"{tag}.q" if tag else ""))
            qds.append(Variable(f"qd[{i + 1}]", self.qd[i], "rad/s" if rev else "m/s",
                                f"velocity of joint {i + 1} ({name})", start=0.0, output=True,
                                alias=f"{tag}.qd" if tag else ""))
            effort = None if lim is None else lim.effort
            inputs.append(Variable(f"tau[{i + 1}]", self.tau[i], "N.m" if rev else "N",
                                   f"{'torque' if rev else 'force'} applied by actuator {i + 1} ({name})"
                                   if L.joint_name else
                                   f"{'torque' if rev else 'force'} applied by actuator {i + 1}", start=0.0,
                                   min=None if effort is None else -effort, max=effort,
                                   alias=f"{tag}.tau" if tag else ""))
        return states + qds, inputs

    def _wrench_inputs(self) -> list:
        """The external-wrench inputs, in the order of ``ext_symbols``."""
        out = []
        for k in self.external_links:
            f, t = self.ext[k]
            for c in range(3):
                out.append(Variable(f"f_ext_{k + 1}[{c + 1}]", f[c], "N",
                                    f"external force on link {k + 1} at its centre of mass, base {'xyz'[c]}",
                                    start=0.0))
            for c in range(3):
                out.append(Variable(f"t_ext_{k + 1}[{c + 1}]", t[c], "N.m",
                                    f"external torque on link {k + 1}, base {'xyz'[c]}", start=0.0))
        return out

    def inverse_dynamics_model(self, formulation=None, name=None, strategy: str = "auto") -> SymbolicModel:
        """tau = ID(q, qd, qdd, w_ext) as a state-free model (e.g. for computed-torque control).

        Inputs q[i], qd[i], qdd[i] (and external wrenches), outputs tau[i]
        (direct feedthrough), with the exact Jacobian d tau / d inputs.
        ``strategy``: straight-line code, or the runtime's loops
        (``c_runtime/chain_dynamics.c``: recursive Newton-Euler and its
        analytical derivatives); "auto" takes the loops from
        ``LOOP_MIN_LINKS`` joints on, as :meth:`state_space_model` does.
        """
        if strategy not in ("auto", "straight", "loops"):
            raise ValueError(f"strategy must be 'auto', 'straight' or 'loops', not {strategy!r}")
        robot = self.robot
        looped = strategy == "loops" or (strategy == "auto" and self.n >= LOOP_MIN_LINKS)
        if looped:
            P, tau, D = self._looped_inverse_dynamics()
        else:
            P, tau = self.inverse_dynamics_program(formulation)
        inputs = []
        for group, stem, units, what in ((self.q, "q", ("rad", "m"), "position"),
                                         (self.qd, "qd", ("rad/s", "m/s"), "velocity"),
                                         (self.qdd, "qdd", ("rad/s2", "m/s2"), "acceleration")):
            for i, L in enumerate(robot.bodies):
                unit = units[0] if L.joint == REVOLUTE else units[1]
                inputs.append(Variable(f"{stem}[{i + 1}]", group[i], unit, f"{what} of joint {i + 1} ({_joint_label(L)})",
                                       start=0.0))
        inputs += self._wrench_inputs()
        outputs = tuple(
            Variable(f"tau[{i + 1}]", _real(f"tau_out_{i + 1}"), "N.m" if L.joint == REVOLUTE else "N",
                     f"{'torque' if L.joint == REVOLUTE else 'force'} that joint {i + 1} needs")
            for i, L in enumerate(robot.bodies))
        if looped:
            Jp = D[1]
            D = D[0]
        else:
            Jp = Program("_j")
            D = differentiate([P], tau, [v.symbol for v in inputs], Jp)
        params = robot_parameters(robot)
        return SymbolicModel(
            name=name or f"{robot.name}_inverse_dynamics",
            description=f"{robot.name}: tau = M(q) qdd + h(q, qd), inverse dynamics",
            states=(), inputs=tuple(inputs), parameters=params, outputs=outputs,
            program=P, derivatives=(), output_exprs=tuple(tau),
            jacobian=Jp, dfdx=sp.zeros(0, 0), dfdu=sp.zeros(0, len(inputs)), dgdx=sp.zeros(len(tau), 0), dgdu=D,
            provenance=f"{robot.source or robot.name}; "
                       + ("recursive Newton-Euler in the runtime's loops" if looped
                          else f"{formulation or self.formulation} formulation"),
        )

    def _looped_inverse_dynamics(self) -> tuple:
        """``(program, tau, (dtau/dinputs, Jacobian program))``: two calls of the runtime's loops."""
        n = self.n
        rev, parents, ee_body, constants = robot_tree(self.robot)
        ne = len(self.external_links)
        B = sp.Matrix(self.q + self.qd + self.qdd + constants + self.ext_symbols)
        tree = dict(revolute=rev, external=tuple(self.external_links), parent=parents, ee_body=ee_body)
        P = Program("_w")
        X = sp.Matrix([P.fresh("tau") for _ in range(n)])
        P.steps.append(ChainDynamics(X, sp.zeros(0, 0), B, kind="id", **tree))
        Jp = Program("_j")
        nu = 3 * n + 6 * ne
        XJ = sp.Matrix([Jp.fresh("jd") for _ in range(n + n * nu)])
        Jp.steps.append(ChainDynamics(XJ, sp.zeros(0, 0), B, kind="id_jacobian", **tree))
        return P, list(X), (sp.Matrix(n, nu, list(XJ[n:])), Jp)

    # ------------------------------------------------------------------
    # numeric evaluators
    def parameter_vector(self, values: Optional[dict] = None) -> np.ndarray:
        """Parameter values in ``robot.parameters`` order: file defaults, overridden by ``values``."""
        values = dict(values or {})
        known = {p.name for p in self.robot.parameters}
        unknown = set(values) - known
        if unknown:
            raise KeyError(f"{self.robot.name}: unknown parameter(s) {sorted(unknown)}; known: {sorted(known)}")
        vec, missing = [], []
        for p in self.robot.parameters:
            v = values.get(p.name, p.value)
            if v is None:
                missing.append(p.name)
            vec.append(v)
        if missing:
            raise ValueError(f"{self.robot.name}: no value for symbolic parameter(s) {missing}; "
                             f"pass them as keywords, e.g. {missing[0]}=1.0")
        return np.asarray(vec, dtype=float)

    def _fn(self, key, formulation):
        formulation = formulation or self.formulation
        k = (key, formulation)
        if k not in self._compiled:
            ps = self.parameter_symbols
            if key == "M":
                P, M = self.mass_matrix_program(formulation)
                fn = compile_program(P, [self.q, ps], [M], "mass_matrix")
            elif key == "h":
                P, h = self.bias_program(formulation)
                fn = compile_program(P, [self.q, self.qd, self.ext_symbols, ps], [sp.Matrix(h)], "bias")
            elif key == "ID":
                P, tau = self.inverse_dynamics_program(formulation)
                fn = compile_program(P, [self.q, self.qd, self.qdd, self.ext_symbols, ps], [sp.Matrix(tau)],
                                     "inverse_dynamics")
            elif isinstance(key, tuple) and key[0] == "K":
                P, T, J = self.kinematics_program(key[1])
                fn = compile_program(P, [self.q, ps], [T, J], "kinematics")
            else:
                raise KeyError(key)
            self._compiled[k] = fn
        return self._compiled[k]

    def _ext_vector(self, ext):
        m = 6 * len(self.external_links)
        if ext is None:
            return np.zeros(m)
        ext = np.asarray(ext, dtype=float).ravel()
        if ext.size != m:
            raise ValueError(f"ext must have {m} entries (f, t per link with external_wrench), got {ext.size}")
        return ext

    def _vec(self, name, v):
        v = np.asarray(v, dtype=float).ravel()
        if v.size != self.n:
            raise ValueError(f"{name} must have {self.n} entries, got {v.size}")
        return v

    def mass_matrix(self, q, formulation=None, **params) -> np.ndarray:
        """M(q), n x n, symmetric positive definite."""
        return self._fn("M", formulation)(self._vec("q", q), self.parameter_vector(params))[0]

    def bias(self, q, qd, ext=None, formulation=None, **params) -> np.ndarray:
        """h(q, qd) with tau = M qdd + h: Coriolis, centrifugal, gravity, damping, -J^T w."""
        return self._fn("h", formulation)(self._vec("q", q), self._vec("qd", qd), self._ext_vector(ext),
                                          self.parameter_vector(params))[0][:, 0]

    def inverse_dynamics(self, q, qd, qdd, ext=None, formulation=None, **params) -> np.ndarray:
        return self._fn("ID", formulation)(self._vec("q", q), self._vec("qd", qd), self._vec("qdd", qdd),
                                           self._ext_vector(ext), self.parameter_vector(params))[0][:, 0]

    def forward_dynamics(self, q, qd, tau, ext=None, formulation=None, **params) -> np.ndarray:
        """qdd = M(q)^{-1} (tau - h(q, qd)) by a Cholesky factorisation."""
        M = self.mass_matrix(q, formulation, **params)
        h = self.bias(q, qd, ext, formulation, **params)
        L = np.linalg.cholesky(M)
        return np.linalg.solve(L.T, np.linalg.solve(L, self._vec("tau", tau) - h))

    def fk(self, q, frame: Optional[str] = None, **params) -> np.ndarray:
        """4x4 pose of ``frame`` in base coordinates (default: ``robot.end_frame``, the thesis's TRANSP).

        ``frame``: a body (URDF link) or frame name: ``arm.fk(q, "tool0")``.
        """
        return self._fn(("K", frame or self.robot.end_frame), None)(self._vec("q", q),
                                                                     self.parameter_vector(params))[0]

    def jacobian(self, q, frame: Optional[str] = None, **params) -> np.ndarray:
        """6 x n geometric Jacobian of ``frame``'s origin (default ``robot.end_frame``), linear rows first.

        Columns of joints not between the frame and the base are zero.
        """
        return self._fn(("K", frame or self.robot.end_frame), None)(self._vec("q", q),
                                                                     self.parameter_vector(params))[1]

    def energy(self, q, qd, **params) -> tuple:
        """(kinetic, potential) energy; kinetic = qd^T M qd / 2, potential from gravity.

        Potential energy: -sum m_i g . c_i with c_i the centres of mass (payload
        included), evaluated from the link frames.
        """
        M = self.mass_matrix(q, **params)
        qd = self._vec("qd", qd)
        return 0.5 * qd @ M @ qd, self._potential(q, params)

    def _potential(self, q, params) -> float:
        k = ("PE", None)
        if k not in self._compiled:
            P = Program("_e")
            Ts = kinematics.body_frames(P, self.robot, self.q)
            g = [sp.sympify(x) for x in self.robot.gravity]
            pe = 0
            for i, L in enumerate(self.robot.bodies):
                T = Ts[i]
                c = [sum(T[r][m] * L.com[m] for m in range(3)) + T[r][3] for r in range(3)]
                pe += -L.mass * sum(g[r] * c[r] for r in range(3))
            self._compiled[k] = compile_program(P, [self.q, self.parameter_symbols], [pe], "potential")
        return self._compiled[k](self._vec("q", q), self.parameter_vector(params))[0]
