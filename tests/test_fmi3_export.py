"""FMI 3.0 export (opt-in, ``build_fmu(..., fmi_version=3)`` / ``fmugen build --fmi-version 3``).

The FMI 3.0 functions (c_runtime/fmi3/fmi3_functions.c) translate onto the FMI 2.0 runtime, so an
FMI 3.0 FMU must compute exactly what the FMI 2.0 FMU of the same model computes: the PUMA robot
and the bouncing ball (state events, a re-initialised state) are built both ways and simulated by
fmpy with the same settings, ME (fmpy's own solver) and CS, and compared to 1e-12.  fmpy's FMI 3.0
schema validation must find nothing; misuse through the API returns fmi3Error with a logged message.
"""
from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Model, FMU3Slave
from fmpy.validation import validate_fmu

import fmugen
from fmugen.cli import main as cli_main
from fmugen.components.equations import load_component
from fmugen.errors import FmugenError
from fmugen.fmi.build import build_fmu
from fmugen.fmi.platforms import host_platform

ROOT = Path(__file__).resolve().parent.parent
PUMA = ROOT / "robots" / "puma_thesis_com.toml"
BALL = ROOT / "examples" / "components" / "bouncing_ball.toml"

pytestmark = pytest.mark.skipif(host_platform() != "linux64", reason="FMI 3.0 export: x86_64 Linux only so far")


@pytest.fixture(scope="module")
def puma_fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmi3_puma")
    m = fmugen.load_robot(str(PUMA)).state_space_model(outputs=("p_ee",))
    return build_fmu(m, d / "puma2.fmu").path, build_fmu(m, d / "puma3.fmu", fmi_version=3).path


@pytest.fixture(scope="module")
def ball_fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmi3_ball")
    m = load_component(BALL)
    return build_fmu(m, d / "ball2.fmu").path, build_fmu(m, d / "ball3.fmu", fmi_version=3).path


def _same(r2, r3, tol=1e-12):
    assert r2.dtype.names == r3.dtype.names
    assert len(r2) == len(r3) and len(r2) > 10
    return max(float(np.max(np.abs(r3[n] - r2[n]))) for n in r2.dtype.names)


def test_puma_fmi3_validates_and_has_the_fmi3_layout(puma_fmus):
    _, p3 = puma_fmus
    assert validate_fmu(str(p3)) == []
    # fmpy's stricter checks, off by default: the names' EBNF and the model structure's rules
    md = fmpy.read_model_description(str(p3), validate_variable_names=True, validate_model_structure=True)
    assert md.fmiVersion == "3.0" and md.guid.startswith("{")
    assert md.modelExchange is not None and md.coSimulation is not None
    names = zipfile.ZipFile(p3).namelist()
    assert "binaries/x86_64-linux/puma_thesis_com.so" in names
    assert "sources/fmi3_functions.c" in names and not any(n.endswith(".o") for n in names)
    vrs = [v.valueReference for v in md.modelVariables]
    assert len(vrs) == len(set(vrs))  # one value-reference space in FMI 3.0
    assert len(md.derivatives) == 12 and len(md.outputs) >= 12 and md.initialUnknowns


def test_puma_fmi3_exports_only_fmi3_functions(puma_fmus, tmp_path):
    _, p3 = puma_fmus
    with zipfile.ZipFile(p3) as z:
        z.extract("binaries/x86_64-linux/puma_thesis_com.so", tmp_path)
    so = tmp_path / "binaries/x86_64-linux/puma_thesis_com.so"
    out = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True, text=True, check=True)
    syms = [line.split()[-1] for line in out.stdout.splitlines() if line.strip()]
    assert len(syms) == 75 and all(s.startswith("fmi3") for s in syms), syms  # the whole FMI 3.0 API


@pytest.mark.parametrize("fmi_type", ["ModelExchange", "CoSimulation"])
def test_puma_fmi3_results_equal_fmi2(puma_fmus, fmi_type):
    p2, p3 = puma_fmus
    kw = dict(fmi_type=fmi_type, stop_time=0.5, output_interval=0.01, start_values={"tau[2]": 1.5})
    r2, r3 = fmpy.simulate_fmu(str(p2), **kw), fmpy.simulate_fmu(str(p3), **kw)
    assert _same(r2, r3) <= 1e-12
    assert abs(r3["q[2]"][-1]) > 0.1  # it moved


