"""Looped dynamics for large arms and trees: a program step that calls ``c_runtime/chain_dynamics.c``.

Straight-line code for the forward dynamics of an N-link arm has O(N^2)
statements and its exact Jacobian O(N^2) to O(N^3): at N = 24 the generated
``model.c`` is 63,000 lines that gcc -O2 needs a quarter of an hour for.
Past :data:`LOOP_MIN_LINKS` links the arm's model therefore holds no
dynamics at all: one :class:`ChainDynamics` step evaluates the body
constants (29 numbers per body, expressions of the parameters) and calls the
hand-written loops of the runtime -- Featherstone's articulated-body algorithm
for the forward dynamics (O(N)) and the analytical derivatives of recursive
Newton-Euler with one Cholesky solve for its Jacobian.

The runtime works on the general joint model of a kinematic tree: per body a
parent, a fixed placement (R, p) in the parent's frame, a unit joint axis, a
joint type (revolute/prismatic), mass, centre of mass, inertia, rotor
inertia, damping and smooth Coulomb friction (:func:`tree_constants`).  A Denavit-Hartenberg chain
is the special case :func:`link_constants` writes.  The generated file
grows linearly with N (the constants, and one copy per Jacobian entry), so
deriving, generating and compiling take seconds at N = 60.

A :class:`ChainDynamics` is a :class:`~fmugen.codegen.program.SolveSPD`
(solution symbols ``X``, an empty ``A`` and the inputs ``B``), so everything
that reasons about a program's dependencies -- the ``<ModelStructure>`` of
modelDescription.xml, pruning, folding parameters into constants -- treats
it as an opaque step coupling all of X to all of B, which it is.  Only the C
generator (:func:`fmugen.codegen.c_code.lower`) knows how to print it; the
Python evaluators (:mod:`fmugen.codegen.python_code`: linearisation, trim)
call the same C loops through ctypes (:func:`evaluate_chain`; the runtime file
is compiled once per process into a temporary folder).

When every body constant is a number at generation time (parameters folded)
the C generator prints the step as a call of code generated for the robot
instead (:func:`unrolled_choice`, :func:`unrolled_step_lines`): the same
model, its numbers folded into straight-line code.
"""
from __future__ import annotations

import atexit
import ctypes
import shutil
import subprocess
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import sympy as sp

from .op_count import OpCount
from .program import SolveSPD

__all__ = ["ChainDynamics", "LOOP_MIN_LINKS", "NC", "NG", "UNROLLED_JACOBIAN_MAX", "link_constants", "tree_constants",
           "robot_tree", "chain_work_doubles", "chain_ops", "evaluate_chain", "unrolled_choice", "unrolled_step_lines"]

#: Arms with at least this many links get the looped dynamics by default
#: (``state_space_model(strategy="auto")``).  Measured with
#: ``examples/bench_large_models.py`` on a 2-core machine (CPU µs per call,
#: chains with random values): straight-line code has the faster forward
#: dynamics (N = 6: 0.24 against 0.60 µs; Pinocchio's ABA 1.5 µs), but from
#: N = 6 on the looped Jacobian is faster (2.2 against 2.6 µs; N = 8: 4.9 µs
#: straight-line, 1.14x Pinocchio's computeABADerivatives) and the
#: straight-line build costs 21 s (N = 6) and 32 s (N = 8) of wall time
#: against 8 s.  Six links and fewer -- the PUMA -- keep straight-line code.
LOOP_MIN_LINKS = 7

#: per-body constants (layout of c_runtime/chain_dynamics.h): placement R (9, row-major) and p (3),
#: joint axis (3), mass, COM (3), inertia about the COM (xx yy zz xy xz yz), rotor inertia, damping,
#: Coulomb friction F_c and its velocity scale v_c (smooth: F_c tanh(qd / v_c))
NC = 29
#: global constants: gravity (3), end-effector position in its body's frame (3)
NG = 6


