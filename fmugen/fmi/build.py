"""Build an FMI 2.0 FMU from a :class:`SymbolicModel`.

    model --generate_c--> model.c ─┐
    model --model_description_xml--> modelDescription.xml
    c_runtime/*.c, *.h + FMI 2.0 headers (from fmpy) + model.c
        --cc -O2 -fPIC -shared--> binaries/<platform>/<modelIdentifier>.so
        (and per requested platform: win64 .dll, darwin64 universal .dylib; fmugen/fmi/platforms.py)
    zip --> <name>.fmu

The FMU is self-contained: ``sources/`` holds every C file and header needed
to compile it on another platform (listed in ``<SourceFiles>`` and in
``sources/README.txt`` with the command used here).

>>> # build_fmu(model, "out/Pendulum.fmu", fmi_type="both")  # doctest: +SKIP
"""
from __future__ import annotations

import hashlib
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence, Union

from .. import __version__
from ..cache import compiled_cache, hash_compiler
from ..codegen.c_code import GUID_PLACEHOLDER, c_identifier, deterministic_guid, generate_c
from ..codegen.model import SymbolicModel
from ..errors import IDENTIFIER_PATTERN, MAX_IDENTIFIER_LENGTH, FmugenError
from .model_description import model_description_xml
from .platforms import Slice, link_flags, resolve, sources_readme, universal_binary

FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
CFLAGS = ("-O2", "-fPIC", "-shared", "-Wall", "-Wextra", "-std=c99")
# zip entries get a fixed date so that identical inputs give identical FMUs
_ZIP_DATE = (2020, 1, 1, 0, 0, 0)


class BuildError(RuntimeError):
    """The FMU could not be built; the message holds the failing command and its output."""


@dataclass
class BuildResult:
    path: Path
    model_identifier: str
    guid: str
    op_counts: dict  # function name -> FunctionOps
    timings: dict = field(default_factory=dict)  # generate / compile / zip, seconds
    command: str = ""  # the compiler command (link) of the first platform
    platforms: tuple = ()  # the binaries/ folders, e.g. ("linux64", "win64")
    commands: dict = field(default_factory=dict)  # "<platform>/<arch>" -> its link command

    def __str__(self) -> str:
        t = ", ".join(f"{k} {v:.2f} s" for k, v in self.timings.items())
        ops = "; ".join(f"{k}: {v}" for k, v in self.op_counts.items())
        return f"{self.path} ({t}); {ops}"


def runtime_dir() -> Path:
    """``c_runtime/`` of the fmugen source tree."""
    d = Path(__file__).resolve().parents[2] / "c_runtime"
    if not d.is_dir() or not (d / "fmugen_model.h").is_file():
        raise BuildError(f"C runtime not found at {d} (expected c_runtime/fmugen_model.h next to the "
                         f"fmugen package; fmugen must be installed from its source tree)")
    return d


def fmi_headers_dir() -> Path:
    """The FMI 2.0 standard headers shipped with fmpy."""
    import fmpy

    d = Path(fmpy.__file__).resolve().parent / "c-code"
    missing = [h for h in FMI_HEADERS if not (d / h).is_file()]
    if missing:
        raise BuildError(f"FMI 2.0 headers {', '.join(missing)} not found in {d}")
    return d


def platform_binary() -> tuple:
    """``(platform folder, shared library suffix)`` of this machine, as FMI 2.0 names them."""
    from fmpy import platform, sharedLibraryExtension

    return platform, sharedLibraryExtension


def _check_identifier(ident: str, name: str, given: bool) -> None:
    """The model identifier names the shared library and the FMU file: ASCII,
    at most MAX_IDENTIFIER_LENGTH characters, and never a silent replacement
    of a name that had no ASCII characters to keep."""
    if not given and not any(c.isascii() and c.isalnum() for c in name):
        raise FmugenError(f"model name {name!r} has no ASCII letters or digits to make a model identifier "
                          f"from; give model_identifier=")
    if len(ident) > MAX_IDENTIFIER_LENGTH or not IDENTIFIER_PATTERN.match(ident):
        raise FmugenError(f"model identifier {ident[:80]!r} must be a C identifier of at most "
                          f"{MAX_IDENTIFIER_LENGTH} characters (it names the shared library and the .fmu file)")


