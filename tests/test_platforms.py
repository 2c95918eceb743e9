"""FMUs for Windows and macOS built on Linux (fmugen/fmi/platforms.py), checked as their loaders see them.

* win64: the DLL run under wine by tests/tools/fmu_driver.c compiled for
  Windows gives the linux64 library's results (the same driver, dlopen) to
  1e-12 on a 2 s PUMA run and on a scene FMU; objdump's import table lists
  Windows system DLLs only, its export table exactly the functions
  fmi2Functions.h marks FMI2_Export.
* darwin64: a universal Mach-O read here (fat header, load commands, symbol
  table -- mach-o/loader.h, mach-o/fat.h): an x86_64 and an arm64 dylib,
  LC_ID_DYLIB, libSystem the only library, _fmi2* the only exports; llvm-lipo,
  where installed, reads the fat file fmugen wrote the same way.
* sources/: rebuilt by fmpy's own route (CMake) and by the README's plain cc,
  the rebuilt library gives the shipped one's results to 1e-12.

A missing toolchain skips its tests with the way to install it (.ci/run installs them).
"""
from __future__ import annotations

import os
import re
import shutil
import struct
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fmugen.errors import FmugenError
from fmugen.fmi import platforms as plat
from fmugen.fmi.build import build_fmu, fmi_headers_dir

ROOT = Path(__file__).resolve().parents[1]
DRIVER = ROOT / "tests" / "tools" / "fmu_driver.c"
MINGW = shutil.which(plat.MINGW)
MINGW_OBJDUMP = shutil.which("x86_64-w64-mingw32-objdump")
WINE = shutil.which("wine64") or shutil.which("wine")
ZIG = plat._zig()
CC = shutil.which("cc") or shutil.which("gcc")

need_mingw = pytest.mark.skipif(MINGW is None, reason=f"no {plat.MINGW}: {plat.INSTALL['win64']}")
need_wine = pytest.mark.skipif(WINE is None, reason="no wine: apt-get install wine64 (or wine)")
need_zig = pytest.mark.skipif(ZIG is None, reason=f"no zig: {plat.INSTALL['darwin64']}")
pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler")

STOP, STEP = 2.0, 0.01
TAU = (1.0, 2.0, 0.5, 0.1, 0.1, 0.05)  # N m on the six joints


def _available() -> list:
    return ["linux64"] + (["win64"] if MINGW else []) + (["darwin64"] if ZIG else [])


def _fmi2_functions() -> set:
    """The functions fmi2Functions.h declares with FMI2_Export (the FMI 2.0 standard header)."""
    text = (fmi_headers_dir() / "fmi2Functions.h").read_text()
    return set(re.findall(r"FMI2_Export\s+fmi2\w+TYPE\s+(fmi2\w+)\s*;", text))


@pytest.fixture(scope="module")
def puma(tmp_path_factory):
    import fmugen

    arm = fmugen.load_robot(ROOT / "robots" / "puma_thesis_com.toml")
    model = arm.state_space_model(outputs=("p_ee",))
    res = build_fmu(model, tmp_path_factory.mktemp("puma") / "puma.fmu", fmi_type="cs", platforms=_available())
    unzip = res.path.parent / "unzipped"
    with zipfile.ZipFile(res.path) as z:
        z.extractall(unzip)
    return res, unzip


@pytest.fixture(scope="module")
def scene_fmus(tmp_path_factory):
    """examples/scenes/single_joint_split.toml with ``platforms`` in its [scene] table (darwin64 left to the
    PUMA: its two slices are the slowest compile)."""
    from fmugen.scene import load_scene

    d = tmp_path_factory.mktemp("scene")
    text = (ROOT / "examples" / "scenes" / "single_joint_split.toml").read_text()
    names = ", ".join(f'"{p}"' for p in _available() if p != "darwin64")
    f = d / "split.toml"
    f.write_text(text.replace("[scene]\n", f"[scene]\nplatforms = [{names}]\n", 1))
    built = load_scene(f).build(d / "out", use_cache=False)
    return {g: r.path for g, r in built.fmus.items()}


