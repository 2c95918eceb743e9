"""FMI 3.0 FMUs in fmugen's co-simulation master (fmugen/cosim/units3.py), alone and mixed with FMI 2.0.

fmugen's FMI 3.0 FMUs run the FMI 2.0 runtime (c_runtime/fmi3), so a system of them must give what the
same system of FMI 2.0 FMUs gives, bit for bit: the split actuator-chain rig of the other cosim tests
(tests/cosim_rigs.py) built both ways, under every scheme, mixed, in the ME block, with rollback and
Newton.  FMI 3.0 has no input derivatives: the master sets an fmugen FMI 3.0 FMU's inputs in the
intermediate update to the values of the polynomial it passes an FMI 2.0 FMU as input derivatives
(tests/test_fmi3_input_interpolation.py), so both interpolate alike.  An FMI 3.0 FMU whose inputs are
not intermediateUpdate="true" holds them at the extrapolant's midpoint, as its FMI 2.0 twin told it
cannot interpolate (``held_fmi2``) does.
The bouncing ball (state events) in the ME block against its closed-form bounce times; an SSP archive
of FMI 3.0 FMUs; refusals in one line.
"""
from __future__ import annotations

import math
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import fmugen
import fmugen.cosim.units as units
import fmugen.cosim.units3 as units3
from cosim_rigs import CHAIN_LINKS, INTERNAL, _components, amp_split_system, split_system
from fmugen.components import amplifier, assemble, current_driver, hydraulic_actuator, joint_inertia, servo_valve
from fmugen.components.equations import load_component
from fmugen.cosim import Master, run
from fmugen.cosim.errors import CosimError
from fmugen.cosim.system import CosimSystem, Recorded, Unit
from fmugen.fmi.platforms import host_platform

ROOT = Path(__file__).resolve().parent.parent
BALL = ROOT / "examples" / "components" / "bouncing_ball.toml"
STOP = 0.2

pytestmark = pytest.mark.skipif(host_platform() != "linux64", reason="FMI 3.0 export: x86_64 Linux only so far")


@pytest.fixture(scope="module")
def rig3(tmp_path_factory):
    """The FMI 3.0 twins of split_system("stiff", "smooth")'s FMUs (cosim_rigs.fmu_dir builds the FMI 2.0 ones)."""
    d = tmp_path_factory.mktemp("rig3")
    comps, links = _components("stiff", "smooth", False)
    fmugen.build_fmu(assemble("chain", comps, links, outputs=["actuator.tau"]), d / "chain.fmu", fmi_type="both",
                     fmi_version=3)
    fmugen.build_fmu(joint_inertia(parameter_set="stiff", name="joint"), d / "joint.fmu", fmi_type="both",
                     fmi_version=3)
    return d


@pytest.fixture(scope="module")
def amp3(tmp_path_factory):
    """The FMI 3.0 twins of amp_split_system()'s three CS FMUs (the amplifier has no states: Newton takes its
    columns from fmi3GetDirectionalDerivative)."""
    d = tmp_path_factory.mktemp("amp3")
    ps = "default"
    amp = assemble("amp", {"amp": amplifier(parameter_set=ps, name="amp")}, [], outputs=["amp.u"])
    fmugen.build_fmu(amp, d / "amp.fmu", fmi_type="cs", fmi_version=3)
    comps = {"driver": current_driver(parameter_set=ps, name="driver"),
             "valve": servo_valve(parameter_set=ps, name="valve"),
             "actuator": hydraulic_actuator(parameter_set=ps, name="actuator")}
    fmugen.build_fmu(assemble("chain", comps, CHAIN_LINKS[1:], outputs=["actuator.tau"]), d / "chain.fmu",
                     fmi_type="cs", fmi_version=3)
    fmugen.build_fmu(joint_inertia(parameter_set=ps, name="joint"), d / "joint.fmu", fmi_type="cs", fmi_version=3)
    return d


