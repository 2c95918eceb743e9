"""Robot joints with stick-slip friction and end stops as FMI events.

``Manipulator.state_space_model(friction="stick-slip", limits="stops")``: per joint a friction mode
slip[i] in {-1, 0, +1} (0: stuck) and a stop mode rest[i] in {-1, 0, +1}; one SPD solve whose rows and
columns of locked joints are the identity's (the docstring has the design).  Checked here:

(a) a 2-link planar arm held against gravity by stiction (breakaway above the gravity torque) does not
    move in 10 s (exactly: a locked joint has qdd = 0 and qd = 0), while its smooth-friction twin creeps;
(b) a torque pulse above breakaway: every breakaway and stick (a stick and a reversal in one event
    iteration included) at the time an independent simulation gives -- numpy lock solves on the robot's
    own M(q), h(q, qd), scipy's event location, restarts -- in CS (the runtime's own solver) and in ME
    (fmpy, CVode);
(c) a pendulum driven into its URDF lower limit: with e = 0.5 every rebound has exactly half the impact
    speed (kinetic energy e^2), with e = 0 it rests on the stop exactly and stays;
(d) the FMUs pass fmpy's validate_fmu; ME and CS give the same event times;
(e) the exact Jacobian (dfdx, dfdu, dgdx, dgdu) equals central differences of f and g in every mode
    (81 modes of friction and stops on both joints, a locked joint, a Lagrange derivation);
and the refusals (loops, tied mimic followers with friction, no friction to make hybrid), the DH file's
``friction`` and ``limits`` fields, and ``fmugen build --friction stick-slip --limits stops``.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fmugen
from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.robot.urdf import robot_from_urdf

# a planar arm in the x-z plane (axes y, gravity -z): q > 0 lowers a link
PLANAR = """<?xml version="1.0"?>
<robot name="planar2">
  <link name="base"/>
  <link name="upper">
    <inertial><origin xyz="0.25 0 0"/><mass value="2.0"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.045" iyz="0" izz="0.045"/></inertial>
  </link>
  <link name="fore">
    <inertial><origin xyz="0.2 0 0"/><mass value="1.0"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.015" iyz="0" izz="0.015"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2.5" upper="2.5" effort="100" velocity="5"/>
    <dynamics damping="0.1" friction="15"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/><origin xyz="0.5 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2.5" upper="2.5" effort="50" velocity="5"/>
    <dynamics damping="0.05" friction="3"/>
  </joint>
</robot>
"""

# a pendulum falling from q = 3 onto its lower limit 2 (hanging straight down is q = pi/2)
PENDULUM = """<?xml version="1.0"?>
<robot name="pendulum">
  <link name="base"/>
  <link name="rod">
    <inertial><origin xyz="0.3 0 0"/><mass value="1.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial>
  </link>
  <joint name="hinge" type="revolute">
    <parent link="base"/><child link="rod"/><origin xyz="0 0 0"/>
    <axis xyz="0 1 0"/><limit lower="2.0" upper="3.1" effort="50" velocity="10"/>
  </joint>
