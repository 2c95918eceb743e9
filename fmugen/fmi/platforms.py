"""Binaries of an FMU for other platforms than the one it is built on.

FMI 2.0 names three 64-bit platform folders under ``binaries/``: ``linux64``,
``win64`` and ``darwin64`` (FMI 2.0.4, section 2.3, "binaries").  It has no
folder of its own for arm64 macOS: importers there look in ``darwin64`` (fmpy
names an arm64 Mac's platform so), hence a universal Mach-O in ``darwin64``
that holds an x86_64 and an arm64 slice, of which the loader picks its own.  Linux on aarch64
has no FMI 2.0 name either -- fmpy on such a machine looks in ``linux64``,
where the x86_64 library is -- so it is not offered (FMI 3.0 has
``aarch64-linux``).

The cross compilers are found, never installed:

    win64     MinGW-w64 (x86_64-w64-mingw32-gcc), the C runtime linked
              statically: the DLL imports KERNEL32.dll and msvcrt.dll only;
              what it exports is what fmi2Functions.h marks FMI2_Export
              (__declspec(dllexport)), i.e. the fmi2* functions
    darwin64  zig's C compiler (the ``ziglang`` wheel from PyPI, or a ``zig``
              on PATH), which carries the macOS libc headers and libSystem
              stubs: one slice per architecture, joined into a universal
              binary here (the fat header is a few words); exports limited to
              _fmi2* by -fvisibility=hidden (the exported-symbols list beside
              it is for Apple's ld64: zig's linker ignores it)

FMI 3.0 (section 2.5.1.4) names a folder ``<architecture>-<operating system>``
per binary, one architecture each: ``x86_64-linux``, ``x86_64-windows``,
``x86_64-darwin``, ``aarch64-darwin`` -- and ``aarch64-linux``, which zig's
compiler (``-target aarch64-linux-gnu``, glibc 2.17 and later) builds as cheaply
as the macOS slices.  ``fmi_version=3`` takes these names or the FMI 2.0 ones
(``darwin64`` is then both macOS folders) and exports the fmi3* functions only:
the runtime's fmi2* functions, the binary's internals, are compiled without
FMI2_Export (fmugen/fmi/build.py: ``fmi2_header_for_fmi3``), and on Linux a
version script exports fmi3* alone.

A platform whose compiler is missing is refused, before anything is
generated, in one line that names the compiler and how to install it.
"""
from __future__ import annotations

import shutil
import struct
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence, Union

from ..errors import FmugenError

#: the FMI 2.0 platform folders fmugen can build, in the order of the FMU's binaries/
PLATFORMS = ("linux64", "win64", "darwin64")
SUFFIX = {"linux64": ".so", "win64": ".dll", "darwin64": ".dylib"}
#: why a name that is not an FMI 2.0 folder is refused
NOT_FMI2 = {
    "linux-aarch64": "FMI 2.0 has no folder for Linux on aarch64 (fmpy there looks in linux64)",
    "aarch64-linux": "FMI 2.0 has no folder for Linux on aarch64 (fmpy there looks in linux64)",
    "darwin-arm64": "arm64 macOS is a slice of the universal binary in darwin64",
    "aarch64-darwin": "arm64 macOS is a slice of the universal binary in darwin64",
    "win32": "fmugen builds 64-bit binaries only",
    "linux32": "fmugen builds 64-bit binaries only",
    "darwin32": "fmugen builds 64-bit binaries only",
}

#: the FMI 3.0 folders of each name fmi_version=3 takes (FMI 2.0 names stand for theirs)
FMI3_FOLDERS = {"linux64": ("x86_64-linux",), "win64": ("x86_64-windows",),
                "darwin64": ("x86_64-darwin", "aarch64-darwin"),
                "x86_64-linux": ("x86_64-linux",), "x86_64-windows": ("x86_64-windows",),
                "x86_64-darwin": ("x86_64-darwin",), "aarch64-darwin": ("aarch64-darwin",),
                "aarch64-linux": ("aarch64-linux",)}
