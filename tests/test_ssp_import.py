"""Any SSP in: third-party FMUs (hand-written C, built here) run by fmugen's master, parameter bindings and a
linear transformation honoured, Newton stable and accurate where held-input Jacobi diverges (against the
matrix exponential and the report's self-convergence reference); unsafe or unsupported archives refused."""
import math
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import fmugen
import fmugen.ssp.loader  # the attribute fmugen.ssp exists only once imported (the tests below use it)
from fmugen.cosim import run
from fmugen.errors import InputFileError
from ssp_third_party import K, M_A, SSD, build_fmus, exact, write_ssp

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return build_fmus(tmp_path_factory.mktemp("third_party"))


def _err(r, ex):
    return max(np.max(np.abs(r[c] - ex[c])) / np.max(np.abs(ex[c])) for c in ex)


def test_bindings_transformation_and_records(fmus, tmp_path):
    # bound values differ from the FMUs' own start values: the binding must win
    p = write_ssp(tmp_path / "two.ssp", fmus, m_a=1.5, k=3.0e4, stop=0.3)
    system = fmugen.load_system(p)
    assert [c.column for c in system.recorded] == ["A.x", "A.v", "B.F", "B.v2"]  # every output, comp.connector
    assert system.unit("A").start_values == {"m": 1.5} and system.unit("B").start_values == {"k": 3.0e4}
    assert [(c.source, c.target, c.factor) for c in system.couplings] == [
        (("A", "v"), ("B", "v_in"), 1000.0), (("B", "F"), ("A", "F"), 1.0)]
    r = run(system, "newton", "linear", step=1e-3)
    assert r.ok
    assert _err(r, exact(r.time, m_a=1.5, k=3.0e4)) < 1e-3
    assert _err(r, exact(r.time)) > 1e-2  # the FMUs' own values give another motion: bindings matter
    narrowed = fmugen.load_system(p, record=["B.F"])
    assert [c.column for c in narrowed.recorded] == ["B.F"]


def test_newton_where_held_jacobi_diverges(fmus, tmp_path):
    """At H = 5 ms held-input Jacobi diverges (a report names the coupling); Newton with linear inputs is
    stable and within 5e-3 of the exact solution, closer than Jacobi/held at a fifth of the step.  The
    self-convergence reference of fmugen report agrees with the exact error, and its own estimate bounds
    its true error."""
    from fmugen.ssp.report import self_convergence_reference, _error

    p = write_ssp(tmp_path / "two.ssp", fmus, stop=0.5)
    system = fmugen.load_system(p)
    jh = run(system, "jacobi", "hold", step=5e-3)
    assert not jh.ok and jh.summary.failure.cause == "diverged"
    assert "A.v -> B.v_in" in str(jh.summary.failure) or "B.F -> A.F" in str(jh.summary.failure)
    nw = run(system, "newton", "linear", step=5e-3)
    assert nw.ok
    e_exact = _err(nw, exact(nw.time))
    assert e_exact < 5e-3
    jh1 = run(system, "jacobi", "hold", step=1e-3)
    assert jh1.ok and _err(jh1, exact(jh1.time)) > e_exact
    scheme, ref, estimate, _ = self_convergence_reference(system, 5e-3 / 8, system.stop_time)
    assert scheme == "newton/linear"  # cubic needs output derivatives these FMUs do not give
    true_ref_error = _err(ref, exact(ref.time))
    assert true_ref_error <= estimate
    e_self = _error(nw, ref, list(ref.columns))
    assert abs(e_self - e_exact) <= 0.05 * e_exact


