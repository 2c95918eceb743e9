"""FMI 3.0 Co-Simulation Event Mode, early return and intermediate update (c_runtime/fmi3/fmi3_functions.c).

With ``eventModeUsed`` an event inside a communication step ends ``fmi3DoStep`` there
(``eventHandlingNeeded``, ``earlyReturn``, ``lastSuccessfulTime`` = the event's time) and the importer's
``fmi3EnterEventMode`` / ``fmi3UpdateDiscreteStates`` / ``fmi3EnterStepMode`` run the event iteration that
fmi3DoStep runs inside the step otherwise -- so both give the same trajectory.  The intermediate-update
callback comes after every accepted internal solver step, may read outputs and may ask for an early
return.  Driven through fmpy's low-level ``FMU3Slave`` and ctypes, and (when built) by fmusim of the
Reference-FMUs with its event-mode and early-return options.
"""
from __future__ import annotations

import ctypes
import subprocess
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave, fmi3IntermediateUpdateCallback
from fmpy.validation import validate_fmu

from fmugen.components.equations import load_component
from fmugen.fmi.build import build_fmu
from fmugen.fmi.platforms import host_platform
from test_fmi3_export import _fmusim  # finds fmusim as there (tests/tools/build_fmusim.sh), skips without

ROOT = Path(__file__).resolve().parent.parent
BALL = ROOT / "examples" / "components" / "bouncing_ball.toml"
H0, G, E = 1.0, 9.81, 0.7  # the ball's start height, gravity and restitution (bouncing_ball.toml)

pytestmark = pytest.mark.skipif(host_platform() != "linux64", reason="FMI 3.0 export: x86_64 Linux only so far")

# a damped pendulum: nonlinear, so that a changed sequence of internal steps would show in the results
PENDULUM = """
[component]
name = "pendulum"
description = "a damped pendulum driven by an input acceleration"
equations = [
  "der(phi) = w",
  "der(w) = -g/l*sin(phi) - d*w + a",
  "y = l*sin(phi)",
]
[parameters]
g = { value = 9.81, unit = "m/s2" }
l = { value = 0.5, unit = "m" }
d = { value = 0.3, unit = "1/s" }
[inputs]
a = { unit = "rad/s2", start = 0.0 }
[states]
phi = { unit = "rad", start = 1.2 }
w = { unit = "rad/s", start = 0.0 }
[outputs]
y = { unit = "m" }
"""


class Fmu:
    """An FMI 3.0 FMU unzipped once; ``slave()`` gives a fresh FMU3Slave of it."""

    def __init__(self, path, tmp):
        self.path = path
        self.md = fmpy.read_model_description(str(path))
        self.dir = fmpy.extract(str(path), unzipdir=str(tmp))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.log = []

    def slave(self, update=None, **kw):
        f = FMU3Slave(guid=self.md.guid, unzipDirectory=self.dir, modelIdentifier=self.md.coSimulation.modelIdentifier,
                      instanceName="i")
        self.log.clear()
        f.instantiate(logMessage=lambda env, status, cat, msg: self.log.append((status, msg.decode())),
                      intermediateUpdate=update, **kw)
        return f


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmi3_cs_events")
    (d / "pendulum.toml").write_text(PENDULUM)
    pi = load_component("lib:discrete_pi", overrides={"K_p": 0.5, "K_i": 2.0, "T_s": 0.1})
    out = {}
    for name, model in (("ball", load_component(BALL)), ("pi", pi), ("pendulum", load_component(d / "pendulum.toml"))):
        path = build_fmu(model, d / f"{name}.fmu", fmi_version=3).path
        out[name] = Fmu(path, d / name)
    return out


