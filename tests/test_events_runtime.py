"""Events in the FMI runtime (c_runtime/events.c): the bouncing ball, the classic check of every FMI tool.

From h = 1 m, e = 0.7 the bounce times are t_1 = sqrt(2 h0/g), t_(k+1) = t_k + 2 e^k v_1/g (v_1 = g t_1)
and the ball comes to rest at the Zeno point t_1 (1 + e)/(1 - e).  Between bounces the motion is a parabola,
so any recorded (h, v) names the bounce before it: v_b = sqrt(v^2 + 2 g h), t_b = t - (v_b - v)/g.  The CS
FMU locates each bounce inside the communication step (every internal solver, a 1 ms and a 0.1 s step give
the same times), fmpy's ME run under CVode finds the same, the Zeno point ends in fmi2Discard naming the
indicator, and FMU state restores a run across events bit for bit.
"""
import numpy as np
import pytest
import sympy as sp

import fmugen
from fmugen.codegen.model import EventClause, Events, SymbolicModel, Variable

G, E, H0 = 9.81, 0.7, 1.0


def ball_model(name="bouncing_ball"):
    h, v, g, e = sp.symbols("h v g e", real=True)
    states = [Variable("h", h, "m", "height above the ground", start=H0, output=True),
              Variable("v", v, "m/s", "upward speed", start=0.0, output=True)]
    params = [Variable("g", g, "m/s2", "gravity", start=G, sign=">0"),
              Variable("e", e, "1", "coefficient of restitution", start=E, min=0.0, max=1.0)]
    events = Events(indicators=(("h", h),), clauses=(EventClause(sp.And(h <= 0, v < 0), ((v, -e * v),), "bounce"),))
    return SymbolicModel.from_equations(name, states, [], params, [v, -g], events=events)


def closed_form(n=30):
    t1 = np.sqrt(2 * H0 / G)
    tb = [t1]
    for k in range(1, n):
        tb.append(tb[-1] + 2 * E ** k * G * t1 / G)
    return np.array(tb)


def bounce_errors(time, h, v, grid=None):
    """|estimated - closed-form| bounce time for every recorded sample after the first bounce.  ``grid``:
    keep only the output grid's rows (fmpy's ME result adds rows before and after each event)."""
    tb = closed_form()
    if grid is not None:
        keep = np.abs(time / grid - np.round(time / grid)) < 1e-6
        time, h, v = time[keep], h[keep], v[keep]
    est = time - (np.sqrt(v ** 2 + 2 * G * np.maximum(h, 0.0)) - v) / G
    idx = np.searchsorted(tb, time, side="right") - 1
    ok = idx >= 0
    return np.abs(est[ok] - tb[idx[ok]]), len(set(idx[ok]))


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    path = tmp_path_factory.mktemp("ball") / "bouncing_ball.fmu"
    fmugen.build_fmu(ball_model(), path, fmi_type="both")
    return path


def test_the_fmu_declares_its_indicator_and_validates(ball):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(ball)) == []
    md = read_model_description(str(ball))
    assert md.numberOfEventIndicators == 1
    assert "solver.n_events" in {v.name for v in md.modelVariables}


@pytest.mark.parametrize("method,extra", [(1, {}), (2, {}), (3, {"solver.fixed_step": 1e-3})],
                         ids=["dopri5", "rodas3", "rk4"])
@pytest.mark.parametrize("H", [1e-3, 0.1])
def test_cs_bounce_times_equal_the_closed_form(ball, method, extra, H):
    from fmpy import simulate_fmu

    r = simulate_fmu(str(ball), fmi_type="CoSimulation", stop_time=2.5, output_interval=H,
                     start_values={"solver.method": method, "solver.rtol": 1e-10, **extra},
                     output=["h", "v", "solver.n_events"])
    err, seen = bounce_errors(r["time"], r["h"], r["v"])
    assert seen >= (11 if H < 0.01 else 8)  # 11 bounces before 2.5 s; a 0.1 s grid samples 8 flights
    assert err.max() < 1e-9, err.max()
    # one event per bounce: the rise through h = 0 right after it is no second event (the indicator's
    # domain after an event is the one the trajectory enters)
    assert r["solver.n_events"][-1] == 11


