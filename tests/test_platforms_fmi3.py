"""FMI 3.0 FMUs for every platform folder fmugen builds (``fmi_version=3`` with ``platforms``).

FMI 3.0 has one folder per architecture and system (``x86_64-windows``, ``x86_64-darwin``,
``aarch64-darwin``, ``aarch64-linux``, ``x86_64-linux``), each a thin library exporting the fmi3*
functions only:

* x86_64-windows: objdump's import table lists Windows system DLLs only, its export table exactly
  the functions fmi3Functions.h marks FMI3_Export (not the runtime's fmi2* internals, which fmpy's
  fmi2Functions.h marks dllexport); run under wine by tests/tools/fmu3_driver.c it gives the
  x86_64-linux library's results (the same driver, dlopen) to 1e-12;
* x86_64-darwin, aarch64-darwin: thin Mach-O dylibs of their CPU, libSystem the only library,
  _fmi3* the only exports;
* aarch64-linux: an AArch64 ELF whose dynamic symbols are the fmi3* functions, needing glibc 2.17.

The model is the bouncing ball (state events): small, so that five cross builds stay cheap.
"""
from __future__ import annotations

import re
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fmugen.components.equations import load_component
from fmugen.fmi import platforms as plat
from fmugen.fmi.build import build_fmu, fmi_headers_dir
from test_platforms import (CC, MINGW, MINGW_OBJDUMP, WINE, ZIG, _assert_same, _macho, _run, _vrs, need_mingw,
                            need_wine, need_zig)

ROOT = Path(__file__).resolve().parents[1]
DRIVER3 = ROOT / "tests" / "tools" / "fmu3_driver.c"
BALL = ROOT / "examples" / "components" / "bouncing_ball.toml"

pytestmark = pytest.mark.skipif(CC is None or plat.host_tuple() != "x86_64-linux",
                                reason="FMI 3.0 FMUs are built on x86_64 Linux")


def _folders() -> list:
    return (["x86_64-linux"] + (["x86_64-windows"] if MINGW else [])
            + (["x86_64-darwin", "aarch64-darwin", "aarch64-linux"] if ZIG else []))


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmi3_platforms")
    res = build_fmu(load_component(BALL), d / "ball.fmu", fmi_version=3, platforms=_folders())
    unzip = d / "unzipped"
    zipfile.ZipFile(res.path).extractall(unzip)
    return res, unzip


def _fmi3_functions() -> set:
    text = (fmi_headers_dir() / "fmi3Functions.h").read_text()
    return set(re.findall(r"FMI3_Export\s+fmi3\w+TYPE\s+(fmi3\w+)\s*;", text))


def test_every_folder_holds_its_library(ball):
    res, unzip = ball
    assert res.platforms == tuple(_folders())
    suffix = {"linux": ".so", "windows": ".dll", "darwin": ".dylib"}
    for folder in _folders():
        assert (unzip / "binaries" / folder / f"bouncing_ball{suffix[folder.split('-')[1]]}").is_file(), folder
    assert sorted(p.name for p in (unzip / "binaries").iterdir()) == sorted(_folders())


@need_mingw
@pytest.mark.skipif(MINGW_OBJDUMP is None, reason="no x86_64-w64-mingw32-objdump (binutils-mingw-w64-x86-64)")
def test_windows_dll_imports_system_dlls_and_exports_fmi3_only(ball):
    _, unzip = ball
    text = subprocess.run([MINGW_OBJDUMP, "-p", str(unzip / "binaries" / "x86_64-windows" / "bouncing_ball.dll")],
                          capture_output=True, text=True, check=True).stdout
    dlls = {d.lower() for d in re.findall(r"DLL Name: (\S+)", text)}
    assert dlls == {"kernel32.dll", "msvcrt.dll"}, dlls
    table = text.split("[Ordinal/Name Pointer] Table", 1)[1].split("\n\n", 1)[0]
    exports = set(re.findall(r"\[\s*\d+\]\s+(\S+)", table))
    assert exports == _fmi3_functions() and len(exports) > 70