def run(fmu, stop, H, outputs, event_mode=False, early=False, update=None, inputs=None, slave=None, ints=None):
    """The importer's loop over the grid k H: after an early return it steps on from lastSuccessfulTime
    to the next grid point, after eventHandlingNeeded it runs Event Mode.  Returns the values at the grid
    points (after the event for one there), the early returns (time, eventHandlingNeeded, values at
    the return), the grid points with eventHandlingNeeded and the instance (terminated)."""
    f = slave or fmu.slave(update, eventModeUsed=event_mode, earlyReturnAllowed=early)
    vrs = [fmu.vr[n] for n in outputs]
    f.enterInitializationMode(startTime=0.0)
    for name, value in (inputs or {}).items():
        f.setFloat64([fmu.vr[name]], [value])
    for name, value in (ints or {}).items():
        f.setInt32([fmu.vr[name]], [value])
    f.exitInitializationMode()
    if event_mode:  # FMI 3.0: initialisation ends in Event Mode with eventModeUsed
        assert f.updateDiscreteStates()[0] is False
        f.enterStepMode()
    t, k = 0.0, 0
    grid, returns, at_end_events = [f.getFloat64(vrs)], [], []
    while k * H < stop - 1e-12:
        t_next = (k + 1) * H
        event, terminate, early_return, last = f.doStep(t, t_next - t)
        assert not terminate
        if early_return:
            assert early and last < t_next
            t = last
            returns.append((last, event, f.getFloat64(vrs)))
        else:
            assert last == t_next
            t, k = t_next, k + 1
            grid.append(f.getFloat64(vrs))
            if event:
                at_end_events.append(t)
        if event:
            assert event_mode
            f.enterEventMode()
            while f.updateDiscreteStates()[0]:
                pass
            f.enterStepMode()
            if not early_return:  # an event at the grid point: its values after the event, as inside a step
                grid[-1] = f.getFloat64(vrs)
    f.terminate()
    return np.array(grid), returns, at_end_events, f


def impact_times(n):
    """The ball's closed form: t_1 = sqrt(2 h0/g), t_{k+1} = t_k + 2 e^k sqrt(2 g h0)/g."""
    t = [np.sqrt(2 * H0 / G)]
    for k in range(1, n):
        t.append(t[-1] + 2 * E ** k * np.sqrt(2 * G * H0) / G)
    return np.array(t)


def test_model_descriptions_declare_event_mode_and_intermediate_update(fmus):
    for name, event_mode in (("ball", True), ("pi", True), ("pendulum", False)):
        fmu = fmus[name]
        assert validate_fmu(str(fmu.path)) == [], name
        fmpy.read_model_description(str(fmu.path), validate_variable_names=True, validate_model_structure=True)
        cs = fmu.md.coSimulation
        assert cs.hasEventMode is event_mode, name  # Event Mode where there are events to hand over
        assert cs.providesIntermediateUpdate and cs.canReturnEarlyAfterIntermediateUpdate
        assert cs.mightReturnEarlyFromDoStep
    xml = Path(fmus["pendulum"].dir, "modelDescription.xml").read_text()
    assert 'name="y"' in xml and 'intermediateUpdate="true"' in xml


def test_ball_returns_early_at_each_impact_and_equals_the_run_without_event_mode(fmus):
    """Communication steps of 0.3 s, eight bounces in 2.4 s: every early return is an impact (h just
    below 0, falling) at its closed-form time, and the trajectory at the grid points equals the run
    without Event Mode (eventModeUsed = false: the events handled inside fmi3DoStep) exactly."""
    ball = fmus["ball"]
    plain, none, _, _ = run(ball, 2.4, 0.3, ("h", "v"))
    assert none == []
    grid, returns, _, _ = run(ball, 2.4, 0.3, ("h", "v"), event_mode=True, early=True)
    times = np.array([r[0] for r in returns])
    assert len(returns) == 8 and all(ev for _, ev, _ in returns)
    assert np.max(np.abs(times - impact_times(8))) < 1e-9  # found: 3.5e-13
    assert all(-1e-9 < h <= 0 and v < 0 for _, _, (h, v) in returns)  # just after the crossing, not bounced yet
    assert np.array_equal(grid, plain)  # bit for bit: the same iteration and the same solver steps
    assert max(plain[:, 1]) > 1.0  # bounced