@pytest.fixture(scope="module")
def balls(tmp_path_factory):
    d = tmp_path_factory.mktemp("ball")
    m = load_component(BALL)
    return (fmugen.build_fmu(m, d / "ball2.fmu", fmi_type="me").path,
            fmugen.build_fmu(m, d / "ball3.fmu", fmi_type="me", fmi_version=3).path)


@pytest.fixture
def held_fmi2(monkeypatch):
    """FMI 2.0 CS units told they cannot interpolate inputs, as FMI 3.0 cannot."""
    make = units.SlaveUnit._make_fmu

    def held(self):
        fmu = make(self)
        self.can_interpolate = False
        return fmu

    monkeypatch.setattr(units.SlaveUnit, "_make_fmu", held)


def twin(system, d, names=None, **changes):
    """``system`` with the FMUs of units ``names`` (all) taken from folder ``d`` (their FMI 3.0 twins)."""
    return replace(system, units=tuple(replace(u, path=d / Path(u.path).name, **changes)
                                       if names is None or u.name in names else u for u in system.units))


def me(unit):
    return replace(unit, fmi_type="me", start_values={k: v for k, v in unit.start_values.items()
                                                      if not k.startswith("solver.")})


def largest_difference(a, b) -> float:
    assert a.columns == b.columns and np.array_equal(a.time, b.time)
    return max(float(np.max(np.abs(a[c] - b[c]))) for c in a.columns)


def work(r):
    s = r.summary
    return s.status, s.macro_steps, s.rollbacks, s.iterations, s.jacobians, s.do_steps


def test_units_are_the_fmus_version(rig3):
    s3 = twin(split_system("stiff", "smooth", stop=STOP), rig3, ("chain",))
    with Master(s3, "jacobi", "hold") as m:
        chain, joint = m.units
        assert type(chain) is units3.Slave3Unit and type(joint) is units.SlaveUnit
        assert chain.md.fmiVersion == "3.0" and chain.md.guid.startswith("{")  # the instantiation token
        # interpolates: its inputs are set in the intermediate update (providesIntermediateUpdate, inputs
        # intermediateUpdate="true")
        assert chain.can_interpolate and chain.can_save_state and chain.max_output_derivative_order == 1
        assert sorted(chain.intermediate_inputs) == sorted(v.valueReference for v in chain.md.modelVariables
                                                           if v.causality == "input")
        assert chain.variables["solver.method"].type == "Int32"


SCHEMES = [("jacobi", "hold"), ("gauss-seidel", "hold"), ("newton", "linear"), ("jacobi", "linear"),
           ("gauss-seidel", "linear"), ("iterative", "linear"), ("jacobi", "quadratic"), ("newton", "quadratic"),
           ("iterative", "cubic")]


@pytest.mark.parametrize("scheme,extrapolation", SCHEMES)
def test_fmi3_system_equals_fmi2_under_each_scheme(rig3, scheme, extrapolation):
    s2 = split_system("stiff", "smooth", stop=STOP)
    r2 = run(s2, scheme, extrapolation, step=1e-3)
    r3 = run(twin(s2, rig3), scheme, extrapolation, step=1e-3)
    assert r2.ok and r3.ok, (r2.summary, r3.summary)
    assert largest_difference(r2, r3) <= 1e-12  # 0.0: the same runtime
    assert work(r2) == work(r3)
    assert abs(r3["joint.theta"][-1]) > 1e-4  # it moved
    assert not [w for w in r3.summary.warnings if "FMI 3.0 has no input derivatives" in w], r3.summary.warnings


def test_fmi3_without_intermediate_inputs_is_the_fmi2_fmu_that_cannot_interpolate(rig3, held_fmi2, monkeypatch):
    """An FMI 3.0 FMU whose inputs cannot be set in the intermediate update (a third-party one without
    intermediateUpdate="true" inputs) holds them at the extrapolant's midpoint, said in Summary.warnings:
    bit for bit the FMI 2.0 twin told it cannot interpolate."""
    monkeypatch.setattr(units3, "_intermediate_inputs", lambda unzip: [])
    s2 = split_system("stiff", "smooth", stop=STOP)
    for scheme, ext in (("gauss-seidel", "linear"), ("jacobi", "linear"), ("newton", "linear")):
        r2, r3 = run(s2, scheme, ext, step=1e-3), run(twin(s2, rig3), scheme, ext, step=1e-3)
        assert r2.ok and r3.ok
        assert largest_difference(r2, r3) <= 1e-12 and work(r2) == work(r3)
        said = [w for w in r3.summary.warnings if "FMI 3.0 has no input derivatives" in w]
        assert len(said) == 1 and "held at the midpoint" in said[0], r3.summary.warnings