def test_report_command_labels_the_reference(fmus, tmp_path):
    p = write_ssp(tmp_path / "two.ssp", fmus, stop=0.1)
    out = subprocess.run([sys.executable, "-m", "fmugen.cli", "report", str(p), "--steps", "0.005,0.0025",
                          "--schemes", "jacobi/hold,newton/linear", "--repeats", "1", "--out", str(tmp_path / "r")],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    text = (tmp_path / "r" / "report.txt").read_text()
    assert "self-convergence reference, not an independent solution" in text
    assert "self-convergence error estimate" in text
    err = {line.split()[0]: float(line.split()[2].rstrip("*")) for line in text.splitlines()
           if line.split()[:2] in (["jacobi/hold", "0.005"], ["newton/linear", "0.005"])}
    assert err["newton/linear"] < 0.1 * err["jacobi/hold"]


def test_report_measures_an_unreliable_run_as_the_scene_report_does(fmus, monkeypatch):
    """A run that reached the stop time with an "unreliable" verdict is measured and labelled with its
    reason (the scene's report does so); it was listed as "failed" with no error."""
    import dataclasses

    import fmugen.ssp.report as rep

    system = fmugen.load_system(write_ssp(Path(fmus["mass"]).parent / "two_unreliable.ssp", fmus, stop=0.05))
    plain = rep.report_ssp(system, [0.005], [("newton", "linear")])
    real = rep.run

    def verdict(*a, **kw):
        r = real(*a, **kw)
        if kw.get("step") == 0.005:  # the measured run, not the reference's
            r = dataclasses.replace(r, summary=dataclasses.replace(r.summary, status="unreliable",
                                                                   reliability="a test verdict"))
        return r

    monkeypatch.setattr(rep, "run", verdict)
    marked = rep.report_ssp(system, [0.005], [("newton", "linear")])
    (_, _, _, err, status, _), = marked["rows"]
    assert status == "unreliable: a test verdict"
    assert err == plain["rows"][0][3] and 0 < err < 0.05  # the same run, measured (1.8e-2 at 5 ms)


# ---------------------------------------------------------------------------- refusals
def _archive(path, members: dict, links=()):
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
        for name, target in links:
            info = zipfile.ZipInfo(name)
            info.external_attr = (0o120777 << 16)
            zf.writestr(info, target)
    return path


def _ok_ssd(stop=0.1):
    return SSD.format(m_a=M_A, stop=stop)


@pytest.mark.parametrize("members,links,match", [
    ({"../evil.txt": "x"}, (), "unsafe path"),
    ({"/etc/evil": "x"}, (), "unsafe path"),
    ({"a\\..\\..\\evil": "x"}, (), "unsafe path"),
    ({}, [("resources/link.fmu", "/etc/passwd")], "symbolic link"),
    ({"SystemStructure.ssd": '<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "aaaa">]><x>&a;</x>'}, (), "DOCTYPE"),
    ({"SystemStructure.ssd": "<ssd:SystemStructureDescription xmlns:ssd='http://ssp-standard.org/SSP1/"
                             "SystemStructureDescription' name='x'/>"}, (), "schema"),
    ({"SystemStructure.ssd": "not xml"}, (), "not well-formed"),
    ({"other.txt": "x"}, (), "no SystemStructure.ssd"),
])
def test_unsafe_or_invalid_archives_are_refused(tmp_path, members, links, match):
    p = _archive(tmp_path / "bad.ssp", members, links)
    work = tmp_path / "work"
    with pytest.raises(InputFileError, match=match):
        fmugen.ssp.loader.load_system(p, workdir=work)
    assert not (tmp_path / "evil.txt").exists()
    assert not any(q.is_symlink() for q in work.rglob("*")) if work.exists() else True


def test_binding_prefix_is_prepended_to_the_source_names(fmus, tmp_path):
    """SSP 1.0, ParameterBinding/@prefix: "the specified prefix is prepended to all names in the parameter
    source" (the schema's documentation).  The loader stripped it instead and dropped every other name."""
    ssd = _ok_ssd().replace("<ssd:ParameterBinding>", '<ssd:ParameterBinding prefix="f">', 1) \
        .replace('<ssv:Parameter name="m">', '<ssv:Parameter name="0">', 1)
    a = {u.name: u for u in fmugen.load_system(write_ssp(tmp_path / "p.ssp", fmus, ssd=ssd)).units}["A"]
    assert a.start_values["f0"] == M_A and "m" not in a.start_values and "0" not in a.start_values
    ssd = _ok_ssd().replace("<ssd:ParameterBinding>", '<ssd:ParameterBinding prefix="sub.">', 1)
    with pytest.raises(InputFileError, match="names 'sub.m'"):
        fmugen.load_system(write_ssp(tmp_path / "q.ssp", fmus, ssd=ssd))


def test_connections_without_a_transformation_convert_units(fmus, tmp_path):
    """SSP 1.0: without a LinearTransformation an importer converts between the connectors' units unless
    suppressUnitConversion.  A.v [m/s] -> B.v_in [mm/s] then couples with 1000, the factor the fixture
    states (it was coupled with 1: a silent factor of 1000 off); different quantities are refused."""
    def couplings(ssd, name):
        return {(c.source, c.target): c.factor
                for c in fmugen.load_system(write_ssp(tmp_path / name, fmus, ssd=ssd)).couplings}

    stated = couplings(_ok_ssd(), "stated.ssp")
    assert stated[("A", "v"), ("B", "v_in")] == 1000.0
    plain = _ok_ssd().replace('<ssc:LinearTransformation factor="1000"/>', "")
    assert couplings(plain, "implied.ssp") == stated
    suppressed = plain.replace('endConnector="v_in"', 'endConnector="v_in" suppressUnitConversion="true"')
    assert couplings(suppressed, "suppressed.ssp")[("A", "v"), ("B", "v_in")] == 1.0
    wrong = plain.replace('startConnector="v" endElement="B"', 'startConnector="x" endElement="B"')
    with pytest.raises(InputFileError, match=r"\[m\] and \[mm/s\] are different quantities"):
        couplings(wrong, "wrong.ssp")


def test_export_states_a_factor_of_one_between_different_units(fmus):
    """A scene may state factor 1 between different units; the archive must say so (a LinearTransformation),
    or an importer converts the units itself (SSP 1.0, and fmugen's loader) -- m/s to mm/s by 1000."""
    import dataclasses
    from types import SimpleNamespace

    from fmugen.ssp.export import ssd_xml
    from fmugen.ssp.ssd import NS, parse_xml

    system = fmugen.load_system(write_ssp(Path(fmus["mass"]).parent / "two_export.ssp", fmus))
    system = dataclasses.replace(system, couplings=tuple(dataclasses.replace(c, factor=1.0)
                                                         for c in system.couplings))
    built = SimpleNamespace(scene=SimpleNamespace(name="t", spec=SimpleNamespace(description=""), groups={}),
                            system=system, jacobi_limit=math.inf)
    root = parse_xml(ssd_xml(built, {"scheme": "newton", "extrapolation": "linear"}, system.step)[0], "t")
    lin = {(e.get("startConnector"), e.get("endConnector")): e.find("ssc:LinearTransformation", NS)
           for e in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS)}
    assert lin[("v", "v_in")].get("factor") == "1.0"  # m/s -> mm/s, stated
    assert lin[("F", "F")] is None  # N -> N: nothing to say