def chain_work_doubles(n: int, kind: str) -> int:
    """Work space of the runtime call, in doubles (``FMUGEN_CHAIN_FD_WORK``, ``FMUGEN_CHAIN_WORK`` of chain_dynamics.h)."""
    return n * (312 + 28 * n) + 64 if kind in ("jacobian", "id_jacobian") else 114 * n + 16


@dataclass(frozen=True)
class ChainDynamics(SolveSPD):
    """``X = chain(B)``: the forward dynamics (``kind="fd"``) or the inverse dynamics (``"id"``) of an
    n-body tree or chain, or their Jacobians (``"jacobian"``, ``"id_jacobian"``).

    ``B`` (column) = [q (n), qd (n), tau (n; qdd for the inverse dynamics), body constants (n x NC,
    row by row), global constants (NG), external wrenches (6 per entry of ``external``: force at
    the body's centre of mass, torque; base coordinates)]; ``A`` is empty.  ``X`` (column):

    * ``fd``:          [qdd (n), p_ee (3)]
    * ``jacobian``:    [qdd (n), dqdd (n x (3n + 6e), row-major: d/dq, d/dqd, d/dtau, d/dext),
                        dp_ee/dq (3 x n)]
    * ``id``:          [tau (n)]
    * ``id_jacobian``: [tau (n), dtau (n x (3n + 6e), row-major: d/dq, d/dqd, d/dqdd = M, d/dext)]

    ``revolute`` holds one bool per joint (False: prismatic); ``parent`` the
    parent of each body (-1: the base; parents are numbered first; empty:
    a serial chain, body i - 1); ``ee_body`` the body whose frame carries
    the end effector (None: the last body; -1: none); ``external`` the
    0-based bodies with an external wrench, in input order.
    """

    kind: str = "fd"
    revolute: tuple = ()
    external: tuple = ()
    parent: tuple = ()
    ee_body: Optional[int] = None

    def __post_init__(self):
        if self.kind not in ("fd", "jacobian", "id", "id_jacobian"):
            raise ValueError(f"chain dynamics: unknown kind {self.kind!r}")
        n = len(self.revolute)
        par = self.parents
        if len(par) != n or any(not (-1 <= p < i) for i, p in enumerate(par)):
            raise ValueError(f"chain dynamics: parents {par} must number every body after its parent")
        if not -1 <= self.end_effector < max(n, 1):
            raise ValueError(f"chain dynamics: end-effector body {self.ee_body} out of range")

    @property
    def n(self) -> int:
        return len(self.revolute)

    @property
    def parents(self) -> tuple:
        return tuple(self.parent) if self.parent else tuple(range(-1, self.n - 1))

    @property
    def end_effector(self) -> int:
        return self.n - 1 if self.ee_body is None else self.ee_body

    def joint_array(self) -> list:
        """The ``joint`` ints of the runtime call: types, parents, end-effector body."""
        return [1 if r else 0 for r in self.revolute] + list(self.parents) + [self.end_effector]

    def outputs_size(self) -> int:
        n, e = self.n, len(self.external)
        return {"fd": n + 3, "jacobian": n + n * (3 * n + 6 * e) + 3 * n, "id": n,
                "id_jacobian": n + n * (3 * n + 6 * e)}[self.kind]


