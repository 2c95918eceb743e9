"""Components written as equations in a TOML file (Modelica-style, causal explicit ODEs).

:func:`load_component` reads a component file -- parameters, inputs, states,
intermediates, outputs, ``der(x) = ...`` and ``y = ...`` equations --
checks every equation's dimensions, and returns a
:class:`fmugen.codegen.model.SymbolicModel` like any built-in factory.  A
scene uses it as ``type = "file:components/x.toml"``; the shipped files are in
``fmugen/components/library/`` (``type = "lib:stribeck"``).  Format:
``fmugen/components/README.md`` ("Component files").
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Mapping, Optional

from ...codegen.model import SymbolicModel
from ...errors import InputFileError
from .file import ComponentFile, component_model, read_component_file

LIBRARY = Path(__file__).resolve().parent.parent / "library"

__all__ = ["load_component", "read_component_file", "component_model", "library_path", "library_names",
           "ComponentFile", "LIBRARY"]


def library_names() -> list:
    """Names of the shipped component files (``lib:<name>`` in a scene)."""
    return sorted(p.stem for p in LIBRARY.glob("*.toml"))


def library_path(name: str) -> Path:
    p = LIBRARY / f"{name}.toml"
    if not name.replace("_", "a").isalnum() or not p.is_file():
        raise InputFileError(f"no shipped component {name!r}; shipped: {', '.join(library_names())}")
    return p


@lru_cache(maxsize=64)
def _read(path: str, mtime: int, size: int) -> ComponentFile:
    return read_component_file(path)


def read_cached(path) -> ComponentFile:
    """:func:`read_component_file`, once per file version (scenes read a file per instance)."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError:
        return read_component_file(p)  # its own error message
    return _read(str(p.resolve()), st.st_mtime_ns, st.st_size)


def load_component(path, name: Optional[str] = None, parameter_set=None,
                   overrides: Optional[Mapping[str, float]] = None, strict_set: bool = True) -> SymbolicModel:
    """The SymbolicModel of component file ``path`` (or ``"lib:<name>"``), see :func:`component_model`."""
    if isinstance(path, str) and path.startswith("lib:"):
        path = library_path(path[4:])
    return component_model(read_cached(path), name, parameter_set, overrides, strict_set)