def test_dense_output_slopes_from_fmi3_get_output_derivatives(rig3):
    s2 = split_system("stiff", "smooth", stop=0.05)
    r2 = run(s2, "gauss-seidel", "hold", step=1e-3, dense=True)
    r3 = run(twin(s2, rig3), "gauss-seidel", "hold", step=1e-3, dense=True)
    assert r2.ok and r3.ok and r3.slopes is not None
    assert np.array_equal(r2.slopes, r3.slopes, equal_nan=True)
    assert np.all(np.isfinite(r3.slopes[:, :2])) and np.any(r3.slopes[:, 0] != 0)  # joint.theta, joint.w


@pytest.mark.parametrize("fmi3_units", [("chain",), ("joint",)])
def test_mixed_fmi2_fmi3_system_equals_all_fmi2(rig3, fmi3_units):
    s2 = split_system("stiff", "smooth", stop=STOP)
    for scheme, ext in (("gauss-seidel", "hold"), ("newton", "linear")):
        r2, rm = run(s2, scheme, ext, step=1e-3), run(twin(s2, rig3, fmi3_units), scheme, ext, step=1e-3)
        assert r2.ok and rm.ok
        assert largest_difference(r2, rm) <= 1e-12 and work(r2) == work(rm), (scheme, fmi3_units)


def test_rollback_and_adaptive_steps_on_fmi3(rig3):
    """Adaptive macro steps roll FMI 3.0 FMUs back (fmi3GetFMUState / fmi3SetFMUState), also under Newton
    (whose interface Jacobian re-steps rolled-back FMUs): the same steps and results as FMI 2.0."""
    s2 = split_system("stiff", "smooth", stop=STOP)
    # newton/linear at tol 1e-4: with interpolated inputs 1e-3 needs no rollback (held at the midpoint it did)
    for kw in (dict(scheme="gauss-seidel", extrapolation="hold", step=5e-3, tol=1e-2),
               dict(scheme="newton", extrapolation="linear", step=5e-3, tol=1e-4)):
        r2, r3 = run(s2, adaptive=True, **kw), run(twin(s2, rig3), adaptive=True, **kw)
        assert r3.summary.failure is None and r3.summary.rollbacks >= 2, r3.summary
        assert largest_difference(r2, r3) <= 1e-12 and work(r2) == work(r3), kw


def test_newton_with_directional_derivatives_of_an_fmi3_fmu(amp3):
    """The amplifier FMU has no states: Newton's columns for it are fmi3GetDirectionalDerivative's (unknowns,
    knowns, seed and sensitivity with their sizes), equal to fmi2GetDirectionalDerivative's."""
    s2 = amp_split_system(stop=STOP)
    s3 = twin(s2, amp3)
    with Master(s3, "newton", "linear") as m:
        assert [u.algebraic for u in m.units] == [True, False, False]
    r2, r3 = run(s2, "newton", "linear", step=2e-3), run(s3, "newton", "linear", step=2e-3)
    assert r3.ok and r3.summary.jacobians >= 1
    assert largest_difference(r2, r3) <= 1e-12 and work(r2) == work(r3)


