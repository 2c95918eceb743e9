"""Shared test hygiene.

fmpy routes every FMU's log messages through one process-wide proxy in its
``logging`` library: ``simulate_fmu(..., logger=f)`` points that proxy at ``f``
and never points it back, so once ``f`` is gone the next FMU that logs through
fmpy's default callbacks calls freed memory.  After every test the proxy is
pointed back at fmpy's own printer (through a callback kept alive here).

OpenBLAS picks its kernels by the CPU (Haswell, SkylakeX, Zen, ...), and the
kernels round differently: the master's Newton solves then differ in the last
bits from one machine to another, and the results stored bit for bit
(tests/test_cosim_structure.py) were made with the Haswell kernels.  The suite
runs with those kernels on every x86-64 CPU (AVX2, the CI machines' floor); the
variable must be set before numpy is first imported, which is why it is here.
"""
import os
import platform

if platform.machine() in ("x86_64", "AMD64"):
    os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")
import warnings
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


_START_FOLDER = os.getcwd()  # where pytest was started: the checkout, which many tests name files relative to


@pytest.fixture(autouse=True)
def _working_folder_kept(request):
    """Every test starts in the folder pytest started in.  The process's working folder is global, and code a
    test runs may move it and not move back: fmpy changes into an FMU's binary folder to load it and did
    not change back when the load failed (fmugen's master now restores it, tests/test_hardening_master.py),
    and libcosim's C++ library calls chdir too.  Once moved, every later test naming a file relative to the
    checkout failed; a move is put back and reported as a warning naming the test."""
    if os.getcwd() != _START_FOLDER:
        warnings.warn(f"the working folder was {os.getcwd()} before {request.node.nodeid}; put back")
        os.chdir(_START_FOLDER)
    yield
    if os.getcwd() != _START_FOLDER:
        warnings.warn(f"{request.node.nodeid} left the working folder at {os.getcwd()}; put back")
        os.chdir(_START_FOLDER)


@pytest.fixture(scope="module")
def private_reference_cache(tmp_path_factory):
    """A module's own FMUGEN_CACHE: reference solutions and scene FMUs computed afresh, not read from the
    user's cache (``pytestmark = pytest.mark.usefixtures("private_reference_cache")``)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("FMUGEN_CACHE", str(tmp_path_factory.mktemp("reference_cache")))
    yield
    mp.undo()
