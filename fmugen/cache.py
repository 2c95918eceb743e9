"""Where fmugen keeps what it computed once: ``$FMUGEN_CACHE`` (default ``~/.cache/fmugen``), one folder per
kind (compiled runtime objects, batched kernels' libraries, scene builds, reference solutions), and the
identity of a compiler, which a compiled thing's key must change with.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Optional

__all__ = ["cache_home", "compiled_cache", "hash_compiler"]


def cache_home() -> Path:
    """``$FMUGEN_CACHE``, default ``~/.cache/fmugen``."""
    return Path(os.environ.get("FMUGEN_CACHE") or Path.home() / ".cache" / "fmugen")


def compiled_cache(kind: str) -> Optional[Path]:
    """The folder of compiled code of this ``kind`` under :func:`cache_home`; None when
    ``FMUGEN_OBJECT_CACHE=0`` (compile into a temporary folder instead)."""
    if os.environ.get("FMUGEN_OBJECT_CACHE", "1") == "0":
        return None
    return cache_home() / kind


def hash_compiler(h, cc: str, flags) -> None:
    """Feed hash ``h`` the compiler ``cc`` (its resolved path, size and time: an upgrade in place changes
    the key) and its ``flags``."""
    path = shutil.which(cc) or cc
    try:
        real = os.path.realpath(path)
        st = os.stat(real)
        h.update(f"{real}\0{st.st_size}\0{st.st_mtime_ns}\0".encode())
    except OSError:
        h.update(path.encode())
    h.update("\0".join(flags).encode() + b"\1")