</robot>
"""

Q0 = [0.3, 0.2]  # gravity torque there: 11.09 and 1.72 N.m, below the breakaway levels 15 and 3 N.m
FC = [15.0, 3.0]
PULSE = (0.5, 0.7, -40.0)  # tau[1] = -40 N.m for 0.5 <= t < 0.7 s: above breakaway (lifts the arm)
LO = 2.0


def _events(messages):
    """The times of the state events the CS runtime logged (logEvents), to 17 digits."""
    return [float(m.split("state event at t = ")[1].split()[0]) for m in messages if "state event at t = " in m]


def _mode_changes(res, names):
    """ME result rows (fmpy records before and after every event): [(t, before, after)] of the modes."""
    s = np.c_[tuple(res[n] for n in names)]
    ch = np.nonzero(np.any(np.diff(s, axis=0) != 0, axis=1))[0]
    return [(res["time"][k + 1], tuple(s[k]), tuple(s[k + 1])) for k in ch]


def _pulse_input(t_end):
    t_on, t_off, amp = PULSE
    return np.array([(0.0, 0.0, 0.0), (t_on, 0.0, 0.0), (t_on, amp, 0.0), (t_off, amp, 0.0), (t_off, 0.0, 0.0),
                     (t_end, 0.0, 0.0)], dtype=[("time", float), ("tau[1]", float), ("tau[2]", float)])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("robot_events")
    (d / "planar2.urdf").write_text(PLANAR)
    (d / "pendulum.urdf").write_text(PENDULUM)
    return d


@pytest.fixture(scope="module")
def arm(files):
    return fmugen.load_robot(files / "planar2.urdf")


@pytest.fixture(scope="module")
def fmus(files, arm):
    starts = {"q[1]": Q0[0], "q[2]": Q0[1]}
    out = {"stick": files / "stick.fmu", "smooth": files / "smooth.fmu", "stops": files / "stops.fmu"}
    fmugen.build_fmu(arm.state_space_model(outputs=(), friction="stick-slip").with_starts(starts), out["stick"],
                     fmi_type="both")
    fmugen.build_fmu(arm.state_space_model(outputs=()).with_starts(starts), out["smooth"], fmi_type="cs")
    pend = fmugen.load_robot(files / "pendulum.urdf")
    fmugen.build_fmu(pend.state_space_model(outputs=(), limits="stops").with_starts({"q[1]": 3.0}), out["stops"],
                     fmi_type="both")
    return out


def test_held_by_stiction_the_arm_does_not_move_while_the_smooth_twin_creeps(fmus, arm):
    from fmpy import simulate_fmu

    h = arm.bias(Q0, [0, 0])
    assert np.all(np.abs(h) < FC) and np.abs(h).min() > 1.0  # held by stiction, against a real load
    r = simulate_fmu(str(fmus["stick"]), fmi_type="CoSimulation", stop_time=10.0, output_interval=0.05,
                     start_values={"solver.rtol": 1e-10},
                     output=["q[1]", "q[2]", "qd[1]", "qd[2]", "slip[1]", "slip[2]", "solver.n_events"])
    drift = max(np.abs(r["q[1]"] - Q0[0]).max(), np.abs(r["q[2]"] - Q0[1]).max())
    assert drift < 1e-12, drift
    assert np.all(r["qd[1]"] == 0) and np.all(r["qd[2]"] == 0)
    assert np.all(r["slip[1]"] == 0) and np.all(r["slip[2]"] == 0) and r["solver.n_events"][-1] == 0
    s = simulate_fmu(str(fmus["smooth"]), fmi_type="CoSimulation", stop_time=10.0, output_interval=0.05,
                     start_values={"solver.rtol": 1e-10, "solver.method": 2}, output=["q[1]", "q[2]"])
    creep = (abs(s["q[1]"][-1] - Q0[0]), abs(s["q[2]"][-1] - Q0[1]))
    print(f"\nheld 10 s: stick-slip drift {drift:.1e} rad; smooth (tanh, v_c = 0.01 rad/s) twin drift "
          f"{creep[0]:.4f} rad (shoulder), {creep[1]:.4f} rad (elbow)")
    assert min(creep) > 0.01


def hybrid_reference(arm, q0, torque, switch_times, t_end, Fs=FC, rtol=1e-12):
    """Stick-slip friction simulated without the model's masks: per mode the free joints by a numpy solve
    on the robot's own M(q) and h(q, qd) (its smooth friction switched off), the sliding friction
    -m_i F_c_i, the locked joints' constraint torques tau - h - M qdd; scipy's event location, restarts.
    ``torque(t)`` is piecewise constant between ``switch_times``.  Returns ([(t, what, joint)], q, qd, m)."""
    params = {"fc_shoulder": 0.0, "fc_elbow": 0.0}
    n = len(q0)
    Fc, Fs = np.asarray(FC), np.asarray(Fs)

    def dyn(q, qd, mode, tau):
        M, h = arm.mass_matrix(q, **params), arm.bias(q, qd, **params)
        free = [i for i in range(n) if mode[i] != 0]
        qdd = np.zeros(n)
        if free:
            qdd[free] = np.linalg.solve(M[np.ix_(free, free)], (tau - h - mode * Fc)[free])
        return qdd, tau - h - M @ qdd

    events = []

    def settle(t, q, qd, mode, tau):  # rounds until nothing changes: stick first, breakaway in the next round
        for _ in range(50):
            qdd, tc = dyn(q, qd, mode, tau)
            new, changed = mode.copy(), False
            for i in range(n):
                if mode[i] != 0 and mode[i] * qd[i] <= 0 and (mode[i] * qd[i] < 0 or mode[i] * qdd[i] <= 0):
                    new[i], qd[i], changed = 0, 0.0, True
                    events.append((t, "stick", i + 1))
                elif mode[i] == 0 and abs(tc[i]) > Fs[i]:
                    new[i], changed = np.sign(tc[i]), True
                    events.append((t, "breakaway", i + 1))
            mode = new
            if not changed:
                return mode
        raise RuntimeError(f"the reference's event iteration at t = {t} does not settle")

    t, q, qd = 0.0, np.array(q0, float), np.zeros(n)
    mode = settle(t, q, qd, np.zeros(n), torque(t))
    for t_b in sorted(s for s in switch_times if 0 < s < t_end) + [t_end]:
        while t < t_b:
            tau = torque(t)
            evs = []
            for i in range(n):
                if mode[i] != 0:
                    f = lambda t, x, i=i, m=mode[i]: m * x[n + i]  # noqa: E731
                else:
                    f = lambda t, x, i=i, mode=mode: Fs[i] - abs(dyn(x[:n], x[n:], mode, tau)[1][i])  # noqa: E731
                f.terminal, f.direction = True, -1
                evs.append(f)
            sol = solve_ivp(lambda t, x: np.r_[x[n:], dyn(x[:n], x[n:], mode, tau)[0]], (t, t_b), np.r_[q, qd],
                            method="DOP853", rtol=rtol, atol=rtol, events=evs)
            t, q, qd = sol.t[-1], sol.y[:n, -1].copy(), sol.y[n:, -1].copy()
            if sol.status != 1:
                break
            i = next(k for k, te in enumerate(sol.t_events) if len(te))
            if mode[i] != 0:  # the located stick: qd_i = 0, then the iteration (a breakaway in the next round)
                events.append((t, "stick", i + 1))
                mode[i], qd[i] = 0, 0.0
            else:
                events.append((t, "breakaway", i + 1))
                mode[i] = np.sign(dyn(q, qd, mode, tau)[1][i])
            mode = settle(t, q, qd, mode, tau)
        t = t_b
        mode = settle(t, q, qd, mode, torque(t))
    return events, q, qd, mode


@pytest.fixture(scope="module")
def reference(arm):
    t_on, t_off, amp = PULSE
    return hybrid_reference(arm, Q0, lambda t: np.array([amp if t_on <= t < t_off else 0.0, 0.0]), (t_on, t_off),
                            2.0)


def test_breakaway_and_stick_times_equal_an_independent_simulation(fmus, reference):
    from fmpy import simulate_fmu

    t_on, t_off, amp = PULSE
    t_end = 2.0
    events, q_ref, _, mode_ref = reference
    ref_times = sorted({round(float(t), 12) for t, _, _ in events})
    # the pulse breaks both joints away at its start (closed form: the step time); the elbow sticks and
    # reverses in one event iteration, then both stick
    assert ref_times[0] == t_on and len(ref_times) == 4
    assert [w for t, w, j in events if abs(t - ref_times[1]) < 1e-9] == ["stick", "breakaway"]

    log = []
    cs = simulate_fmu(str(fmus["stick"]), fmi_type="CoSimulation", stop_time=t_end, output_interval=0.01,
                      input=_pulse_input(t_end), start_values={"solver.rtol": 1e-10},
                      output=["q[1]", "q[2]", "slip[1]", "slip[2]", "solver.n_events"], debug_logging=True,
                      logger=lambda env, name, status, cat, msg: log.append(msg.decode()))
    cs_times = _events(log)
    me = simulate_fmu(str(fmus["stick"]), fmi_type="ModelExchange", stop_time=t_end, output_interval=0.01,
                      input=_pulse_input(t_end), relative_tolerance=1e-10,
                      output=["q[1]", "q[2]", "slip[1]", "slip[2]"])
    changes = _mode_changes(me, ["slip[1]", "slip[2]"])
    me_times = [t for t, _, _ in changes]
    assert len(cs_times) == len(me_times) == len(ref_times), (cs_times, me_times, ref_times)
    err_cs = np.abs(np.array(cs_times) - ref_times).max()
    err_me = np.abs(np.array(me_times) - ref_times).max()
    print(f"\nevent times {np.round(ref_times, 9).tolist()}: |CS - reference| <= {err_cs:.1e} s, "
          f"|ME - reference| <= {err_me:.1e} s, |ME - CS| <= {np.abs(np.subtract(me_times, cs_times)).max():.1e} s")
    assert err_cs < 1e-6 and err_me < 1e-6
    # the modes: both slide (-1 lifting, +1), the elbow reverses (+1 -> -1 in one iteration), both stick
    assert [(b, a) for _, b, a in changes] == [((0, 0), (-1, 1)), ((-1, 1), (-1, -1)), ((-1, -1), (0, -1)),
                                               ((0, -1), (0, 0))]
    assert cs["solver.n_events"][-1] == 4 and tuple(mode_ref) == (0, 0)
    for res in (cs, me):
        assert abs(res["q[1]"][-1] - q_ref[0]) < 1e-5 and abs(res["q[2]"][-1] - q_ref[1]) < 1e-5
        after = res["time"] > ref_times[-1] + 1e-6  # stuck again: not a bit of motion
        assert np.ptp(res["q[1]"][after]) == 0 and np.ptp(res["q[2]"][after]) == 0


@pytest.mark.parametrize("method,extra", [(1, {}), (2, {}), (3, {"solver.fixed_step": 1e-4})],
                         ids=["dopri5", "rodas3", "rk4"])
def test_every_cs_solver_finds_the_same_events_at_a_large_communication_step(fmus, reference, method, extra):
    from fmpy import simulate_fmu

    ref_times = sorted({round(float(t), 12) for t, _, _ in reference[0]})
    log = []
    r = simulate_fmu(str(fmus["stick"]), fmi_type="CoSimulation", stop_time=2.0, output_interval=0.05,
                     input=_pulse_input(2.0), start_values={"solver.rtol": 1e-10, "solver.method": method, **extra},
                     output=["q[1]", "q[2]"], debug_logging=True,
                     logger=lambda env, name, status, cat, msg: log.append(msg.decode()))
    times = _events(log)
    assert len(times) == len(ref_times) and np.abs(np.subtract(times, ref_times)).max() < 1e-6
    assert np.abs(np.array([r["q[1]"][-1], r["q[2]"][-1]]) - reference[1]).max() < 1e-5


def test_a_stop_returns_e_times_the_impact_speed_and_holds_an_inelastic_joint_exactly(fmus, files):
    from fmpy import simulate_fmu

    pend = fmugen.load_robot(files / "pendulum.urdf")
    # the first impact, independently: the robot's own forward dynamics, scipy's event location
    hit = lambda t, x: x[0] - LO  # noqa: E731
    hit.terminal, hit.direction = True, -1
    sol = solve_ivp(lambda t, x: [x[1], pend.forward_dynamics([x[0]], [x[1]], [0.0])[0]], (0, 1), [3.0, 0.0],
                    method="DOP853", rtol=1e-13, atol=1e-13, events=hit)
    t_hit, v_hit = sol.t_events[0][0], sol.y_events[0][0][1]
    pe_lo = pend.energy([LO], [0.0])[1]

    log = []
    cs = simulate_fmu(str(fmus["stops"]), fmi_type="CoSimulation", stop_time=3.0, output_interval=0.005,
                      start_values={"solver.rtol": 1e-12, "solver.max_step": 1e-3, "e_stop_hinge": 0.5},
                      output=["q[1]", "qd[1]", "rest[1]"], debug_logging=True,
                      logger=lambda env, name, status, cat, msg: log.append(msg.decode()))
    cs_times = _events(log)
    assert abs(cs_times[0] - t_hit) < 1e-9, cs_times[0] - t_hit
    energy = np.array([sum(pend.energy([a], [b])) for a, b in zip(cs["q[1]"], cs["qd[1]"])])
    e0 = energy[0] - pe_lo  # the kinetic energy at the impact
    worst = 0.0
    for k in range(3):  # after each of the first three impacts: kinetic energy e^2 of the one before
        seg = (cs["time"] > cs_times[k]) & (cs["time"] < cs_times[k + 1])
        ratio = (energy[seg] - pe_lo) / e0
        worst = max(worst, np.abs(ratio / 0.25 ** (k + 1) - 1).max())
        assert np.abs(ratio - 0.25 ** (k + 1)).max() < 1e-9 * 0.25 ** k, ratio
    # ME: fmpy records the state before and after each impact: qd_after = -e qd_before exactly
    me = simulate_fmu(str(fmus["stops"]), fmi_type="ModelExchange", stop_time=3.0, output_interval=0.005,
                      start_values={"e_stop_hinge": 0.5}, relative_tolerance=1e-12, output=["q[1]", "qd[1]", "rest[1]"])
    times, first, count = np.unique(me["time"], return_index=True, return_counts=True)
    events = [(t, me["qd[1]"][k], me["qd[1]"][k + c - 1]) for t, k, c in zip(times, first, count) if c > 1]
    bounces = [ev for ev in events if ev[2] > 0]
    assert len(bounces) >= 8
    assert abs(bounces[0][1] - v_hit) < 1e-9 * abs(v_hit)
    for t, before, after in bounces:
        assert abs(after / before + 0.5) < 1e-12  # the speed ratio e, hence kinetic energy e^2
    me_times = [t for t, _, _ in bounces]
    gap = np.abs(np.array(me_times[:8]) - cs_times[:8]).max()
    print(f"\nstop, e = 0.5: first impact |CS - reference| {abs(cs_times[0] - t_hit):.1e} s; kinetic energy after "
          f"3 impacts / e^2k - 1 <= {worst:.1e} (CS); ME speed ratio exact; |ME - CS| impact times <= {gap:.1e} s; "
          f"{len(cs_times)} impacts (CS), {len(bounces)} rebounds (ME) before resting")
    assert gap < 1e-6 and len(cs_times) == len(events)
    # the bounces shrink below the rest speed: resting on the stop, exactly
    for res in (cs, me):
        assert res["rest[1]"][-1] == -1 and res["q[1]"][-1] == LO and res["qd[1]"][-1] == 0

    # e = 0: the first impact rests the joint on the stop, exactly, for good
    log.clear()
    cs0 = simulate_fmu(str(fmus["stops"]), fmi_type="CoSimulation", stop_time=3.0, output_interval=0.005,
                       start_values={"solver.rtol": 1e-12}, output=["q[1]", "qd[1]", "rest[1]"],
                       debug_logging=True, logger=lambda env, name, status, cat, msg: log.append(msg.decode()))
    assert len(_events(log)) == 1 and abs(_events(log)[0] - t_hit) < 1e-6
    after = cs0["time"] > t_hit + 1e-6
    assert np.all(cs0["q[1]"][after] == LO) and np.all(cs0["qd[1]"][after] == 0) and np.all(cs0["rest[1]"][after] == -1)
    assert np.all(cs0["q[1]"] >= LO - 1e-12)


def test_the_fmus_validate_and_declare_their_modes(fmus):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    for key in ("stick", "stops"):
        assert validate_fmu(str(fmus[key])) == [], key
    md = read_model_description(str(fmus["stick"]))
    var = {v.name: v for v in md.modelVariables}
    assert md.numberOfEventIndicators == 4  # stick and breakaway per joint
    assert var["slip[1]"].variability == "discrete" and var["fs_shoulder"].start == "15.0"
    md = read_model_description(str(fmus["stops"]))
    var = {v.name: v for v in md.modelVariables}
    assert md.numberOfEventIndicators == 3  # lower, upper, leave
    assert {"rest[1]", "q_lower_hinge", "q_upper_hinge", "e_stop_hinge", "v_rest"} <= set(var)
    assert var["q[1]"].min is None  # the stops hold q; no validity range to leave


def _check_jacobian(model, x, u, modes):
    """Exact (A, B, C, D) against central differences of f and g, in every mode of ``modes``."""
    ev = ModelEvaluator(model)  # compiled once; each mode's values go where ModelEvaluator puts them
    names = [v.name for v in model.events.discrete]
    base = len(model.parameters)
    worst = 0.0
    for n_mode, mode in enumerate(modes):
        for k, name in enumerate(names):
            ev.p[base + k] = mode[name]
        if n_mode in (0, len(modes) - 1):  # the same as an evaluator made for that mode
            assert np.array_equal(ev.f(0.0, x, u), ModelEvaluator(model, mode).f(0.0, x, u))
        A, B, C, D = ev.jacobians(0.0, x, u)
        for exact, fun, z0, other in ((A, ev.f, x, "x"), (B, ev.f, u, "u"), (C, ev.g, x, "x"), (D, ev.g, u, "u")):
            if exact.size == 0:
                continue
            fd = np.zeros_like(exact)
            for c in range(len(z0)):
                step = 1e-6 * max(1.0, abs(z0[c]))
                zp, zm = z0.copy(), z0.copy()
                zp[c] += step
                zm[c] -= step
                fp = fun(0.0, zp, u) if other == "x" else fun(0.0, x, zp)
                fm = fun(0.0, zm, u) if other == "x" else fun(0.0, x, zm)
                fd[:, c] = (fp - fm) / (2 * step)
            err = np.abs(exact - fd) / np.maximum(1.0, np.abs(fd))
            worst = max(worst, err.max())
            assert err.max() < 1e-7, (mode, other, exact, fd)
    return worst


def test_the_exact_jacobian_is_the_current_modes_in_every_mode(arm):
    import itertools

    model = arm.state_space_model(outputs=("qdd",), friction="stick-slip", limits="stops")
    assert [v.name for v in model.events.discrete] == ["slip[1]", "rest[1]", "slip[2]", "rest[2]"]
    x, u = np.array([0.4, -0.3, 0.7, -0.5]), np.array([1.3, -0.4])
    modes = [dict(zip(["slip[1]", "rest[1]", "slip[2]", "rest[2]"], m))
             for m in itertools.product((-1.0, 0.0, 1.0), repeat=4)]
    worst = _check_jacobian(model, x, u, modes)
    # a locked mode: that joint's acceleration is exactly zero, the other sees it held
    ev = ModelEvaluator(model, {"slip[1]": 0.0, "slip[2]": 1.0})
    f = ev.f(0.0, x, u)
    assert f[2] == 0.0
    M = arm.mass_matrix(x[:2])
    h = arm.bias(x[:2], x[2:], fc_shoulder=0.0, fc_elbow=0.0)
    assert abs(f[3] - (u[1] - h[1] - FC[1]) / M[1, 1]) < 1e-12 * max(1, abs(f[3]))
    # scene-locked shoulder: the elbow alone, three modes; and a Lagrange derivation, same f
    locked = arm.state_space_model(outputs=(), friction="stick-slip", locked={1: 0.3})
    assert [v.name for v in locked.events.discrete] == ["slip[2]"]
    worst = max(worst, _check_jacobian(locked, np.array([-0.2, 0.6]), np.array([0.8]),
                                       [{"slip[2]": s} for s in (-1.0, 0.0, 1.0)]))
    lag = arm.state_space_model(outputs=(), friction="stick-slip", formulation="lagrange")
    for m in ({"slip[1]": 1.0, "slip[2]": -1.0}, {"slip[1]": 0.0, "slip[2]": 1.0}):
        a = ModelEvaluator(lag, m).f(0.0, x, u)
        b = ModelEvaluator(arm.state_space_model(outputs=(), friction="stick-slip"), m).f(0.0, x, u)
        assert np.allclose(a, b, rtol=1e-12, atol=1e-12)
    print(f"\nJacobian vs central differences, 84 modes: worst relative error {worst:.1e}")


def test_smooth_and_range_are_todays_model(arm):
    a = arm.state_space_model(outputs=("qdd",))
    b = arm.state_space_model(outputs=("qdd",), friction="smooth", limits="range")
    assert a.events is None and b.events is None
    assert a.program.steps == b.program.steps and a.derivatives == b.derivatives and a.dfdx == b.dfdx
    assert [(v.name, v.min, v.max) for v in a.states] == [(v.name, v.min, v.max) for v in b.states]


def test_what_the_hybrid_model_refuses(arm, files):
    from fmugen.robot.chain import n_link_chain
    from fmugen.dynamics.manipulator import Manipulator

    with pytest.raises(ValueError, match="strategy='straight'"):
        arm.state_space_model(friction="stick-slip", strategy="loops")
    with pytest.raises(ValueError, match="strategy='straight'"):  # auto would take the loops from 7 joints
        Manipulator(n_link_chain(7, seed=1)).state_space_model(limits="stops")
    with pytest.raises(ValueError, match="friction must be one of"):
        arm.state_space_model(friction="stiction")
    with pytest.raises(ValueError, match="limits must be one of"):
        arm.state_space_model(limits="hard")
    pendulum = fmugen.load_robot(files / "pendulum.urdf")
    with pytest.raises(ValueError, match="no free joint has Coulomb friction"):
        pendulum.state_space_model(friction="stick-slip")
    with pytest.raises(ValueError, match="no free joint has limits"):
        Manipulator(n_link_chain(2, seed=1)).state_space_model(limits="stops")
    tied = PLANAR.replace('<dynamics damping="0.05" friction="3"/>',
                          '<dynamics damping="0.05" friction="3"/><mimic joint="shoulder" multiplier="0.5"/>')
    follower = Manipulator(robot_from_urdf(tied, mimic="tied"))
    with pytest.raises(ValueError, match="tied mimic joints with friction of their own \\(elbow\\)"):
        follower.state_space_model(friction="stick-slip")
    with pytest.raises(ValueError, match="tied mimic joints with limits of their own \\(elbow\\)"):
        follower.state_space_model(limits="stops")


DH_PENDULUM = """
[robot]
name = "dh_pendulum"
gravity = [0, -9.81, 0]

