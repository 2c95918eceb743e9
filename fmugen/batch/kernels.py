"""The batched kernels: one object per robot, arrays of states in, arrays of results out.

:class:`Kernels` holds the robot as the numbers of the runtime's general joint model (the
joint array and the ``n x NC`` body constants of ``c_runtime/chain_dynamics.h``, written by
:func:`fmugen.codegen.chain.robot_tree` and evaluated at the parameters' values) and calls
``batch.c`` (this folder), whose C loop runs the runtime's functions over all states of a call.
The library is compiled once per machine (:func:`library`) and kept in the cache folder of
fmugen (``$FMUGEN_CACHE/batch``, default ``~/.cache/fmugen/batch``), in a subfolder named by
the hash of the compiler, its flags and the sources, so an edited runtime is compiled anew.

``threads=k`` cuts a batch into k contiguous ranges run at once by Python threads, each with its
own work array; ctypes releases the GIL for the duration of a foreign call (``ctypes.CDLL``, not
``PyDLL``), so the ranges run on separate cores.  Each state is computed alone, the same
operations in the same order whatever the split, so the results are the same to the bit.
"""
from __future__ import annotations

import ctypes
import subprocess
import tempfile
import threading
from pathlib import Path
from typing import Mapping, Optional

import numpy as np
import sympy as sp

from ..codegen.chain import NC, robot_tree
from .common import CC as _CC, Ranges, StateError, _address, _cache_root, _cached, _compiler_hash

__all__ = ["Kernels", "StateError", "library", "MASS_MATRIX_METHODS"]

_HERE = Path(__file__).resolve().parent
_RUNTIME = _HERE.parents[1] / "c_runtime"
# the flags of the FMU build (fmugen.fmi.build.CFLAGS): the same optimisation as the FMUs the kernels stand beside
_FLAGS = ("-std=c99", "-O2", "-fPIC", "-shared")

# kinds of batch.c
_FD, _FD_JAC, _ID, _ID_JAC, _M_COLUMNS, _M_JAC, _MINV_COLUMNS, _MINV_JAC, _M_DIRECT, _MINV_DIRECT = range(10)
#: ways of :meth:`Kernels.mass_matrix` and :meth:`Kernels.mass_matrix_inverse`: ``"direct"`` (the
#: default) -- composite rigid bodies for M (``fmugen_chain_mass_matrix``) and the tree factorisation
#: M = L^T L without fill-in for M^-1 (``fmugen_chain_mass_matrix_inverse``); ``"jacobian"`` -- the third
#: block of the analytical Jacobian of the inverse dynamics (M = dtau/dqdd, ``fmugen_chain_id_jacobian``)
#: or of the forward dynamics (M^-1 = dqdd/dtau, ``fmugen_chain_fd_jacobian``) at qd = 0; ``"columns"`` --
#: n calls of recursive Newton-Euler, M e_j = ID(q, 0, e_j), or of the articulated-body algorithm,
#: M^-1 e_j = FD(q, 0, e_j), gravity off.  The last two are kept as independent checks of the first
#: (``examples/bench_derivatives.py`` times them).
MASS_MATRIX_METHODS = ("direct", "jacobian", "columns")
_M_KIND = {"direct": _M_DIRECT, "jacobian": _M_JAC, "columns": _M_COLUMNS}
_MINV_KIND = {"direct": _MINV_DIRECT, "jacobian": _MINV_JAC, "columns": _MINV_COLUMNS}


_lock = threading.Lock()
_lib = None


def _sources() -> list:
    return [_HERE / "batch.c", *sorted(_RUNTIME.glob("*.h")), _RUNTIME / "chain_dynamics.c"]


def _key() -> str:
    h = _compiler_hash(_FLAGS)
    for p in _sources():
        h.update(p.name.encode() + b"\0" + p.read_bytes() + b"\1")
    return h.hexdigest()[:32]


def _compile(folder: Path) -> Path:
    out = folder / "batch.so"
    cmd = [_CC, *_FLAGS, f"-I{_RUNTIME}", "-o", str(out), str(_HERE / "batch.c"), "-lm"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"cannot compile the batched kernels: {' '.join(cmd)}\n{r.stderr}")
    return out


