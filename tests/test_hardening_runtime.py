"""Issue 9, classes 5 and 6: the FMU never says fmi2OK about a state it has
not checked, and time that cannot advance is refused.

FMUs built by fmugen from small models whose answers are known in closed form:

* ``ramp``: x' = 1 (x(0) = 0), y = sqrt(1 - x): the output becomes NaN
  exactly after t = 1 while the state stays finite;
* ``ranged``: x' = 1 with the validity range x <= 0.5, an input u in [0, 1]
  and an output z = 2 x in [-1, 1.5];
* the one-joint hydraulic rig (stiff set) under a load torque 48 times the
  actuator's stall torque, so that the load pressure must leave |P_L| <= P_s
  (the issue's "24x the supply pressure without a word").
"""
import re
from pathlib import Path

import fmpy
import pytest
import sympy as sp
from fmpy import read_model_description
from fmpy.fmi2 import (FMU2Model, FMU2Slave, fmi2Discard, fmi2Error, fmi2OK, fmi2Warning, fmi2LastSuccessfulTime)

from fmugen.codegen.model import SymbolicModel, Variable
from fmugen.fmi import build_fmu, variable_layout
import fmi_log
from fmi_log import Log, start, status_of, step

ROOT = Path(__file__).resolve().parents[1]
RK4, DOPRI5, RODAS3 = 3, 1, 2


def symbol(name):
    return sp.Symbol(name, real=True)


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("hardening_runtime")
    x, u = symbol("x"), symbol("u")
    ramp = SymbolicModel.from_equations(
        "ramp", [Variable("x", x, start=0.0)], [], [], [sp.Integer(1)],
        [Variable("y", symbol("y"))], [sp.sqrt(1 - x)])
    ranged = SymbolicModel.from_equations(
        "ranged", [Variable("x", x, start=0.0, max=0.5)], [Variable("u", u, start=0.0, min=0.0, max=1.0)], [],
        [sp.Integer(1) + 0 * u], [Variable("z", symbol("z"), min=-1.0, max=1.5)], [2 * x])
    from fmugen.components.assembly import load_assembly

    rig = load_assembly(ROOT / "examples" / "single_joint_stiff.toml")
    out = {}
    for m in (ramp, ranged, rig):
        out[m.name] = (m, build_fmu(m, d / f"{m.name}.fmu", fmi_type="both").path)
    out["dir"] = d
    return out


def open_fmu(fmus, name, cls=FMU2Slave, tag="a"):
    return fmi_log.open_fmu(fmus[name][1], fmus["dir"] / f"{name}_{cls.__name__}_{tag}", name, cls)


# --------------------------------------------------------------------------
# non-finite results are discarded at the step where they appear
# --------------------------------------------------------------------------
@pytest.mark.parametrize("solver", [RK4, DOPRI5, RODAS3])
def test_output_that_becomes_nan_is_discarded_at_that_step(fmus, solver):
    fmu = open_fmu(fmus, "ramp", tag=f"nan{solver}")
    start(fmu, ints={"solver.method": solver})
    t, h = 0.0, 0.25
    statuses = []
    while t < 2.0:
        s = step(fmu, t, h)
        statuses.append(s)
        if s != fmi2OK:
            break
        y = fmu.getReal([fmu.vr["y"]])[0]
        assert y ** 2 == pytest.approx(1 - (t + h), abs=1e-12)  # x = t to round-off for every solver
        t += h
    # the last good point is t = 1 (y = 0); the step to 1.25 is refused, not reported OK
    assert statuses == [fmi2OK] * 4 + [fmi2Discard]
    msg = fmu.log.text(fmi2Discard)
    assert re.search(r"output y = -?nan is not finite at t = 1\.25", msg), msg
    assert fmu.getRealStatus(fmi2LastSuccessfulTime) == 1.0
    fmu.freeInstance()