def test_me_fmi3_in_the_me_block_equals_its_fmi2_twin(rig3):
    s2 = split_system("stiff", "smooth", stop=0.3)
    all2 = replace(s2, units=tuple(me(u) for u in s2.units))
    all3 = twin(all2, rig3)
    r2, r3 = run(all2, "jacobi", "hold", step=0.05), run(all3, "jacobi", "hold", step=0.05)
    assert r2.ok and r3.ok and largest_difference(r2, r3) <= 1e-12
    # a CS chain (FMI 2.0) and an ME joint (FMI 3.0)
    mixed2 = replace(s2, units=(s2.units[0], me(s2.units[1])), stop_time=0.1)
    r2 = run(mixed2, "gauss-seidel", "linear", step=1e-3)
    r3 = run(twin(mixed2, rig3, ("joint",)), "gauss-seidel", "linear", step=1e-3)
    assert r2.ok and r3.ok and largest_difference(r2, r3) <= 1e-12
    # the block's Jacobian from fmi3GetDirectionalDerivative, against fmi2GetDirectionalDerivative's
    jacobians = []
    for system in (all2, all3):
        with Master(system, "jacobi", "hold") as m:
            assert m.run(step=0.05, stop=0.1).ok
            blk = m.me_block
            x = blk._current_x()
            jacobians.append(blk.jac(0.1, x))
            assert blk.nominal.shape == x.shape
    assert np.count_nonzero(jacobians[0]) > 0 and np.array_equal(jacobians[0], jacobians[1])


def _bounces(stop, h0=1.0, g=9.81, e=0.7):
    """Closed form: t_1 = sqrt(2 h0 / g), t_{k+1} = t_k + 2 e^k sqrt(2 g h0) / g."""
    t = [math.sqrt(2 * h0 / g)]
    while True:
        nxt = t[-1] + 2 * e ** len(t) * math.sqrt(2 * g * h0) / g
        if nxt > stop:
            return t
        t.append(nxt)


def _height(times, bounces, h0=1.0, g=9.81, e=0.7):
    """The ball's height from the closed-form bounce times (a parabola between two bounces)."""
    out = np.empty(len(times))
    for i, t in enumerate(times):
        k = int(np.searchsorted(bounces, t))
        if k == 0:
            out[i] = h0 - 0.5 * g * t * t
        else:
            v0, s = e ** k * math.sqrt(2 * g * h0), t - bounces[k - 1]
            out[i] = v0 * s - 0.5 * g * s * s
    return out


def test_bouncing_ball_me_fmi3_state_events_at_the_closed_form_bounce_times(balls):
    """The ME block locates the ball's state events (fmi3GetEventIndicators, fmi3EnterEventMode,
    fmi3UpdateDiscreteStates; the ground reached at the bounce times) as it does those of the FMI 2.0 twin."""
    stop = 2.0
    exact = _bounces(stop)
    assert len(exact) == 4
    found = []
    for path in balls:
        system = CosimSystem("ball", (Unit("ball", path, "me", {}),), (),
                             (Recorded("h", "ball", "h", "m"), Recorded("v", "ball", "v", "m/s")), 0.0, stop, 0.01)
        with Master(system, "jacobi", "hold") as m:
            r = m.run(step=0.01, estimate=False)
            assert r.ok, r.summary
            assert not any("event" in w for w in r.summary.warnings), r.summary.warnings
            assert r.summary.events == len(exact) == r.summary.discontinuities  # the FMU's solver.n_events
            found.append((r, list(m.me_block.event_times)))
    (r2, t2), (r3, t3) = found
    assert t2 == t3 and largest_difference(r2, r3) == 0.0
    assert len(t3) == len(exact) and max(abs(a - b) for a, b in zip(t3, exact)) < 1e-12, (t3, exact)
    assert float(np.max(np.abs(r3["h"] - _height(r3.time, exact)))) < 1e-9
    assert r3["v"].max() > 3.0 and r3["h"].min() > -1e-9  # it bounced back up, never sank below the ground