def _driver(tmp: Path, target: str) -> Path:
    """tests/tools/fmu_driver.c for linux64 (cc, dlopen) or win64 (MinGW, LoadLibrary)."""
    exe = tmp / ("fmu_driver.exe" if target == "win64" else "fmu_driver")
    if not exe.exists():
        cc = [MINGW, "-static-libgcc"] if target == "win64" else [CC]
        # libm in the importer, as in Python and the simulation tools: fmpy's CMake route links no -lm
        libs = [] if target == "win64" else ["-ldl", "-Wl,--no-as-needed", "-lm"]
        r = subprocess.run([*cc, "-O2", "-Wall", "-Wextra", "-std=c99", f"-I{fmi_headers_dir()}", "-o", str(exe),
                            str(DRIVER), *libs], capture_output=True, text=True)
        assert r.returncode == 0 and not r.stderr, r.stderr
    return exe


def _run(exe: Path, lib: Path, guid: str, outputs: list, sets: dict) -> np.ndarray:
    argv = [str(exe), str(lib), guid, repr(STOP), repr(STEP), ",".join(map(str, outputs)),
            *(f"{k}={v!r}" for k, v in sets.items())]
    env = dict(os.environ)
    if exe.suffix == ".exe":
        argv.insert(0, WINE)
        # one wine prefix for every run (making one takes ~15 s); its debug chatter off
        env.setdefault("WINEPREFIX", str(Path(os.environ.get("FMUGEN_CACHE") or Path.home() / ".cache" / "fmugen")
                                         / "wine"))
        env["WINEDEBUG"] = "-all"
    r = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return np.loadtxt(r.stdout.splitlines())


def _vrs(fmu, names=None, causality="output") -> list:
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    return md, {v.name: v.valueReference for v in md.modelVariables
                if v.causality == causality and (names is None or v.name in names)}


def _assert_same(a: np.ndarray, b: np.ndarray, tol=1e-12) -> float:
    assert a.shape == b.shape
    err = float(np.max(np.abs(a - b) / np.maximum(1.0, np.abs(a))))
    assert err <= tol, err
    return err


def _puma_run(puma, exe: Path, lib: Path) -> np.ndarray:
    res, unzip = puma
    md, out = _vrs(unzip)
    _, inp = _vrs(unzip, causality="input")
    sets = {inp[f"tau[{i + 1}]"]: t for i, t in enumerate(TAU)}
    return _run(exe, lib, md.guid, [out[n] for n in sorted(out)], sets)


def _linux_run(puma, tmp_path, lib=None) -> np.ndarray:
    res, unzip = puma
    return _puma_run(puma, _driver(tmp_path, "linux64"), lib or unzip / "binaries" / "linux64" / "puma_thesis_com.so")


# -- win64 ---------------------------------------------------------------------------------------

@need_mingw
@need_wine
def test_win64_dll_under_wine_gives_the_linux64_results(puma, tmp_path):
    res, unzip = puma
    linux = _linux_run(puma, tmp_path)
    win = _puma_run(puma, _driver(tmp_path, "win64"), unzip / "binaries" / "win64" / "puma_thesis_com.dll")
    assert linux.shape == (round(STOP / STEP) + 1, 1 + 15)
    assert np.max(np.abs(linux[-1, 1:] - linux[0, 1:])) > 0.1  # the arm moved: the comparison is not of zeros
    _assert_same(linux, win)


@need_mingw
@need_wine
def test_win64_scene_fmu_under_wine(scene_fmus, tmp_path):
    fmu = scene_fmus["joint"]
    d = tmp_path / "joint"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(d)
    md, out = _vrs(fmu)
    _, inp = _vrs(fmu, causality="input")
    sets = {vr: 2.0 for vr in inp.values()}  # a constant torque on the inertia
    vrs = [out[n] for n in sorted(out)]
    linux = _run(_driver(tmp_path, "linux64"), d / "binaries" / "linux64" / "joint.so", md.guid, vrs, sets)
    win = _run(_driver(tmp_path, "win64"), d / "binaries" / "win64" / "joint.dll", md.guid, vrs, sets)
    assert np.max(np.abs(linux[-1, 1:])) > 1e-3
    _assert_same(linux, win)


