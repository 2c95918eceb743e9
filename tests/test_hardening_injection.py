"""Issue 9, class 1 and 4: no user text becomes code.

A robot file whose descriptions, units and sources hold every trick that
rebuilds ``*/`` in the C preprocessor's early phases (backslash-newline,
the trigraph ``??/``), control characters, ``]]>``, quotes and non-ASCII
text, and whose parameters are named like the runtime's macros
(``FMUGEN_OK``), is built into an FMU.  The test then

* compiles every C file of the FMU's ``sources/`` with ``-Wall -Wextra
  -Werror -trigraphs`` (a payload that escaped its comment would not compile,
  and ``-Wcomment``/``-Wtrigraphs`` warnings become errors),
* checks that the generated ``model.c`` contains no character outside
  printable ASCII and that every comment closes where the generator closed it,
* checks with ``nm -D`` that the shared library exports only ``fmi2*``
  functions,
* parses modelDescription.xml with fmpy and finds the descriptions there,
  control characters replaced, everything else intact.
"""
import re
import shutil
import subprocess
import zipfile

import pytest
from fmpy import read_model_description

from fmugen import load_robot
from fmugen.codegen.c_code import _c_string, _comment_safe, generate_c
from fmugen.fmi import build_fmu
from fmugen.fmi.model_description import xml_text

# each of these, copied raw into a C comment, ends the comment early
PAYLOADS = [
    "*\\\n/ __attribute__((constructor)) static void pwn(void){ system(\"touch /tmp/pwned\"); } /*",
    "*??/\n/ int injected_by_trigraph = 1; /*",
    "*/ int injected_plain = 1; /*",
    "nul \u0000 soh \u0001 bell \u0007 esc \u001b",
    "]]> <![CDATA[ x ]]> & < > \" ' </ScalarVariable>",
    "unicode: \u00e9\u00df\u2028line separator\u00a0\U0001F600",
    "trailing backslash \\",
    "???/??=??(??)??!??<??>??-",
]