def test_sampled_me_fmu_time_events_fmi3_equal_fmi2(tmp_path):
    """A sampled PI controller as ME: its ticks are time events (nextEventTime of fmi3UpdateDiscreteStates),
    handled by the ME block at the communication points they fall on; u = K_p e + K_i T_s e k after tick k."""
    m = load_component("lib:discrete_pi", overrides={"K_p": 0.5, "K_i": 2.0, "T_s": 0.1})
    out = []
    for version in (2, 3):
        path = fmugen.build_fmu(m, tmp_path / f"pi{version}.fmu", fmi_type="me", fmi_version=version).path
        system = CosimSystem("pi", (Unit("pi", path, "me", {"r": 1.0, "y": 0.2}),), (), (Recorded("u", "pi", "u", ""),),
                             0.0, 1.0, 0.05)
        with Master(system, "jacobi", "hold") as mm:
            r = mm.run(step=0.05, estimate=False)
            assert r.ok, r.summary
            out.append((r, len(mm.me_block.event_times)))
    (r2, n2), (r3, n3) = out
    assert largest_difference(r2, r3) == 0.0 and n2 == n3 == 10
    assert np.allclose(r3["u"][::2], 0.5 * 0.8 + 2.0 * 0.1 * 0.8 * np.arange(11), rtol=0, atol=1e-12)


SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="split3">
  <ssd:System name="split3">
    <ssd:Elements>
      <ssd:Component name="chain" source="resources/chain.fmu">
        <ssd:Connectors>
          <ssd:Connector name="amp.theta" kind="input"><ssc:Real unit="rad"/></ssd:Connector>
          <ssd:Connector name="actuator.w" kind="input"><ssc:Real unit="rad/s"/></ssd:Connector>
          <ssd:Connector name="actuator.tau" kind="output"><ssc:Real unit="N.m"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding source="resources/solver.ssv"/></ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="joint" source="resources/joint.fmu">
        <ssd:Connectors>
          <ssd:Connector name="tau" kind="input"><ssc:Real unit="N.m"/></ssd:Connector>
          <ssd:Connector name="theta" kind="output"><ssc:Real unit="rad"/></ssd:Connector>
          <ssd:Connector name="w" kind="output"><ssc:Real unit="rad/s"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding source="resources/solver.ssv"/></ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="joint" startConnector="theta" endElement="chain" endConnector="amp.theta"/>
      <ssd:Connection startElement="joint" startConnector="w" endElement="chain" endConnector="actuator.w"/>
      <ssd:Connection startElement="chain" startConnector="actuator.tau" endElement="joint" endConnector="tau"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="{stop!r}"/>
</ssd:SystemStructureDescription>
"""

# the rig's internal solver settings; solver.method is an FMI 3.0 Int32, an SSP 1.0 ssv:Integer
SSV = """<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="s">
  <ssv:Parameters>
    <ssv:Parameter name="solver.method"><ssv:Integer value="{method}"/></ssv:Parameter>
    <ssv:Parameter name="solver.rtol"><ssv:Real value="{rtol!r}"/></ssv:Parameter>
    <ssv:Parameter name="solver.atol"><ssv:Real value="{atol!r}"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>