def _fold(model: SymbolicModel, fold_parameters) -> SymbolicModel:
    if fold_parameters is None:
        return model
    if fold_parameters == "all":
        return model.with_parameters_folded()
    if isinstance(fold_parameters, str):
        raise FmugenError(f"fold_parameters must be None, 'all' or a list of parameter names, "
                         f"got {fold_parameters!r}")
    names = list(fold_parameters)
    known = {v.name for v in model.parameters}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise FmugenError(f"fold_parameters: {', '.join(unknown)} not parameters of {model.name!r} "
                         f"(parameters: {', '.join(sorted(known))})")
    return model.with_parameters_folded(names)


def _fmi_types(fmi_type: str) -> tuple:
    try:
        return {"both": ("me", "cs"), "me": ("me",), "cs": ("cs",)}[fmi_type]
    except KeyError:
        raise FmugenError(f"fmi_type must be 'me', 'cs' or 'both', got {fmi_type!r}") from None


class BuildBudgetExceeded(BuildError, FmugenError):
    """The build went past the time or memory budget the caller gave (``budget_seconds``/``budget_memory``).

    Also a :class:`~fmugen.errors.FmugenError` (a ValueError): the command line prints it as one line."""


class BuildInterrupted(BuildError):
    """The build was stopped by SIGTERM (or SIGINT); its temporary files are gone."""


class _Budget:
    """Wall-clock and memory limits of one build, checked between and during stages.

    Memory is the resident set of this process plus that of every compiler
    it runs at the moment (read from /proc where there is one), so the
    figure is what the build holds, not what other programs use.
    """

    def __init__(self, seconds: Optional[float], memory: Optional[float], t0: float):
        for what, v in (("budget_seconds", seconds), ("budget_memory", memory)):
            if v is not None and not (isinstance(v, (int, float)) and v > 0):
                raise FmugenError(f"{what} must be a positive number, got {v!r}")
        self.seconds, self.memory, self.t0 = seconds, memory, t0
        self.peak = 0.0

    def check(self, stage: str, pids: Sequence[int] = ()) -> None:
        used = time.perf_counter() - self.t0
        if self.seconds is not None and used > self.seconds:
            raise BuildBudgetExceeded(f"build stopped: {used:.1f} s exceeds the time budget of "
                                      f"{self.seconds:g} s (in stage '{stage}')")
        if self.memory is not None:
            rss = _rss_bytes(os.getpid()) + sum(_rss_bytes(p) for p in pids)
            self.peak = max(self.peak, rss)
            if rss > self.memory:
                raise BuildBudgetExceeded(f"build stopped: {rss / 2**20:.0f} MiB in use exceeds the memory "
                                          f"budget of {self.memory / 2**20:.0f} MiB (in stage '{stage}')")