def library() -> ctypes.CDLL:
    """``batch.c`` with the runtime's chain_dynamics.c as a loaded shared library: from the cache if
    compiled before from the same sources, compiler and flags, else compiled now (about a second) and
    stored -- by one rename of a complete folder, so processes compiling at once never see half of one.
    ``FMUGEN_OBJECT_CACHE=0`` compiles into a temporary folder instead."""
    global _lib
    with _lock:
        if _lib is not None:
            return _lib
        root = _cache_root()
        so = _cached(root, _key(), _compile) if root is not None else None
        if so is None:
            tmp = Path(tempfile.mkdtemp(prefix="fmugen_batch_"))
            so = _compile(tmp)
        lib = ctypes.CDLL(str(so))  # CDLL: the GIL is released during each call
        vp = ctypes.c_void_p
        lib.fmugen_batch_work.argtypes = [ctypes.c_int, ctypes.c_int]
        lib.fmugen_batch_work.restype = ctypes.c_long
        lib.fmugen_batch.argtypes = [ctypes.c_int, ctypes.c_int, vp, vp, vp, ctypes.c_long, vp, vp, vp,
                                     vp, vp, vp, vp, vp, vp]
        lib.fmugen_batch.restype = ctypes.c_int
        _lib = lib
        return lib


_F64 = np.dtype(np.float64)


def _method(what: str, method: str):
    if method not in MASS_MATRIX_METHODS:
        raise ValueError(f"{what}: method must be one of {', '.join(MASS_MATRIX_METHODS)}, got {method!r}")


def _number(expr, env: dict, what: str) -> float:
    e = sp.sympify(expr).xreplace(env)
    if e.free_symbols:
        raise ValueError(f"{what}: no value for parameter(s) {', '.join(sorted(s.name for s in e.free_symbols))}")
    return float(e)