"""


def test_an_ssp_archive_of_fmi3_fmus_runs_as_its_system(rig3, tmp_path):
    path = tmp_path / "split3.ssp"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("SystemStructure.ssd", SSD.format(stop=STOP))
        zf.writestr("resources/solver.ssv", SSV.format(method=INTERNAL["solver.method"], rtol=INTERNAL["solver.rtol"],
                                                       atol=INTERNAL["solver.atol"]))
        zf.write(rig3 / "chain.fmu", "resources/chain.fmu")
        zf.write(rig3 / "joint.fmu", "resources/joint.fmu")
    system = fmugen.load_system(path)
    assert {u.name: u.start_values["solver.method"] for u in system.units} == {"chain": 1, "joint": 1}
    r = run(system, "gauss-seidel", "hold", step=1e-3, order=("joint", "chain"))  # the rig's order
    direct = run(twin(split_system("stiff", "smooth", stop=STOP), rig3), "gauss-seidel", "hold", step=1e-3)
    assert r.ok and direct.ok and np.array_equal(r.time, direct.time)
    for col in ("joint.theta", "joint.w"):
        assert np.array_equal(r[col], direct[col]), col


def test_an_fmi3_scene_runs_and_exports_to_an_ssp_that_runs(tmp_path):
    """A scene built as FMI 3.0 ([scene] fmi_version = 3) runs as its FMI 2.0 build does, and export_ssp
    writes its FMI 3.0 FMUs (their Float64 connectors as ssc:Real, the Int32 solver.method as ssv:Integer)
    into an archive that runs as the scene."""
    from fmugen.scene import load_scene
    from fmugen.ssp import export_ssp

    split = ROOT / "examples" / "scenes" / "single_joint_split.toml"
    runs = {}
    for version in (2, 3):
        scene = load_scene(split, set={"scene.fmi_version": version})
        built = scene.build(tmp_path / f"v{version}")
        runs[version] = run(built, "gauss-seidel", "hold", stop=STOP)
        assert runs[version].ok
    assert largest_difference(runs[2], runs[3]) == 0.0
    out = export_ssp(scene, tmp_path / "split3.ssp", fmus_dir=tmp_path / "v3")
    system = fmugen.load_system(out["path"])
    assert all(units3.read_description(u.name, u.path, u.fmi_type).fmiVersion == "3.0" for u in system.units)
    r = run(system, "gauss-seidel", "hold", stop=STOP)
    assert r.ok
    for col in r.columns:
        if col in runs[3].columns:
            assert np.array_equal(r[col], runs[3][col]), col
    # a sweep over the archive sets its FMI 3.0 Float64 parameters (one worker thread, no cluster)
    from fmugen.sweep import sweep

    sw = sweep(out["path"], grid=["joint.J=1,3"], out=tmp_path / "sweep", workers=1, processes=False,
               options={"stop": STOP}, progress=False, metrics=["final"])
    assert [row["status"] for row in sw.rows] == ["ok", "ok"]
    # the inertia reached the FMU: the actuator's torque differs between the points
    assert abs(sw.rows[1]["actuator.tau:final"] - sw.rows[0]["actuator.tau:final"]) > 1e-3


def _edited(src: Path, dst: Path, edit) -> Path:
    """A copy of FMU ``src`` whose modelDescription.xml is ``edit(text)``."""
    with zipfile.ZipFile(src) as zi, zipfile.ZipFile(dst, "w") as zo:
        for i in zi.infolist():
            data = zi.read(i)
            if i.filename == "modelDescription.xml":
                data = edit(data.decode()).encode()
            zo.writestr(i, data)
    return dst


def _one_line(exc_info, *parts):
    msg = str(exc_info.value)
    assert "\n" not in msg and all(p in msg for p in parts), msg
    return msg


def test_refusals_in_one_line(rig3, tmp_path):
    s = split_system("stiff", "smooth", stop=STOP)
    joint3 = rig3 / "joint.fmu"
    for version in ("1.0", "4.0"):  # another FMI version: refused before its description is parsed
        bad = _edited(joint3, tmp_path / f"v{version}.fmu", lambda t: t.replace('fmiVersion="3.0"',
                                                                                 f'fmiVersion="{version}"'))
        with pytest.raises(CosimError) as e:
            run(replace(s, units=(s.units[0], replace(s.units[1], path=bad))), "jacobi", "hold")
        _one_line(e, "FMU 'joint'", f"FMI {version}; the master runs FMI 2.0 FMUs and FMI 3.0 FMUs")
    # an array variable coupled (fmugen's FMI 3.0 FMUs are scalar: theta given a <Dimension>)
    arr = _edited(joint3, tmp_path / "array.fmu", lambda t: t.replace(
        'unit="rad" nominal="1.0" start="0.0" />', 'unit="rad" nominal="1.0" start="0.0"><Dimension start="1" /></Float64>', 1))
    with pytest.raises(CosimError) as e:
        run(replace(s, units=(s.units[0], replace(s.units[1], path=arr))), "jacobi", "hold")
    _one_line(e, "FMU 'joint'", "variable 'theta' is an array (1)", "scalar variables only")
    with pytest.raises(CosimError) as e:
        run(replace(s, units=(s.units[0], replace(s.units[1], path=arr, start_values={"theta": 0.1}))), "jacobi")
    _one_line(e, "FMU 'joint'", "start value of 'theta': it is an array")
    # a Boolean start value goes to fmi3SetBoolean (fmugen's runtime has no Booleans: it refuses the call)
    flag = _edited(joint3, tmp_path / "flag.fmu", lambda t: t.replace("  </ModelVariables>", '    <Boolean name="flag" '
                   'valueReference="999" causality="parameter" variability="fixed" start="false" />\n  </ModelVariables>'))
    with pytest.raises(CosimError) as e:
        run(replace(s, units=(s.units[0], replace(s.units[1], path=flag, start_values={"flag": True}))), "jacobi")
    _one_line(e, "FMU 'joint'", "fmi3SetBoolean(flag = 1.0) returned fmi3Error")
    # the interface asked is not in the FMU
    no_me = _edited(joint3, tmp_path / "no_me.fmu", lambda t: "\n".join(
        ln for ln in t.splitlines() if "<ModelExchange " not in ln))
    with pytest.raises(CosimError) as e:
        run(replace(s, units=(s.units[0], replace(me(s.units[1]), path=no_me))), "jacobi", "hold")
    _one_line(e, "FMU 'joint'", "has no Model-Exchange interface")
    # Hermite inputs need input derivatives, which FMI 3.0 does not have: refused for an FMU whose inputs
    # cannot be set in the intermediate update either
    held = _edited(joint3, tmp_path / "held.fmu", lambda t: t.replace(
        'causality="input" variability="continuous" intermediateUpdate="true"',
        'causality="input" variability="continuous"'))
    with pytest.raises(CosimError) as e:
        run(replace(twin(s, rig3), units=(replace(s.units[0], path=rig3 / "chain.fmu"),
                                          replace(s.units[1], path=held))), "newton", "quadratic", step=1e-3)
    _one_line(e, "FMU 'joint'", "cannot interpolate inputs (FMI 3.0 has no input derivatives")
    # a coupling needs a Float64 (FMI 2.0: Real) variable
    with pytest.raises(CosimError) as e:
        Master(replace(twin(s, rig3), recorded=(Recorded("n", "chain", "solver.n_steps", ""),)), "jacobi", "hold")
    _one_line(e, "FMU 'chain'", "variable 'solver.n_steps' is Int32; couplings need Float64")


_BIND = units3.Slave3Unit._bind


def _fake_step(monkeypatch, make):
    """fmi3DoStep of the FMI 3.0 units replaced by ``make(real)``'s function (the same arguments)."""
    bind = _BIND

    def patched(self, f):
        f = dict(f)
        f["fmi3DoStep"] = make(f["fmi3DoStep"])
        bind(self, f)

    monkeypatch.setattr(units3.Slave3Unit, "_bind", patched)