def link_constants(chain, gravity: Sequence) -> list:
    """The NC constants of every link and the NG globals of a Denavit-Hartenberg chain (sympy).

    ``chain`` is :func:`fmugen.dynamics.joint_frames.joint_frame_chain` of the
    robot (payload merged into the last link, inertial data in joint frames).
    Joint frame F_i = F_{i-1} Tx(a) Rx(alpha) Rz(theta0) Tz(d0) J(q): the placement
    R = Rx(alpha) Rz(theta0), p = [a, -sin(alpha) d0, cos(alpha) d0], axis z; the end
    effector is the origin of F_n Tx(end_a).
    """
    out = []
    for L in chain:
        ca, sa, ct, st = sp.cos(L.alpha), sp.sin(L.alpha), sp.cos(L.theta0), sp.sin(L.theta0)
        R = [ct, -st, 0, ca * st, ca * ct, -sa, sa * st, sa * ct, ca]
        p = [L.a, -sa * L.d0, ca * L.d0]
        out += _body(R, p, (0, 0, 1), L.mass, L.com, L.inertia_com, L.rotor_inertia, L.damping, 0, 0)
    out += [sp.sympify(g) for g in gravity] + [chain[-1].end_a, sp.Integer(0), sp.Integer(0)]
    return [sp.sympify(e) for e in out]


def tree_constants(bodies, gravity: Sequence, ee_position: Sequence = (0, 0, 0)) -> list:
    """The NC constants of every body and the NG globals of the general joint model (sympy).

    ``bodies``: per body a mapping or object with ``R`` (3x3 placement rotation in the
    parent frame), ``p`` (3), ``axis`` (3, unit, in the placed frame), ``mass``, ``com``
    (3, body frame), ``inertia`` (3x3 about the COM, body axes), ``rotor_inertia`` and
    ``damping`` (and optionally ``friction``, ``friction_velocity``: the smooth Coulomb term
    F_c tanh(qd / v_c)); ``ee_position`` the end effector in its body's frame.
    """
    def get(b, k, default=None):
        if isinstance(b, dict):
            return b[k] if default is None else b.get(k, default)
        return getattr(b, k) if default is None else getattr(b, k, default)

    out = []
    for b in bodies:
        R = sp.Matrix(get(b, "R"))
        out += _body(list(R), list(get(b, "p")), list(get(b, "axis")), get(b, "mass"), list(get(b, "com")),
                     sp.Matrix(get(b, "inertia")), get(b, "rotor_inertia"), get(b, "damping"),
                     get(b, "friction", 0), get(b, "friction_velocity", 0))
    out += [sp.sympify(g) for g in gravity] + [sp.sympify(e) for e in ee_position]
    return [sp.sympify(e) for e in out]