def test_ball_fmi3_validates_and_events_equal_fmi2(ball_fmus):
    p2, p3 = ball_fmus
    assert validate_fmu(str(p3)) == []
    md = fmpy.read_model_description(str(p3), validate_variable_names=True, validate_model_structure=True)
    assert len(md.eventIndicators) == 1
    for fmi_type in ("ModelExchange", "CoSimulation"):
        kw = dict(fmi_type=fmi_type, stop_time=2.0, output_interval=0.01)
        r2, r3 = fmpy.simulate_fmu(str(p2), **kw), fmpy.simulate_fmu(str(p3), **kw)
        assert _same(r2, r3) <= 1e-12, fmi_type
        assert r3["v"].max() > 1.0  # bounced (the speed reversed upwards)


def test_sampled_pi_fmi3_time_events_equal_fmi2(tmp_path):
    """A sampled component: its clock's ticks are time events (nextEventTime in ME, inside the step in
    CS), as in FMI 2.0; the fmugen clock annotation sits in FMI 3.0's <Annotations>."""
    m = load_component("lib:discrete_pi", overrides={"K_p": 0.5, "K_i": 2.0, "T_s": 0.1})
    p2, p3 = build_fmu(m, tmp_path / "pi2.fmu").path, build_fmu(m, tmp_path / "pi3.fmu", fmi_version=3).path
    assert validate_fmu(str(p3)) == []
    fmpy.read_model_description(str(p3), validate_variable_names=True, validate_model_structure=True)
    inp = np.array([(0.0, 1.0, 0.2), (1.0, 1.0, 0.2)], dtype=[("time", float), ("r", float), ("y", float)])
    for fmi_type in ("ModelExchange", "CoSimulation"):
        kw = dict(fmi_type=fmi_type, stop_time=1.0, output_interval=0.01, input=inp)
        r2, r3 = fmpy.simulate_fmu(str(p2), **kw), fmpy.simulate_fmu(str(p3), **kw)
        assert _same(r2, r3) <= 1e-12, fmi_type
        assert len(np.unique(r3["u"])) == 11  # held between the ticks at 0, 0.1, ..., 1


def test_urdf_robot_aliases_and_ranges_fmi3_equal_fmi2(tmp_path):
    """A URDF robot: joint-name aliases (<Alias> children in FMI 3.0), validity ranges
    (needsCompletedIntegratorStep)."""
    from fmugen.cli import symbolic_model

    m = symbolic_model(ROOT / "robots" / "ur5.urdf", ("p:tool0",), "newton_euler", "forward_dynamics")
    p2, p3 = build_fmu(m, tmp_path / "u2.fmu").path, build_fmu(m, tmp_path / "u3.fmu", fmi_version=3).path
    assert validate_fmu(str(p3)) == []
    md = fmpy.read_model_description(str(p3), validate_variable_names=True, validate_model_structure=True)
    assert md.modelExchange.needsCompletedIntegratorStep
    assert "<Alias name=\"shoulder_pan_joint.q\"" in zipfile.ZipFile(p3).read("modelDescription.xml").decode()
    for fmi_type in ("ModelExchange", "CoSimulation"):
        kw = dict(fmi_type=fmi_type, stop_time=0.2, output_interval=0.01, start_values={"tau[2]": 5.0})
        r2, r3 = fmpy.simulate_fmu(str(p2), **kw), fmpy.simulate_fmu(str(p3), **kw)
        assert _same(r2, r3) <= 1e-12, fmi_type


FMUSIM_SCRIPT = "tests/tools/build_fmusim.sh"


def _fmusim():
    """fmusim (Reference-FMUs' importer): $FMUSIM, on the PATH, or in the build script's default prefix."""
    for cand in (os.environ.get("FMUSIM"), shutil.which("fmusim"),
                 Path.home() / ".cache" / "fmugen" / "fmusim" / "fmusim"):
        if cand and Path(cand).is_file() and os.access(cand, os.X_OK):
            return str(cand)
    pytest.skip(f"fmusim not found: build it with {FMUSIM_SCRIPT} (or set $FMUSIM)")