def _driver3(tmp: Path, windows: bool) -> Path:
    exe = tmp / ("fmu3_driver.exe" if windows else "fmu3_driver")
    cc = [MINGW, "-static-libgcc"] if windows else [CC]
    libs = [] if windows else ["-ldl", "-Wl,--no-as-needed", "-lm"]
    r = subprocess.run([*cc, "-O2", "-Wall", "-Wextra", "-std=c99", f"-I{fmi_headers_dir()}", "-o", str(exe),
                        str(DRIVER3), *libs], capture_output=True, text=True)
    assert r.returncode == 0 and not r.stderr, r.stderr
    return exe


@need_mingw
@need_wine
def test_windows_dll_under_wine_gives_the_linux_results(ball, tmp_path):
    res, unzip = ball
    md, out = _vrs(unzip)
    names = sorted(out)
    vrs = [out[n] for n in names]
    linux = _run(_driver3(tmp_path, False), unzip / "binaries" / "x86_64-linux" / "bouncing_ball.so", md.guid,
                 vrs, {})
    win = _run(_driver3(tmp_path, True), unzip / "binaries" / "x86_64-windows" / "bouncing_ball.dll", md.guid,
               vrs, {})
    assert _assert_same(linux, win) <= 1e-12
    h = linux[:, 1 + names.index("h")]
    assert h.min() >= -1e-9 and np.any(np.diff(np.sign(np.diff(h))) > 0)  # it fell, bounced and rose


@need_zig
def test_macos_dylibs_are_thin_and_export_fmi3_only(ball):
    _, unzip = ball
    fmi3 = {"_" + f for f in _fmi3_functions()}
    for folder, cpu, minos in (("x86_64-darwin", "x86_64", 10), ("aarch64-darwin", "arm64", 11)):
        m = _macho((unzip / "binaries" / folder / "bouncing_ball.dylib").read_bytes())
        assert m["cpu"] == cpu and m["filetype"] == 6, folder  # MH_DYLIB
        assert m["id"] == ["@rpath/bouncing_ball.dylib"] and m["links"] == ["/usr/lib/libSystem.B.dylib"]
        assert m["exports"] - {"__mh_dylib_header", "___dso_handle"} == fmi3, folder
        assert m["minos"] == minos


@need_zig
def test_aarch64_linux_library_exports_fmi3_only(ball):
    _, unzip = ball
    lib = unzip / "binaries" / "aarch64-linux" / "bouncing_ball.so"
    head = lib.read_bytes()[:20]
    assert head[:4] == b"\x7fELF" and head[4] == 2 and int.from_bytes(head[18:20], "little") == 183  # EM_AARCH64
    text = subprocess.run(["readelf", "--dyn-syms", "-W", str(lib)], capture_output=True, text=True,
                          check=True).stdout
    rows = [ln.split() for ln in text.splitlines() if re.match(r"\s*\d+:", ln)]
    defined = {r[7] for r in rows if len(r) >= 8 and r[4] == "GLOBAL" and r[6] != "UND"}
    assert defined == _fmi3_functions()
    needed = {v for r in rows if len(r) >= 8 and r[6] == "UND" for v in re.findall(r"@(GLIBC_[\d.]+)", r[7])}
    assert needed and max(tuple(map(int, v[6:].split("."))) for v in needed) <= (2, 17), needed


def test_fmi3_platform_names_are_checked():
    assert plat.parse_platforms("linux64,darwin64", "here", 3) == ("x86_64-linux", "x86_64-darwin",
                                                                   "aarch64-darwin")
    assert plat.parse_platforms(["aarch64-linux"], "here", 3) == ("aarch64-linux",)
    with pytest.raises(plat.PlatformError, match="platform 'win32' is not one fmugen builds as FMI 3.0"):
        plat.parse_platforms("win32", "here", 3)
    with pytest.raises(plat.PlatformError, match="lists aarch64-darwin more than once"):
        plat.parse_platforms("darwin64,aarch64-darwin", "here", 3)
    with pytest.raises(plat.PlatformError, match="no folder for Linux on aarch64"):  # FMI 2.0 has none
        plat.parse_platforms("aarch64-linux", "here")
