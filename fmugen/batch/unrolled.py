"""The batched kernels of one robot as code generated for it: :class:`UnrolledKernels`.

:class:`fmugen.batch.Kernels` runs the runtime's looped tree dynamics, the same for every robot, whose
numbers it reads from arrays.  ``Kernels.unrolled()`` writes the robot's forward dynamics and the
Jacobians of its forward and inverse dynamics as straight-line C with its numbers folded in
(:mod:`fmugen.codegen.unrolled_aba`, :mod:`fmugen.codegen.unrolled_derivatives`: the code of folded
FMUs), compiles them into one library and runs batches of states through it, with the same checks,
errors and threads as the looped kernels.  The results are those of the looped kernels to rounding
(the tests hold them to 1e-12), and the calls take a fraction of the time (README "Derivatives, against
Pinocchio ..."): for sweeps, Monte-Carlo samples and trajectory optimisation with a robot whose numbers
do not change.

Generating and compiling costs seconds for an arm and up to a minute for a robot of a hundred joints
(the three files compile at once, one per core); the library is kept in fmugen's cache folder
(``$FMUGEN_CACHE/batch/unrolled``) under the hash of the robot's numbers, the generators' files, the
compiler and its flags, so the next process with the same robot loads it at once.
``FMUGEN_OBJECT_CACHE=0`` compiles into a temporary folder instead.
"""
from __future__ import annotations

import ctypes
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from .common import CC as _CC, Ranges, _address, _cache_root, _cached, _compiler_hash

__all__ = ["UnrolledKernels"]

# the generated files' compiler flags (the FMU build's optimisation; the files set their own per function)
_FLAGS = ("-std=c99", "-O2", "-fPIC")

_HARNESS = r"""
#include <math.h>
int fmugen_ub_fd(const double *q, const double *qd, const double *tau, double *qdd);
int fmugen_ub_fd_jacobian(const double *q, const double *qd, const double *tau, double *qdd, double *J);
int fmugen_ub_id_jacobian(const double *q, const double *qd, const double *qdd, double *tau, double *J);

static int finite_inputs(int n, const double *a, const double *b, const double *c)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(a[i]) || !isfinite(b[i]) || !isfinite(c[i])) return 0;
    return 1;
}

/* rows of states through kernel `kind` (0 FD, 1 its Jacobian, 2 the ID's Jacobian); the status of the
 * first row that fails (1: a pivot not positive, 2: a result not finite, 3: an input not finite) and its
 * row in *bad, 0 when all succeed.  J: n x 3n per row. */
int fmugen_ub_rows(int kind, int rows, int n, const double *a, const double *b, const double *c, double *y,
                   double *J, long *bad)
{
    for (long r = 0; r < rows; r++) {
        const long o = r * n;
        int s;
        if (!finite_inputs(n, a + o, b + o, c + o)) s = 3;
        else if (kind == 0) s = fmugen_ub_fd(a + o, b + o, c + o, y + o);
        else if (kind == 1) s = fmugen_ub_fd_jacobian(a + o, b + o, c + o, y + o, J + 3 * n * o);
        else s = fmugen_ub_id_jacobian(a + o, b + o, c + o, y + o, J + 3 * n * o);
        if (s) {
            *bad = r;
            return s;
        }
    }
    return 0;
}
"""


def _sources(kernels) -> dict:
    """The generated C files: name -> text."""
    from ..codegen import unrolled_aba, unrolled_derivatives

    return {"fd.c": unrolled_aba.from_kernels(kernels, name="fmugen_ub_fd").source,
            "fd_jacobian.c": unrolled_derivatives.from_kernels(kernels, "fd", name="fmugen_ub_fd_jacobian").source,
            "id_jacobian.c": unrolled_derivatives.from_kernels(kernels, "id", name="fmugen_ub_id_jacobian").source,
            "harness.c": _HARNESS}


def _key(kernels) -> str:
    """The cache key: the compiler and its flags, the generators' own files and the robot's numbers (not the
    generated text: generating it takes a second for a large tree, loading the library a millisecond)."""
    from ..codegen import unrolled_aba, unrolled_derivatives

    h = _compiler_hash(_FLAGS)
    for f in (unrolled_aba.__file__, unrolled_derivatives.__file__, __file__):
        h.update(Path(f).read_bytes() + b"\1")
    h.update(np.asarray(kernels.revolute, np.int8).tobytes() + np.asarray(kernels.parents, np.int64).tobytes())
    h.update(np.ascontiguousarray(kernels.constants, np.float64).tobytes())
    h.update(np.asarray(kernels.globals, np.float64).tobytes())
    return h.hexdigest()[:32]