def test_me_under_cvode_finds_the_same_bounces(ball):
    from fmpy import simulate_fmu

    me = simulate_fmu(str(ball), fmi_type="ModelExchange", stop_time=2.5, output_interval=1e-3,
                      relative_tolerance=1e-12, output=["h", "v"])
    err, seen = bounce_errors(me["time"], me["h"], me["v"], grid=1e-3)
    assert seen >= 11 and err.max() < 1e-9, err.max()
    cs = simulate_fmu(str(ball), fmi_type="CoSimulation", stop_time=2.5, output_interval=1e-3,
                      start_values={"solver.rtol": 1e-10}, output=["h", "v"])
    # at the common grid points the two runs agree to the event location's accuracy
    t = np.intersect1d(np.round(me["time"], 9), np.round(cs["time"], 9))
    a = np.interp(t, me["time"], me["h"])
    b = np.interp(t, cs["time"], cs["h"])
    assert np.abs(a - b).max() < 1e-7


def test_the_zeno_point_ends_in_discard_naming_the_indicator(ball, tmp_path):
    """Past t_inf = t_1 (1 + e)/(1 - e) = 2.5586 s the bounces accumulate: the step is discarded, the run
    does not hang, and the message names the indicator and the time."""
    from fmpy.fmi2 import fmi2Discard, fmi2OK

    from fmi_log import open_fmu, start, step

    t_inf = closed_form()[0] * (1 + E) / (1 - E)
    fmu = open_fmu(ball, tmp_path / "unzip", "zeno")
    try:
        start(fmu, 0.0, reals={"solver.rtol": 1e-10})
        t, status = 0.0, fmi2OK
        while t < 3.0 and status == fmi2OK:
            status = step(fmu, t, 0.01)
            t += 0.01
        assert status == fmi2Discard, status
        assert abs(t - t_inf) < 0.02, t
        text = fmu.log.text()
        assert "event storm" in text and "z[1] (h)" in text, text[-2000:]
    finally:
        fmu.freeInstance()


def test_fmu_state_restores_a_run_across_events_bit_for_bit(ball):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(ball))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = extract(str(ball))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="b")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for k in range(40):  # past the first bounce (0.45 s)
            fmu.doStep(k * 0.0125, 0.0125)
        saved = fmu.getFMUstate()
        blob = fmu.serializeFMUstate(saved)

        def run():
            out = []
            for k in range(40, 120):  # two more bounces
                fmu.doStep(k * 0.0125, 0.0125)
                out.append(fmu.getReal([vr["h"], vr["v"]]))
            return np.array(out)

        a = run()
        fmu.setFMUstate(fmu.deSerializeFMUstate(blob))
        b = run()
        assert np.array_equal(a, b) and np.any(np.diff(np.sign(a[:, 1])) > 0)  # a bounce is inside
        fmu.freeFMUstate(saved)
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_an_event_iteration_that_never_settles_is_an_error(tmp_path):
    """Two clauses that undo each other (m := 1 - m whenever x <= 0): the event iteration stops after 100
    rounds with an error naming it, at initialisation and never a hang."""
    x, m = sp.symbols("x m", real=True)
    states = [Variable("x", x, "m", start=0.0, output=True)]
    events = Events(discrete=(Variable("m", m, "1", "mode", start=0.0),), indicators=(("x", x),),
                    clauses=(EventClause(x <= 0, ((m, 1 - m),), "flip"),))
    model = SymbolicModel.from_equations("flip", states, [], [], [1 - m], events=events)
    path = tmp_path / "flip.fmu"
    fmugen.build_fmu(model, path, fmi_type="cs")
    from fmpy.fmi2 import fmi2Error

    from fmi_log import open_fmu, status_of

    fmu = open_fmu(path, tmp_path / "unzip", "flip")
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        assert status_of(fmu.exitInitializationMode) == fmi2Error
        assert "does not converge" in fmu.log.text()
    finally:
        fmu.freeInstance()