def test_fmpy_simulate_fmu_with_event_mode(fmus):
    """fmpy's own Co-Simulation loop (simulate_fmu with use_event_mode and early_return_allowed): a row
    before and after each impact, at its closed-form time; the rows on the 0.01 s grid equal the run
    without Event Mode bit for bit."""
    ball = fmus["ball"]
    kw = dict(fmi_type="CoSimulation", stop_time=2.0, output_interval=0.01)
    plain = fmpy.simulate_fmu(str(ball.path), **kw)
    ev = fmpy.simulate_fmu(str(ball.path), use_event_mode=True, early_return_allowed=True, **kw)
    t = ev["time"]
    grid = np.isclose(t / 0.01, np.round(t / 0.01), atol=1e-6, rtol=0)
    off = t[~grid]
    assert len(off) == 8 and np.array_equal(off[::2], off[1::2])  # before and after each of 4 impacts
    assert np.max(np.abs(off[::2] - impact_times(4))) < 1e-9
    keep = grid & np.r_[np.diff(t) != 0, True]
    assert np.array_equal(t[keep], plain["time"])
    assert all(np.array_equal(ev[n][keep], plain[n]) for n in ("h", "v"))


def test_ball_event_mode_without_early_return_handles_inside_the_step(fmus):
    """eventModeUsed without earlyReturnAllowed: the FMU cannot stop at the event, so the step handles it
    inside as without Event Mode (Reference-FMUs do the same) -- the same trajectory, no early return."""
    ball = fmus["ball"]
    plain, _, _, _ = run(ball, 2.4, 0.3, ("h", "v"))
    grid, returns, _, _ = run(ball, 2.4, 0.3, ("h", "v"), event_mode=True, early=False)
    assert returns == [] and np.array_equal(grid, plain)


def test_ball_early_return_without_event_mode_gives_a_point_at_each_impact(fmus):
    """earlyReturnAllowed without eventModeUsed: the event is handled inside the step, which then ends
    there (a communication point at the discontinuity), eventHandlingNeeded false."""
    ball = fmus["ball"]
    plain, _, _, _ = run(ball, 2.4, 0.3, ("h", "v"))
    grid, returns, _, _ = run(ball, 2.4, 0.3, ("h", "v"), early=True)
    assert len(returns) == 8 and not any(ev for _, ev, _ in returns)
    assert np.max(np.abs(np.array([r[0] for r in returns]) - impact_times(8))) < 1e-9
    assert all(v > 0 for _, _, (h, v) in returns)  # already bounced
    assert np.max(np.abs(grid - plain)) < 1e-12


def test_sampled_pi_returns_early_at_each_sample_instant(fmus):
    """Time events: the PI controller's clock ticks every 0.1 s; with communication steps of 0.25 s the
    step ends at each tick inside it (0.1, 0.2, 0.3, 0.4, 0.6, ...), and at the ticks on the grid (0.5,
    1.0) it reaches the grid point with eventHandlingNeeded; the output u equals the run without Event
    Mode, and nextEventTime is the next tick."""
    pi = fmus["pi"]
    inputs = {"r": 1.0, "y": 0.2}
    plain, _, _, _ = run(pi, 1.0, 0.25, ("u",), inputs=inputs)
    grid, returns, at_end, _ = run(pi, 1.0, 0.25, ("u",), event_mode=True, early=True, inputs=inputs)
    ticks = [0.1 * j for j in range(1, 10) if j % 5]
    assert [r[0] for r in returns] == pytest.approx(ticks, abs=1e-12) and all(ev for _, ev, _ in returns)
    assert at_end == pytest.approx([0.5, 1.0], abs=1e-12)
    assert np.array_equal(grid, plain)
    assert len(np.unique([r[2][0] for r in returns])) >= 8  # u changed at every instant (the integral grows)
    # nextEventTime after a tick's update
    f = pi.slave(eventModeUsed=True, earlyReturnAllowed=True)
    f.enterInitializationMode(startTime=0.0)
    f.exitInitializationMode()
    assert f.updateDiscreteStates()[4:] == (True, pytest.approx(0.1))
    f.enterStepMode()
    event, _, early_return, last = f.doStep(0.0, 0.25)
    assert event and early_return and last == pytest.approx(0.1, abs=1e-12)
    f.enterEventMode()
    assert f.updateDiscreteStates() == (False, False, False, False, True, pytest.approx(0.2, abs=1e-12))
    f.enterStepMode()
    f.terminate()
    f.freeInstance()