# --------------------------------------------------------------------------
# validity ranges: warning by default, fmi2Discard when asked, nothing when off
# --------------------------------------------------------------------------
def test_ranges_are_in_the_model_description(fmus):
    md = read_model_description(str(fmus["ranged"][1]))
    v = {x.name: x for x in md.modelVariables}
    assert v["x"].max == "0.5" and v["u"].min == "0.0" and v["z"].max == "1.5"
    assert v["solver.range_check"].start == "1" and v["solver.range_check"].causality == "parameter"


def test_leaving_a_range_is_a_warning_by_default(fmus):
    fmu = open_fmu(fmus, "ranged", tag="warn")
    start(fmu)
    assert step(fmu, 0.0, 0.25) == fmi2OK
    assert step(fmu, 0.25, 0.25) == fmi2OK  # x = 0.5: on the boundary is inside
    assert step(fmu, 0.5, 0.25) == fmi2Warning
    assert "state x = 0.75 left its validity range [-inf, 0.5] at t = 0.75" in fmu.log.text(fmi2Warning)
    # the simulation goes on, and the result is still exact
    assert step(fmu, 0.75, 0.25) == fmi2Warning
    assert fmu.getReal([fmu.vr["x"]]) == [pytest.approx(1.0, abs=1e-12)]
    fmu.freeInstance()


def test_input_and_output_ranges(fmus):
    fmu = open_fmu(fmus, "ranged", tag="io")
    start(fmu)
    fmu.setReal([fmu.vr["u"]], [2.0])
    assert step(fmu, 0.0, 0.1) == fmi2Warning
    assert "input u = 2 left its validity range [0, 1]" in fmu.log.text(fmi2Warning)
    fmu.freeInstance()


def test_range_check_2_discards_and_0_ignores(fmus):
    fmu = open_fmu(fmus, "ranged", tag="err")
    start(fmu, ints={"solver.range_check": 2})
    assert step(fmu, 0.0, 0.5) == fmi2OK
    assert step(fmu, 0.5, 0.1) == fmi2Discard
    assert "state x = 0.6" in fmu.log.text(fmi2Discard) and "validity range" in fmu.log.text(fmi2Discard)
    assert fmu.getRealStatus(fmi2LastSuccessfulTime) == 0.5
    fmu.freeInstance()
    fmu = open_fmu(fmus, "ranged", tag="off")
    start(fmu, ints={"solver.range_check": 0})
    assert step(fmu, 0.0, 2.0) == fmi2OK
    fmu.freeInstance()
    fmu = open_fmu(fmus, "ranged", tag="bad")
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    assert status_of(lambda: fmu.fmi2SetInteger(fmu.component, (fmpy.fmi2.fmi2ValueReference * 1)(
        fmu.vr["solver.range_check"]), 1, (fmpy.fmi2.fmi2Integer * 1)(3))) == fmi2Error
    assert "range_check = 3 rejected" in fmu.log.text(fmi2Error)
    fmu.freeInstance()


@pytest.mark.parametrize("solver", [DOPRI5, RK4])
def test_load_pressure_beyond_the_supply_is_reported(fmus, solver):
    """Load torque 1e4 N.m against a stall torque P_s D_m = 210 N.m: P_L -> 1e4/D_m = 48 P_s."""
    fmu = open_fmu(fmus, "single_joint_stiff", tag=f"PL{solver}")
    start(fmu, ints={"solver.method": solver}, reals={"joint.tau_load": 1e4, "solver.fixed_step": 1e-5})
    statuses, t, h = [], 0.0, 0.01
    for _ in range(20):
        statuses.append(step(fmu, t, h))
        t += h
    assert fmi2Warning in statuses and fmi2Discard not in statuses
    first = statuses.index(fmi2Warning)
    assert all(s == fmi2OK for s in statuses[:first])
    msg = fmu.log.text(fmi2Warning)
    assert "actuator.P_L" in msg and "[-14000000, 14000000]" in msg, msg
    fmu.freeInstance()