def toml_basic_string(s: str) -> str:
    """``s`` as a TOML basic string (every control character escaped)."""
    out = []
    for ch in s:
        if ch == '"' or ch == "\\":
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def hostile_robot(path):
    desc = " | ".join(PAYLOADS)
    lines = [
        "[robot]",
        'name = "hostile"',
        f"description = {toml_basic_string(desc)}",
        f"source = {toml_basic_string(PAYLOADS[0] + PAYLOADS[1])}",
        "gravity = [0, 0, -9.81]",
        "",
        "[parameters]",
    ]
    # names of the runtime's macros and identifiers: must still build
    for k, name in enumerate(["FMUGEN_OK", "FMUGEN_NOT_FINITE", "fmugen_model", "fmi2OK", "M_PI2", "evaluate"]):
        lines.append(f"{name} = {{ value = {1.0 + 0.1 * k}, unit = \"kg\", "
                     f"description = {toml_basic_string(PAYLOADS[k % len(PAYLOADS)])} }}")
    lines += [
        "",
        "[[links]]",
        'joint = "revolute"',
        'a = 0.3', 'alpha = 0', 'd = 0', 'theta = 0',
        'mass = "FMUGEN_OK + FMUGEN_NOT_FINITE + fmugen_model"',
        'com = [-0.15, 0, 0]',
        'inertia = [0.01, "0.01*fmi2OK", "0.01*M_PI2*evaluate"]',
    ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    d = tmp_path_factory.mktemp("hostile")
    arm = load_robot(hostile_robot(d / "hostile.toml"))
    model = arm.state_space_model(outputs=("p_ee",))
    res = build_fmu(model, d / "hostile.fmu", fmi_type="both")
    return model, res, d


def test_comment_text_cannot_close_a_comment():
    for p in PAYLOADS:
        s = _comment_safe(p)
        assert all(" " <= c <= "~" for c in s)
        assert "*/" not in s and "/*" not in s and "\\" not in s and "??" not in s
        # idempotent: cleaning twice changes nothing
        assert _comment_safe(s) == s
    assert _comment_safe("a*/b") == "a* /b"
    assert _comment_safe("???") == "?_?_?"


def test_c_string_literal_is_printable_ascii_and_round_trips(tmp_path):
    cases = PAYLOADS + ['quote " and backslash \\ and ?? and \\x41', "9\u00e9f"]
    prog = ['#include <stdio.h>', "int main(void) {"]
    for s in cases:
        lit = _c_string(s)
        assert all(" " <= c <= "~" for c in lit), lit
        prog.append(f"    fwrite({lit}, 1, sizeof({lit}) - 1, stdout); putchar(0xff);")
    prog += ["    return 0;", "}"]
    src = tmp_path / "lit.c"
    src.write_text("\n".join(prog) + "\n")
    exe = tmp_path / "lit"
    subprocess.run(["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-trigraphs", "-o", str(exe), str(src)],
                   check=True, capture_output=True, text=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True).stdout
    assert out.split(b"\xff")[:-1] == [s.encode("utf-8") for s in cases]


def test_generated_model_c_is_ascii_and_comments_close_where_opened(hostile):
    model, res, d = hostile
    src = generate_c(model).source
    assert all(c == "\n" or " " <= c <= "~" for c in src)
    assert "??" not in src and "\\\n" not in src
    assert "injected" not in re.sub(r"/\*.*?\*/", "", src, flags=re.S)  # only inside comments
    assert "pwn" not in re.sub(r"/\*.*?\*/", "", src, flags=re.S)
    # the parameters named like runtime macros are read under other C names
    assert re.search(r"const double v_FMUGEN_OK = p\[\d+\];", src)
    assert not re.search(r"const double FMUGEN_OK\b", src)


def test_every_generated_file_compiles_with_werror_trigraphs(hostile, tmp_path):
    model, res, d = hostile
    with zipfile.ZipFile(res.path) as z:
        z.extractall(tmp_path)
    src = tmp_path / "sources"
    cfiles = sorted(p.name for p in src.glob("*.c"))
    assert "model.c" in cfiles and len(cfiles) > 5
    lib = tmp_path / "strict.so"
    r = subprocess.run(["cc", "-std=c99", "-O1", "-fPIC", "-shared", "-Wall", "-Wextra", "-Werror",
                        "-trigraphs", "-I.", "-o", str(lib), *cfiles, "-lm"],
                       cwd=src, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


@pytest.mark.skipif(shutil.which("nm") is None, reason="nm not installed")
def test_shared_library_exports_only_fmi2_functions(hostile, tmp_path):
    model, res, d = hostile
    with zipfile.ZipFile(res.path) as z:
        so = [n for n in z.namelist() if n.startswith("binaries/") and n.endswith(".so")]
        assert len(so) == 1
        z.extract(so[0], tmp_path)
    out = subprocess.run(["nm", "-D", "--defined-only", str(tmp_path / so[0])],
                         check=True, capture_output=True, text=True).stdout
    exported = [line.split()[-1] for line in out.splitlines()
                if len(line.split()) == 3 and line.split()[1] in "TDRBVWtdrb" and line.split()[1].isupper()]
    assert exported, out
    assert all(name.startswith("fmi2") for name in exported), exported
    assert "fmi2DoStep" in exported and "fmi2Instantiate" in exported


def test_model_description_parses_and_keeps_the_text(hostile, tmp_path):
    model, res, d = hostile
    md = read_model_description(str(res.path), validate=True)
    assert md.description == xml_text(model.description)
    assert "\u00e9\u00df" in md.description and "]]>" in md.description and '"' in md.description
    assert "\u0000" not in md.description and "\u0001" not in md.description
    byname = {v.name: v for v in md.modelVariables}
    assert byname["FMUGEN_OK"].description == xml_text(PAYLOADS[0])
    assert byname["fmi2OK"].description == xml_text(PAYLOADS[3])
    assert "nul ? soh ? bell ? esc ?" == byname["fmi2OK"].description
    assert byname["FMUGEN_OK"].start == "1.0"


def test_the_fmu_runs_with_macro_named_parameters(hostile):
    """q(t) = tau t^2 / (2 J) with J = Izz + m r^2 read from the macro-named parameters."""
    from fmpy import simulate_fmu

    model, res, d = hostile
    for ok in (1.0, 2.0):
        m = ok + 1.1 + 1.2                       # FMUGEN_OK + FMUGEN_NOT_FINITE + fmugen_model
        J = 0.01 * 1.4 * 1.5 + m * 0.15 ** 2     # 0.01*M_PI2*evaluate + m r^2
        r = simulate_fmu(str(res.path), fmi_type="CoSimulation", stop_time=0.2, output_interval=0.1,
                         start_values={"tau[1]": 1.0, "FMUGEN_OK": ok}, output=["q[1]"])
        assert r["q[1]"][-1] == pytest.approx(0.2 ** 2 / (2 * J), rel=1e-6)


def test_assembly_description_cannot_escape_its_comment(tmp_path):
    """The [assembly] description reaches model.c and the XML the same way."""
    from fmugen.components.assembly import load_assembly
    from fmugen.fmi.model_description import model_description_xml

    root = __import__("pathlib").Path(__file__).resolve().parents[1]
    text = (root / "examples" / "single_joint_stiff.toml").read_text()
    line = "description = " + toml_basic_string(" ".join(PAYLOADS))
    text = re.sub(r'^description = ".*"$', lambda m: line, text, count=1, flags=re.M)
    p = tmp_path / "rig.toml"
    p.write_text(text, encoding="utf-8")
    model = load_assembly(p)
    assert model.description == " ".join(PAYLOADS)
    src = tmp_path / "model.c"
    src.write_text(generate_c(model).source)
    runtime = root / "c_runtime"
    r = subprocess.run(["cc", "-std=c99", "-fsyntax-only", "-Wall", "-Wextra", "-Werror", "-trigraphs",
                        f"-I{runtime}", str(src)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    import xml.etree.ElementTree as ET

    xml = model_description_xml(model, "{x}", "rig")
    assert ET.fromstring(xml.split("\n", 1)[1]).get("description") == xml_text(model.description)