def test_inputs_set_in_event_mode_take_effect_there(fmus):
    """Event Mode is where an importer changes inputs discontinuously: set at a sample instant before
    fmi3UpdateDiscreteStates, the sampled update uses them (u = K_p e + ... jumps with r)."""
    pi = fmus["pi"]
    vr = pi.vr
    us = []
    for r_new in (1.0, 3.0):
        f = pi.slave(eventModeUsed=True, earlyReturnAllowed=True)
        f.enterInitializationMode(startTime=0.0)
        f.setFloat64([vr["r"], vr["y"]], [1.0, 0.2])
        f.exitInitializationMode()
        f.updateDiscreteStates()
        f.enterStepMode()
        assert f.doStep(0.0, 0.25)[0]
        f.enterEventMode()
        f.setFloat64([vr["r"]], [r_new])
        f.updateDiscreteStates()
        us.append(f.getFloat64([vr["u"]])[0])
        f.enterStepMode()
        f.terminate()
        f.freeInstance()
    assert us[1] - us[0] == pytest.approx(0.5 * 2.0, rel=1e-9)  # K_p (r_new - r) with K_p = 0.5


def _callback(f, vrs, calls, plan=None):
    """An intermediate-update callback recording (time, canReturnEarly, flags, values); plan(t, i) gives
    an earlyReturnTime to request (or None).  Exceptions are recorded, not lost in ctypes."""

    def cb(env, t, set_requested, get_allowed, step_finished, can_return_early, requested, when):
        try:
            calls.append((t, bool(can_return_early), (bool(set_requested), bool(get_allowed), bool(step_finished)),
                          f[0].getFloat64(vrs)))
            wanted = plan(t, len(calls) - 1) if plan else None
            if wanted is not None:
                requested[0] = True
                when[0] = wanted
        except Exception as e:  # noqa: BLE001 -- reported by the test
            calls.append(("error", repr(e)))

    return fmi3IntermediateUpdateCallback(cb)


def _cs_slave(fmu, early, callback, required=()):
    """An FMU3Slave instantiated with an intermediate-update callback (ctypes: fmpy's instantiate takes
    a Python function, the tests need the instance inside it)."""
    f = FMU3Slave(guid=fmu.md.guid, unzipDirectory=fmu.dir, modelIdentifier=fmu.md.coSimulation.modelIdentifier,
                  instanceName="i")
    fmu.log.clear()
    f.logMessage = fmpy.fmi3.fmi3LogMessageCallback(lambda env, status, cat, msg: fmu.log.append((status, msg.decode())))
    f.intermediateUpdate = callback
    f.component = f.fmi3InstantiateCoSimulation(b"i", fmu.md.guid.encode(), b"", False, False, False, early,
                                                (fmpy.fmi3.fmi3ValueReference * len(required))(*required),
                                                len(required), None, f.logMessage, callback)
    assert f.component
    return f


def _run_with_callback(fmu, stop, H, outputs, early, plan=None, inputs=None, ints=None):
    calls, holder = [], [None]
    vrs = [fmu.vr[n] for n in outputs]
    f = holder[0] = _cs_slave(fmu, early, _callback(holder, vrs, calls, plan), vrs)
    grid, returns, _, _ = run(fmu, stop, H, outputs, early=early, inputs=inputs, slave=f, ints=ints)
    return grid, returns, calls, f


def test_intermediate_update_after_each_solver_step_reads_outputs(fmus):
    """The callback comes at increasing times inside each communication step, the last at its end, where
    the outputs read in it equal those fmi3GetFloat64 gives after the step; with it the trajectory is
    the one without it, bit for bit (the callback does not touch the solver)."""
    pend = fmus["pendulum"]
    outputs = ("y", "w")
    plain, _, _, _ = run(pend, 1.0, 0.1, outputs, inputs={"a": 0.5})
    grid, _, calls, f = _run_with_callback(pend, 1.0, 0.1, outputs, early=False, inputs={"a": 0.5})
    f.freeInstance()
    assert not [c for c in calls if c[0] == "error"], calls
    times = np.array([c[0] for c in calls])
    assert len(calls) > 20 and np.all(np.diff(times) > 0)
    assert all(flags == (False, True, True) and not can for _, can, flags, _ in calls)
    for k in range(1, 11):  # each step's callbacks lie in [t_k-1, t_k]; the last is at t_k with its outputs
        inside = [c for c in calls if (k - 1) * 0.1 < c[0] <= k * 0.1 + 1e-12]
        assert inside and inside[-1][0] == pytest.approx(k * 0.1, abs=1e-12)
        assert inside[-1][3] == list(grid[k])
    assert np.array_equal(grid, plain)