def test_fmi3_error_and_terminate_simulation_end_the_run_naming_the_call(rig3, monkeypatch):
    s3 = twin(split_system("stiff", "smooth", stop=STOP), rig3, ("chain",))

    def erring(real):
        def step(c, t, H, no_prior, event, term, early, last):
            return 3 if t >= 0.05 - 1e-12 else real(c, t, H, no_prior, event, term, early, last)
        return step

    _fake_step(monkeypatch, erring)
    r = run(s3, "gauss-seidel", "hold", step=1e-3)
    f = r.summary.failure
    assert f.cause == "fmu-failure" and f.unit == "chain" and abs(f.time - 0.05) < 1e-9
    assert "fmi3DoStep(t = 0.05" in f.message and "returned fmi3Error" in f.message, f.message

    def terminating(real):
        def step(c, t, H, no_prior, event, term, early, last):
            st = real(c, t, H, no_prior, event, term, early, last)
            if t >= 0.1 - 1e-12:
                term._obj.value = True  # what an FMU that ends the simulation returns
            return st
        return step

    _fake_step(monkeypatch, terminating)
    r = run(s3, "jacobi", "hold", step=1e-3)
    f = r.summary.failure
    assert r.summary.status == "failed" and f.cause == "terminated" and f.unit == "chain", r.summary
    assert "fmi3DoStep" in f.message and "terminateSimulation = true" in f.message and abs(r.time[-1] - 0.1) < 1e-9