def _run_fmusim(exe, fmu, tmp, interface, stop, extra=()):
    out = tmp / f"{Path(fmu).stem}_{interface}.csv"
    log = tmp / f"{Path(fmu).stem}_{interface}.log"
    r = subprocess.run([exe, "--interface-type", interface, "--stop-time", str(stop), "--output-interval", "0.01",
                        "--solver", "euler", *extra, "--log-fmi-calls", "--fmi-log-file", str(log),
                        "--output-file", str(out), str(fmu)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    return np.genfromtxt(out, delimiter=",", names=True), log.read_text()


@pytest.mark.parametrize("interface", ["me", "cs"])
def test_fmusim_runs_fmi3_as_fmi2(puma_fmus, ball_fmus, tmp_path, interface):
    """An independent FMI 3.0 importer (fmusim reads the XML with libxml2 against the FMI 3.0 schema and
    calls the functions itself): every call returns OK, and the results equal fmusim's of the FMI 2.0 FMU."""
    exe = _fmusim()
    for (p2, p3), stop, extra in ((puma_fmus, 0.5, ("--start-value", "tau[2]", "1.5")), (ball_fmus, 2.0, ())):
        r2, _ = _run_fmusim(exe, p2, tmp_path, interface, stop, extra)
        r3, log3 = _run_fmusim(exe, p3, tmp_path, interface, stop, extra)
        calls = [ln for ln in log3.splitlines() if ln.startswith("fmi3")]
        assert calls and all(ln.endswith("-> OK") for ln in calls), [ln for ln in calls if not ln.endswith("-> OK")]
        assert _same(r2, r3) <= 1e-12, (p3, interface)
    assert r3["v"].max() > 1.0  # the ball bounced under fmusim too


def _model(path, tmp, cls=FMU3Model, name="inst"):
    md = fmpy.read_model_description(str(path))
    d = fmpy.extract(str(path), unzipdir=str(tmp))
    log = []
    fmu = cls(guid=md.guid, unzipDirectory=d, modelIdentifier=md.modelExchange.modelIdentifier,
              instanceName=name)
    return md, fmu, log, (lambda env, status, cat, msg: log.append((status, msg.decode())))


def test_fmi3_misuse_returns_error_with_a_message(puma_fmus, tmp_path):
    _, p3 = puma_fmus
    md, fmu, log, cb = _model(p3, tmp_path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    # a wrong instantiation token: NULL, logged
    fmu.guid = "{not-this-fmu}"
    with pytest.raises(Exception):
        fmu.instantiate(logMessage=cb)
    assert any("does not match" in m for _, m in log), log
    fmu.guid = md.guid
    fmu.instantiate(logMessage=cb)

    def refused(call, text):
        log.clear()
        with pytest.raises(FMICallException) as e:
            call()
        assert "status 3" in str(e.value)
        assert any(text in m for _, m in log), log
        assert not any("fmi2" in m for _, m in log), log  # the importer called fmi3 functions

    refused(lambda: fmu.getFloat64([vr["q[1]"]]), "fmi3GetFloat64: not allowed in state instantiated")
    refused(lambda: fmu.exitInitializationMode(), "fmi3ExitInitializationMode: not allowed")
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    refused(lambda: fmu.getFloat64([100000]), "unknown value reference 100000")
    refused(lambda: fmu.setFloat64([vr["time"]], [1.0]), "cannot set time")
    refused(lambda: fmu.setFloat64([vr["der(q[1])"]], [1.0]), "cannot set der(q[1])")
    refused(lambda: fmu.getClock([0]), "not supported")
    refused(lambda: fmu.getBoolean([0]), "no variables of that type")
    refused(lambda: fmu.fmi3DoStep(fmu.component, 0.0, 0.1, False, ctypes.byref(fmpy.fmi3.fmi3Boolean()),
                                   ctypes.byref(fmpy.fmi3.fmi3Boolean()), ctypes.byref(fmpy.fmi3.fmi3Boolean()),
                                   ctypes.byref(fmpy.fmi3.fmi3Float64())), "Co-Simulation function")
    # the solver method is an Int32, after the Float64 value references; readable, fixed after init
    assert fmu.getInt32([vr["solver.method"]]) == [1]
    assert fmu.getFloat64([vr["time"]]) == [0.0]
    assert fmu.getNumberOfContinuousStates() == 12 and fmu.getNumberOfEventIndicators() == 0
    # a NULL instance: fmi3Error, no crash
    lib = fmu.dll
    lib.fmi3GetFloat64.restype = ctypes.c_int
    assert lib.fmi3GetFloat64(None, None, ctypes.c_size_t(0), None, ctypes.c_size_t(0)) == 3
    lib.fmi3DoStep.restype = ctypes.c_int
    assert lib.fmi3EnterEventMode(None) == 3
    fmu.terminate()
    fmu.freeInstance()


def test_fmi3_cs_event_mode_refused_and_fmu_state_round_trip(puma_fmus, tmp_path):
    _, p3 = puma_fmus
    md, fmu, log, cb = _model(p3, tmp_path, FMU3Slave)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu.logMessage = fmpy.fmi3.fmi3LogMessageCallback(cb)
    inst = fmu.fmi3InstantiateCoSimulation(b"cs", md.guid.encode(), b"", False, False, True, False, None, 0,
                                           None, fmu.logMessage, fmpy.fmi3.fmi3IntermediateUpdateCallback())
    assert not inst and any("eventModeUsed" in m for _, m in log), log
    fmu.instantiate(logMessage=cb)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.setFloat64([vr["tau[2]"]], [1.5])
    fmu.exitInitializationMode()
    fmu.doStep(0.0, 0.1)
    state = fmu.getFMUState()
    blob = fmu.serializeFMUState(state)
    fmu.doStep(0.1, 0.1)
    q_a = fmu.getFloat64([vr["q[2]"]])
    fmu.setFMUState(fmu.deserializeFMUState(blob))
    fmu.doStep(0.1, 0.1)
    assert fmu.getFloat64([vr["q[2]"]]) == q_a
    # a state's first output derivative is its derivative
    assert fmu.getOutputDerivatives([vr["q[2]"]], [1]) == fmu.getFloat64([vr["qd[2]"]])
    fmu.freeFMUState(state)
    fmu.terminate()
    fmu.reset()  # back to instantiated: initialisable again
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    assert fmu.getFloat64([vr["q[2]"], vr["time"]]) == [0.0, 0.0]
    fmu.terminate()
    fmu.freeInstance()


def test_fmi3_runtime_compiles_warning_free():
    from fmugen.fmi.build import fmi_headers_dir, runtime_dir

    out = subprocess.run(["cc", "-fsyntax-only", "-Wall", "-Wextra", "-pedantic", "-std=c99", "-Werror",
                          f"-I{runtime_dir()}", f"-I{fmi_headers_dir()}",
                          str(runtime_dir() / "fmi3" / "fmi3_functions.c")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_fmi_version_refusals(tmp_path):
    m = load_component(BALL)
    with pytest.raises(FmugenError, match="fmi_version must be 2 or 3, got 4"):
        build_fmu(m, tmp_path / "x.fmu", fmi_version=4)
    with pytest.raises(FmugenError, match="platform 'win32' is not one fmugen builds as FMI 3.0"):
        build_fmu(m, tmp_path / "x.fmu", fmi_version=3, platforms=["win32"])
    assert not list(tmp_path.iterdir())


def test_cli_fmi_version(tmp_path, capsys):
    assert cli_main(["build", str(BALL), "-o", str(tmp_path / "b.fmu"), "--fmi-version", "3"]) == 0
    assert fmpy.read_model_description(str(tmp_path / "b.fmu")).fmiVersion == "3.0"
    assert cli_main(["build", str(BALL), "-o", str(tmp_path / "c.fmu"), "--fmi-version", "2.5"]) != 0
    err = capsys.readouterr().err
    assert "--fmi-version" in err and len(err.strip().splitlines()) == 1
    # (scenes as FMI 3.0: tests/test_fmi3_scene.py; other platforms: tests/test_platforms_fmi3.py)
    assert cli_main(["build", str(BALL), "-o", str(tmp_path / "d.fmu"), "--fmi-version", "3",
                     "--platforms", "linux32"]) == 2
    err = capsys.readouterr().err
    assert "is not one fmugen builds as FMI 3.0" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "c.fmu").exists() and not (tmp_path / "d.fmu").exists()


def test_fmi3_directional_derivative_equals_fmi2(puma_fmus, tmp_path):
    from fmpy.fmi2 import FMU2Model

    p2, p3 = puma_fmus
    md3, fmu3, _, cb = _model(p3, tmp_path / "3")
    md2 = fmpy.read_model_description(str(p2))
    fmu2 = FMU2Model(guid=md2.guid, unzipDirectory=fmpy.extract(str(p2), unzipdir=str(tmp_path / "2")),
                     modelIdentifier=md2.modelExchange.modelIdentifier, instanceName="i2")
    fmu3.instantiate(logMessage=cb)
    fmu2.instantiate()
    fmu2.setupExperiment(startTime=0.0)
    for f in (fmu3, fmu2):
        f.enterInitializationMode() if f is fmu2 else f.enterInitializationMode(startTime=0.0)
        f.exitInitializationMode()
    vr = {v.name: v.valueReference for v in md3.modelVariables}
    unknowns = [vr[f"der(qd[{k}])"] for k in range(1, 7)] + [vr["p_ee[1]"]]
    knowns = [vr["q[2]"], vr["qd[3]"], vr["tau[1]"]]
    seed = [1.0, -0.5, 2.0]
    d3 = fmu3.getDirectionalDerivative(unknowns, knowns, seed)
    d2 = fmu2.getDirectionalDerivative(unknowns, knowns, seed)  # the FMI 2.0 Real value references are the same
    assert list(d3) == list(d2) and any(abs(x) > 1e-3 for x in d3)
    for f in (fmu3, fmu2):
        f.terminate()
        f.freeInstance()


def test_fmi3_binary_built_from_the_build_description(puma_fmus, tmp_path):
    """sources/buildDescription.xml: fmpy compiles the binary from it (CMake), and that FMU computes
    what fmugen's binary does."""
    pytest.importorskip("cmake")
    from fmpy.build import build_platform_binary
    from fmpy.model_description import read_build_description

    _, p3 = puma_fmus
    d = tmp_path / "src"
    with zipfile.ZipFile(p3) as z:
        z.extractall(d)
    (bc,) = read_build_description(str(p3))  # schema-validated by fmpy
    assert "fmi3_functions.c" in bc.sourceFileSets[0].sourceFiles
    so = d / "binaries/x86_64-linux/puma_thesis_com.so"
    so.unlink()
    (tmp_path / "cmake").mkdir()
    build_platform_binary(str(d.resolve()), build_dir=str(tmp_path / "cmake"))
    assert so.is_file()
    # FMI2_Export defined empty: no dllexport on the runtime's fmi2* functions (a DLL then exports fmi3* alone)
    assert [(d.name, d.value) for d in bc.sourceFileSets[0].preprocessorDefinitions] == [("FMI2_Export", "")]
    kw = dict(fmi_type="CoSimulation", stop_time=0.2, output_interval=0.01, start_values={"tau[2]": 1.5})
    ref = fmpy.simulate_fmu(str(p3), **kw)
    assert _same(ref, fmpy.simulate_fmu(str(d), **kw)) <= 1e-12


def test_fmi3_model_exchange_misuse_and_logging(ball_fmus, tmp_path):
    """ME of the bouncing ball: wrong array lengths, a function out of its mode, an unknown log
    category: fmi3Error and a message; debug logging reaches FMI 3.0's logger with fmi3 names; the
    event indicator read as a variable equals fmi3GetEventIndicators."""
    _, p3 = ball_fmus
    md, fmu, log, cb = _model(p3, tmp_path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu.instantiate(loggingOn=True, logMessage=cb)
    fmu.setDebugLogging(True, ["logEvents"])
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    assert any("fmi3InstantiateModelExchange" not in m and "fmi3" in m for _, m in log)  # OK messages arrived
    assert not any("fmi2" in m for _, m in log), log

    def refused(call, text):
        log.clear()
        with pytest.raises(FMICallException):
            call()
        assert any(text in m for _, m in log), log

    x3 = (fmpy.fmi3.fmi3Float64 * 3)()
    refused(lambda: fmu.getContinuousStates(x3, 3), "nx = 3, but the model has 2")
    refused(lambda: fmu.getEventIndicators(x3, 3), "= 3, but the model has 1")
    refused(lambda: fmu.setDebugLogging(True, ["logNothing"]), "unknown log category")
    refused(lambda: fmu.enterContinuousTimeMode() or fmu.updateDiscreteStates(),
            "fmi3UpdateDiscreteStates: not allowed in state continuousTimeMode")
    refused(lambda: fmu.setContinuousStates((fmpy.fmi3.fmi3Float64 * 2)(float("nan"), 0.0), 2), "")
    fmu.setTime(0.1)
    z = (fmpy.fmi3.fmi3Float64 * 1)()
    fmu.getEventIndicators(z, 1)
    assert fmu.getFloat64([vr["solver.event_indicator_1"]]) == [z[0]] and z[0] > 0  # h above the ground
    fmu.terminate()
    fmu.freeInstance()


def test_linearize_fmu_of_fmi3_equals_fmi2(puma_fmus):
    """fmugen.linearize_fmu on the FMI 3.0 FMU (fmi3GetDirectionalDerivative through fmpy's FMU3Model):
    the A, B, C, D of the FMI 2.0 FMU, at a pose with a torque applied."""
    from fmugen.control import linearize_fmu

    p2, p3 = puma_fmus
    x = {"q[2]": 0.3, "q[3]": -0.2, "qd[1]": 0.5}
    u = {"tau[2]": 1.5}
    s2, s3 = linearize_fmu(p2, x=x, u=u), linearize_fmu(p3, x=x, u=u)
    assert s2.A.shape == s3.A.shape == (12, 12) and s3.B.shape[1] == 6
    for m2, m3 in ((s2.A, s3.A), (s2.B, s3.B), (s2.C, s3.C), (s2.D, s3.D)):
        assert np.max(np.abs(m3 - m2)) <= 1e-12 * max(1.0, np.max(np.abs(m2)))
    assert np.max(np.abs(s3.A[6:, :6])) > 1.0  # gravity and inertia coupling: not a trivial matrix


def test_fmi3_sources_rebuilt_by_the_readme_command(puma_fmus, tmp_path):
    """sources/README.txt's Linux command of the FMI 3.0 FMU (cc, FMI2_Export empty, the version script):
    warning-free, a library that exports the fmi3* functions alone and computes what the shipped one does."""
    _, p3 = puma_fmus
    d = tmp_path / "fmu"
    with zipfile.ZipFile(p3) as z:
        z.extractall(d)
    src = d / "sources"
    cmd = (src / "README.txt").read_text().split("\n\n")[1].strip()
    assert cmd.startswith("cc ") and "-DFMI2_Export=" in cmd and "--version-script" in cmd
    r = subprocess.run(cmd, shell=True, cwd=src, capture_output=True, text=True)
    assert r.returncode == 0 and not r.stderr, r.stderr[:2000]
    so = d / "binaries" / "x86_64-linux" / "puma_thesis_com.so"
    shutil.move(str(src / "puma_thesis_com.so"), str(so))  # in place of the shipped binary
    out = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True, text=True, check=True)
    exported = {line.split()[-1] for line in out.stdout.splitlines() if line.strip()}
    assert exported and all(e.startswith("fmi3") for e in exported), sorted(exported)[:5]
    kw = dict(fmi_type="CoSimulation", stop_time=0.2, output_interval=0.01, start_values={"tau[2]": 1.5})
    assert _same(fmpy.simulate_fmu(str(p3), **kw), fmpy.simulate_fmu(str(d), **kw)) <= 1e-12