def test_early_return_requested_in_the_intermediate_update(fmus):
    """Asked in a callback: at its own time (the first callback of the step from 0.3), and at a later
    earlyReturnTime (from the first callback of the step from 0.5, for a time between it and 0.6); the
    step ends there (earlyReturn, lastSuccessfulTime), and stepping on gives the trajectory of the run
    without early returns -- bit for bit after a return at a solver step's end (the solver goes on with
    the step it had), within the solver's tolerance after the later one (a solver step ends there)."""
    pend = fmus["pendulum"]
    outputs = ("y", "w")
    plain, _, _, _ = run(pend, 1.0, 0.1, outputs, inputs={"a": 0.5})
    asked = {}

    def plan(t, i):
        if 0.31 < t < 0.4 and "here" not in asked:
            asked["here"] = t
            return t
        if 0.51 < t < 0.6 and "later" not in asked:
            asked["later"] = t + 0.3 * (0.6 - t)
            return asked["later"]
        return None

    grid, returns, calls, f = _run_with_callback(pend, 1.0, 0.1, outputs, early=True, plan=plan, inputs={"a": 0.5})
    f.freeInstance()
    assert not [c for c in calls if c[0] == "error"], calls
    assert [r[0] for r in returns] == [asked["here"], asked["later"]] and not any(ev for _, ev, _ in returns)
    assert all(can for t, can, _, _ in calls if not np.isclose(t * 10, round(t * 10), rtol=0, atol=1e-9))
    assert not any(can for t, can, _, _ in calls if np.isclose(t * 10, round(t * 10), rtol=0, atol=1e-9))
    # the values at the early return are those the callback read there
    assert returns[0][2] == next(c[3] for c in calls if c[0] == asked["here"])
    assert np.array_equal(grid[:6], plain[:6])  # up to 0.5: the return at 0.36 changed nothing
    # from 0.6 on: a solver step ended at the later time, so the steps differ -- by the solver's error
    # (rtol = atol = 1e-6; found 1.9e-7)
    assert 0 < np.max(np.abs(grid - plain)) < 1e-5


@pytest.mark.parametrize("method", [2, 3], ids=["rodas3", "rk4"])
def test_intermediate_update_with_the_other_solvers(fmus, method):
    """RODAS3 and RK4 (fixed_step 0.02) call the intermediate update after their accepted steps too, and
    an early return at one of them changes nothing in the trajectory (RK4's grid restarts there, on the
    same points)."""
    pend = fmus["pendulum"]
    setup = dict(inputs={"a": 0.5, "solver.fixed_step": 0.02}, ints={"solver.method": method})
    plain, _, _, _ = run(pend, 0.5, 0.1, ("y", "w"), **setup)
    asked = {}

    def plan(t, i):
        if 0.21 < t < 0.29 and "here" not in asked:
            asked["here"] = t
            return t
        return None

    grid, returns, calls, f = _run_with_callback(pend, 0.5, 0.1, ("y", "w"), early=True, plan=plan, **setup)
    f.freeInstance()
    times = [c[0] for c in calls]
    assert "error" not in times and np.all(np.diff(times) > 0) and len(times) >= 10
    assert [r[0] for r in returns] == [asked["here"]]
    assert np.max(np.abs(grid - plain)) < 1e-12  # found: 0 (RODAS3), rounding (RK4)


