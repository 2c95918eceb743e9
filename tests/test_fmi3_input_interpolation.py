"""FMI 3.0 inputs set in the intermediate update: the replacement for FMI 2.0's input derivatives.

An fmugen FMI 3.0 Co-Simulation FMU whose importer names inputs in requiredIntermediateVariables asks for
them with intermediateVariableSetRequested = true wherever its solver needs u(t) inside fmi3DoStep
(c_runtime/fmi3/fmi3_functions.c, intermediate_inputs); fmugen's master sets its extrapolation polynomial's
values there (fmugen/cosim/units3.py, Slave3Unit).  So an FMI 3.0 system is coupled with the same
interpolated inputs as its FMI 2.0 twin (fmi2SetRealInputDerivatives):

* the hydraulic joint cut in two (examples/scenes/single_joint_split.toml) under gauss-seidel/linear and
  jacobi/linear: FMI 3.0 equals FMI 2.0 to 1e-12 rad (measured: 0.0, bit for bit), while the coupling error
  against the monolithic reference is 1.7e-5 .. 1.1e-6 rad (gauss-seidel) and 8.7e-5 .. 5.4e-6 rad (jacobi)
  for H = 4, 2, 1 ms, falling with order 2.0 as the macro step halves;
* the FMU alone through fmpy's FMU3Slave with a ctypes callback setting a known ramp equals the FMI 2.0 FMU
  with fmi2SetRealInputDerivatives of the same ramp (to 1e-12; measured 0.0: the same values at the same
  solver stages), while holding the ramp's start over each step is 0.36 rad/s off;
* misuse in the callback returns fmi3Error with a message.
"""
from __future__ import annotations

import ctypes
import math
import zipfile
from pathlib import Path

import fmpy
import fmpy.fmi3
import numpy as np
import pytest
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave, fmi3IntermediateUpdateCallback
from fmpy.validation import validate_fmu

from fmugen.cosim import run
from fmugen.cosim.reference import solve_reference
from fmugen.fmi.platforms import host_platform
from fmugen.scene import load_scene

ROOT = Path(__file__).resolve().parent.parent
SPLIT = ROOT / "examples" / "scenes" / "single_joint_split.toml"
STOP = 0.3
STEPS = (4e-3, 2e-3, 1e-3)

pytestmark = pytest.mark.skipif(host_platform() != "linux64", reason="FMI 3.0 export: x86_64 Linux only so far")


@pytest.fixture(scope="module")
def split(tmp_path_factory):
    """single_joint_split's groups as FMI 2.0 and FMI 3.0 FMUs, their systems, and the reference solution."""
    d = tmp_path_factory.mktemp("fmi3_interp")
    out = {}
    for version in (2, 3):
        scene = load_scene(SPLIT, set={"scene.fmi_version": version, "scene.stop": STOP})
        built = scene.build(d / f"v{version}", use_cache=False)
        paths = {g: Path(f.path) for g, f in built.fmus.items()}
        out[version] = (scene.cosim_system(paths), paths)
    times = np.linspace(0.0, STOP, int(round(STOP / STEPS[-1])) + 1)
    out["ref"] = solve_reference(scene.reference_problem(), times=times)
    return out


def _error(result, ref, column="joint.theta"):
    h = ref.time[1] - ref.time[0]
    idx = np.rint((result.time - ref.time[0]) / h).astype(int)
    assert np.allclose(ref.time[idx], result.time, atol=1e-12)
    return float(np.max(np.abs(result[column] - ref[column][idx])))


def test_inputs_declared_for_the_intermediate_update(split):
    _, paths = split[3]
    for g, path in paths.items():
        xml = zipfile.ZipFile(path).read("modelDescription.xml").decode()
        inputs = [ln for ln in xml.splitlines() if 'causality="input"' in ln]
        assert inputs and all('intermediateUpdate="true"' in ln for ln in inputs), (g, inputs)
        assert validate_fmu(str(path)) == [], g


@pytest.mark.parametrize("scheme", ["gauss-seidel", "jacobi"])
def test_fmi3_system_interpolates_as_fmi2(split, scheme):
    """FMI 3.0 with inputs set in the intermediate update = FMI 2.0 with input derivatives, far below the
    coupling error, which converges with order ~2 (linear extrapolation) for both."""
    (s2, _), (s3, _), ref = split[2], split[3], split["ref"]
    errors, diffs = [], []
    for H in STEPS:
        r2, r3 = run(s2, scheme, "linear", step=H), run(s3, scheme, "linear", step=H)
        assert r2.ok and r3.ok, (r2.summary, r3.summary)
        assert not [w for w in r3.summary.warnings if "no input derivatives" in w], r3.summary.warnings
        diffs.append(max(float(np.max(np.abs(r2[c] - r3[c]))) for c in ("joint.theta", "joint.w")))
        errors.append(_error(r3, ref))
        assert errors[-1] == pytest.approx(_error(r2, ref), rel=1e-6, abs=1e-15)
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    assert all(1.6 < p < 2.6 for p in orders), (errors, orders)
    assert max(diffs) <= 1e-12 and max(diffs) < 1e-4 * min(errors), (diffs, errors)


