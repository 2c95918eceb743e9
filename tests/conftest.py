"""Shared test hygiene.

fmpy routes every FMU's log messages through one process-wide proxy in its
``logging`` library: ``simulate_fmu(..., logger=f)`` points that proxy at ``f``
and never points it back, so once ``f`` is gone the next FMU that logs through
fmpy's default callbacks calls freed memory.  After every test the proxy is
pointed back at fmpy's own printer (through a callback kept alive here).
"""
from ctypes import byref

import pytest

_PRINTER = None  # the callbacks struct whose logger the proxy forwards to; lives as long as the process
_KEPT = []  # every struct handed to the proxy stays alive too


def _restore_fmpy_logger():
    global _PRINTER
    try:
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                               fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, printLogMessage, calloc, free)
        from fmpy.logging import addLoggerProxy
    except ImportError:  # pragma: no cover - an fmpy without its logging library
        return
    if _PRINTER is None:
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(printLogMessage)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        _PRINTER = (cb, cb.logger)
    # a fresh struct each time: the proxy rewrites the struct's logger to itself
    cb = fmi2CallbackFunctions()
    cb.logger = _PRINTER[1]
    cb.allocateMemory, cb.freeMemory = _PRINTER[0].allocateMemory, _PRINTER[0].freeMemory
    _KEPT[:] = [cb]
    addLoggerProxy(byref(cb))


@pytest.fixture(autouse=True)
def _fmpy_default_logger_restored():
    yield
    _restore_fmpy_logger()


@pytest.fixture(scope="module")
def private_reference_cache(tmp_path_factory):
    """A module's own FMUGEN_CACHE: reference solutions and scene FMUs computed afresh, not read from the
    user's cache (``pytestmark = pytest.mark.usefixtures("private_reference_cache")``)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("FMUGEN_CACHE", str(tmp_path_factory.mktemp("reference_cache")))
    yield
    mp.undo()