@need_mingw
@pytest.mark.skipif(MINGW_OBJDUMP is None, reason="no x86_64-w64-mingw32-objdump (binutils-mingw-w64-x86-64)")
def test_win64_dll_imports_system_dlls_and_exports_fmi2_only(puma):
    res, unzip = puma
    text = subprocess.run([MINGW_OBJDUMP, "-p", str(unzip / "binaries" / "win64" / "puma_thesis_com.dll")],
                          capture_output=True, text=True, check=True).stdout
    dlls = set(re.findall(r"DLL Name: (\S+)", text))
    assert dlls and all(d.lower() in ("kernel32.dll", "msvcrt.dll") or d.lower().startswith("api-ms-win-crt-")
                        for d in dlls), dlls
    table = text.split("[Ordinal/Name Pointer] Table", 1)[1].split("\n\n", 1)[0]
    exports = set(re.findall(r"\[\s*\d+\]\s+(\S+)", table))
    assert exports == _fmi2_functions()
    # the sources/README.txt MinGW command compiles the sources without a warning (-Wall -Wextra)
    cmd = (unzip / "sources" / "README.txt").read_text().split("\n\n")[3].strip()
    assert cmd.startswith("x86_64-w64-mingw32-gcc ") and "-Wall -Wextra" in cmd
    r = subprocess.run(cmd + " -fsyntax-only", shell=True, cwd=unzip / "sources", capture_output=True, text=True)
    assert r.returncode == 0 and not r.stderr, r.stderr[:2000]


# -- darwin64 ------------------------------------------------------------------------------------

LC_ID_DYLIB, LC_LOAD_DYLIB, LC_SYMTAB = 0xD, 0xC, 0x2
LC_BUILD_VERSION, LC_VERSION_MIN_MACOSX, LC_CODE_SIGNATURE = 0x32, 0x24, 0x1D
LINKS = {LC_LOAD_DYLIB, 0x80000018, 0x8000001F, 0x20, 0x80000023}  # load, weak, reexport, lazy, upward
CPU = {0x01000007: "x86_64", 0x0100000C: "arm64"}


def _macho(data: bytes) -> dict:
    """A thin 64-bit Mach-O: cpu, file type, ids and linked libraries, externally visible symbols."""
    magic, cpu, _, filetype, ncmds, _, _, _ = struct.unpack_from("<IiiIIIII", data, 0)
    assert magic == 0xFEEDFACF
    out = {"cpu": CPU.get(cpu, hex(cpu)), "filetype": filetype, "id": [], "links": [], "exports": set(),
           "minos": None, "signed": False}
    off = 32
    for _ in range(ncmds):
        cmd, size = struct.unpack_from("<II", data, off)
        if cmd == LC_BUILD_VERSION:  # platform, minos (X.Y.Z as 16.8.8 bits), sdk
            out["minos"] = struct.unpack_from("<I", data, off + 12)[0] >> 16
        elif cmd == LC_VERSION_MIN_MACOSX:
            out["minos"] = struct.unpack_from("<I", data, off + 8)[0] >> 16
        elif cmd == LC_CODE_SIGNATURE:
            out["signed"] = True
        elif cmd == LC_ID_DYLIB or cmd in LINKS:
            name_off = struct.unpack_from("<I", data, off + 8)[0]
            name = data[off + name_off:off + size].split(b"\0", 1)[0].decode()
            out["id" if cmd == LC_ID_DYLIB else "links"].append(name)
        elif cmd == LC_SYMTAB:
            symoff, nsyms, stroff, _ = struct.unpack_from("<IIII", data, off + 8)
            for k in range(nsyms):
                strx, ntype, _, _, _ = struct.unpack_from("<IBBHQ", data, symoff + 16 * k)
                # N_EXT, not N_PEXT, not a debug entry, defined (N_TYPE != N_UNDF)
                if ntype & 0x01 and not ntype & 0x10 and not ntype & 0xE0 and ntype & 0x0E:
                    out["exports"].add(data[stroff + strx:].split(b"\0", 1)[0].decode())
        off += size
    return out