def _rss_bytes(pid: int) -> float:
    """Resident memory of a process, bytes (0 where /proc is not available or the process is gone)."""
    try:
        with open(f"/proc/{pid}/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0.0


class _Progress:
    """One line per stage on a terminal ("generate ... 0.6 s"); silent when stderr is not a terminal."""

    def __init__(self, enabled: Optional[bool], name: str):
        self.on = sys.stderr.isatty() if enabled is None else bool(enabled)
        self.name = name
        self.t = None

    def start(self, stage: str, detail: str = "") -> None:
        self.t = time.perf_counter()
        if self.on:
            print(f"fmugen build {self.name}: {stage}{' (' + detail + ')' if detail else ''} ...",
                  end="", file=sys.stderr, flush=True)

    def done(self) -> None:
        if self.on and self.t is not None:
            print(f" {time.perf_counter() - self.t:.1f} s", file=sys.stderr, flush=True)
        self.t = None


class _Signals:
    """SIGTERM and SIGINT of one build in the main thread.

    Outside a shielded block a signal raises at once (SIGTERM as
    :class:`BuildInterrupted`, SIGINT as KeyboardInterrupt), so a long code
    generation stops on the spot.  Inside :func:`_shielded` -- starting a
    compiler and recording it, reaping one, making or removing a temporary
    file -- it is kept and raised when the block ends: an exception raised
    between ``fork`` and the return of ``subprocess.Popen`` left a compiler
    nobody knew of running for its whole run time (tests/test_large_models.py
    saw that 4 times in 30 under load), and one raised inside ``Popen.poll``
    between taking and releasing its wait lock would leave the lock taken, so
    that the ``wait`` after killing the compiler never returned."""

    def __init__(self):
        self.depth = 0
        self.pending = None

    def handler(self, signum, frame):
        if self.depth:
            self.pending = self.pending or signum
            return
        raise _interruption(signum)

    def raise_pending(self) -> None:
        if self.pending is not None:
            signum, self.pending = self.pending, None
            raise _interruption(signum)


_ACTIVE: Optional[_Signals] = None  # the main thread's build, while one runs


def _interruption(signum: int) -> BaseException:
    if signum == signal.SIGINT:
        return KeyboardInterrupt()
    return BuildInterrupted(f"build interrupted by signal {signum}; temporary files removed")


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextmanager
def _terminate_as_exception():
    """SIGTERM raises :class:`BuildInterrupted` while the build runs, so every
    ``with``/``finally`` on the way out removes its files and stops its
    compilers (a SIGTERM would otherwise end the process on the spot); SIGINT
    raises KeyboardInterrupt as always, but never inside a shielded block (see
    :class:`_Signals`).  A SIGINT the process ignores stays ignored, one with
    a handler of the caller's stays the caller's.  Only in the main thread,
    where Python can install handlers (and where signals arrive)."""
    global _ACTIVE
    if not _in_main_thread() or _ACTIVE is not None:
        yield
        return
    state, previous = _Signals(), {}
    try:
        # installed inside the try: a signal between the two calls still puts the first back
        previous[signal.SIGTERM] = signal.signal(signal.SIGTERM, state.handler)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            previous[signal.SIGINT] = signal.signal(signal.SIGINT, state.handler)
        _ACTIVE = state
        yield
    finally:
        state.depth += 1  # a signal while the handlers are put back waits for the end
        _ACTIVE = None
        for signum, h in previous.items():
            signal.signal(signum, h)
        state.raise_pending()


@contextmanager
def _shielded():
    """A signal arriving in the block is raised when the block ends (see :class:`_Signals`)."""
    state = _ACTIVE if _in_main_thread() else None
    if state is None:
        yield
        return
    state.depth += 1
    try:
        yield
    finally:
        state.depth -= 1
        if state.depth == 0:
            state.raise_pending()


def _checkpoint() -> None:
    """Raise a signal kept by a shielded block now (a place inside one where stopping is safe)."""
    if _ACTIVE is not None and _in_main_thread():
        _ACTIVE.raise_pending()
    _check_cancelled()


_CANCEL = threading.local()  # the event that cancels the builds of this thread (see cancellable)


@contextmanager
def cancellable(event: threading.Event):
    """Builds run in this thread stop with :class:`BuildInterrupted` -- compilers killed, files removed --
    within a poll of their compiler supervisor (20 ms) once ``event`` is set.  Signals reach only the main
    thread: a scene's groups built in worker threads learn of a Ctrl-C in the main thread, or of another
    group's failure, through this event, instead of running their compilers on to the end."""
    previous = getattr(_CANCEL, "event", None)
    _CANCEL.event = event
    try:
        yield
    finally:
        _CANCEL.event = previous


def _check_cancelled() -> None:
    event = getattr(_CANCEL, "event", None)
    if event is not None and event.is_set():
        raise BuildInterrupted("build cancelled (another part of the build stopped); temporary files removed")


@contextmanager
def _temporary_folder(prefix: str):
    """A temporary folder that is made and removed whole whatever signal arrives meanwhile."""
    path = None
    try:
        with _shielded():
            path = Path(tempfile.mkdtemp(prefix=prefix))
        yield path
    finally:
        if path is not None:
            with _shielded():
                shutil.rmtree(path, ignore_errors=True)


def _run_jobs(jobs: list, cwd: Path, what: str, budget: _Budget, stage: str) -> None:
    """Run compiler commands, at most one per CPU at a time; the first failure
    (or an exceeded budget, or an exception such as a SIGTERM) kills the rest."""
    pending, running = list(jobs), []
    width = max(1, os.cpu_count() or 1)
    with _shielded():  # a signal waits for the next _checkpoint(), a few ms away
        _supervise(pending, running, width, cwd, what, budget, stage)


def _supervise(pending: list, running: list, width: int, cwd: Path, what: str, budget: _Budget,
               stage: str) -> None:
    try:
        while pending or running:
            while pending and len(running) < width:
                cmd = pending.pop(0)
                # output to a file, not a pipe: a compiler with more warnings than a
                # pipe holds would block until read, and this loop reads at the end
                log = tempfile.TemporaryFile(mode="w+")
                try:
                    proc = subprocess.Popen(cmd, cwd=cwd, stdout=log, stderr=subprocess.STDOUT, text=True)
                except OSError as e:
                    log.close()
                    raise BuildError(f"cannot run the C compiler: {shlex.join(cmd)}\n(in {cwd})\n{e}") from None
                proc.log = log
                running.append((cmd, proc))
            time.sleep(0.02)
            _checkpoint()
            budget.check(stage, [p.pid for _, p in running])
            for cmd, proc in list(running):
                if proc.poll() is None:
                    continue
                running.remove((cmd, proc))
                proc.log.seek(0)
                out = proc.log.read()
                proc.log.close()
                if proc.returncode != 0:
                    raise BuildError(f"C compiler failed (exit {proc.returncode}) building {what!r}:\n"
                                     f"  cd {cwd} && {shlex.join(cmd)}\n{out.strip()}")
    finally:
        for _, proc in running:  # only on the way out through an exception
            proc.kill()
            proc.wait()
            proc.log.close()


def object_cache_dir() -> Optional[Path]:
    """Where compiled runtime objects are kept (``$FMUGEN_CACHE/objects``, default
    ``~/.cache/fmugen/objects``); None when ``FMUGEN_OBJECT_CACHE=0``."""
    return compiled_cache("objects")


def _runtime_key(cc: str, flags: list, src: Path, runtime: list, target: str = "") -> str:
    """Hash of what the runtime objects depend on: the target platform and architecture, the
    compiler (its resolved path, size and time), the flags, and every source and header of
    the build folder but model.c."""
    h = hashlib.sha256()
    h.update(f"target {target}\0".encode())
    hash_compiler(h, cc, flags)
    for p in sorted(src.iterdir()):
        if p.name != "model.c" and p.suffix in (".c", ".h"):
            h.update(p.name.encode() + b"\0" + p.read_bytes() + b"\1")
    h.update("\0".join(runtime).encode())
    return h.hexdigest()[:32]


def _compile(cc: Union[str, Slice], extra: list, sources: list, src: Path, lib: Path, what: str,
             budget: _Budget, objdir: Optional[Path] = None, target: str = "") -> list:
    """Compile each source to an object file in parallel, then link ``lib``.

    Equivalent to one ``cc ... -o lib *.c`` call (the command of the README),
    but the generated model.c -- the longest file by far for a manipulator --
    compiles while the runtime files do.  The runtime's objects depend only
    on the runtime's files, the compiler and the flags: they are compiled
    once and kept in :func:`object_cache_dir` (2.4 s of CPU of every build
    before), so a build compiles model.c alone.  ``cc`` is a compiler name or a
    :class:`~fmugen.fmi.platforms.Slice` (a cross compiler, its target flags),
    ``target`` the platform/architecture the cache keys on.  Returns the link command.
    """
    s = cc if isinstance(cc, Slice) else Slice("", (cc,), cc, (), ())
    flags = [*s.cflags, *(f for f in CFLAGS if f != "-shared" and (s.pic or f != "-fPIC")), *extra, "-I."]
    objs = [(objdir or src.parent / "obj") / (Path(c).stem + ".o") for c in sources]
    objs[0].parent.mkdir(parents=True, exist_ok=True)
    runtime = [i for i, c in enumerate(sources) if c != "model.c"]
    cache = object_cache_dir()
    cached = cache / _runtime_key(s.compiler, flags, src, [sources[i] for i in runtime], target) \
        if cache and runtime else None
    hit = cached is not None and all((cached / objs[i].name).is_file() for i in runtime)
    if hit:
        for i in runtime:
            objs[i] = cached / objs[i].name
    todo = [i for i in range(len(sources)) if not (hit and i in runtime)]
    # largest first, so the long model.c starts at once
    order = sorted(todo, key=lambda i: -(src / sources[i]).stat().st_size)
    jobs = [[*s.cc, *flags, "-c", sources[i], "-o", str(objs[i])] for i in order]
    _run_jobs(jobs, src, what, budget, "compile")
    if cached is not None and not hit:
        _store_objects(cached, [objs[i] for i in runtime])
    workdir = objdir or src.parent / "obj"  # never the cache folder the runtime's objects may come from
    link = [*s.cc, *s.cflags, "-shared", *extra, "-o", str(lib), *map(str, objs), "-lm", *link_flags(s, workdir)]
    _run_jobs([link], src, what, budget, "link")
    return link


def _store_objects(target: Path, objs: list) -> None:
    """Put freshly compiled runtime objects into the cache: a complete folder appears by one
    rename (builds running in parallel never see half of it); a cache that cannot be
    written is no error.  Shielded: a signal meanwhile leaves no half folder behind."""
    with _shielded():
        _store(target, objs)


def _store(target: Path, objs: list) -> None:
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".part-", dir=target.parent))
        for o in objs:
            shutil.copy2(o, tmp / o.name)
        try:
            os.rename(tmp, target)
        except OSError:  # another build stored them first
            shutil.rmtree(tmp, ignore_errors=True)
    except OSError:
        pass