FMI3_SUFFIX = {"linux": ".so", "windows": ".dll", "darwin": ".dylib"}

MINGW = "x86_64-w64-mingw32-gcc"
INSTALL = {
    "win64": "install MinGW-w64, e.g. `apt-get install gcc-mingw-w64-x86-64`",
    "darwin64": "install zig's C compiler, e.g. `pip install ziglang`",
}
INSTALL["aarch64-linux"] = INSTALL["darwin64"]


class PlatformError(FmugenError):
    """A requested platform is unknown or its compiler is missing (one line, as every FmugenError)."""


@dataclass(frozen=True)
class Slice:
    """One compile-and-link of the sources: an architecture of a platform."""
    arch: str  # "x86_64", "arm64"
    cc: tuple  # the compiler's argv head, e.g. ("cc",) or ("/.../zig", "cc")
    compiler: str  # the executable whose identity keys the object cache (path, size, time)
    cflags: tuple  # target flags for every compile, before fmugen's CFLAGS
    ldflags: tuple  # target flags of the link (after -shared)
    pic: bool = True  # -fPIC (PE code is position-independent anyway, and MinGW would say so)
    exports: str = "fmi2"  # the prefix of the exported functions (Mach-O's exported-symbols list)


@dataclass(frozen=True)
class Target:
    """The binary of one FMI 2.0 platform folder: one slice, or several joined (darwin64)."""
    name: str
    suffix: str
    slices: tuple

    @property
    def host(self) -> bool:
        return self.name in (host_platform(), host_tuple())


def host_platform() -> str:
    """This machine's FMI 2.0 platform folder, as fmpy names it."""
    from fmpy import platform

    return platform


def host_tuple() -> str:
    """This machine's FMI 3.0 platform folder (``x86_64-linux`` ...)."""
    system = {"linux": "linux", "win32": "windows", "darwin": "darwin"}.get(sys.platform, sys.platform)
    return f"{_host_arch().replace('arm64', 'aarch64')}-{system}"


def parse_platforms(value: Union[None, str, Sequence[str]], where: str, fmi_version: int = 2) -> Optional[tuple]:
    """``"linux64,win64"`` or ``["linux64", "win64"]`` -> ``("linux64", "win64")``; None stays None
    (the host only).  Unknown names and duplicates are refused, naming ``where``.  With ``fmi_version``
    3 the FMI 3.0 folders those names stand for (``darwin64``: ``x86_64-darwin``, ``aarch64-darwin``)."""
    if value is None:
        return None
    if isinstance(value, str):
        items = [v.strip() for v in value.split(",")]
    elif isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        items = [v.strip() for v in value]
    else:
        raise PlatformError(f"{where}: platforms must be a list of names such as [\"linux64\", \"win64\"], "
                            f"got {value!r}")
    if not items or any(not v for v in items):
        raise PlatformError(f"{where}: platforms {value!r} names an empty platform; choose from "
                            f"{', '.join(PLATFORMS)}")
    if fmi_version == 3:
        for v in items:
            if v not in FMI3_FOLDERS:
                raise PlatformError(f"{where}: platform {v!r} is not one fmugen builds as FMI 3.0; choose from "
                                    f"{', '.join(FMI3_FOLDERS)}")
        items = [f for v in items for f in FMI3_FOLDERS[v]]
    for v in items:
        if v not in PLATFORMS and fmi_version != 3:
            why = NOT_FMI2.get(v.lower())
            raise PlatformError(f"{where}: platform {v!r} is not one fmugen builds"
                                f"{' (' + why + ')' if why else ''}; choose from {', '.join(PLATFORMS)}")
    twice = sorted({v for v in items if items.count(v) > 1})
    if twice:
        raise PlatformError(f"{where}: platforms lists {', '.join(twice)} more than once")
    return tuple(items)