def _compile(folder: Path, sources: dict) -> Path:
    """Every file compiled at once (the large trees' Jacobians take most of a minute each), then linked."""
    for name, text in sources.items():
        (folder / name).write_text(text)
    try:
        procs = [(name, subprocess.Popen([_CC, *_FLAGS, "-c", "-o", str(folder / (name + ".o")), str(folder / name)],
                                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
                 for name in sources]
    except FileNotFoundError:
        raise RuntimeError(f"cannot compile the unrolled kernels: no C compiler {_CC!r} on the PATH") from None
    errors = []
    for name, p in procs:
        _, err = p.communicate()
        if p.returncode != 0:
            errors.append(f"{name}:\n{err}")
    if errors:
        raise RuntimeError("cannot compile the unrolled kernels:\n" + "\n".join(errors))
    out = folder / "unrolled.so"
    cmd = [_CC, "-shared", "-o", str(out), *(str(folder / (n + ".o")) for n in sources), "-lm"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"cannot link the unrolled kernels: {' '.join(cmd)}\n{r.stderr}")
    for name in sources:  # the library is what is kept
        (folder / name).unlink()
        (folder / (name + ".o")).unlink()
    return out


def _library(kernels) -> tuple:
    """(loaded library, its temporary folder or None): from the cache if built before for the same numbers,
    generators, compiler and flags, else generated, built and stored now."""
    root = _cache_root()
    so = _cached(root / "unrolled", _key(kernels), lambda d: _compile(d, _sources(kernels))) if root else None
    if so is not None:
        return ctypes.CDLL(str(so)), None
    tmp = Path(tempfile.mkdtemp(prefix="fmugen_unrolled_batch_"))
    try:
        return ctypes.CDLL(str(_compile(tmp, _sources(kernels)))), tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


class UnrolledKernels(Ranges):
    """``fd``, ``fd_derivatives`` and ``id_derivatives`` of :class:`fmugen.batch.Kernels` for many states per
    call, through code generated for the robot (made by :meth:`fmugen.batch.Kernels.unrolled`).

    The same inputs, checks and errors as the looped kernels (:class:`fmugen.batch.StateError` with the index
    of the first failing state) and the same ``threads``.  The three blocks of a derivatives' result are
    views of one (N, n, 3n) array (the generated code writes a state's Jacobian as one row-major block):
    numpy arrays like any other, not contiguous."""

    def __init__(self, kernels, threads: int = 1):
        from ..codegen.unrolled_aba import NotPositiveDefinite

        self.kernels, self.name, self.n = kernels, kernels.name, kernels.n
        self._tmp = None
        try:
            self._lib, self._tmp = _library(kernels)
        except NotPositiveDefinite as e:  # a massless leaf: singular at every state
            raise ValueError(f"{self.name}: {e}") from None
        vp = ctypes.c_void_p
        self._lib.fmugen_ub_rows.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int] + [vp] * 6
        self._lib.fmugen_ub_rows.restype = ctypes.c_int
        self.threads = threads

    def _run(self, what: str, kind: int, arrays: dict, jacobian: bool) -> tuple:
        count, ins = self.kernels._check(what, arrays)
        n = self.n
        y = np.empty((count, n))
        J = np.empty((count, n, 3 * n)) if jacobian else None
        fn = self._lib.fmugen_ub_rows
        a, yb, jb = [_address(x) for x in ins], _address(y), J is not None and _address(J)

        def part(i, lo, hi):
            bad = ctypes.c_long(-1)
            s = fn(kind, hi - lo, n, *(x + 8 * n * lo for x in a), yb + 8 * n * lo,
                   jb + 8 * 3 * n * n * lo if jb else None, ctypes.byref(bad))
            return s, lo + bad.value

        self._ranges(f"{what} (unrolled)", count, part)
        return y, J

    def fd(self, q, qd, tau) -> np.ndarray:
        """qdd = M(q)^-1 (tau - h(q, qd)) per state (N, n): the articulated-body algorithm."""
        return self._run("fd", 0, {"q": q, "qd": qd, "tau": tau}, False)[0]

    def fd_derivatives(self, q, qd, tau) -> tuple:
        """``(qdd, dqdd/dq, dqdd/dqd, M^-1)``: (N, n) and three (N, n, n) views; M^-1 = dqdd/dtau."""
        qdd, J = self._run("fd_derivatives", 1, {"q": q, "qd": qd, "tau": tau}, True)
        n = self.n
        return qdd, J[:, :, :n], J[:, :, n:2 * n], J[:, :, 2 * n:]

    def id_derivatives(self, q, qd, qdd) -> tuple:
        """``(tau, dtau/dq, dtau/dqd, M)``: (N, n) and three (N, n, n) views; M = dtau/dqdd."""
        tau, J = self._run("id_derivatives", 2, {"q": q, "qd": qd, "qdd": qdd}, True)
        n = self.n
        return tau, J[:, :, :n], J[:, :, n:2 * n], J[:, :, 2 * n:]

    def close(self):
        """Stop the worker threads; remove the library's temporary folder (without the cache)."""
        super().close()
        if self._tmp is not None:
            self._lib = None
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def __repr__(self):
        return f"UnrolledKernels({self.name!r}, n={self.n}, threads={self._threads})"