[[links]]
joint = "revolute"
a = 0.6
alpha = 0
d = 0
theta = 0
mass = 1.5
com = [-0.3, 0, 0]
inertia = [0.001, 0.02, 0.02]
friction = 0.4
limits = [-2.0, "pi/2"]
"""


def test_a_dh_file_gives_friction_and_limits(tmp_path):
    from fmugen.robot.checks import RobotFileError

    path = tmp_path / "dh_pendulum.toml"
    path.write_text(DH_PENDULUM)
    arm = fmugen.load_robot(path)
    body = arm.robot.bodies[0]
    assert str(body.friction) == "fc_1" and str(body.friction_velocity) == "v_coulomb"
    assert body.limits.lower == -2.0 and body.limits.upper == pytest.approx(np.pi / 2, abs=1e-15)
    # the smooth term (as URDF robots), the validity range, and the events from the same fields
    assert arm.bias([0.0], [0.02])[0] - arm.bias([0.0], [0.02], fc_1=0.0)[0] == pytest.approx(0.4 * np.tanh(2.0))
    smooth = arm.state_space_model(outputs=())
    assert (smooth.states[0].min, smooth.states[0].max) == (-2.0, body.limits.upper)
    both = arm.state_space_model(outputs=(), friction="stick-slip", limits="stops", formulation="lagrange")
    assert {v.name for v in both.parameters} >= {"fs_1", "q_lower_1", "q_upper_1", "e_stop_1", "v_rest"}
    f = ModelEvaluator(both, {"slip[1]": 1.0}).f(0.0, [0.3, 0.5], [0.2])
    assert f[1] == pytest.approx(arm.forward_dynamics([0.3], [0.5], [0.2 - 0.4], fc_1=0.0)[0], rel=1e-12)
    for bad, why in (("limits = [1.0, -1.0]", "must be below upper"), ("limits = [0, 1, 2]", "expected \\[lower"),
                     ("friction = -1", "negative"), ("friction = 0.4\nfriction_velocity = 0", "must be > 0")):
        path.write_text(DH_PENDULUM.replace("friction = 0.4\nlimits = [-2.0, \"pi/2\"]", bad))
        with pytest.raises(RobotFileError, match=why):
            fmugen.load_robot(path)


def test_the_build_command_takes_the_event_flags(files, tmp_path, capsys):
    from fmpy import read_model_description

    from fmugen.cli import main

    out = tmp_path / "planar_hybrid.fmu"
    assert main(["build", str(files / "planar2.urdf"), "--friction", "stick-slip", "--limits", "stops",
                 "--outputs", "", "--fmi-type", "cs", "-o", str(out)]) == 0
    md = read_model_description(str(out))
    assert md.numberOfEventIndicators == 10
    assert {"slip[2]", "rest[2]", "fs_elbow", "e_stop_shoulder"} <= {v.name for v in md.modelVariables}
    capsys.readouterr()
    assert main(["build", "fmugen/components/library/pid.toml", "--friction", "stick-slip",
                 "-o", str(tmp_path / "x.fmu")]) == 2
    assert "--friction stick-slip is for a robot's forward dynamics" in capsys.readouterr().err