# --------------------------------------------------------------------------
# fmi2DoStep and fmi2SetTime arguments (issue item 6)
# --------------------------------------------------------------------------
@pytest.mark.parametrize("t0, h, fragment", [
    (1e15, 0.01, "time would not advance"),
    (1e10, 0.01, "advance by a wrong amount"),
    (0.0, 0.0, "the step size > 0"),
    (0.0, -0.1, "the step size > 0"),
    (0.0, float("nan"), "must be finite"),
])
def test_steps_that_cannot_advance_time_are_errors(fmus, t0, h, fragment):
    fmu = open_fmu(fmus, "ranged", tag=f"t{t0}{h}")
    start(fmu, t0=t0)
    assert step(fmu, t0, h) == fmi2Error
    assert fragment in fmu.log.text(fmi2Error), fmu.log.text()
    # refused calls change nothing: a good step still works from the same time
    assert step(fmu, t0, 1.0) in (fmi2OK, fmi2Warning) if t0 < 1e15 else True
    fmu.freeInstance()


def test_large_start_time_with_a_resolvable_step_works(fmus):
    fmu = open_fmu(fmus, "ranged", tag="t1e6")
    start(fmu, t0=1e6)
    for k in range(4):
        assert step(fmu, 1e6 + 0.1 * k, 0.1) == fmi2OK
    assert fmu.getReal([fmu.vr["x"]])[0] == pytest.approx(0.4, abs=1e-9)
    fmu.freeInstance()


def test_flag_that_is_not_a_boolean_is_an_error(fmus):
    fmu = open_fmu(fmus, "ranged", tag="flag")
    start(fmu)
    assert step(fmu, 0.0, 0.1, flag=2) == fmi2Error
    assert "noSetFMUStatePriorToCurrentPoint = 2 is not a Boolean" in fmu.log.text(fmi2Error)
    assert step(fmu, 0.0, 0.1, flag=0) == fmi2OK
    fmu.freeInstance()


def test_me_time_cannot_go_back_before_a_completed_step(fmus):
    model, path = fmus["ranged"]
    md = read_model_description(str(path))
    unzip = fmpy.extract(str(path), unzipdir=str(fmus["dir"] / "ranged_me"))
    fmu = FMU2Model(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="me")
    log = Log()
    fmu.instantiate(callbacks=log.callbacks)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.enterContinuousTimeMode()
    fmu.setTime(1.0)
    assert status_of(lambda: fmu.fmi2SetTime(fmu.component, 0.5)) == fmi2OK  # a retried step: allowed
    fmu.completedIntegratorStep()
    assert status_of(lambda: fmu.fmi2SetTime(fmu.component, 0.25)) == fmi2Error
    assert "fmi2SetTime: time 0.25 goes back before t = 0.5" in log.text(fmi2Error)
    assert status_of(lambda: fmu.fmi2SetTime(fmu.component, 0.75)) == fmi2OK
    fmu.freeInstance()


TWO_CHAMBER_RIG = """
[assembly]
name = "two_chamber_rig"
parameter_set = "stiff"
inputs = ["amp.theta_ref", "joint.tau_load"]
connections = [
  ["joint.theta", "amp.theta"], ["amp.u", "driver.u"], ["driver.i", "valve.i"],
  ["actuator.P_A_eff", "valve.P_A"], ["actuator.P_B_eff", "valve.P_B"],
  ["valve.Q_A", "actuator.Q_A"], ["valve.Q_B", "actuator.Q_B"],
  ["joint.theta", "actuator.theta"], ["joint.w", "actuator.w"], ["actuator.tau", "joint.tau"],
]
[components.amp]
type = "amplifier"
[components.driver]
type = "current_driver"
kind = "lag"
[components.valve]
type = "servo_valve"
flow = "chambers"
[components.actuator]
type = "hydraulic_actuator"
form = "two_chamber"
[components.joint]
type = "joint_inertia"
"""