def test_fmi3_without_setting_is_held_and_worse(split, monkeypatch):
    """The same FMI 3.0 FMUs with the master's fallback (inputs held at the extrapolant's midpoint over each
    step, said in Summary.warnings): what the intermediate update replaces.  Measured at H = 4 ms: 2.38e-5
    rad against 1.73e-5 rad interpolated (the midpoint is second order too, with a larger constant)."""
    import fmugen.cosim.units3 as units3

    (s3, _), ref = split[3], split["ref"]
    good = run(s3, "gauss-seidel", "linear", step=STEPS[0])
    monkeypatch.setattr(units3, "_intermediate_inputs", lambda unzip: [])
    held = run(s3, "gauss-seidel", "linear", step=STEPS[0])
    assert held.ok and any("held at the midpoint" in w for w in held.summary.warnings)
    assert _error(held, ref) > 1.25 * _error(good, ref), (_error(held, ref), _error(good, ref))


def test_an_fmu_that_never_requests_its_inputs_is_said(split, monkeypatch):
    """An FMU declaring intermediateUpdate inputs whose callback never requests setting (here: fmugen's, told
    no input in requiredIntermediateVariables) held its inputs at U_n: the run says so in Summary.warnings."""
    import fmugen.cosim.units3 as units3

    instantiate = units3.Slave3Unit._instantiate

    def without_required(self, path):
        keep, self.intermediate_inputs = self.intermediate_inputs, []
        try:
            instantiate(self, path)
        finally:
            self.intermediate_inputs = keep

    (s3, _), ref = split[3], split["ref"]
    good = run(s3, "gauss-seidel", "linear", step=STEPS[0])
    monkeypatch.setattr(units3.Slave3Unit, "_instantiate", without_required)
    silent = run(s3, "gauss-seidel", "linear", step=STEPS[0])
    said = [w for w in silent.summary.warnings if "never requested them" in w]
    assert silent.ok and len(said) == 1 and "'chain', 'joint'" in said[0], silent.summary.warnings
    assert not [w for w in good.summary.warnings if "never requested" in w]
    assert _error(silent, ref) > 1.25 * _error(good, ref)


# ---- the FMU alone: a ctypes callback setting a known ramp -----------------------------------------------

TAU0, TAU1 = 150.0, -900.0  # the ramp tau(t) = TAU0 + TAU1 (t - t_n) of each step, restarted at every point
H = 0.01


def _vr(md):
    return {v.name: v.valueReference for v in md.modelVariables}


def _fmi2_run(path, n=20):
    md = fmpy.read_model_description(str(path))
    vr = _vr(md)
    f = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="j2")
    f.instantiate()
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    f.exitInitializationMode()
    rows = []
    for k in range(n):
        f.setReal([vr["tau"]], [TAU0 + 10.0 * k])
        f.setRealInputDerivatives([vr["tau"]], [1], [TAU1])
        f.doStep(k * H, H)
        rows.append(f.getReal([vr["theta"], vr["w"]]))
    f.terminate()
    f.freeInstance()
    return np.array(rows)


class _Fmi3Run:
    """The FMI 3.0 joint FMU through fmpy's FMU3Slave, instantiated with a ctypes callback; ``plan(t, lib, c)``
    runs inside it when setting is requested (default: the ramp)."""

    def __init__(self, path, required=("tau",), plan=None, get_plan=None):
        self.md = md = fmpy.read_model_description(str(path))
        self.vr = _vr(md)
        self.log, self.calls, self.results = [], [], []
        self.t_n, self.k = 0.0, 0
        self.plan, self.get_plan = plan, get_plan
        f = self.f = FMU3Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(path)),
                               modelIdentifier=md.coSimulation.modelIdentifier, instanceName="j3")
        self.callback = fmi3IntermediateUpdateCallback(self._cb)  # kept alive with the run
        f.logMessage = fmpy.fmi3.fmi3LogMessageCallback(lambda env, st, cat, msg: self.log.append((st, msg.decode())))
        req = [self.vr[r] for r in required]
        f.component = f.fmi3InstantiateCoSimulation(b"j3", md.guid.encode(), b"", False, False, False, False,
                                                    (fmpy.fmi3.fmi3ValueReference * len(req))(*req), len(req),
                                                    None, f.logMessage, self.callback)
        assert f.component
        f.enterInitializationMode(startTime=0.0)
        f.exitInitializationMode()
        self.lib = f.dll

    def _cb(self, env, t, set_requested, get_allowed, step_finished, can_return_early, requested, when):
        try:
            self.calls.append((t, bool(set_requested), bool(get_allowed), bool(step_finished)))
            if set_requested:
                if self.plan is not None:
                    self.results.append(self.plan(t, self.lib, self.f.component))
                    return
                v = (ctypes.c_double * 1)(TAU0 + 10.0 * self.k + TAU1 * (t - self.t_n))
                st = self.lib.fmi3SetFloat64(self.f.component, (ctypes.c_uint32 * 1)(self.vr["tau"]), 1, v, 1)
                assert st == 0, st
            elif self.get_plan is not None:
                self.results.append(self.get_plan(t, self.lib, self.f.component))
        except Exception as e:  # noqa: BLE001 -- reported by the test
            self.calls.append(("error", repr(e)))

    def run(self, n=20):
        rows = []
        for k in range(n):
            self.k, self.t_n = k, k * H
            self.f.setFloat64([self.vr["tau"]], [TAU0 + 10.0 * k])
            self.f.doStep(k * H, H)
            rows.append(self.f.getFloat64([self.vr["theta"], self.vr["w"]]))
        return np.array(rows)

    def close(self):
        self.f.terminate()
        self.f.freeInstance()


