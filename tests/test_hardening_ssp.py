"""The SSP surface under hostile input (issue 27): numbers by XML Schema's grammar, every malformed
attribute one line naming the archive, the file in it, the element and the attribute; the API and the
command line refuse what they cannot run instead of raising bare Python errors; an FMU whose
modelDescription GUID is not its binary's is refused at instantiation with one line naming the
component and the FMU; and no import circle between fmugen.cosim and fmugen.ssp.

The third-party FMUs are the hand-written ones of ``ssp_third_party`` (built here from C)."""
import ast
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import fmugen.ssp.loader  # noqa: F401  (fmugen.ssp.load_system)
from fmugen.cosim import run
from fmugen.errors import FmugenError, InputFileError
from fmugen.ssp import load_system
from fmugen.values import parse_xs_boolean, parse_xs_double, parse_xs_int
from ssp_third_party import SSD, build_fmus, write_ssp
from third_party_fmu import compile_fmu, model_description, rk4_source

ROOT = Path(__file__).resolve().parents[1]
BASE = SSD.format(m_a=1.0, stop=0.5)
RUN = ('  <ssd:Annotations><ssc:Annotation type="org.fmugen.run"><fmugen:Run xmlns:fmugen="urn:fmugen:ssp:1" '
       'scene="two" {attrs}>{body}</fmugen:Run></ssc:Annotation></ssd:Annotations>\n'
       '</ssd:SystemStructureDescription>')
UNITS = ('  <ssd:Units><ssc:Unit name="mm/s"><ssc:BaseUnit m="1" s="-1" factor="{f}"/></ssc:Unit></ssd:Units>\n'
         '  <ssd:DefaultExperiment')
OSP = ('<ssd:DefaultExperiment startTime="0" stopTime="0.5"><ssd:Annotations><ssc:Annotation '
       'type="com.opensimulationplatform"><osp:Algorithm xmlns:osp="http://opensimulationplatform.com/SSP/'
       'OSPAnnotations"><osp:FixedStepAlgorithm baseStepSize="{h}"/></osp:Algorithm></ssc:Annotation>'
       '</ssd:Annotations></ssd:DefaultExperiment>')


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return build_fmus(tmp_path_factory.mktemp("third_party"))


def annotated(attrs='scheme="newton" extrapolation="linear" step="0.001"', body="", ssd=BASE):
    return ssd.replace("</ssd:SystemStructureDescription>", RUN.format(attrs=attrs, body=body))


def without_transform(factor):
    """The SSD with the A.v -> B.v_in connection converted by the archive's own definition of mm/s."""
    return BASE.replace('<ssc:LinearTransformation factor="1000"/>', '').replace(
        "  <ssd:DefaultExperiment", UNITS.format(f=factor))