def test_cs_event_mode_misuse_returns_error_with_a_message(fmus):
    ball, pend = fmus["ball"], fmus["pendulum"]
    vr = ball.vr

    def refused(fmu, call, text):
        n = len(fmu.log)
        with pytest.raises(FMICallException) as e:
            call()
        assert "status 3" in str(e.value)
        new = [m for _, m in fmu.log[n:]]
        assert any(text in m for m in new), new
        assert not any("fmi2" in m for m in new), new  # the importer called fmi3 functions

    # eventModeUsed for a model without events: hasEventMode is false, instantiation refused
    with pytest.raises(Exception):
        pend.slave(eventModeUsed=True)
    assert any("hasEventMode is false" in m for _, m in pend.log), pend.log
    # without eventModeUsed: no Event Mode for Co-Simulation
    f = ball.slave()
    f.enterInitializationMode(startTime=0.0)
    f.exitInitializationMode()
    refused(ball, f.enterEventMode, "fmi3EnterEventMode: this Co-Simulation instance was instantiated with "
                                    "eventModeUsed = false")
    refused(ball, f.enterStepMode, "fmi3EnterStepMode: only for a Co-Simulation instance with eventModeUsed")
    refused(ball, f.updateDiscreteStates, "eventModeUsed = false")
    f.terminate()
    f.freeInstance()
    # with it: the calling sequence of Event Mode
    f = ball.slave(eventModeUsed=True, earlyReturnAllowed=True)
    f.enterInitializationMode(startTime=0.0)
    f.exitInitializationMode()
    refused(ball, lambda: f.doStep(0.0, 0.3), "fmi3DoStep: not allowed in state eventMode")
    f.enterStepMode()
    refused(ball, f.enterStepMode, "fmi3EnterStepMode: not allowed in state stepComplete")
    refused(ball, f.updateDiscreteStates, "fmi3UpdateDiscreteStates: not allowed in state stepComplete")
    event, _, early_return, t1 = f.doStep(0.0, 0.6)
    assert event and early_return and t1 == pytest.approx(impact_times(1)[0], abs=1e-9)
    refused(ball, lambda: f.doStep(t1, 0.6 - t1), "call fmi3EnterEventMode and fmi3UpdateDiscreteStates")
    f.enterEventMode()
    refused(ball, f.enterEventMode, "fmi3EnterEventMode: not allowed in state eventMode")
    refused(ball, f.enterStepMode, "fmi3EnterStepMode: the event at t = ")
    assert f.getFloat64([vr["v"]])[0] < 0  # outputs readable in Event Mode: still falling
    assert f.updateDiscreteStates()[:4] == (False, False, False, True)  # v re-initialised
    assert f.getFloat64([vr["v"]])[0] > 0  # bounced
    f.enterStepMode()
    assert f.doStep(t1, 0.6 - t1)[2] is False
    f.terminate()
    f.freeInstance()


def test_fmu_state_taken_at_an_early_return_keeps_its_event(fmus):
    """fmi3GetFMUState between the early return and Event Mode: restored, the event is pending again
    (fmi3DoStep refuses to step over it) and handling it gives the same continuation, bit for bit."""
    ball = fmus["ball"]
    vr = [ball.vr["h"], ball.vr["v"]]
    f = ball.slave(eventModeUsed=True, earlyReturnAllowed=True)
    f.enterInitializationMode(startTime=0.0)
    f.exitInitializationMode()
    f.enterStepMode()
    event, _, early_return, t1 = f.doStep(0.0, 0.6)
    assert event and early_return
    state = f.getFMUState()

    def finish():
        f.enterEventMode()
        f.updateDiscreteStates()
        f.enterStepMode()
        assert f.doStep(t1, 0.6 - t1)[:3] == (False, False, False)
        return f.getFloat64(vr)

    first = finish()
    f.setFMUState(state)
    with pytest.raises(FMICallException):
        f.doStep(t1, 0.6 - t1)
    assert finish() == first and first[1] > 0
    f.freeFMUState(state)
    f.terminate()
    f.freeInstance()