def build_fmu(
    model: SymbolicModel,
    output_path: Union[str, os.PathLike],
    fmi_type: str = "both",
    fold_parameters: Union[None, str, Sequence[str]] = None,
    cc: str = "cc",
    extra_cflags: Sequence[str] = (),
    keep_sources: bool = True,
    model_identifier: Optional[str] = None,
    default_experiment: Optional[dict] = None,
    runtime_start: Optional[dict] = None,
    budget_seconds: Optional[float] = None,
    budget_memory: Optional[float] = None,
    progress: Optional[bool] = None,
    budget_start: Optional[float] = None,
    platforms: Optional[Sequence[str]] = None,
    fmi_version: int = 2,
    terminals: Optional[Sequence] = None,
) -> BuildResult:
    """Generate, compile and zip ``model`` into an FMI 2.0 FMU (FMI 3.0 with ``fmi_version=3``).

    Parameters:
        model            the symbolic model (states, inputs, parameters, outputs)
        output_path      the .fmu file, or an existing directory to put
                         ``<modelIdentifier>.fmu`` in
        fmi_type         "me", "cs" or "both" (one binary serves both)
        fold_parameters  None (all parameters settable), "all", or names of
                         parameters to replace by their values
        cc, extra_cflags the C compiler and flags appended to
                         ``-O2 -fPIC -shared -Wall -Wextra -std=c99``
        keep_sources     put ``sources/`` into the FMU
        model_identifier defaults to a C identifier made from the model name
        default_experiment  optional {startTime, stopTime, stepSize, tolerance}
        runtime_start    start values of solver.method, solver.rtol, solver.atol,
                         solver.max_step, solver.fixed_step (in the XML and the
                         binary's defaults alike), e.g. a scene's RODAS3 at 1e-10
        budget_seconds   stop with :class:`BuildBudgetExceeded` when the build
                         (generate, compile, zip) takes longer (wall clock, s)
        budget_memory    ... or when it holds more memory (bytes: this process
                         plus the compilers it runs)
        progress         one line per stage on stderr; None: only when stderr
                         is a terminal
        budget_start     time.perf_counter() at which the time budget began
                         (default: this call), e.g. before deriving the model
        platforms        FMI 2.0 platform folders to build binaries for, e.g.
                         ["linux64", "win64", "darwin64"] (None: this machine's
                         only); cross compilers as fmugen/fmi/platforms.py
                         finds them, a missing one refused (PlatformError) before
                         anything is generated; ``cc`` compiles the host's binary,
                         ``extra_cflags`` go to every compiler
        fmi_version      2 (default) or 3: an FMI 3.0 FMU of the same runtime
                         (c_runtime/fmi3/fmi3_functions.c) for this machine
                         (x86_64-linux) only, scalar variables; see
                         fmugen/fmi/README.md "FMI 3.0"
        terminals        FMI 3.0 only: the :class:`fmugen.fmi.terminals.Terminal`
                         list of terminalsAndIcons/terminalsAndIcons.xml (none:
                         no file); None: a robot model's joints
                         (:func:`~fmugen.fmi.terminals.joint_terminals`; a model
                         without joints has none)

    Temporary files are removed on every way out, including SIGINT and
    SIGTERM (raised as :class:`BuildInterrupted` while the build runs); the
    .fmu appears only when complete.

    Returns a :class:`BuildResult` with the path, GUID, operation counts and
    timings.  Raises :class:`BuildError` (compiler command and its stderr in
    the message) when compilation fails.
    """
    types = _fmi_types(fmi_type)
    _check_fmi_version(fmi_version, platforms)
    if terminals and fmi_version != 3:
        raise FmugenError("terminals: FMI 2.0 has no terminals (terminalsAndIcons.xml is FMI 3.0's); "
                          "give fmi_version=3 or no terminals")
    t0 = time.perf_counter()
    budget = _Budget(budget_seconds, budget_memory, t0 if budget_start is None else budget_start)
    with _terminate_as_exception():
        return _build(model, output_path, types, fold_parameters, cc, extra_cflags, keep_sources,
                      model_identifier, default_experiment, budget, _Progress(progress, model.name), t0,
                      runtime_start, platforms, fmi_version, terminals)