def _refusal(path, match):
    with pytest.raises(InputFileError) as info:
        load_system(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    assert re.search(match, msg), msg
    return msg


# ------------------------------------------------------------------------------------------ the grammar
def test_xs_double_is_the_xsd_lexical_space_not_pythons():
    # XML Schema 1.0 Part 2, 3.2.5.1: "-1E4, 1267.43233E12, 12.78e-2, 12 , -0, 0 and INF are all legal
    # literals for double"; white space is collapsed (3.2.5: whiteSpace fixed to collapse)
    legal = {"-1E4": -1e4, "1267.43233E12": 1.26743233e15, "12.78e-2": 0.1278, "12": 12.0, "-0": -0.0,
             "0": 0.0, " \t12.5\n": 12.5, ".5": 0.5, "5.": 5.0, "+3": 3.0}
    for text, value in legal.items():
        assert parse_xs_double(text, "f: a") == value
    assert parse_xs_double("INF", "f", finite=False) == float("inf")
    assert parse_xs_double("-INF", "f", finite=False) == float("-inf")
    assert parse_xs_double("NaN", "f", finite=False) != parse_xs_double("NaN", "f", finite=False)
    # what Python's float() reads and XML Schema does not
    for text in ("1_5", "\u0661\u0662", "\uff11", "infinity", "inf", "nan", "NAN", "Infinity", "+INF", "0x1p3",
                 "1,5", "", "\u00a012", "1 2", "1e", "e3", "."):
        with pytest.raises(InputFileError, match=r"^f: a: .* is not an xs:double"):
            parse_xs_double(text, "f: a")
    for text, why in (("INF", "INF is not a finite number"), ("NaN", "NaN is not a finite number"),
                      ("1e999", "beyond the double-precision range")):
        with pytest.raises(InputFileError, match=why):
            parse_xs_double(text, "f: a")


def test_xs_int_and_boolean():
    # 3.3.17 int: maxInclusive 2147483647, minInclusive -2147483648; 3.2.2 boolean: {true, false, 1, 0}
    assert parse_xs_int(" -2147483648 ", "w") == -2 ** 31 and parse_xs_int("+2147483647", "w") == 2 ** 31 - 1
    for text, why in (("2147483648", "outside the range of xs:int"), ("1.0", "not an xs:int"),
                      ("\u0661", "not an xs:int"), ("1_0", "not an xs:int"), ("0x10", "not an xs:int")):
        with pytest.raises(InputFileError, match=why):
            parse_xs_int(text, "w")
    assert [parse_xs_boolean(t, "w") for t in ("true", "false", "1", " 0 ")] == [True, False, True, False]
    for text in ("True", "yes", "on", "2", ""):
        with pytest.raises(InputFileError, match="not an xs:boolean"):
            parse_xs_boolean(text, "w")


# every numeric attribute the SSP readers take, with a spelling only float() accepts: (where, how to
# put a value there, the element/attribute the refusal names)
PLACES = {
    "SSV Real value": (lambda v: None, r"resources/B\.ssv: .*(parameter k: Real value|'ssv:Real', attribute 'value')"),
    "inline Real value": (lambda v: BASE.replace('<ssv:Real value="1.0"/>', f'<ssv:Real value="{v}"/>'),
                          r"component A: parameter binding: parameter m: Real value"),
    "LinearTransformation factor": (lambda v: BASE.replace('factor="1000"', f'factor="{v}"'),
                                    r"(LinearTransformation factor|'ssc:LinearTransformation', attribute 'factor')"),
    "DefaultExperiment stopTime": (lambda v: BASE.replace('stopTime="0.5"', f'stopTime="{v}"'),
                                   r"(DefaultExperiment stopTime|'ssd:DefaultExperiment', attribute 'stopTime')"),
    "BaseUnit factor": (lambda v: without_transform(v),
                        r"(Unit 'mm/s': BaseUnit factor|'ssc:BaseUnit', attribute 'factor')"),
    "BaseUnit exponent": (lambda v: without_transform("0.001").replace('m="1"', f'm="{v}"'),
                          r"(Unit 'mm/s': BaseUnit m|'ssc:BaseUnit', attribute 'm')"),
    "suppressUnitConversion": (lambda v: BASE.replace('endConnector="F"/>',
                                                      f'endConnector="F" suppressUnitConversion="{v}"/>'),
                               r"'ssd:Connection', attribute 'suppressUnitConversion'"),
    "annotation step": (lambda v: annotated(attrs=f'step="{v}"'), r"annotation org\.fmugen\.run: Run step"),
    "annotation Start value": (lambda v: annotated(body=f'<fmugen:Unit name="A" fmiType="cs"><fmugen:Start '
                                                        f'name="m" value="{v}"/></fmugen:Unit>'),
                               r"annotation org\.fmugen\.run: Unit A: Start m value"),
    "OSP baseStepSize": (lambda v: BASE.replace('<ssd:DefaultExperiment startTime="0" stopTime="0.5"/>',
                                                OSP.format(h=v)), r"FixedStepAlgorithm baseStepSize"),
}


@pytest.mark.parametrize("place", sorted(PLACES))
def test_every_numeric_attribute_refuses_what_only_float_reads(fmus, tmp_path, place):
    make, names = PLACES[place]
    for i, bad in enumerate(("1_5", "\u0661\u0662", "infinity", "NaN")):
        if place in ("BaseUnit exponent", "suppressUnitConversion") and bad == "NaN":
            continue  # not a number of their types in any spelling: covered by the three others
        path = tmp_path / f"{i}.ssp"
        if place == "SSV Real value":
            write_ssp(path, fmus, k=0.0)
            _rewrite(path, "resources/B.ssv", lambda t: t.replace('value="0.0"', f'value="{bad}"'))
        else:
            write_ssp(path, fmus, ssd=make(bad))
        msg = _refusal(path, names)
        assert bad in msg and ("SystemStructure.ssd: " in msg or "resources/B.ssv: " in msg)


def _rewrite(path, member, edit):
    with zipfile.ZipFile(path) as zf:
        items = [(i.filename, zf.read(i)) for i in zf.infolist()]
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in items:
            zf.writestr(name, edit(data.decode()).encode() if name == member else data)


# ------------------------------------------------------------------------------------------ the reports
def test_an_annotation_without_scheme_or_step_runs_on_the_defaults(fmus, tmp_path):
    """Was TypeError: float() argument must be ... 'NoneType'.  Without a step the OSP's baseStepSize is
    the step, else the run's tenth of a thousand; without a scheme the master's default."""
    p = write_ssp(tmp_path / "a.ssp", fmus, ssd=annotated(attrs=""))
    s = load_system(p)
    assert s.step == pytest.approx(0.5 / 1000) and "scheme" not in s.settings
    osp = annotated(attrs="", ssd=BASE.replace('<ssd:DefaultExperiment startTime="0" stopTime="0.5"/>',
                                               OSP.format(h="0.002")))
    assert load_system(write_ssp(tmp_path / "b.ssp", fmus, ssd=osp)).step == 0.002
    for attrs, why in (('step="0"', "Run step: '0' is not positive"), ('scheme="bogus"', "bogus"),
                       ('version="2"', "version '2'; this fmugen reads version 1")):
        _refusal(write_ssp(tmp_path / "c.ssp", fmus, ssd=annotated(attrs=attrs)), why)


def test_unit_factors_zero_negative_or_nan_are_refused_a_valid_one_is_honoured(fmus, tmp_path):
    """Was ZeroDivisionError.  mm/s defined as 1e-3 m/s: the A.v [m/s] -> B.v_in [mm/s] connection
    converts by 1000 (the factor the transformation stated before)."""
    for f, why in (("0", "'0' is not positive"), ("-0.001", "'-0.001' is not positive"),
                   ("NaN", "NaN is not a finite number")):
        _refusal(write_ssp(tmp_path / "u.ssp", fmus, ssd=without_transform(f)),
                 rf"SystemStructure\.ssd: Unit 'mm/s': BaseUnit factor: {why}")
    s = load_system(write_ssp(tmp_path / "ok.ssp", fmus, ssd=without_transform("0.001")))
    assert s.couplings[0].factor == pytest.approx(1000.0, rel=1e-15)


def test_a_bound_value_in_another_unit_is_converted_or_refused(fmus, tmp_path):
    # 1500 g bound to the mass m [kg]: 1.5 kg; in [m] it is another quantity
    g = BASE.replace('<ssv:Real value="1.0"/>', '<ssv:Real value="1500" unit="g"/>')
    assert load_system(write_ssp(tmp_path / "g.ssp", fmus, ssd=g)).unit("A").start_values["m"] == 1.5
    _refusal(write_ssp(tmp_path / "m.ssp", fmus, ssd=g.replace('unit="g"', 'unit="m"')),
             r"parameter binding m: \[m\] and \[kg\] are different quantities")


@pytest.mark.parametrize("edit, why", [
    (lambda t: t.replace('startElement="B" startConnector="F"', 'startElement="C" startConnector="F"'),
     r"connection C\.F -> A\.F: no component 'C'"),
    (lambda t: t.replace('endConnector="F"/>', 'endConnector="G"/>'), r"component A declares no Connector 'G'"),
    (lambda t: t.replace('<ssd:Connection startElement="B"', '<ssd:Connection startElement="A" startConnector="x" '
                         'endElement="A" endConnector="F"/><ssd:Connection startElement="B"'),
     r"A\.F is already driven by A\.x"),
    (lambda t: t.replace('name="x" kind="output"', 'name="v" kind="output"'), r"Connector 'v' is declared twice"),
    (lambda t: t.replace('name="B" source', 'name="A" source'), r"component A: the name is used twice"),
    (lambda t: t.replace('name="B" source', 'name="B.1" source'), r"Component name: 'B\.1' contains '\.'"),
    (lambda t: t.replace('name="x" kind', 'name="x&#10;y" kind'), r"Connector name: 'x\\ny' contains control"),
    (lambda t: t.replace('<ssc:Real unit="m"/>', '<ssc:Real unit="mm"/>'),
     r"Connector 'x' is declared in \[mm\]; the FMU's variable is in \[m\]"),
    (lambda t: t.replace('name="x" kind="output"', 'name="nosuch" kind="output"'),
     r"Connector 'nosuch': its FMU \(mass\.fmu\) has no such variable"),
    (lambda t: t.replace('<ssv:Parameter name="m"><ssv:Real value="1.0"/></ssv:Parameter>',
                         '<ssv:Parameter name="m"><ssv:Real value="1.0"/></ssv:Parameter>'
                         '<ssv:Parameter name="m"><ssv:Real value="2.0"/></ssv:Parameter>'),
     r"parameter m: given twice"),
    (lambda t: t.replace('stopTime="0.5"', 'startTime="1" stopTime="0.5"').replace('startTime="0" ', ''),
     r"stopTime '0\.5' is not after its startTime '1'"),
])
def test_structural_faults_are_one_line_naming_the_element(fmus, tmp_path, edit, why):
    _refusal(write_ssp(tmp_path / "s.ssp", fmus, ssd=edit(BASE)), why)


@pytest.mark.parametrize("body, why", [
    ('<fmugen:Order>A C</fmugen:Order>', r"Order names 'C', which is no component"),
    ('<fmugen:Order>A</fmugen:Order>', r"Order 'A' must name every component once"),
    ('<fmugen:Unit name="Z" fmiType="cs"/>', r"Unit Z: no component of that name"),
    ('<fmugen:Unit name="A" fmiType="me"/>', r"component A: fmiType 'me' of annotation org\.fmugen\.run asks for "
                                             r"Model Exchange; the FMU has no such interface"),
    ('<fmugen:Unit name="A" fmiType="xx"/>', r"fmiType 'xx' is neither"),
    ('<fmugen:Unit name="A" fmiType="cs" directionalDerivatives="yes"/>', r"directionalDerivatives: 'yes' is not an"),
    ('<fmugen:Unit name="A" fmiType="cs"><fmugen:Start name="q" value="1"/></fmugen:Unit>', r"Start 'q'"),
    ('<fmugen:Record column="A.q" unit="A" variable="q"/>', r"Record A\.q: A has no Real variable 'q'"),
    ('<fmugen:Record column="A.x" unit="A" variable="x"/><fmugen:Record column="A.x" unit="B" variable="F"/>',
     r"Record A\.x: given twice"),
    ('<fmugen:Setting name="tol" value="abc"/>', r"Setting tol"),
    ('<fmugen:Setting name="nosuch" value="1"/>', r"unknown key 'nosuch'"),
])
def test_a_malformed_run_annotation_is_one_line_naming_its_element(fmus, tmp_path, body, why):
    msg = _refusal(write_ssp(tmp_path / "r.ssp", fmus, ssd=annotated(body=body)), why)
    assert "annotation org.fmugen.run" in msg


def test_the_api_refuses_bad_arguments_as_the_cli_does(fmus, tmp_path):
    p = write_ssp(tmp_path / "two.ssp", fmus)
    afile = tmp_path / "file"
    afile.write_text("x")
    full = tmp_path / "full"
    full.mkdir()
    (full / "x").write_text("x")
    for kwargs, why in ((dict(workdir=afile), "is a file, not a folder"),  # was FileExistsError
                        (dict(workdir=full), "must be empty"),
                        (dict(workdir=3), "workdir must be a file path"),
                        (dict(record="A.x"), "a list of columns"),
                        (dict(record=["A.x", "A.x"]), "'A.x' is named twice"),
                        (dict(record=["A.nosuch"]), "no output 'A.nosuch'")):
        with pytest.raises(FmugenError, match=why):
            load_system(p, **kwargs)
    for path, why in ((3, "path must be a file path"), (tmp_path, "not a file"), (tmp_path / "no.ssp", "no such")):
        with pytest.raises(FmugenError, match=why):
            load_system(path)
    import fmugen  # the top-level API takes the same arguments (it dropped workdir)

    with pytest.raises(FmugenError, match="is a file, not a folder"):
        fmugen.load_system(p, workdir=afile)
    into = tmp_path / "into"
    system = fmugen.load_system(p, workdir=into)
    assert system is not None and any(into.rglob("*.fmu"))


def test_the_command_line_prints_one_line_and_exits_2(fmus, tmp_path):
    p = write_ssp(tmp_path / "bad.ssp", fmus, ssd=without_transform("0"))
    r = subprocess.run([sys.executable, "-m", "fmugen.cli", "cosim", str(p), "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr
    assert "bad.ssp: SystemStructure.ssd: Unit 'mm/s': BaseUnit factor: '0' is not positive" in lines[0]


# ------------------------------------------------------------------------------------------ GUIDs
def test_a_third_party_fmu_whose_description_guid_is_not_its_binarys(fmus, tmp_path):
    """An FMU that checks the GUID it is instantiated with (as FMI 2.0 asks, and as fmugen's runtime does),
    shipped with another GUID in its modelDescription.xml: the run is refused before any step, in one line
    naming the component and the FMU -- not a traceback and not an ok run.  The same FMU with its own GUID
    runs."""
    from ssp_third_party import MODEL_C, NR, NY

    source = rk4_source(NR, NY, MODEL_C).replace(
        "    Comp *c = calloc(1, sizeof(Comp));",
        '    if (!guid || strcmp(guid, "{third-party-mass}") != 0) return NULL;\n'
        "    Comp *c = calloc(1, sizeof(Comp));", 1)
    assert "strcmp(guid" in source
    variables = [("x", 0, "output", "continuous", "exact", 0.0, "m"), ("v", 1, "output", "continuous", "exact", 0.0,
                                                                       "m/s"),
                 ("m", 2, "parameter", "fixed", "exact", 1.0, "kg"), ("c", 3, "parameter", "fixed", "exact", 150.0,
                                                                      "N.s/m"),
                 ("F", 4, "input", "continuous", None, 0.0, "N"), ("f0", 5, "parameter", "fixed", "exact", 100.0, "N")]
    flags = ["-O2", "-std=c99", "-DXA0=0.0", "-DMA=1.0", "-DCA=150.0", "-DF0=100.0", "-DW=20.0"]
    checking = dict(fmus)
    checking["mass"] = compile_fmu(tmp_path / "own", "mass", "#include <string.h>\n" + source,
                                   model_description("mass", "{third-party-mass}", variables,
                                                     [(1, ""), (2, "")], []), flags)
    good = write_ssp(tmp_path / "good.ssp", checking, stop=0.05)
    assert run(load_system(good), "newton", "linear", step=1e-3).ok
    bad = write_ssp(tmp_path / "bad.ssp", checking, stop=0.05)
    _edit_description(bad, "resources/mass.fmu", "{third-party-mass}", "{third-party-mass-2}")
    system = load_system(bad)
    with pytest.raises(FmugenError) as info:
        run(system, "newton", "linear", step=1e-3)
    msg = str(info.value)
    assert "\n" not in msg and "fmi2Instantiate failed" in msg, msg
    assert "'A'" in msg or " A " in msg or "A (" in msg, msg
    assert "mass.fmu" in msg, msg


def _edit_description(ssp, member, old, new):
    """The archive with ``old`` replaced by ``new`` in the FMU ``member``'s modelDescription.xml (the binary
    unchanged)."""
    import io

    with zipfile.ZipFile(ssp) as zf:
        items = [(i.filename, zf.read(i)) for i in zf.infolist()]
    out = []
    for name, data in items:
        if name == member:
            buf_in, buf = io.BytesIO(data), io.BytesIO()
            with zipfile.ZipFile(buf_in) as fz, zipfile.ZipFile(buf, "w") as fo:
                for i in fz.infolist():
                    d = fz.read(i)
                    if i.filename == "modelDescription.xml":
                        assert old.encode() in d
                        d = d.replace(old.encode(), new.encode())
                    fo.writestr(i, d)
            data = buf.getvalue()
        out.append((name, data))
    with zipfile.ZipFile(ssp, "w") as zf:
        for name, data in out:
            zf.writestr(name, data)


def test_fmugens_runtime_refuses_a_foreign_guid_with_a_logged_message(tmp_path):
    """fmugen's own fmi2Instantiate (c_runtime/fmi2_functions.c) compares the GUID it is given with the
    one compiled in: a modelDescription.xml edited to another GUID gives NULL and the logged reason, which
    the master's one line quotes."""
    import sympy as sp

    from fmugen.codegen.model import SymbolicModel, Variable
    from fmugen.fmi import build_fmu

    x, T, u = sp.symbols("x T u", real=True)
    model = SymbolicModel.from_equations("lag1", [Variable("x", x, start=0.0, output=True)],
                                         [Variable("u", u, start=1.0)], [Variable("T", T, start=0.1, min=0.0)],
                                         [(u - x) / T], [], [])
    fmu = build_fmu(model, tmp_path / "lag1.fmu", fmi_type="cs").path
    from fmpy import read_model_description

    guid = read_model_description(str(fmu)).guid
    ssd = ('<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/'
           'SSP1/SystemStructureDescription" xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
           'version="1.0" name="one"><ssd:System name="one"><ssd:Elements><ssd:Component name="lag" '
           'source="resources/lag1.fmu"><ssd:Connectors><ssd:Connector name="x" kind="output"><ssc:Real/>'
           '</ssd:Connector></ssd:Connectors></ssd:Component></ssd:Elements></ssd:System>'
           '<ssd:DefaultExperiment startTime="0" stopTime="0.1"/></ssd:SystemStructureDescription>')
    p = tmp_path / "one.ssp"
    with zipfile.ZipFile(p, "w") as zf:
        zf.writestr("SystemStructure.ssd", ssd)
        zf.write(fmu, "resources/lag1.fmu")
    r = run(load_system(p), "jacobi", "hold", step=0.01)
    assert r.ok and r["lag.x"][-1] == pytest.approx(1 - 2.718281828459045 ** -1, rel=1e-6)  # u = 1, T = 0.1
    _edit_description(p, "resources/lag1.fmu", guid, "{00000000-0000-0000-0000-000000000000}")
    with pytest.raises(FmugenError) as info:
        run(load_system(p), "jacobi", "hold", step=0.01)
    msg = str(info.value)
    assert "\n" not in msg and "lag" in msg and "lag1.fmu" in msg and "fmi2Instantiate failed" in msg, msg
    assert f"does not match this FMU's \"{guid}\"" in msg, msg
    # the command line: that line, exit 2, no traceback (and no results written as if the run were ok)
    r = subprocess.run([sys.executable, "-m", "fmugen.cli", "cosim", str(p), "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "fmi2Instantiate failed" in r.stderr
    assert "fmugen_ssp_one_" in r.stderr  # the extraction folder is named after the archive
    assert not (tmp_path / "out" / "results.csv").exists()


# ------------------------------------------------------------------------------------------ imports
def _imports(path: Path, module: str) -> set:
    """The fmugen modules ``module`` (the file ``path``) imports, at module level or inside functions."""
    pkg = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = pkg.split(".")[:len(pkg.split(".")) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
    return out


def test_no_import_circle_between_cosim_commands_and_ssp_report():
    """fmugen.ssp.report used fmugen.cosim.commands' argument checks while commands imports ssp.report to
    run `fmugen report x.ssp`: the walk over every import (function-level ones too) finds no way back."""
    mods = {}
    for f in (ROOT / "fmugen").rglob("*.py"):
        rel = f.relative_to(ROOT).with_suffix("")
        mods[".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)] = f
    graph = {m: {d for d in _imports(f, m) if d in mods and d != m} for m, f in mods.items()}

    def reaches(a, b):
        seen, todo = {a}, [a]
        while todo:
            for d in graph[todo.pop()]:
                if d == b:
                    return True
                if d not in seen:
                    seen.add(d)
                    todo.append(d)
        return False

    assert reaches("fmugen.cosim.commands", "fmugen.ssp.report")  # the dispatch of `fmugen report x.ssp`
    assert not reaches("fmugen.ssp.report", "fmugen.cosim.commands")
    for m in ("fmugen.ssp.report", "fmugen.cosim.commands"):  # each imports on its own in a fresh interpreter
        subprocess.run([sys.executable, "-c", f"import {m}"], check=True, cwd=ROOT, timeout=120)


def test_the_report_and_export_apis_refuse_bad_arguments(fmus, tmp_path):
    from fmugen.ssp import export_ssp
    from fmugen.ssp.report import report_ssp

    system = load_system(write_ssp(tmp_path / "two.ssp", fmus, stop=0.05))
    for kwargs, why in ((dict(steps="0.01"), "steps must be a list"), (dict(steps=["x"]), "a step must be a finite"),
                        (dict(steps=[float("nan")]), "finite number"), (dict(steps=[-1.0]), "steps must be positive"),
                        (dict(schemes="newton"), r"\(scheme, extrapolation\) pairs"),
                        (dict(schemes=[("warp", "hold")]), "unknown scheme 'warp'"),
                        (dict(repeats=0), "repeats must be a whole number"),
                        (dict(stop=float("inf")), "stop must be a finite number"),
                        (dict(stop=-1.0), "must be after the system's start time")):
        args = {"steps": [0.01], "schemes": [("newton", "linear")], **kwargs}
        with pytest.raises(FmugenError, match=why):
            report_ssp(system, **args)
    for args, why in (((None, tmp_path / "x.ssp"), "scene must be a loaded scene"),):
        with pytest.raises(FmugenError, match=why):
            export_ssp(*args)


@pytest.mark.parametrize("old, new, why", [
    ('unit="m"', 'unit="a&#10;b"', r"the FMU's variable is in \[a\\nb\]"),
    ('causality="output"', 'causality="out&#10;put"', r"the FMU's variable is out\\nput"),
])
def test_an_fmus_own_strings_with_newlines_stay_on_one_line(fmus, tmp_path, old, new, why):
    """A message quotes the FMU's unit or causality, which nobody checked: a newline in it is written as
    an escape (found probing the fuzz battery's fmu class)."""
    p = write_ssp(tmp_path / "nl.ssp", fmus)
    _edit_description(p, "resources/mass.fmu", old, new)
    _refusal(p, why)