def _fat(data: bytes) -> dict:
    magic, n = struct.unpack_from(">II", data, 0)
    assert magic == 0xCAFEBABE
    slices = {}
    for k in range(n):
        cpu, _, offset, size, align = struct.unpack_from(">iiIII", data, 8 + 20 * k)
        assert offset % (1 << align) == 0
        slices[CPU.get(cpu, hex(cpu))] = _macho(data[offset:offset + size])
    return slices


@need_zig
def test_darwin64_is_a_universal_dylib_exporting_fmi2_only(puma):
    res, unzip = puma
    lib = unzip / "binaries" / "darwin64" / "puma_thesis_com.dylib"
    slices = _fat(lib.read_bytes())
    assert sorted(slices) == ["arm64", "x86_64"]
    fmi2 = {"_" + f for f in _fmi2_functions()}
    for arch, m in slices.items():
        assert m["cpu"] == arch and m["filetype"] == 6  # MH_DYLIB
        assert m["id"] == ["@rpath/puma_thesis_com.dylib"]
        assert m["links"] == ["/usr/lib/libSystem.B.dylib"]
        # zig's linker also exports the Mach-O header's two linker-made symbols (no code)
        assert m["exports"] - {"__mh_dylib_header", "___dso_handle"} == fmi2, arch
        # loads on macOS 10.13 (Intel) and 11 (Apple silicon, the first), not only on the newest
        assert m["minos"] == {"x86_64": 10, "arm64": 11}[arch], (arch, m["minos"])
    assert slices["arm64"]["signed"]  # Apple silicon runs no unsigned code: the linker's ad-hoc signature
    lipo = shutil.which("llvm-lipo") or shutil.which("llvm-lipo-14")
    if lipo:  # an independent reader of the fat header fmugen wrote
        info = subprocess.run([lipo, "-info", str(lib)], capture_output=True, text=True, check=True).stdout
        assert "x86_64" in info and "arm64" in info


def test_universal_binary_layout(tmp_path):
    """The fat header of two thin files: big-endian, each slice at a 2^14 boundary, bytes kept."""
    a, b = tmp_path / "a", tmp_path / "b"
    a.write_bytes(b"A" * 100)
    b.write_bytes(b"B" * 5000)
    plat.universal_binary({"x86_64": a, "arm64": b}, tmp_path / "fat")
    data = (tmp_path / "fat").read_bytes()
    assert data[:8] == bytes.fromhex("cafebabe00000002")
    recs = [struct.unpack_from(">iiIII", data, 8 + 20 * k) for k in range(2)]
    assert recs == [(0x01000007, 3, 16384, 100, 14), (0x0100000C, 0, 32768, 5000, 14)]
    assert data[16384:16484] == b"A" * 100 and data[32768:] == b"B" * 5000


# -- sources/ ------------------------------------------------------------------------------------

def _rebuilt_by_fmpy(unzip: Path, tmp: Path) -> Path:
    from fmpy.build import build_platform_binary

    copy = tmp / "fmpy_build"
    shutil.copytree(unzip, copy)
    shutil.rmtree(copy / "binaries")
    (tmp / "cmake").mkdir()
    build_platform_binary(str(copy), build_dir=str(tmp / "cmake"))
    return next((copy / "binaries" / "linux64").glob("*.so"))


def _rebuilt_by_readme(unzip: Path, tmp: Path) -> Path:
    src = tmp / "readme_build"
    shutil.copytree(unzip / "sources", src)
    cmd = (src / "README.txt").read_text().split("\n\n")[1].strip()
    assert cmd.startswith("cc ")
    r = subprocess.run(cmd, shell=True, cwd=src, capture_output=True, text=True)
    assert r.returncode == 0 and not r.stderr, r.stderr  # warning-free, as shipped
    return next(src.glob("*.so"))


@pytest.mark.skipif(shutil.which("cmake") is None, reason="no cmake (fmpy's build_platform_binary needs it)")
def test_puma_sources_rebuilt_by_fmpy_and_by_the_readme(puma, tmp_path):
    res, unzip = puma
    shipped = _linux_run(puma, tmp_path)
    for lib in (_rebuilt_by_fmpy(unzip, tmp_path), _rebuilt_by_readme(unzip, tmp_path)):
        _assert_same(shipped, _linux_run(puma, tmp_path, lib))