#: FMI 3.0 files of the runtime (c_runtime/fmi3/), copied into sources/ beside the FMI 2.0 ones
FMI3_RUNTIME = ("fmi3_functions.c", "fmi3_exports.map")
FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
#: the FMI 3.0 binaries folder of the one host fmi_version=3 builds for
FMI3_HOST = ("linux64", "x86_64-linux")


#: the FMI 3.0 build's define that leaves the runtime's fmi2* functions (its internals) unexported
FMI3_HIDE_FMI2 = "-DFMI2_Export="
_FMI2_EXPORT_BLOCK = "#if defined _WIN32 || defined __CYGWIN__\n    /* Note: both gcc & MSVC on Windows support this syntax. */"


def fmi2_header_for_fmi3(text: str) -> str:
    """fmi2Functions.h for an FMI 3.0 FMU's sources: its FMI2_Export definition made conditional, as in the
    FMI standard's own header (fmpy's copy defines it always), so that ``-DFMI2_Export=`` keeps the runtime's
    fmi2* functions out of the binary's exports on every platform -- Windows' dllexport and zig's Mach-O
    linker, which ignores exported-symbols lists, included."""
    start = text.find(_FMI2_EXPORT_BLOCK)
    end = text.find("#endif", text.find("#endif", start) + 1) if start >= 0 else -1
    if start < 0 or end < 0 or "FMI2_Export" not in text[start:end]:
        raise BuildError("fmi2Functions.h of this fmpy has no FMI2_Export block fmugen knows: the FMI 3.0 build "
                         "cannot keep the fmi2* functions unexported")
    end += len("#endif")
    return (text[:start] + "#if !defined(FMI2_Export) /* fmugen: -DFMI2_Export= in FMI 3.0 FMUs */\n"
            + text[start:end] + "\n#endif" + text[end:])


