"""Load a generated ``model.c`` into Python without the FMI runtime.

Compiles the model with ``c_runtime/linalg.c`` and a tiny shim into a shared
library and calls its ``evaluate``/``jacobian`` through ctypes.  Used by the
tests (generated C against sympy/numpy) and by benchmarks: ``time_evaluate``
times the function in a compiled loop, so no Python call overhead is in the
figure.

>>> import sympy as sp
>>> from fmugen.codegen.model import SymbolicModel, Variable
>>> x, k = sp.symbols("x k", real=True)
>>> m = SymbolicModel.from_equations("Decay", [Variable("x", x, start=1.0)], [],
...                                  [Variable("k", k, start=2.0)], [-k * x])
>>> with CompiledModel.build(generate_c(m).source) as cm:
...     dx, y = cm.evaluate([3.0], 0.0, [0.5], [])
>>> float(dx[0])
-1.5
"""
from __future__ import annotations

import ctypes
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from .c_code import generate_c  # noqa: F401  (re-exported for the doctest)

_SHIM = r"""
#include <time.h>
#include "fmugen_model.h"
int harness_sizes(int *s) {
    s[0] = fmugen_model.nx; s[1] = fmugen_model.nu; s[2] = fmugen_model.ny; s[3] = fmugen_model.np;
    return fmugen_model.has_jacobian;
}
int harness_evaluate(const double *p, double t, const double *x, const double *u, double *dx, double *y) {
    return fmugen_model.evaluate(p, t, x, u, dx, y);
}
int harness_jacobian(const double *p, double t, const double *x, const double *u,
                     double *a, double *b, double *c, double *d) {
    if (!fmugen_model.jacobian) return -1;
    return fmugen_model.jacobian(p, t, x, u, a, b, c, d);
}
const char *harness_guid(void) { return fmugen_model.guid; }
/* seconds per call of evaluate (which = 0) or jacobian (which = 1), n calls */
double harness_time(int which, long n, const double *p, const double *x, const double *u,
                    double *o1, double *o2, double *o3, double *o4) {
    struct timespec a, b;
    volatile int sink = 0;
    clock_gettime(CLOCK_MONOTONIC, &a);
    for (long i = 0; i < n; i++) {
        if (which == 0) sink += fmugen_model.evaluate(p, 0.0, x, u, o1, o2);
        else sink += fmugen_model.jacobian(p, 0.0, x, u, o1, o2, o3, o4);
    }
    clock_gettime(CLOCK_MONOTONIC, &b);
    (void)sink;
    return ((double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec)) / (double)n;
}
"""

_DP = ctypes.POINTER(ctypes.c_double)


def runtime_dir() -> Path:
    """``c_runtime/`` of the repository (next to the ``fmugen`` package)."""
    d = Path(__file__).resolve().parents[2] / "c_runtime"
    if not (d / "fmugen_model.h").is_file():
        raise FileNotFoundError(f"C runtime not found: {d} has no fmugen_model.h (fmugen must be "
                                f"used from its source tree)")
    return d