def _zig() -> Optional[tuple]:
    """(argv head, executable) of zig's C compiler: the ziglang wheel's, else a zig on PATH."""
    try:
        import ziglang  # the PyPI wheel: the zig executable sits in the package folder
    except ImportError:
        ziglang = None
    if ziglang is not None:
        exe = Path(ziglang.__file__).resolve().parent / ("zig.exe" if sys.platform == "win32" else "zig")
        if exe.is_file():
            return (str(exe), "cc"), str(exe)
    exe = shutil.which("zig")
    return ((exe, "cc"), exe) if exe else None


def resolve(platforms: Optional[Sequence[str]], cc: str = "cc", where: str = "platforms",
            model_identifier: str = "model", fmi_version: int = 2) -> list:
    """The :class:`Target` of each requested platform (None: the host only), or a :class:`PlatformError`
    naming the first missing compiler.  The host platform is compiled by ``cc``."""
    if fmi_version == 3:
        return _resolve3(platforms, cc, where, model_identifier)
    host = host_platform()
    names = parse_platforms(platforms, where) or (host,)
    targets = []
    for name in names:
        if name == host:
            slices = (Slice(_host_arch(), (cc,), cc, (), ()),)
        elif name == "win64":
            slices = (_mingw_slice(name, where, "fmi2"),)
        elif name == "darwin64":
            slices = tuple(_macos_slice(arch, name, where, model_identifier, "fmi2") for arch in ("x86_64", "arm64"))
        else:  # linux64 from another host: not offered (a Linux machine builds it)
            raise PlatformError(f"{where}: {name} binaries are built on {name} itself (this machine is {host})")
        targets.append(Target(name, SUFFIX[name], slices))
    return targets


#: FMI 3.0 binaries export the fmi3* functions only; on Linux by this version script (sources/)
FMI3_VERSION_SCRIPT = "fmi3_exports.map"


def _resolve3(platforms, cc: str, where: str, model_identifier: str) -> list:
    """:func:`resolve` for FMI 3.0: one thin binary per ``<arch>-<os>`` folder."""
    host = host_tuple()
    names = parse_platforms(platforms, where, 3) or (host,)
    script = f"-Wl,--version-script={FMI3_VERSION_SCRIPT}"
    targets = []
    for name in names:
        arch, system = name.split("-", 1)
        if name == host:
            slices = (Slice(_host_arch(), (cc,), cc, (), (script,), exports="fmi3"),)
        elif name == "x86_64-windows":
            slices = (_mingw_slice(name, where, "fmi3"),)
        elif system == "darwin":
            slices = (_macos_slice(_macho_arch(arch), name, where, model_identifier, "fmi3"),)
        elif name == "aarch64-linux":  # glibc 2.17 (2012) and later: every aarch64 Linux distribution in use
            argv, exe = _zig_or_refuse(name, where)
            # -g0 and -s: zig's compiler writes DWARF, and links its compiler-rt with it (6x the library)
            slices = (Slice("arm64", argv, exe, ("-target", "aarch64-linux-gnu.2.17", "-g0"), (script, "-s"),
                            exports="fmi3"),)
        else:
            raise PlatformError(f"{where}: {name} binaries are built on {name} itself (this machine is {host})")
        targets.append(Target(name, FMI3_SUFFIX[system], slices))
    return targets


def _mingw_slice(name: str, where: str, exports: str) -> Slice:
    exe = shutil.which(MINGW)
    if exe is None:
        raise PlatformError(f"{where}: {name} needs the MinGW-w64 cross compiler {MINGW}, not found on PATH; "
                            f"{INSTALL['win64']}")
    # no timestamp in the PE header: the same inputs give the same DLL (and FMU)
    return Slice("x86_64", (exe,), exe, (), ("-static-libgcc", "-Wl,--no-insert-timestamp"), pic=False,
                 exports=exports)


def _zig_or_refuse(name: str, where: str) -> tuple:
    zig = _zig()
    if zig is None:
        raise PlatformError(f"{where}: {name} needs zig's C compiler (fmugen's cross compiler for macOS and "
                            f"aarch64 Linux), not found; {INSTALL['darwin64']}")
    return zig