class Kernels(Ranges):
    """Forward and inverse dynamics, their derivatives and the mass matrix of one robot, for many states
    per call.

    Inputs are arrays of shape ``(N, n)`` (N states, n joints in the robot's order), float64; a
    non-contiguous array is copied, any other shape or dtype is refused (ValueError naming the argument
    and the shape expected).  Joint angles are angles also for continuous joints.  A state where the
    dynamics fail -- the mass matrix not positive definite, a NaN or infinite input or result --
    raises :class:`StateError` with the index of the first such state; nothing is returned then.

    Build one with :meth:`from_urdf` or :meth:`from_robot`; the constructor takes the runtime's numbers
    directly (``revolute``: n bools, ``parents``: n ints, -1 the base, parents first; ``constants``: n x
    NC body constants; ``gravity``: 3).
    """

    def __init__(self, revolute, parents, constants, gravity, threads: int = 1, names=(), name: str = "robot"):
        n = len(revolute)
        parents = [int(p) for p in parents]
        if len(parents) != n or any(not -1 <= p < i for i, p in enumerate(parents)):
            raise ValueError(f"{name}: parents {parents} must number every body after its parent")
        lc = np.ascontiguousarray(np.asarray(constants, dtype=float).reshape(n, NC))
        g = np.asarray(gravity, dtype=float).ravel()
        if g.size != 3:
            raise ValueError(f"{name}: gravity must have 3 components, got {g.size}")
        if not np.all(np.isfinite(lc)) or not np.all(np.isfinite(g)):
            raise ValueError(f"{name}: the body constants or gravity are not finite")
        self.name, self.n, self.names = name, n, tuple(names)
        self.revolute, self.parents = tuple(bool(r) for r in revolute), tuple(parents)
        self._lc = lc
        self._g = np.ascontiguousarray(np.r_[g, 0.0, 0.0, 0.0])  # no end effector: p_ee is not computed
        self._jt = np.array([1 if r else 0 for r in self.revolute] + parents + [-1], dtype=np.intc)
        self._lib = library()
        self._const = (_address(self._jt), _address(self._lc), _address(self._g))
        self._works = {}
        self.threads = threads

    @property
    def joint_array(self) -> np.ndarray:
        """The runtime's ``joint`` ints (chain_dynamics.h: types, parents, end-effector body -1), a copy."""
        return self._jt.copy()

    @property
    def constants(self) -> np.ndarray:
        """The n x NC body constants of chain_dynamics.h, a copy."""
        return self._lc.copy()

    @property
    def globals(self) -> np.ndarray:
        """The NG global constants of chain_dynamics.h (gravity, then a zero end-effector position), a copy."""
        return self._g.copy()

    # ------------------------------------------------------------ construction
    @classmethod
    def from_robot(cls, robot, values: Optional[Mapping[str, float]] = None, threads: int = 1) -> "Kernels":
        """The kernels of a :class:`fmugen.robot.description.Robot` (a URDF, a DH file, a scene's robot);
        ``values`` overrides parameter values by name (defaults: the file's), e.g. ``{"b_joint1": 0}``."""
        by_name = {p.name: p for p in robot.parameters}
        unknown = sorted(set(values or {}) - set(by_name))
        if unknown:
            raise KeyError(f"{robot.name}: unknown parameter(s) {unknown}")
        tied = [b.name for b in robot.bodies if getattr(b, "mimic", None) is not None]
        if tied:
            raise ValueError(f"{robot.name}: tied mimic joints ({', '.join(tied)}) -- the kernels take every "
                             f"joint as independent (load_urdf(..., mimic='independent'))")
        env = {p.symbol: sp.Float(values[p.name]) if values and p.name in values else p.value
               for p in robot.parameters}
        env = {s: sp.sympify(v) for s, v in env.items() if v is not None}
        revolute, parents, _, constants = robot_tree(robot)
        n = len(revolute)
        lc = [_number(c, env, f"{robot.name}: body constant {k % NC} of body {k // NC}")
              for k, c in enumerate(constants[:n * NC])]
        g = [_number(c, env, f"{robot.name}: gravity") for c in constants[n * NC:n * NC + 3]]
        return cls(revolute, parents, lc, g, threads=threads, names=[b.joint_name or b.name for b in robot.bodies],
                   name=robot.name)

    @classmethod
    def from_urdf(cls, path, values: Optional[Mapping[str, float]] = None, threads: int = 1,
                  mimic: str = "independent") -> "Kernels":
        """The kernels of the URDF file at ``path``, read by fmugen's reader (:func:`fmugen.robot.urdf.load_urdf`;
        mimic joints as independent joints, with its warning)."""
        from ..robot.urdf import load_urdf

        return cls.from_robot(load_urdf(path, mimic=mimic), values=values, threads=threads)

    # ------------------------------------------------------------ the calls
    def _check(self, what: str, arrays: dict) -> tuple:
        n, out, count = self.n, [], None
        for name, a in arrays.items():
            if type(a) is not np.ndarray:
                a = np.asarray(a)
            if a.dtype != _F64 or a.ndim != 2 or a.shape[1] != n or (count is not None and a.shape[0] != count):
                want = f"(N, {n})" if count is None else f"({count}, {n})"
                raise ValueError(f"{what}: {name} must be a float64 array of shape {want}, "
                                 f"got {a.dtype} {a.shape}")
            count = a.shape[0]
            out.append(a if a.flags.c_contiguous else np.ascontiguousarray(a))
        return count, out

    def _work(self, kind: int, i: int) -> int:
        """Address of the work array of thread i for ``kind`` (allocated once per object and kept)."""
        key = (kind, i)
        w = self._works.get(key)
        if w is None:
            a = np.empty(max(self._lib.fmugen_batch_work(kind, self.n), 1))
            w = self._works[key] = (a, _address(a))
        return w[1]

    def _outputs(self, count: int, blocks: int) -> tuple:
        """One buffer for the results of a call -- an (count, n) array, then ``blocks`` (count, n, n) arrays,
        each contiguous -- and its address (one address to take instead of four)."""
        n = self.n
        buf = np.empty(count * n * (1 + blocks * n))
        out = [buf[:count * n].reshape(count, n)]
        out += [buf[count * n * (1 + b * n):count * n * (1 + (b + 1) * n)].reshape(count, n, n) for b in range(blocks)]
        return out, _address(buf)

    def _run(self, what: str, kind: int, count: int, ins: list, base: int, blocks: int):
        """Kernel ``kind`` on the inputs ``ins``; the results into the buffer at ``base`` (:meth:`_outputs`:
        a (count, n) array then ``blocks`` (count, n, n) arrays; the mass matrices: one (count, n, n))."""
        # per-call Python work is kept small: at N = 1 it is most of the cost of a call
        fn, n, const = self._lib.fmugen_batch, self.n, self._const
        ins = [_address(a) for a in ins] + [None] * (3 - len(ins))
        row_in = 8 * n
        if blocks < 0:  # the mass matrices: one (count, n, n) result
            outs, rows = [base, None, None, None], [8 * n * n, 0, 0, 0]
        else:
            outs = [base] + [base + 8 * count * n * (1 + b * n) for b in range(blocks)] + [None] * (3 - blocks)
            rows = [row_in] + [8 * n * n] * 3

        def part(i, lo, hi):
            bad = ctypes.c_long(-1)
            a = [x and x + lo * row_in for x in ins]
            o = [x and x + lo * r for x, r in zip(outs, rows)]
            s = fn(kind, n, *const, hi - lo, *a, *o, self._work(kind, i), ctypes.byref(bad))
            return s, lo + bad.value

        self._ranges(what, count, part)

    def fd(self, q, qd, tau) -> np.ndarray:
        """qdd = M(q)^-1 (tau - h(q, qd)) per state (N, n): the articulated-body algorithm."""
        count, ins = self._check("fd", {"q": q, "qd": qd, "tau": tau})
        (qdd,), base = self._outputs(count, 0)
        self._run("fd", _FD, count, ins, base, 0)
        return qdd

    def fd_derivatives(self, q, qd, tau) -> tuple:
        """``(qdd, dqdd/dq, dqdd/dqd, M^-1)``: (N, n) and three (N, n, n); M^-1 = dqdd/dtau.  Pinocchio's
        ``computeABADerivatives`` (``ddq_dq``, ``ddq_dv``, ``Minv``)."""
        count, ins = self._check("fd_derivatives", {"q": q, "qd": qd, "tau": tau})
        out, base = self._outputs(count, 3)
        self._run("fd_derivatives", _FD_JAC, count, ins, base, 3)
        return tuple(out)

    def id(self, q, qd, qdd) -> np.ndarray:
        """tau = M(q) qdd + h(q, qd) per state (N, n): recursive Newton-Euler."""
        count, ins = self._check("id", {"q": q, "qd": qd, "qdd": qdd})
        (tau,), base = self._outputs(count, 0)
        self._run("id", _ID, count, ins, base, 0)
        return tau

    def id_derivatives(self, q, qd, qdd) -> tuple:
        """``(tau, dtau/dq, dtau/dqd, M)``: (N, n) and three (N, n, n); M = dtau/dqdd.  Pinocchio's
        ``computeRNEADerivatives`` (``dtau_dq``, ``dtau_dv``, ``M``)."""
        count, ins = self._check("id_derivatives", {"q": q, "qd": qd, "qdd": qdd})
        out, base = self._outputs(count, 3)
        self._run("id_derivatives", _ID_JAC, count, ins, base, 3)
        return tuple(out)

    def mass_matrix(self, q, method: str = "direct") -> np.ndarray:
        """M(q) per state (N, n, n), symmetric, rotor inertias on the diagonal (Pinocchio's ``crba``, which
        fills the upper triangle).  ``method``: :data:`MASS_MATRIX_METHODS`.  M is not checked for positive
        definiteness here (nothing is solved)."""
        _method("mass_matrix", method)
        count, ins = self._check("mass_matrix", {"q": q})
        M = np.empty((count, self.n, self.n))
        self._run("mass_matrix", _M_KIND[method], count, ins, _address(M), -1)
        return M

    def mass_matrix_inverse(self, q, method: str = "direct") -> np.ndarray:
        """M(q)^-1 per state (N, n, n) (Pinocchio's ``computeMinverse``); ``method``: :data:`MASS_MATRIX_METHODS`.
        Raises StateError where M is not positive definite."""
        _method("mass_matrix_inverse", method)
        count, ins = self._check("mass_matrix_inverse", {"q": q})
        Minv = np.empty((count, self.n, self.n))
        self._run("mass_matrix_inverse", _MINV_KIND[method], count, ins, _address(Minv), -1)
        return Minv

    def unrolled(self, threads: Optional[int] = None):
        """These kernels as code generated for this robot, its numbers folded in
        (:class:`fmugen.batch.unrolled.UnrolledKernels`: ``fd``, ``fd_derivatives``, ``id_derivatives``, a
        fraction of the looped kernels' time); generated and compiled on the first call for these numbers
        (seconds for an arm, up to a minute for a hundred joints), then loaded from fmugen's cache.
        ``threads``: as this object's by default."""
        from .unrolled import UnrolledKernels

        return UnrolledKernels(self, self._threads if threads is None else threads)

    def __repr__(self):
        return f"Kernels({self.name!r}, n={self.n}, threads={self._threads})"