def test_fmu_takes_a_ramp_set_in_the_intermediate_update(split):
    """Setting tau(t) of a ramp at the requested times gives what fmi2SetRealInputDerivatives of the same ramp
    gives (the same inputs at the same solver stages); without inputs in requiredIntermediateVariables the
    FMU never requests setting and holds tau over each step, as before."""
    p2, p3 = split[2][1]["joint"], split[3][1]["joint"]
    ref = _fmi2_run(p2)
    r = _Fmi3Run(p3)
    got = r.run()
    r.close()
    assert not [c for c in r.calls if c[0] == "error"], r.calls
    sets = [c for c in r.calls if c[1]]
    assert sets and all(not get and not fin for _, _, get, fin in sets)  # a trial stage: no getting
    assert all(0.0 <= c[0] <= 20 * H + 1e-12 for c in sets)
    assert np.max(np.abs(got - ref)) <= 1e-12 * max(1.0, float(np.max(np.abs(ref)))), np.max(np.abs(got - ref))
    held = _Fmi3Run(p3, required=())
    h = held.run()
    held.close()
    assert not [c for c in held.calls if c[1]]  # no set request
    assert np.max(np.abs(h - ref)) > 1e3 * max(np.max(np.abs(got - ref)), 1e-15)


def test_misuse_in_the_intermediate_update(split):
    """In a set request only the inputs named in requiredIntermediateVariables may be set, finite; an output,
    a parameter, an input not named, getting, and setting when setting is not requested are refused with
    fmi3Error and a message; the step goes on."""
    path = split[3][1]["chain"]
    md = fmpy.read_model_description(str(path))
    vr = _vr(md)
    parameter = next(v.name for v in md.modelVariables if v.causality == "parameter")
    one = lambda name, value=1.0: ((ctypes.c_uint32 * 1)(vr[name]), (ctypes.c_double * 1)(value))  # noqa: E731

    def plan(t, lib, c):
        if t == 0.0 or any(isinstance(x, list) for x in r.results):
            return None
        out = []
        for name, value in (("actuator.tau", 1.0), (parameter, 1.0), ("actuator.w", 0.1), ("amp.theta", math.nan)):
            refs, vals = one(name, value)
            out.append(lib.fmi3SetFloat64(c, refs, 1, vals, 1))
        refs, vals = one("actuator.tau")
        out.append(lib.fmi3GetFloat64(c, refs, 1, vals, 1))
        refs, vals = one("amp.theta", 0.0)
        out.append(lib.fmi3SetFloat64(c, refs, 1, vals, 1))  # the one allowed
        return out

    def get_plan(t, lib, c):  # after an accepted step: setting is not requested
        refs, vals = one("amp.theta", 0.0)
        return ("get", lib.fmi3SetFloat64(c, refs, 1, vals, 1))

    r = _Fmi3Run(path, required=("amp.theta",), plan=plan, get_plan=get_plan)
    f = r.f
    f.doStep(0.0, 0.01)
    sets = [x for x in r.results if isinstance(x, list)]
    gets = [x for x in r.results if isinstance(x, tuple)]
    assert sets and sets[0] == [3, 3, 3, 3, 3, 0], (sets[0], [m for _, m in r.log])
    assert gets and all(st == 3 for _, st in gets)
    msgs = [m for _, m in r.log]
    assert any("actuator.tau" in m and "only inputs" in m for m in msgs), msgs
    assert any("actuator.w" in m and "requiredIntermediateVariables" in m for m in msgs), msgs
    assert any("not finite" in m for m in msgs), msgs
    assert any(m.startswith("fmi3GetFloat64: not allowed in Intermediate Update Mode") for m in msgs), msgs
    assert any(m.startswith("fmi3SetFloat64: not allowed in Intermediate Update Mode") and "SetRequested is false"
               in m for m in msgs), msgs
    f.terminate()
    f.freeInstance()