def robot_tree(robot) -> tuple:
    """``(revolute, parents, ee_body, constants)`` of a robot written in the general joint model.

    ``robot.bodies`` (fmugen.robot.description.Body: parent, rotation, translation, axis, offset,
    joint, inertial data), ``robot.frames`` and ``robot.end_frame`` (the frame whose origin is
    p_ee) and ``robot.gravity``.  A joint's constant ``offset`` (a DH theta or d) moves into the
    placement: R Rot(k, offset) for a revolute joint (a rotation about k commutes with the
    motion), p + offset R k for a prismatic one.
    """
    bodies = []
    for b in robot.bodies:
        R, p = sp.Matrix(b.rotation), sp.Matrix(b.translation)
        k = sp.Matrix(b.axis)
        off = sp.sympify(getattr(b, "offset", 0))
        if off != 0:
            if b.joint == "prismatic":
                p = p + R * k * off
            else:
                c, s = sp.cos(off), sp.sin(off)
                kx = sp.Matrix([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
                R = R * (c * sp.eye(3) + s * kx + (1 - c) * k * k.T)
        bodies.append(dict(R=R, p=list(p), axis=list(k), mass=b.mass, com=list(b.com),
                           inertia=sp.Matrix(b.inertia_com), rotor_inertia=b.rotor_inertia, damping=b.damping,
                           friction=getattr(b, "friction", 0), friction_velocity=getattr(b, "friction_velocity", 0)))
    end = getattr(robot, "end_frame", "")
    if not end:
        ee, ee_pos = len(bodies) - 1, (0, 0, 0)
    else:
        ee, _, ee_pos = robot.locate(end)  # a body (its origin) or a frame fixed to one
        if ee < 0:
            raise ValueError(f"{robot.name}: the end-effector frame {end!r} is fixed to the base")
    revolute = tuple(b.joint != "prismatic" for b in robot.bodies)
    parents = tuple(int(b.parent) for b in robot.bodies)
    return revolute, parents, ee, tree_constants(bodies, robot.gravity, ee_pos)


def _body(R, p, axis, mass, com, I, rotor, damping, friction, friction_velocity) -> list:
    I = sp.Matrix(I)
    return [*R, *p, *axis, mass, *com, I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2], rotor, damping,
            friction, friction_velocity]


def chain_call_lines(st: ChainDynamics, index: int, b_code: list, ind: str) -> tuple:
    """C statements of one step: ``(lines, output array, offset of X[0] in it, free line)``.

    ``b_code`` are the printed entries of B.  The forward dynamics works in
    local arrays (O(n), free line None); the Jacobian's arrays (O(n^2)) are
    taken from the heap, and the caller emits the free line before the
    function returns.
    """
    n, ne = st.n, len(st.external)
    tag = f"fmugen_chain{index}"  # "fmugen": a prefix no model name takes (c_code.RESERVED_PREFIXES)
    joint = ", ".join(str(j) for j in st.joint_array())
    nb = 3 * n + NC * n + NG + 6 * ne
    nx = st.outputs_size()
    what = {"fd": "forward dynamics", "jacobian": "Jacobian of the forward dynamics", "id": "inverse dynamics",
            "id_jacobian": "inverse dynamics and its Jacobian"}[st.kind]
    lines = [f"{ind}/* {what} of the {n}-body {'chain' if st.parents == tuple(range(-1, n - 1)) else 'tree'}: "
             f"loops of c_runtime/chain_dynamics.c */",
             f"{ind}/* joint types (1 revolute, 0 prismatic), parents (-1 base), end-effector body */",
             f"{ind}static const int {tag}_jt[{2 * n + 1}] = {{{joint}}};"]
    if ne:
        lines.append(f"{ind}static const int {tag}_ext[{ne}] = {{{', '.join(str(k) for k in st.external)}}};")
    lines.append(f"{ind}double {tag}_in[{nb}];")
    lines += [f"{ind}{tag}_in[{k}] = {c};" for k, c in enumerate(b_code)]
    q, lc, g = f"{tag}_in", f"{tag}_in + {3 * n}", f"{tag}_in + {3 * n + NC * n}"
    ext = f"{ne}, {tag}_ext, {tag}_in + {3 * n + NC * n + NG}" if ne else "0, NULL, NULL"
    args = f"{n}, {tag}_jt, {lc}, {g}, {q}, {q} + {n}, {q} + {2 * n}, {ext}"
    if st.kind in ("fd", "id"):
        call = (f"fmugen_chain_fd({args}, {tag}_x, {tag}_x + {n}, {tag}_w)" if st.kind == "fd"
                else f"fmugen_chain_id({args}, {tag}_x, {tag}_w)")
        lines += [f"{ind}double {tag}_x[{nx}], {tag}_w[{chain_work_doubles(n, 'fd')}];",
                  f"{ind}status = {call};",
                  f"{ind}if (status != FMUGEN_OK) return status;"]
        return lines, f"{tag}_x", 0, None
    w = chain_work_doubles(n, "jacobian")
    if st.kind == "jacobian":
        call = (f"fmugen_chain_fd_jacobian({args}, {tag}_w + {w}, {tag}_w + {w + n}, "
                f"{tag}_w + {w + n + n * (3 * n + 6 * ne)}, {tag}_w)")
    else:
        call = f"fmugen_chain_id_jacobian({args}, {tag}_w + {w}, {tag}_w + {w + n}, {tag}_w)"
    lines += [f"{ind}double *{tag}_w = (double *)malloc(sizeof(double) * {w + nx});",
              f"{ind}if ({tag}_w == NULL) return FMUGEN_NOT_FINITE; /* out of memory */",
              f"{ind}status = {call};",
              f"{ind}if (status != FMUGEN_OK) {{ free({tag}_w); return status; }}"]
    return lines, f"{tag}_w", w, f"{ind}free({tag}_w);"


#: A step whose robot numbers are all known when the code is generated (parameters folded: ``--fold
#: all``) and which has no external wrenches is generated per robot instead of calling the loops
#: (:func:`unrolled_step_lines`; :mod:`fmugen.codegen.unrolled_derivatives`): the forward and inverse
#: dynamics always -- 2-5x faster than the loops (``python examples/bench_derivatives.py --unrolled``:
#: FD 0.10-0.20x Pinocchio's ``aba`` against 0.43-0.48x; gcc ~0.3 s of CPU per 1000 lines, linear in
#: n) -- and their Jacobians up to this many bodies: there the unrolled Jacobian takes a third of the
#: loops' time (``--unrolled-only``, one run: iiwa 1.09 against 3.23 µs, HyQ 1.55 against 4.45 µs) for
#: about a second of gcc.  Larger trees gain as much (Atlas 7.0 against 15.9 µs, Talos 13.6 against
#: 29.5, Tiago 21.9 against 49.1) but their Jacobians take 7-17 s of gcc (compiled three times: baseline,
#: x86-64-v3, x86-64-v4), which an FMU build should not pay unasked: a large tree keeps the loops.
UNROLLED_JACOBIAN_MAX = 12


def unrolled_choice(st: ChainDynamics, numbers: Sequence) -> bool:
    """Whether step ``st`` is generated unrolled: ``numbers`` are its body and global constants (B after
    q, qd and tau; None where one is not a number)."""
    if st.external or any(x is None for x in numbers):
        return False
    return st.kind in ("fd", "id") or st.n <= UNROLLED_JACOBIAN_MAX


def unrolled_step_lines(st: ChainDynamics, index: int, numbers: Sequence[float], in_codes: Sequence[str],
                        ind: str) -> tuple:
    """C statements of step ``index`` of a function, generated for its robot's ``numbers``
    (:func:`unrolled_choice`): ``(lines, output array, function name, function source)``; ``in_codes`` are
    the printed q, qd, u.  The function is named by a hash of its text: one copy per file however many
    functions call it.  None when the numbers make a mass matrix that is not positive definite at every
    state (a massless leaf: a pivot that folds to 0): the loops' call then reports it at run time, as the
    same model with its parameters free does."""
    import hashlib

    from .unrolled_aba import NotPositiveDefinite
    from .unrolled_derivatives import chain_step

    n = st.n
    lc = np.asarray(numbers[:NC * n], float).reshape(n, NC)
    g = np.asarray(numbers[NC * n:NC * n + NG], float)
    try:
        gen = chain_step(st.kind, st.revolute, st.parents, lc, g[:3], st.end_effector, g[3:6], "UNROLLED_NAME")
    except NotPositiveDefinite:  # a pivot folded to a non-positive constant
        return None
    name = f"fmugen_unrolled_{st.kind}_{hashlib.sha1(gen.source.encode()).hexdigest()[:12]}"
    source = gen.source.replace("UNROLLED_NAME", name)
    tag = f"fmugen_unrolled{index}"  # "fmugen": a prefix no model name takes (c_code.RESERVED_PREFIXES)
    what = {"fd": "forward dynamics", "jacobian": "Jacobian of the forward dynamics", "id": "inverse dynamics",
            "id_jacobian": "inverse dynamics and its Jacobian"}[st.kind]
    lines = [f"{ind}/* {what} of the {n}-body robot, its numbers folded: {name} (above) */",
             f"{ind}double {tag}_u[{3 * n}], {tag}_x[{st.outputs_size()}];"]
    lines += [f"{ind}{tag}_u[{k}] = {c};" for k, c in enumerate(in_codes)]
    lines += [f"{ind}status = {name}({tag}_u, {tag}_u + {n}, {tag}_u + {2 * n}, {tag}_x);",
              f"{ind}if (status != FMUGEN_OK) return status;"]
    return lines, f"{tag}_x", name, source


def chain_ops(n: int, kind: str, ne: int = 0):
    """Floating-point operations of one runtime call for n bodies (:class:`~fmugen.codegen.c_code.OpCount`).

    Counted by hand from the loops of ``c_runtime/chain_dynamics.c`` with the
    rules of :class:`~fmugen.codegen.c_code.OpCount`, so that looped and
    straight-line models report comparable figures; joint axes along z (every
    DH chain; another axis costs 27 mul / 27 add more per body).  Per body:
    kinematics 137 mul / 107 add / sin and cos; the articulated-body algorithm
    229 mul / 241 add / 2 div.  The Jacobian adds, per body, the forward (180 /
    144) and backward (348 / 483, composite sums handed to the parent included)
    derivative passes; per pair of joints on one path the mass matrix (6 / 5,
    lower triangle) and, for every pair, the columns of M^-1 dID (55 / 56: the
    subtree-sum way of a chain; branched trees take fewer, per root branch); and
    the Cholesky factorisation, L^-1 and M^-1 = L^-T L^-1 (each ~n^3/6); with
    ``ne`` external wrenches about 40 mul per body and 9 per pair more, and n^2
    per wrench component.  For a tree the pairs on one path are fewer than the
    chain's n(n+1)/2 counted here; the subtree sums of the branches add 12 n
    additions per branch point.
    """
    tri = n * (n + 1) // 2
    if kind in ("id", "id_jacobian"):
        # kinematics, then per body the forward (126 mul / 110 add) and backward (6 / 11) passes
        rnea = OpCount(mul=(137 + 132) * n + 12 * ne, add=(107 + 121) * n + 18 * ne, calls=(("cos", n), ("sin", n)))
        if kind == "id":
            return rnea
        # the derivative passes, and per pair on one path three 12- or 6-vector products
        return rnea + OpCount(mul=(180 + 348) * n + 30 * tri, add=(144 + 483) * n + 28 * tri)
    fd = OpCount(mul=366 * n + 12 * ne, add=348 * n + 18 * ne, div=2 * n, calls=(("cos", n), ("sin", n)))
    if kind == "fd":
        return fd
    if ne:
        fd = fd + OpCount(mul=40 * n + 9 * n * n + 6 * ne * n * (n + 1) // 2,
                          add=40 * n + 9 * n * n + 6 * ne * n * (n + 1) // 2)
    chol = (n ** 3 - n) // 6
    linv = (n - 1) * n * (n + 1) // 6
    minv = n * (n + 1) * (n + 2) // 6
    return fd + OpCount(
        mul=(180 + 348) * n + 6 * tri + chol + linv + n * (n - 1) // 2 + minv + 55 * n * n,
        add=(144 + 483) * n + 5 * tri + chol + linv + minv + 56 * n * n,
        div=n * (n - 1) // 2 + n,
        calls=(("sqrt", n),),
    )


# ------------------------------------------------------------ Python access
_SHIM = """
#include "chain_dynamics.c"
/* exported wrappers: the runtime's own symbols are hidden */
int py_chain_fd(int n, const int *r, const double *lc, const double *g, const double *q, const double *qd,
                const double *tau, int ne, const int *xl, const double *x, double *out, double *work)
{ return fmugen_chain_fd(n, r, lc, g, q, qd, tau, ne, xl, x, out, out + n, work); }
int py_chain_jac(int n, const int *r, const double *lc, const double *g, const double *q, const double *qd,
                 const double *tau, int ne, const int *xl, const double *x, double *out, double *work)
{ return fmugen_chain_fd_jacobian(n, r, lc, g, q, qd, tau, ne, xl, x, out, out + n,
                                  out + n + n * (3 * n + 6 * ne), work); }
int py_chain_id(int n, const int *r, const double *lc, const double *g, const double *q, const double *qd,
                const double *qdd, int ne, const int *xl, const double *x, double *out, double *work)
{ return fmugen_chain_id(n, r, lc, g, q, qd, qdd, ne, xl, x, out, work); }
int py_chain_id_jac(int n, const int *r, const double *lc, const double *g, const double *q, const double *qd,
                    const double *qdd, int ne, const int *xl, const double *x, double *out, double *work)
{ return fmugen_chain_id_jacobian(n, r, lc, g, q, qd, qdd, ne, xl, x, out, out + n, work); }
"""
_lib = None
_lock = threading.Lock()


def _library():
    """chain_dynamics.c compiled into a shared library, once per process."""
    global _lib
    with _lock:
        if _lib is None:
            rt = Path(__file__).resolve().parents[2] / "c_runtime"
            work = Path(tempfile.mkdtemp(prefix="fmugen_chain_"))
            atexit.register(shutil.rmtree, work, True)
            (work / "shim.c").write_text(_SHIM)
            cmd = ["cc", "-std=c99", "-O2", "-fPIC", "-shared", f"-I{rt}", "-o", str(work / "chain.so"),
                   str(work / "shim.c"), "-lm"]
            r = subprocess.run(cmd, capture_output=True, text=True)
            if r.returncode != 0:
                raise RuntimeError(f"cannot compile the chain dynamics for Python: {' '.join(cmd)}\n{r.stderr}")
            lib = ctypes.CDLL(str(work / "chain.so"))
            dp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
            for f in (lib.py_chain_fd, lib.py_chain_jac, lib.py_chain_id, lib.py_chain_id_jac):
                f.argtypes = [ctypes.c_int, ip] + [dp] * 5 + [ctypes.c_int, ip, dp, dp, dp]
                f.restype = ctypes.c_int
            _lib = lib
        return _lib


def evaluate_chain(kind: str, revolute: Sequence[bool], b: Sequence[float], external: Sequence[int] = (),
                   parent: Sequence[int] = (), ee_body: Optional[int] = None) -> np.ndarray:
    """X of a :class:`ChainDynamics` step for the numbers ``b`` (its B), by the runtime's loops."""
    st = ChainDynamics(sp.zeros(0, 1), sp.zeros(0, 0), sp.zeros(0, 1), kind=kind, revolute=tuple(revolute),
                       external=tuple(external), parent=tuple(parent), ee_body=ee_body)
    n, ne = len(revolute), len(external)
    b = np.ascontiguousarray(np.asarray(b, dtype=float))
    if b.size != 3 * n + NC * n + NG + 6 * ne:
        raise ValueError(f"chain dynamics of {n} links: {b.size} inputs, expected {3 * n + NC * n + NG + 6 * ne}")
    out = np.zeros(st.outputs_size())
    work = np.zeros(chain_work_doubles(n, kind))
    joint = st.joint_array()
    rev = (ctypes.c_int * len(joint))(*joint)
    xl = (ctypes.c_int * max(ne, 1))(*(list(external) or [0]))
    dp = ctypes.POINTER(ctypes.c_double)

    def at(k):
        return ctypes.cast(b.ctypes.data + 8 * k, dp)

    lib = _library()
    fn = {"fd": lib.py_chain_fd, "jacobian": lib.py_chain_jac, "id": lib.py_chain_id,
          "id_jacobian": lib.py_chain_id_jac}[kind]
    status = fn(n, rev, at(3 * n), at(3 * n + NC * n), at(0), at(n), at(2 * n), ne, xl,
                at(3 * n + NC * n + NG) if ne else None, out.ctypes.data_as(dp), work.ctypes.data_as(dp))
    if status == 1:
        raise np.linalg.LinAlgError("mass matrix is not positive definite")
    if status != 0:
        raise FloatingPointError("chain dynamics: a result is NaN or infinite")
    return out