#: the oldest macOS each architecture runs fmugen's binaries on (zig's default is its newest SDK, macOS 15,
#: which older dyld versions refuse): 10.13 on Intel, 11.0 (the first macOS on arm64) on Apple silicon
MACOS_TARGET = {"x86_64": "x86_64-macos.10.13", "arm64": "aarch64-macos.11.0"}


def _macos_slice(arch: str, name: str, where: str, model_identifier: str, exports: str) -> Slice:
    argv, exe = _zig_or_refuse(name, where)
    link = ("-Wl,-exported_symbols_list,{exports}", f"-Wl,-install_name,@rpath/{model_identifier}.dylib")
    return Slice(arch, argv, exe, ("-target", MACOS_TARGET[arch], "-fvisibility=hidden"), link, exports=exports)


def _macho_arch(arch: str) -> str:
    return "arm64" if arch == "aarch64" else arch


def _host_arch() -> str:
    import platform

    m = platform.machine().lower()
    return {"amd64": "x86_64", "aarch64": "arm64"}.get(m, m)


#: the exported-symbols list of the Mach-O link (ld64 syntax: a C name with its leading underscore)
EXPORTS_LIST = "_{prefix}*\n"

# Mach-O CPU types (mach/machine.h) and the alignment lipo gives each slice (2^14: arm64's page)
_CPU = {"x86_64": (0x01000007, 3), "arm64": (0x0100000C, 0)}
_FAT_MAGIC = 0xCAFEBABE
_ALIGN = 14


def universal_binary(slices: dict, out: Path) -> None:
    """Join thin Mach-O files ``{arch: path}`` into one universal (fat) file, as ``lipo -create`` does:
    a big-endian fat header, one fat_arch record (cputype, cpusubtype, offset, size, align) per slice,
    each slice at a 2^14-byte boundary (mach-o/fat.h)."""
    blobs = [(arch, Path(p).read_bytes()) for arch, p in slices.items()]
    header = struct.pack(">II", _FAT_MAGIC, len(blobs))
    offset = len(header) + 20 * len(blobs)
    records, body = [], b""
    for arch, data in blobs:
        start = -(-(offset + len(body)) // (1 << _ALIGN)) << _ALIGN
        body += b"\0" * (start - offset - len(body)) + data
        cpu, sub = _CPU[arch]
        records.append(struct.pack(">iiIII", cpu, sub, start, len(data), _ALIGN))
    out.write_bytes(header + b"".join(records) + body)


def link_flags(s: Slice, workdir: Path) -> list:
    """The slice's link flags, its exported-symbols list (Mach-O) written into ``workdir``."""
    out = []
    for f in s.ldflags:
        if "{exports}" in f:
            lst = workdir / f"{s.exports}_exports.txt"
            lst.write_text(EXPORTS_LIST.format(prefix=s.exports))
            f = f.replace("{exports}", str(lst))
        out.append(f)
    return out


def sources_readme(ident: str, sources: Sequence[str], cflags: Sequence[str]) -> str:
    """The Windows and macOS commands of ``sources/README.txt`` (the Linux one comes first there)."""
    files = " ".join(sources)
    win = " ".join(f for f in cflags if f != "-fPIC")
    unix = " ".join(cflags)  # with -shared: a dynamic library on macOS too
    msvc = "".join(f" /D{f[2:]}" for f in cflags if f.startswith("-D"))  # FMI 3.0's FMI2_Export= too
    return (f"On Windows with MinGW-w64 (the C runtime linked in, so that the DLL needs no MinGW DLLs):\n\n"
            f"    x86_64-w64-mingw32-gcc {win} -static-libgcc -I. -o {ident}.dll {files} -lm\n\n"
            f"(or MSVC: cl /O2 /LD{msvc} /Fe{ident}.dll *.c).  On macOS, both architectures in one file:\n\n"
            f"    cc {unix} -fvisibility=hidden -arch x86_64 -arch arm64 -I. -o {ident}.dylib {files}\n")