class CompiledModel:
    """A generated model compiled into a shared library (see module doc)."""

    def __init__(self, library: Path, workdir: Optional[Path] = None):
        self._lib = ctypes.CDLL(str(library))
        self._workdir = workdir
        lib = self._lib
        lib.harness_evaluate.argtypes = [_DP, ctypes.c_double, _DP, _DP, _DP, _DP]
        lib.harness_jacobian.argtypes = [_DP, ctypes.c_double, _DP, _DP, _DP, _DP, _DP, _DP]
        lib.harness_guid.restype = ctypes.c_char_p
        lib.harness_time.restype = ctypes.c_double
        lib.harness_time.argtypes = [ctypes.c_int, ctypes.c_long, _DP, _DP, _DP, _DP, _DP, _DP, _DP]
        s = (ctypes.c_int * 4)()
        self.has_jacobian = bool(lib.harness_sizes(s))
        self.nx, self.nu, self.ny, self.np = list(s)

    @classmethod
    def build(cls, source: str, cc: str = "cc", cflags: Sequence[str] = ("-O2",),
              workdir: Optional[Path] = None) -> "CompiledModel":
        """Compile ``source`` (a generated model.c) with -Wall -Wextra -Werror."""
        own = workdir is None
        work = Path(tempfile.mkdtemp(prefix="fmugen_model_")) if own else Path(workdir)
        rt = runtime_dir()
        (work / "model.c").write_text(source)
        (work / "harness.c").write_text(_SHIM)
        lib = work / "libmodel.so"
        # the looped chain dynamics only when the model calls them (a large arm)
        chain = [str(rt / "chain_dynamics.c")] if '#include "chain_dynamics.h"' in source else []
        cmd = [cc, "-std=c99", "-D_POSIX_C_SOURCE=199309L", *cflags, "-fPIC", "-shared",
               "-Wall", "-Wextra", "-Werror", f"-I{rt}", "-o", str(lib),
               str(work / "model.c"), str(rt / "linalg.c"), *chain, str(work / "harness.c"), "-lm"]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"compilation failed: {' '.join(cmd)}\n{r.stderr}")
        return cls(lib, work if own else None)

    def close(self) -> None:
        if self._workdir is not None:
            shutil.rmtree(self._workdir, ignore_errors=True)
            self._workdir = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @staticmethod
    def _arr(v, n):
        a = np.ascontiguousarray(np.asarray(v, dtype=float).reshape(-1))
        if a.size != n:
            raise ValueError(f"expected {n} values, got {a.size}")
        return a

    @staticmethod
    def _ptr(a):
        return a.ctypes.data_as(_DP) if a.size else None

    @property
    def guid(self) -> str:
        return self._lib.harness_guid().decode()

    def evaluate(self, p, t, x, u, want_y: bool = True) -> tuple:
        """``(dx, y)``; raises RuntimeError with the model's status code on failure."""
        p, x, u = self._arr(p, self.np), self._arr(x, self.nx), self._arr(u, self.nu)
        dx, y = np.zeros(self.nx), np.zeros(self.ny)
        # a 0-length array still gets a valid pointer: NULL means "not wanted"
        dummy = np.zeros(1)
        yp = (self._ptr(y) or dummy.ctypes.data_as(_DP)) if want_y else None
        st = self._lib.harness_evaluate(self._ptr(p), float(t), self._ptr(x), self._ptr(u),
                                        self._ptr(dx) or dummy.ctypes.data_as(_DP), yp)
        if st != 0:
            raise RuntimeError(f"evaluate returned status {st}")
        return dx, (y if want_y else None)

    def jacobian(self, p, t, x, u) -> tuple:
        """``(dfdx, dfdu, dgdx, dgdu)`` as 2-D arrays."""
        if not self.has_jacobian:
            raise RuntimeError("model has no Jacobian")
        p, x, u = self._arr(p, self.np), self._arr(x, self.nx), self._arr(u, self.nu)
        nx, nu, ny = self.nx, self.nu, self.ny
        outs = [np.full(nx * nx, np.nan), np.full(nx * nu, np.nan),
                np.full(ny * nx, np.nan), np.full(ny * nu, np.nan)]
        dummy = np.zeros(1)
        ptrs = [self._ptr(o) or dummy.ctypes.data_as(_DP) for o in outs]
        st = self._lib.harness_jacobian(self._ptr(p), float(t), self._ptr(x), self._ptr(u), *ptrs)
        if st != 0:
            raise RuntimeError(f"jacobian returned status {st}")
        return (outs[0].reshape(nx, nx), outs[1].reshape(nx, nu),
                outs[2].reshape(ny, nx), outs[3].reshape(ny, nu))

    def time_per_call(self, p, x, u, function: str = "evaluate", n: int = 100000) -> float:
        """Seconds per call of ``evaluate`` or ``jacobian``, timed in a C loop."""
        p, x, u = self._arr(p, self.np), self._arr(x, self.nx), self._arr(u, self.nu)
        bufs = [np.zeros(max(1, k)) for k in (self.nx * self.nx, self.nx * self.nu,
                                              self.ny * self.nx, self.ny * self.nu)]
        if function == "evaluate":
            bufs = [np.zeros(max(1, self.nx)), np.zeros(max(1, self.ny))] + bufs[2:]
        which = {"evaluate": 0, "jacobian": 1}[function]
        return self._lib.harness_time(which, int(n), self._ptr(p), self._ptr(x), self._ptr(u),
                                      *[b.ctypes.data_as(_DP) for b in bufs])
