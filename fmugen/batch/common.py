"""What the looped and the unrolled batched kernels share: the error of a failing state, array addresses,
and the cache of compiled libraries (``$FMUGEN_CACHE/batch``, default ``~/.cache/fmugen/batch``).
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Optional

import numpy as np

from ..cache import compiled_cache, hash_compiler

__all__ = ["StateError"]

CC = "cc"

_STATUS = {1: "the mass matrix is not positive definite", 2: "a result is NaN or infinite",
           3: "an input is NaN or infinite", 4: "unknown kernel (a bug of fmugen.batch)"}


class StateError(ArithmeticError):
    """A state of a batch where the dynamics fail: ``index`` (0-based row of the inputs) is the first
    such state, ``reason`` says what failed (mass matrix not positive definite, a NaN or infinite
    result or input)."""

    def __init__(self, what: str, index: int, status: int):
        self.index, self.status, self.reason = index, status, _STATUS.get(status, f"status {status}")
        super().__init__(f"{what}: state {index}: {self.reason}")


def _compiler_hash(flags) -> "hashlib._Hash":
    """A sha256 begun with the compiler and ``flags``: a library's key changes with the compiler that
    built it."""
    h = hashlib.sha256()
    hash_compiler(h, CC, flags)
    return h


def _cache_root() -> Optional[Path]:
    return compiled_cache("batch")


def _cached(root: Path, key: str, build) -> Optional[Path]:
    """The library of folder ``root / key``, built there first if missing: ``build(folder)`` writes it into a
    new folder and returns its path, and one rename stores the complete folder, so processes building at
    once never see half of one.  None where the cache cannot be written (no error: the caller builds into
    a temporary folder)."""
    target = root / key
    found = sorted(target.glob("*.so")) if target.is_dir() else []
    if found:
        return found[0]
    try:
        root.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".part-", dir=root))
    except OSError:
        return None
    try:
        name = build(tmp).name
        os.rename(tmp, target)
    except OSError:  # another process stored it first, or the folder cannot be written
        shutil.rmtree(tmp, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return target / name if (target / name).is_file() else None


def _address(a: np.ndarray) -> int:
    """The data address of an array.  Through the buffer protocol first: a quarter of the cost of
    ``a.ctypes.data`` or ``a.__array_interface__``, which build objects per call -- and at N = 1 the
    Python around the C call is most of its cost.  A read-only or empty array takes the slow way."""
    try:
        return _addressof(_char.from_buffer(a))
    except (TypeError, ValueError):
        return a.__array_interface__["data"][0]


_char, _addressof = ctypes.c_char, ctypes.addressof


class Ranges:
    """Batches cut into ``threads`` contiguous ranges that Python threads run at once (ctypes releases the
    GIL during a call into C, so the ranges run on separate cores); the first failing state of a batch is
    raised as :class:`StateError`.  Calls from several threads of the user take turns (the object's work
    arrays are shared)."""

    _threads, _pool, _busy = 1, None, None

    @property
    def threads(self) -> int:
        return self._threads

    @threads.setter
    def threads(self, k: int):
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
            raise ValueError(f"threads: a whole number >= 1, got {k!r}")
        if self._busy is None:  # the constructor sets threads: the lock is there before the first call
            self._busy = threading.Lock()
        if int(k) != self._threads:
            self._stop_pool()  # its size was the old count (the rest of the object stays as it is)
            self._threads = int(k)

    def _ranges(self, what: str, count: int, run):
        """``run(i, lo, hi) -> (status, index of the failing state)`` over the states lo .. hi - 1 of range i
        (i: for per-range work arrays), the ranges at once; StateError for the first failing state."""
        k = min(self._threads, max(count, 1))
        bounds = [count * i // k for i in range(k + 1)]
        with self._busy:
            if k == 1:
                results = [run(0, 0, count)]
            else:
                if self._pool is None:
                    self._pool = ThreadPoolExecutor(max_workers=self._threads - 1, thread_name_prefix="fmugen-batch")
                futures = [self._pool.submit(run, i, bounds[i], bounds[i + 1]) for i in range(1, k)]
                results = [run(0, bounds[0], bounds[1])] + [f.result() for f in futures]
        for s, index in results:  # in order of the ranges: the first bad state of the batch
            if s != 0:
                raise StateError(f"{self.name}: {what}", index, s)

    def _stop_pool(self):
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def close(self):
        """Stop the worker threads (started by the first call with threads > 1)."""
        self._stop_pool()

    def __del__(self):
        try:
            self.close()
        except Exception:  # interpreter shutdown
            pass
