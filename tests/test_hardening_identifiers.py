"""Issue 19: user names are safe C identifiers in the GNU dialects too.

``-std=c99`` has no ``asm`` keyword and no ``linux`` macro; ``gcc``'s default
dialect (gnu17), ``-std=gnu89/gnu11`` and ``fmpy compile`` (CMake, no
``-std``) have both.  Parameters named like GNU keywords, C23 keywords and
the macros gcc predefines must build there as well: the generator prefixes
them (``asm`` -> ``v_asm``).  The coverage of the generator's list is checked
against what this machine's gcc predefines after the headers model.c
includes, in every dialect.
"""
import re
import shutil
import subprocess
import zipfile

import pytest
import sympy as sp

from fmugen.codegen.c_code import PREFIXED_NAMES, RESERVED_NAMES, _reserved, generate_c
from fmugen.codegen.model import SymbolicModel, Variable
from fmugen.fmi import build_fmu

NAMES = ["asm", "typeof", "linux", "unix", "i386", "__attribute__", "__asm__", "bool", "true", "false",
         "alignas", "constexpr", "nullptr", "EXIT_SUCCESS", "BIG_ENDIAN", "RAND_MAX", "HUGE", "errno", "NULL",
         "double", "inline", "restrict", "sun", "WIN32", "OBJC_NEW_PROPERTIES", "y1", "j0", "gamma", "main"]
DIALECTS = [None, "gnu89", "gnu99", "gnu11", "gnu17", "c99", "c11"]
HEADERS = "#include <math.h>\n#include <stddef.h>\n#include <string.h>\n#include <stdlib.h>\n"


def hostile_model():
    x = sp.Symbol("x", real=True)
    ps = [Variable(n, sp.Symbol(n, real=True), start=1.0 + k) for k, n in enumerate(NAMES)]
    return SymbolicModel.from_equations("linux", [Variable("x", x, start=0.0)], [], ps,
                                        [sum((k + 1) * p.symbol for k, p in enumerate(ps)) - x])


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")
def test_gcc_predefined_macros_are_all_kept_apart():
    """Every object-like macro without a leading underscore that gcc defines here in any dialect,
    after model.c's headers, is a name the generator prefixes."""
    seen = set()
    for std in DIALECTS:
        out = subprocess.run(["gcc", "-dM", "-E", "-"] + ([f"-std={std}"] if std else []), input=HEADERS,
                             capture_output=True, text=True, check=True).stdout
        for line in out.splitlines():
            m = re.match(r"#define ([A-Za-z][A-Za-z0-9_]*)(\s|$)", line)  # object-like only
            if m:
                seen.add(m.group(1))
    assert {"linux", "unix"} <= seen  # the GNU dialects' own
    missing = sorted(n for n in seen if not _reserved(n) and n not in RESERVED_NAMES)
    assert not missing, missing


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")
def test_model_c_with_gnu_names_compiles_in_every_dialect(tmp_path):
    gen = generate_c(hostile_model())
    src = tmp_path / "model.c"
    src.write_text(gen.source)
    for n in ("asm", "typeof", "linux", "unix", "i386", "bool", "EXIT_SUCCESS", "sun"):
        assert re.search(rf"const double v_{n} = p\[\d+\]; /\* {n} \*/", gen.source), n
    assert gen.model_identifier == "linux"  # a string literal and a file name, never an identifier in C
    from pathlib import Path

    runtime = Path(__file__).resolve().parents[1] / "c_runtime"
    for std in DIALECTS:
        cmd = ["gcc", "-fsyntax-only", "-Wall", "-Wextra", "-Werror", f"-I{runtime}", str(src)]
        if std:
            cmd.insert(1, f"-std={std}")
        r = subprocess.run(cmd, capture_output=True, text=True)
        assert r.returncode == 0, (std, r.stderr)


@pytest.mark.skipif(shutil.which("gcc") is None or shutil.which("cmake") is None, reason="gcc or cmake missing")
def test_fmu_sources_build_with_plain_gcc_and_fmpy_compile(tmp_path):
    """The FMU's sources/ with a plain ``gcc`` (default dialect), -std=gnu11, and fmpy's own rebuild
    (``fmpy compile``: CMake, no -std); the rebuilt binary then runs: x(t) = S (1 - exp(-t)) with
    S = sum k p_k.  Under -std=gnu89 the runtime says in one line that it is C99."""
    import fmpy
    from fmpy import simulate_fmu
    from fmpy.build import build_platform_binary

    fmu = build_fmu(hostile_model(), tmp_path / "gnu.fmu", fmi_type="cs").path
    unzip = tmp_path / "unzipped"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(unzip)
    src = unzip / "sources"
    cfiles = sorted(p.name for p in src.glob("*.c"))
    for std in (None, "gnu11"):
        cmd = ["gcc", "-fsyntax-only", "-I."] + ([f"-std={std}"] if std else []) + cfiles
        r = subprocess.run(cmd, cwd=src, capture_output=True, text=True)
        assert r.returncode == 0, (std, r.stderr[:2000])
    r = subprocess.run(["gcc", "-fsyntax-only", "-std=gnu89", "-I.", "fmi2_functions.c"], cwd=src,
                       capture_output=True, text=True)
    assert r.returncode != 0 and "fmugen's FMI runtime is C99" in r.stderr
    (unzip / "binaries").rename(tmp_path / "old_binaries")
    (tmp_path / "build").mkdir()
    build_platform_binary(str(unzip), build_dir=str(tmp_path / "build"))
    assert (unzip / "binaries" / fmpy.platform / f"linux{fmpy.sharedLibraryExtension}").is_file()
    S = sum((k + 1) * (1.0 + k) for k in range(len(NAMES)))
    res = simulate_fmu(str(unzip), fmi_type="CoSimulation", stop_time=1.0, output_interval=0.5, output=["x"])
    assert res["x"][-1] == pytest.approx(S * (1 - 2.718281828459045 ** -1), rel=1e-6)
    assert PREFIXED_NAMES >= {"asm", "typeof", "linux", "unix", "i386"}