def test_intermediate_update_refuses_all_but_getting(fmus):
    """Inside the callback (Intermediate Update Mode) a nested fmi3DoStep, setting an input, Event Mode,
    FMU state and freeing the instance are refused with a message; the step goes on unharmed."""
    pend = fmus["pendulum"]
    vr = pend.vr
    results = []
    holder = [None]
    dll = []

    def cb(env, t, set_requested, get_allowed, step_finished, can_return_early, requested, when):
        if results:
            return
        f = holder[0]
        b, x = fmpy.fmi3.fmi3Boolean(), fmpy.fmi3.fmi3Float64()
        lib = dll[0]
        results.append(lib.fmi3DoStep(f.component, t, 0.1, False, ctypes.byref(b), ctypes.byref(b), ctypes.byref(b),
                                      ctypes.byref(x)))
        v = (fmpy.fmi3.fmi3Float64 * 1)(1.0)
        r = (fmpy.fmi3.fmi3ValueReference * 1)(vr["a"])
        results.append(lib.fmi3SetFloat64(f.component, r, 1, v, 1))
        results.append(lib.fmi3EnterEventMode(f.component))
        s = ctypes.c_void_p()
        results.append(lib.fmi3GetFMUState(f.component, ctypes.byref(s)))
        lib.fmi3FreeInstance(f.component)  # void: refused, logged, the instance lives on
        results.append(lib.fmi3GetFloat64(f.component, (fmpy.fmi3.fmi3ValueReference * 1)(vr["y"]), 1, v, 1))

    f = holder[0] = _cs_slave(pend, True, fmi3IntermediateUpdateCallback(cb))
    dll.append(f.dll)
    plain, _, _, _ = run(pend, 0.3, 0.1, ("y", "w"))
    pend.log.clear()
    grid, returns, _, _ = run(pend, 0.3, 0.1, ("y", "w"), early=True, slave=f)
    assert results == [3, 3, 3, 3, 0]
    msgs = [m for _, m in pend.log]
    for fn in ("fmi3DoStep", "fmi3SetFloat64", "fmi3EnterEventMode", "fmi3GetFMUState", "fmi3FreeInstance"):
        assert any(m.startswith(f"{fn}: not allowed in Intermediate Update Mode") for m in msgs), (fn, msgs)
    assert returns == [] and np.array_equal(grid, plain)
    f.freeInstance()


def test_fmusim_event_mode_and_early_return(fmus, tmp_path):
    """fmusim (Reference-FMUs) with --event-mode-used --early-return-allowed (and
    --record-intermediate-values): every fmi3 call returns OK, it samples at each impact (before and
    after the event) at the closed-form times, and at the 0.01 s grid its results equal those without
    the options and fmpy's event-mode run."""
    exe = _fmusim()
    ball = fmus["ball"]
    res = {}
    events = ("--event-mode-used", "--early-return-allowed")
    for key, extra in (("plain", ()), ("events", events), ("intermediate", events + ("--record-intermediate-values",))):
        out, log = tmp_path / f"{key}.csv", tmp_path / f"{key}.log"
        r = subprocess.run([exe, "--interface-type", "cs", "--stop-time", "2.0", "--output-interval", "0.01", *extra,
                            "--log-fmi-calls", "--fmi-log-file", str(log), "--output-file", str(out),
                            str(ball.path)], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stdout + r.stderr
        calls = [ln for ln in log.read_text().splitlines() if ln.startswith("fmi3")]
        assert calls and all(ln.endswith("-> OK") for ln in calls), [ln for ln in calls if not ln.endswith("-> OK")]
        res[key] = (np.genfromtxt(out, delimiter=",", names=True), calls)
    plain, (ev, calls) = res["plain"][0], res["events"]
    assert any(c.startswith("fmi3UpdateDiscreteStates") for c in calls)
    t = ev["time"]
    dup = np.unique(t[1:][np.diff(t) == 0])  # sampled twice: before and after the event
    assert np.max(np.abs(dup - impact_times(len(dup)))) < 1e-9 and len(dup) == 4  # the impacts before 2.0 s
    on_grid = np.isclose(t / 0.01, np.round(t / 0.01), atol=1e-6, rtol=0)
    keep = on_grid & np.r_[np.diff(t) != 0, True]  # the last row of each grid time
    assert np.array_equal(t[keep], plain["time"])
    assert max(np.max(np.abs(ev[n][keep] - plain[n])) for n in ("h", "v")) < 1e-12
    grid, _, _, _ = run(ball, 2.0, 0.01, ("h", "v"), event_mode=True, early=True)
    assert np.max(np.abs(grid - np.c_[plain["h"], plain["v"]])) < 1e-12
    # --record-intermediate-values: fmusim samples in the callback too (after each solver step: here one
    # per 0.01 s step, the ball's flight being a parabola), the values at the grid unchanged
    iv = res["intermediate"][0]
    ti = iv["time"]
    assert np.all(np.diff(ti) >= 0) and len(ti) > len(t) + 150
    off = ~np.isclose(ti / 0.01, np.round(ti / 0.01), atol=1e-6, rtol=0)
    keep = ~off & np.r_[np.diff(ti) != 0, True]
    assert np.array_equal(ti[keep], plain["time"])
    assert max(np.max(np.abs(iv[n][keep] - plain[n])) for n in ("h", "v")) < 1e-12