@pytest.mark.skipif(shutil.which("cmake") is None, reason="no cmake (fmpy's build_platform_binary needs it)")
def test_scene_sources_rebuilt_by_fmpy_and_by_the_readme(scene_fmus, tmp_path):
    """Both FMUs carry the scene's platforms; the joint's sources (the chain's are the same runtime and a
    generated model.c as the PUMA's, three compiles more) rebuilt both ways."""
    exe = _driver(tmp_path, "linux64")
    for group, fmu in scene_fmus.items():
        if group != "joint":
            with zipfile.ZipFile(fmu) as z:
                assert sorted({n.split("/")[1] for n in z.namelist() if n.startswith("binaries/")}) == \
                    sorted(p for p in _available() if p != "darwin64")
            continue
        d = tmp_path / group
        with zipfile.ZipFile(fmu) as z:
            z.extractall(d / "fmu")
        assert sorted(p.name for p in (d / "fmu" / "binaries").iterdir()) == \
            sorted(p for p in _available() if p != "darwin64")
        md, out = _vrs(fmu)
        _, inp = _vrs(fmu, causality="input")
        sets = {vr: 0.5 for vr in inp.values()}
        vrs = [out[n] for n in sorted(out)]
        shipped = _run(exe, d / "fmu" / "binaries" / "linux64" / f"{group}.so", md.guid, vrs, sets)
        (d / "b").mkdir()
        for lib in (_rebuilt_by_fmpy(d / "fmu", d / "b"), _rebuilt_by_readme(d / "fmu", d / "b")):
            _assert_same(shipped, _run(exe, lib, md.guid, vrs, sets))


# -- refusals ------------------------------------------------------------------------------------

def test_missing_cross_compilers_are_refused_with_the_install_line(monkeypatch):
    monkeypatch.setattr(plat.shutil, "which", lambda name: None)
    with pytest.raises(FmugenError, match=r"^platforms: win64 needs the MinGW-w64 cross compiler "
                                          r"x86_64-w64-mingw32-gcc, not found on PATH; install MinGW-w64, "
                                          r"e.g. `apt-get install gcc-mingw-w64-x86-64`$"):
        plat.resolve(["linux64", "win64"])
    monkeypatch.setattr(plat, "_zig", lambda: None)
    with pytest.raises(FmugenError, match=r"darwin64 needs zig's C compiler .*`pip install ziglang`$"):
        plat.resolve(["darwin64"])


@pytest.mark.parametrize("value, message", [
    ("linux64,aarch64-linux", r"platform 'aarch64-linux' is not one fmugen builds \(FMI 2.0 has no folder for "
                              r"Linux on aarch64"),
    (["win32"], r"platform 'win32' is not one fmugen builds \(fmugen builds 64-bit binaries only\)"),
    ("win64,win64", r"platforms lists win64 more than once"),
    ("", r"platforms '' names an empty platform"),
    (3, r"platforms must be a list of names"),
])
def test_platform_names_are_checked(value, message):
    with pytest.raises(FmugenError, match=r"^here: " + message):
        plat.parse_platforms(value, "here")


def test_scene_platforms_key_is_checked(tmp_path):
    from fmugen.scene import SceneError, load_scene

    text = (ROOT / "examples" / "scenes" / "single_joint_split.toml").read_text()
    f = tmp_path / "bad.toml"
    f.write_text(text.replace("[scene]\n", '[scene]\nplatforms = ["linux64", "darwin-arm64"]\n', 1))
    with pytest.raises(SceneError, match=rf"^{re.escape(str(f))}: \[scene\]: platform 'darwin-arm64' is not one "
                                         rf"fmugen builds \(arm64 macOS is a slice of the universal binary"):
        load_scene(f)


def test_cli_refuses_platforms_given_twice_for_a_scene(capsys):
    from fmugen.cli import main

    scene = str(ROOT / "examples" / "scenes" / "single_joint_split.toml")
    assert main(["build", scene, "--platforms", "linux64", "--set", 'scene.platforms="linux64"']) == 2
    assert capsys.readouterr().err.strip().endswith(
        "--platforms and --set scene.platforms both given; give one")