def test_duplicate_members_are_refused_naming_the_archive(tmp_path):
    """Two members of one name: refused as such (open(.., "xb") used to fail with an OSError naming only the
    temporary extraction folder)."""
    p = tmp_path / "dup.ssp"
    with zipfile.ZipFile(p, "w") as zf:
        zf.writestr("SystemStructure.ssd", "x")
        with pytest.warns(UserWarning):
            zf.writestr("SystemStructure.ssd", "y")
    with pytest.raises(InputFileError, match=r"dup\.ssp: archive member 'SystemStructure.ssd' appears twice"):
        fmugen.ssp.loader.load_system(p, workdir=tmp_path / "work")


def test_exported_member_names_are_plain_file_names():
    """A component name from someone else's SSP (an [external] part) becomes a safe, distinct stem under
    resources/ of the archive fmugen writes, never a path."""
    from fmugen.ssp.export import resource_stems

    got = resource_stems(["chain", "../../evil", "a/b", "a_b", "Mass 1", "A_b", ".hidden"])
    assert got == {"chain": "chain", "../../evil": "______evil", "a/b": "a_b", "a_b": "a_b_2",
                   "Mass 1": "Mass_1", "A_b": "A_b_3", ".hidden": "_hidden"}


def test_unsupported_parts_are_refused_with_one_line(fmus, tmp_path):
    base = _ok_ssd()
    cases = {
        "offset": (base.replace('<ssc:LinearTransformation factor="1000"/>',
                                '<ssc:LinearTransformation factor="1000" offset="1"/>'), "offset"),
        "nested": (base.replace("<ssd:Elements>", "<ssd:Elements><ssd:System name='inner'/>"), "nested systems"),
        "dictionary": (base.replace("</ssd:Connections>", "</ssd:Connections><ssd:SignalDictionaries>"
                                    "<ssd:SignalDictionary name='d' source='d.ssb'/></ssd:SignalDictionaries>"),
                       "signal dictionaries"),
        "unknown variable": (base.replace('<ssv:Parameter name="m">', '<ssv:Parameter name="mass">'),
                             "does not have"),
        "system connector": (base.replace('startElement="B" startConnector="F"', 'startConnector="F"'),
                             "system's own connectors"),
    }
    for name, (ssd, match) in cases.items():
        p = write_ssp(tmp_path / f"{name.replace(' ', '_')}.ssp", fmus, ssd=ssd)
        with pytest.raises(InputFileError, match=match) as exc:
            fmugen.load_system(p)
        assert "\n" not in str(exc.value), name
    # an FMI 1.0 component (FMI 3.0 ones run: tests/test_cosim_fmi3.py)
    fmu1 = tmp_path / "mass1.fmu"
    with zipfile.ZipFile(fmus["mass"]) as src, zipfile.ZipFile(fmu1, "w") as dst:
        for i in src.infolist():
            data = src.read(i)
            if i.filename == "modelDescription.xml":
                data = data.replace(b'fmiVersion="2.0"', b'fmiVersion="1.0"')
            dst.writestr(i, data)
    p = write_ssp(tmp_path / "fmi1.ssp", {"mass": fmu1, "spring": fmus["spring"]})
    with pytest.raises(InputFileError, match=r"FMI 1\.0 is not supported \(FMI 2\.0 and 3\.0\)"):
        fmugen.load_system(p)


