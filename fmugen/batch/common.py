"""What the looped and the unrolled batched kernels share: the error of a failing state, array addresses,
and the cache of compiled libraries (``$FMUGEN_CACHE/batch``, default ``~/.cache/fmugen/batch``).
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Optional

import numpy as np

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
    """A sha256 begun with the compiler (its resolved path, size and time) and ``flags``: a library's key
    changes with the compiler that built it."""
    h = hashlib.sha256()
    path = shutil.which(CC) or CC
    try:
        st = os.stat(os.path.realpath(path))
        h.update(f"{os.path.realpath(path)}\0{st.st_size}\0{st.st_mtime_ns}\0".encode())
    except OSError:
        h.update(path.encode())
    h.update("\0".join(flags).encode() + b"\1")
    return h


def _cache_root() -> Optional[Path]:
    if os.environ.get("FMUGEN_OBJECT_CACHE", "1") == "0":
        return None
    return Path(os.environ.get("FMUGEN_CACHE") or Path.home() / ".cache" / "fmugen") / "batch"


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