def test_two_chamber_rig_reports_leaving_the_stroke_its_volumes_allow(tmp_path):
    """Stiff set: V_t/2 - D_m theta > 0 only for |theta| < 1/3 rad.  The actuator's position input is
    connected (it disappears from the assembly); the joint angle driving it carries the range instead,
    and a command of 0.5 rad is reported when the joint passes 1/3 rad -- a word about the stroke,
    instead of a silent 1e14 Pa."""
    from fmugen.components.assembly import load_assembly

    p = tmp_path / "rig.toml"
    p.write_text(TWO_CHAMBER_RIG)
    model = load_assembly(p)
    theta = {v.name: v for v in model.states}["joint.theta"]
    assert theta.max == pytest.approx(1 / 3, rel=1e-15) and theta.min == -theta.max
    fmus_ = {"dir": tmp_path, "rig": (model, build_fmu(model, tmp_path / "rig.fmu", fmi_type="cs").path)}
    fmu = open_fmu(fmus_, "rig", tag="stroke")
    start(fmu, ints={"solver.method": RODAS3}, reals={"amp.theta_ref": 0.5})
    t, h, statuses = 0.0, 0.01, []
    while t < 2.0 and fmi2Warning not in statuses:
        statuses.append(step(fmu, t, h))
        t += h
    assert statuses[-1] == fmi2Warning and set(statuses[:-1]) <= {fmi2OK}
    msg = fmu.log.text(fmi2Warning)
    assert "state joint.theta = 0.33" in msg and "[-0.333333333, 0.333333333]" in msg, msg
    fmu.freeInstance()


@pytest.mark.parametrize("solver", [RK4, DOPRI5, RODAS3])
def test_no_ok_about_a_blown_up_state(fmus, solver):
    """The issue's RK4 reproduction: one RK4 step per communication step of 10 ms on the stiff rig
    (eigenvalues to 5e4 1/s) blows up; every step that answers fmi2OK has |P_L| <= P_s and finite
    states, and the blow-up is reported (warning or discard) at the step where it happens."""
    fmu = open_fmu(fmus, "single_joint_stiff", tag=f"blow{solver}")
    start(fmu, ints={"solver.method": solver}, reals={"amp.theta_ref": 0.1})
    states = [v.name for v in fmus["single_joint_stiff"][0].states]
    vrs = [fmu.vr[n] for n in states]
    t, h, reported = 0.0, 0.01, False
    for _ in range(30):
        s = step(fmu, t, h)
        t += h
        if s == fmi2OK:
            x = dict(zip(states, fmu.getReal(vrs)))
            assert all(abs(v) < 1e300 for v in x.values())
            assert abs(x["actuator.P_L"]) <= 14e6, (t, x)
        else:
            reported = True
            if s == fmi2Discard:
                break
    if solver == RK4:
        assert reported  # 10 ms is 100x beyond RK4's stability limit here


def test_me_completed_integrator_step_reports_ranges(fmus):
    """Model Exchange: a model with ranges declares completedIntegratorStepNotNeeded = false, so fmpy
    calls fmi2CompletedIntegratorStep at every output point; x = t leaves
    x <= 0.5 after t = 0.5 -- a logged warning (default), or the end of the simulation (range_check = 2)."""
    from fmpy import simulate_fmu

    path = str(fmus["ranged"][1])
    assert read_model_description(path).modelExchange.needsCompletedIntegratorStep
    assert not read_model_description(str(fmus["ramp"][1])).modelExchange.needsCompletedIntegratorStep
    seen = []

    def logger(component, instance_name, status, category, message):
        seen.append((status, message.decode()))

    r = simulate_fmu(path, fmi_type="ModelExchange", stop_time=1.0, output_interval=0.1, logger=logger,
                     debug_logging=False, output=["x"])
    assert r["x"][-1] == pytest.approx(1.0, abs=1e-6)
    warn = [m for s, m in seen if s == fmi2Warning]
    assert warn and "fmi2CompletedIntegratorStep: state x = 0.6" in warn[0] and "[-inf, 0.5]" in warn[0], seen
    seen.clear()
    with pytest.raises(Exception):
        simulate_fmu(path, fmi_type="ModelExchange", stop_time=1.0, output_interval=0.1, logger=logger,
                     start_values={"solver.range_check": 2})
    assert any(s == fmi2Error and "range_check = 2" in m for s, m in seen), seen