def test_cli_cosim_on_an_archive_with_set(fmus, tmp_path):
    p = write_ssp(tmp_path / "two.ssp", fmus, stop=0.05)
    out = subprocess.run([sys.executable, "-m", "fmugen.cli", "cosim", str(p), "--scheme", "newton",
                          "--extrapolation", "linear", "--step", "0.001", "--set", "A.m=1.5", "--out",
                          str(tmp_path / "o")], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    data = np.loadtxt(tmp_path / "o" / "results.csv", delimiter=",", skiprows=1)
    def err(m_a):
        ex = exact(data[:, 0], m_a=m_a)["A.x"]
        return np.max(np.abs(data[:, 1] - ex)) / np.max(np.abs(ex))

    assert err(1.5) < 2e-3 and err(1.0) > 10 * err(1.5)  # --set A.m=1.5 reached the FMU
    bad = subprocess.run([sys.executable, "-m", "fmugen.cli", "cosim", str(p), "--set", "A.nope=1", "--out",
                          str(tmp_path / "o2")], capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "A.nope" in bad.stderr
    shutil.rmtree(tmp_path / "o", ignore_errors=True)
    # --set cosim.KEY is a run setting on an archive as on a scene (it was refused as "not a component")
    run_ = subprocess.run([sys.executable, "-m", "fmugen.cli", "cosim", str(p), "--set", "cosim.scheme=newton",
                           "--set", "cosim.step=0.0025", "--out", str(tmp_path / "o3")], capture_output=True,
                          text=True, cwd=ROOT)
    assert run_.returncode == 0, run_.stderr
    assert run_.stdout.startswith(f"{fmugen.load_system(p).name}: newton/")
    t = np.loadtxt(tmp_path / "o3" / "results.csv", delimiter=",", skiprows=1)[:, 0]
    assert len(t) == 21 and t[-1] == pytest.approx(0.05, abs=1e-12)  # 0.05 s in steps of 2.5 ms
    typo = subprocess.run([sys.executable, "-m", "fmugen.cli", "cosim", str(p), "--set", "cosim.schem=newton",
                           "--out", str(tmp_path / "o4")], capture_output=True, text=True, cwd=ROOT)
    assert typo.returncode == 2 and "did you mean 'scheme'" in typo.stderr


def test_scene_with_an_external_ssp_component(fmus, tmp_path):
    """A scene's own joint inertia coupled to a supplier's spring FMU from an SSP ([external]): the
    co-simulation equals the linear system's matrix exponential; the scene keeps tau_load an input."""
    import scipy.linalg as sl

    from ssp_third_party import C_B, M_B, SSD_SPRING_ONLY

    write_ssp(tmp_path / "spring.ssp", fmus, k=3.0e4, ssd=SSD_SPRING_ONLY)
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text('''
[scene]
name = "joint_and_supplier"
stop = 0.3
step = 1e-3
tolerance = 1e-10
record = ["joint.theta", "joint.w"]

[instances]
joint = { type = "joint_inertia", start = { tau = 100.0 } }

[fmus.joint]
members = ["joint"]
solver = "rodas3"

[external]
ssp = "spring.ssp"
connections = [["joint.w", "B.v_in", 1000.0], ["B.F", "joint.tau_load", -1.0]]  # the spring pulls back
record = ["B.F"]
''')
    scene = fmugen.load_scene(scene_file)
    built = scene.build(tmp_path / "fmus")
    assert "inputs of the system: none" in built.summary()  # tau_load is the supplier's, tau fixed
    system = built.system
    assert [u.name for u in system.units] == ["joint", "B"]
    assert [c.column for c in system.recorded] == ["joint.theta", "joint.w", "B.F"]
    r = run(system, "newton", "linear", step=1e-3)
    assert r.ok
    p = {v.name: v.start for v in scene.base_models["joint"].parameters}
    J, B_m, k = p["J"], p["B_m"], 3.0e4
    # theta, w, F, v2 and a constant 1 (the torque tau = 100 N.m)
    A = np.array([[0, 1, 0, 0, 0], [0, -B_m / J, 1 / J, 0, 100.0 / J], [0, -k, 0, k, 0],
                  [0, 0, -1 / M_B, -C_B / M_B, 0], [0, 0, 0, 0, 0]])
    xs = np.array([sl.expm(A * t) @ np.array([0, 0, 0, 0, 1.0]) for t in r.time])
    for col, x in (("joint.theta", xs[:, 0]), ("joint.w", xs[:, 1]), ("B.F", xs[:, 2])):
        assert np.max(np.abs(r[col] - x)) < 5e-3 * np.max(np.abs(x)), col  # Newton/linear: O(H^2)
    with pytest.raises(ValueError, match="no reference solution"):
        scene.reference_problem()
    # the combined system exported as one archive runs as the scene, bit for bit
    from fmugen.ssp import export_ssp

    e = export_ssp(scene, tmp_path / "combined.ssp", fmus_dir=tmp_path / "fmus")
    again = run(fmugen.load_system(e["path"]), "newton", "linear", step=1e-3)
    assert again.columns == r.columns and np.array_equal(again.values, r.values)
    bad = scene_file.read_text().replace('["B.F", "joint.tau_load", -1.0]', '["B.F", "joint.tau_load"]')
    scene_file.write_text(bad)
    with pytest.raises(ValueError, match="unit mismatch"):
        fmugen.load_scene(scene_file)


def test_sweep_over_an_archive(fmus, tmp_path):
    """fmugen sweep x.ssp: each point equals the serial run with that start value, bit for bit, and the
    matrix exponential at its parameter; the error metric (a reference) is refused."""
    import dataclasses

    import fmugen.sweep

    p = write_ssp(tmp_path / "two.ssp", fmus, stop=0.1)
    opts = {"scheme": "newton", "extrapolation": "linear", "step": 1e-3}
    r = fmugen.sweep.sweep(str(p), grid={"A.m": [1.0, 1.5]}, metrics=["A.x:final"], out=str(tmp_path / "sw"),
                           processes=False, workers=1, options=opts, plot=False)
    system = fmugen.load_system(p)
    for row in r.rows:
        assert row["status"] == "ok"
        units = tuple(dataclasses.replace(u, start_values={**u.start_values, "m": row["A.m"]}) if u.name == "A"
                      else u for u in system.units)
        serial = run(dataclasses.replace(system, units=units), **opts)
        assert row["A.x:final"] == serial["A.x"][-1]
        ex = exact(np.array([0.1]), m_a=row["A.m"])["A.x"][-1]
        assert abs(row["A.x:final"] - ex) < 2e-3 * abs(ex)
    with pytest.raises(ValueError, match="no symbolic model"):
        fmugen.sweep.sweep(str(p), grid={"A.m": [1.0]}, metrics=["A.x:error"], out=str(tmp_path / "sw2"),
                           processes=False, workers=1, options=opts, plot=False)
    # --set on a sweep of an archive: the rules of fmugen cosim x.ssp (one function): a run setting and a
    # start value; the point equals the serial run with both
    r = fmugen.sweep.sweep(str(p), grid={"A.m": [1.5]}, metrics=["A.x:final"], out=str(tmp_path / "sw3"),
                           processes=False, workers=1, sets=["cosim.step=0.002", "B.k=2.0"], plot=False,
                           options={"scheme": "newton", "extrapolation": "linear"})
    units = tuple(dataclasses.replace(u, start_values={**u.start_values, **({"m": 1.5} if u.name == "A" else
                                                                              {"k": 2.0})}) for u in system.units)
    serial = run(dataclasses.replace(system, units=units), scheme="newton", extrapolation="linear", step=0.002)
    assert r.rows[0]["A.x:final"] == serial["A.x"][-1]
    assert serial["A.x"][-1] != run(dataclasses.replace(system, units=units), scheme="newton",
                                    extrapolation="linear", step=0.001)["A.x"][-1]