def _check_fmi_version(fmi_version, platforms) -> None:
    """fmi_version 2 or 3; FMI 3.0 built on x86_64 Linux (its host binary linked by GNU ld's version script)."""
    if fmi_version not in (2, 3) or isinstance(fmi_version, bool):
        raise FmugenError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    if fmi_version == 3:
        import platform as platform_module

        from .platforms import host_platform, parse_platforms

        host = host_platform()
        if host != FMI3_HOST[0] or platform_module.machine() not in ("x86_64", "AMD64"):
            raise FmugenError(f"fmi_version 3: FMI 3.0 FMUs are built on x86_64 Linux only so far (this machine: "
                              f"{host} {platform_module.machine()})")
        parse_platforms(platforms, "platforms", 3)  # the names FMI 3.0 builds


def _build(model, output_path, types, fold_parameters, cc, extra_cflags, keep_sources, model_identifier,
           default_experiment, budget: _Budget, progress: _Progress, t0: float,
           runtime_start: Optional[dict] = None, platforms: Optional[Sequence[str]] = None,
           fmi_version: int = 2, terminals: Optional[Sequence] = None) -> BuildResult:
    _check_cancelled()
    progress.start("generate", f"{model.nx} states")
    model = _fold(model, fold_parameters)
    ident = model_identifier or c_identifier(model.name)
    _check_identifier(ident, model.name, model_identifier is not None)
    # a missing cross compiler: refused before any work
    targets = resolve(platforms, cc, "platforms", ident, fmi_version)
    rt, fmi_h = runtime_dir(), fmi_headers_dir()
    suffix = targets[0].suffix

    runtime_c = sorted(p.name for p in rt.glob("*.c"))
    runtime_h = sorted(p.name for p in rt.glob("*.h"))
    if "model.c" in runtime_c:
        raise BuildError(f"{rt}/model.c exists: the runtime must not contain a generated model")
    sources = runtime_c + ["model.c"]
    if fmi_version == 3:  # the binaries export the fmi3* functions only (the fmi2* ones are its internals)
        sources = runtime_c + [FMI3_RUNTIME[0], "model.c"]

    # generate with a placeholder GUID, hash C and XML together, substitute
    gen = generate_c(model, model_identifier=ident, guid=GUID_PLACEHOLDER, runtime_start=runtime_start)
    if fmi_version == 3:
        from .model_description3 import model_description3_xml

        xml = model_description3_xml(model, GUID_PLACEHOLDER, ident, types, default_experiment=default_experiment,
                                      runtime_start=runtime_start)
        from .terminals import TERMINALS_PATH, check_terminals, joint_terminals, terminals_xml

        # checked against the model before anything is compiled: every member an input or output of it
        terminals = joint_terminals(model) if terminals is None else check_terminals(terminals, model)
        extras = {TERMINALS_PATH: terminals_xml(terminals)} if terminals else {}
    else:
        xml = model_description_xml(model, GUID_PLACEHOLDER, ident, types, sources if keep_sources else (),
                                    default_experiment=default_experiment, runtime_start=runtime_start)
        extras = {}  # files beside modelDescription.xml: FMI 3.0's terminalsAndIcons/
    guid = deterministic_guid(gen.source, xml)
    c_src, xml = gen.source.replace(GUID_PLACEHOLDER, guid), xml.replace(GUID_PLACEHOLDER, guid)
    t_gen = time.perf_counter() - t0
    progress.done()
    budget.check("generate")

    out = Path(output_path)
    if out.is_dir():
        out = out / f"{ident}.fmu"

    with _temporary_folder(f"fmugen_{ident}_") as root:
        src = root / "sources"
        src.mkdir()
        for name in runtime_c + runtime_h:
            shutil.copy2(rt / name, src / name)
        for name in FMI_HEADERS:
            shutil.copy2(fmi_h / name, src / name)
        if fmi_version == 3:
            for name in FMI3_RUNTIME:
                shutil.copy2(rt / "fmi3" / name, src / name)
            for name in FMI3_HEADERS:
                shutil.copy2(fmi_h / name, src / name)
            (src / FMI_HEADERS[0]).write_text(fmi2_header_for_fmi3((fmi_h / FMI_HEADERS[0]).read_text()))
            extra_cflags = [*extra_cflags, FMI3_HIDE_FMI2]
        (src / "model.c").write_text(c_src)
        (root / "modelDescription.xml").write_text(xml, encoding="utf-8")
        for name, text in extras.items():
            (root / name).parent.mkdir(parents=True, exist_ok=True)
            (root / name).write_text(text, encoding="utf-8")

        t1 = time.perf_counter()
        libs, commands = [], {}
        for target in targets:
            lib = _compile_target(target, cc, list(extra_cflags), sources, src, root, ident, model.name,
                                  budget, progress, f"model.c {c_src.count(chr(10))} lines, {len(sources)} files",
                                  commands)
            libs.append(lib)
        cmd = commands[next(iter(commands))]
        t_cc = time.perf_counter() - t1
        portable = shlex.join(["cc" if not targets[0].host else cc, *CFLAGS, "-I.", "-o", f"{ident}.so",
                               *sources, "-lm"])
        (src / "README.txt").write_text(
            f"Sources of the FMU {ident} ({model.name}), generated by fmugen {__version__}.\n"
            f"model.c holds the model (generated); the other .c/.h files are the generic fmugen FMI 2.0\n"
            f"runtime and the FMI 2.0 standard headers.  Compile all .c files into one shared library\n"
            f"named after the modelIdentifier, e.g. on Linux:\n\n    {portable}\n\n"
            + sources_readme(ident, sources, CFLAGS) +
            f"\nand place it in binaries/<platform>/ (linux64, darwin64, win64).\n")
        if fmi_version == 3:
            (src / "README.txt").write_text(
                f"Sources of the FMI 3.0 FMU {ident} ({model.name}), generated by fmugen {__version__}.\n"
                f"model.c holds the model (generated); fmi3_functions.c is the FMI 3.0 interface over the\n"
                f"generic fmugen runtime (the other .c/.h files), with the FMI 2.0 and 3.0 standard headers.\n"
                f"Compile all .c files into one shared library named after the modelIdentifier, exporting\n"
                f"only the fmi3* functions ({FMI3_HIDE_FMI2} keeps the runtime's fmi2* functions unexported),\n"
                f"e.g. on Linux:\n\n    "
                f"{shlex.join(['cc', *CFLAGS, FMI3_HIDE_FMI2, '-I.', '-Wl,--version-script=' + FMI3_RUNTIME[1], '-o', ident + '.so', *sources, '-lm'])}"
                f"\n\n" + sources_readme(ident, sources, (*CFLAGS, FMI3_HIDE_FMI2)) +
                f"\nand place it in binaries/<architecture>-<system>/ (x86_64-linux, x86_64-windows,\n"
                f"x86_64-darwin, aarch64-darwin, aarch64-linux).\n")
            from .model_description3 import build_description3_xml

            (src / "buildDescription.xml").write_text(build_description3_xml(ident, sources), encoding="utf-8")

        t2 = time.perf_counter()
        out.parent.mkdir(parents=True, exist_ok=True)  # only now: a failed compile leaves no empty folder
        files = [root / "modelDescription.xml", *(root / name for name in extras), *libs]
        if keep_sources:
            files += sorted(src.iterdir())
        # a name of its own: never a user's file (an existing "x.fmu.part" stays as it was)
        tmp_zip = None
        try:
            with _shielded():  # made and named as one step: a signal in between left it behind
                fd, tmp_name = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent)
                os.close(fd)
                tmp_zip = Path(tmp_name)
            with zipfile.ZipFile(tmp_zip, "w", zipfile.ZIP_DEFLATED) as zf:
                for f in files:
                    info = zipfile.ZipInfo(f.relative_to(root).as_posix(), date_time=_ZIP_DATE)
                    info.compress_type = zipfile.ZIP_DEFLATED
                    info.external_attr = (0o755 if f in libs else 0o644) << 16
                    zf.writestr(info, f.read_bytes())
            budget.check("zip")
            os.replace(tmp_zip, out)
        finally:
            if tmp_zip is not None:
                with _shielded():
                    tmp_zip.unlink(missing_ok=True)
        t_zip = time.perf_counter() - t2

    return BuildResult(path=out, model_identifier=ident, guid=guid, op_counts=gen.op_counts,
                       timings={"generate": t_gen, "compile": t_cc, "zip": t_zip},
                       command=shlex.join(cmd), platforms=tuple(t.name for t in targets),
                       commands={k: shlex.join(v) for k, v in commands.items()})


def _compile_target(target: Target, cc: str, extra: list, sources: list, src: Path, root: Path, ident: str,
                    what: str, budget: _Budget, progress: _Progress, detail: str, commands: dict) -> Path:
    """binaries/<platform>/<ident><suffix> of one platform: each slice compiled and linked (the host's
    by ``cc``), several slices joined into one universal Mach-O.  Records each link command."""
    bindir = root / "binaries" / target.name
    bindir.mkdir(parents=True)
    lib = bindir / f"{ident}{target.suffix}"
    thin = {}
    for s in target.slices:
        key = f"{target.name}/{s.arch}"
        progress.start("compile", detail if target.host else f"{key}, {detail}")
        objdir = root / "obj" / f"{target.name}-{s.arch}"
        out = lib if len(target.slices) == 1 else objdir / lib.name
        commands[key] = _compile(s, extra, sources, src, out, what, budget, objdir,
                                 "" if target.host else key)
        thin[s.arch] = out
        progress.done()
    if len(target.slices) > 1:
        universal_binary(thin, lib)
    return lib
