"""The thesis PUMA as FMI 2.0 FMUs: exact derivatives, accurate CS solvers, FMI behaviour."""
import threading
import warnings
from ctypes import POINTER, c_double

import fmpy
import numpy as np
import pytest
from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp
from scipy.optimize import minimize

import fmugen
from fmugen.dynamics.manipulator import Manipulator
from fmugen.fmi.build import build_fmu
from fmugen.robot.loader import robot_from_toml

N = 6


@pytest.fixture(scope="module")
def puma():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the literal thesis data opt in to an unrealisable link 2
        return fmugen.load_robot("robots/puma_thesis.toml")


@pytest.fixture(scope="module")
def fmu(puma, tmp_path_factory):
    d = tmp_path_factory.mktemp("puma")
    path = build_fmu(puma.state_space_model(outputs=("p_ee", "qdd")), d / "puma.fmu", fmi_type="both").path
    unzip = d / "unzip"
    fmpy.extract(str(path), str(unzip))
    md = fmpy.read_model_description(str(unzip))
    return path, unzip, md, {v.name: v.valueReference for v in md.modelVariables}


def test_validates(fmu):
    assert validate_fmu(str(fmu[0])) == []


def me_instance(fmu, name="puma"):
    _, unzip, md, _ = fmu
    m = FMU2Model(guid=md.guid, unzipDirectory=str(unzip), modelIdentifier=md.modelExchange.modelIdentifier,
                  instanceName=name)
    m.instantiate()
    m.setupExperiment(startTime=0.0)
    m.enterInitializationMode()
    m.exitInitializationMode()
    m.enterContinuousTimeMode()
    return m


def test_me_derivatives_and_outputs_equal_python_model(fmu, puma):
    _, _, md, vr = fmu
    m = me_instance(fmu)
    rng = np.random.default_rng(0)
    x = np.zeros(2 * N)
    dx = np.zeros(2 * N)
    px, pdx = x.ctypes.data_as(POINTER(c_double)), dx.ctypes.data_as(POINTER(c_double))
    for _ in range(10):
        q, qd = rng.uniform(-np.pi, np.pi, N), rng.normal(size=N)
        tau = rng.normal(size=N) * 50
        x[:] = np.r_[q, qd]
        m.setContinuousStates(px, 2 * N)
        m.setReal([vr[f"tau[{i + 1}]"] for i in range(N)], list(tau))
        m.getDerivatives(pdx, 2 * N)
        qdd = puma.forward_dynamics(q, qd, tau)
        assert np.array_equal(dx[:N], qd)
        assert np.abs(dx[N:] - qdd).max() <= 1e-12 * np.abs(qdd).max()
        p_ee = m.getReal([vr[f"p_ee[{r + 1}]"] for r in range(3)])
        assert np.allclose(p_ee, puma.fk(q)[:3, 3], rtol=0, atol=1e-13)
        qdd_out = m.getReal([vr[f"qdd[{i + 1}]"] for i in range(N)])
        assert np.abs(np.array(qdd_out) - qdd).max() <= 1e-12 * np.abs(qdd).max()
    m.terminate()
    m.freeInstance()


def test_directional_derivatives_match_finite_differences(fmu, puma):
    _, _, md, vr = fmu
    m = me_instance(fmu)
    rng = np.random.default_rng(1)
    q, qd, tau = rng.normal(size=N), rng.normal(size=N), rng.normal(size=N) * 20
    x = np.r_[q, qd]
    xs = x.copy()
    m.setContinuousStates(xs.ctypes.data_as(POINTER(c_double)), 2 * N)
    m.setReal([vr[f"tau[{i + 1}]"] for i in range(N)], list(tau))
    unknowns = [vr[f"der(qd[{i + 1}])"] for i in range(N)]
    knowns = [vr[f"q[{i + 1}]"] for i in range(N)] + [vr[f"qd[{i + 1}]"] for i in range(N)] + \
             [vr[f"tau[{i + 1}]"] for i in range(N)]
    z = np.r_[q, qd, tau]

    def f(zz):
        return puma.forward_dynamics(zz[:N], zz[N:2 * N], zz[2 * N:])

    for k in range(3 * N):
        seed = np.zeros(3 * N)
        seed[k] = 1.0
        dd = np.array(m.getDirectionalDerivative(unknowns, knowns, list(seed)))
        eps = 1e-6 * max(1.0, abs(z[k]))
        fd = (f(z + eps * seed) - f(z - eps * seed)) / (2 * eps)
        # FD noise is relative to the size of f, not of this column (dqdd/dq1 is exactly 0 here)
        assert np.allclose(dd, fd, rtol=1e-6, atol=1e-7 * (1 + np.abs(f(z)).max())), k
    m.terminate()
    m.freeInstance()


@pytest.fixture(scope="module")
def damped(tmp_path_factory):
    """The thesis PUMA with 2 N m s/rad joint damping, swinging about its hanging pose.

    Free motion of the undamped arm falls and spins chaotically (two 1e-12
    scipy solvers disagree by 1e-7 after 2 s), where no tolerance is
    meaningful; damped swinging about the stable equilibrium is well posed.
    """
    text = open("robots/puma_thesis.toml").read().replace("[[links]]", "[[links]]\ndamping = 2.0")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        arm = Manipulator(robot_from_toml(text, "puma_damped"))
    res = minimize(lambda q: arm.energy(q, np.zeros(N))[1], np.array([0, 1.0, 0.5, 0, 0.5, 0]))
    d = tmp_path_factory.mktemp("damped")
    path = build_fmu(arm.state_space_model(outputs=()), d / "puma_damped.fmu", fmi_type="cs").path
    return arm, res.x, path


@pytest.fixture(scope="module")
def references(damped):
    """Three initial states near the hanging pose and their DOP853 (rtol 1e-12) solutions."""
    arm, q_hang, _ = damped
    rng = np.random.default_rng(2024)
    cases = []
    for _ in range(3):
        q0 = q_hang + rng.uniform(-0.4, 0.4, N)
        qd0 = rng.uniform(-0.5, 0.5, N)
        ref = solve_ivp(lambda t, x: np.r_[x[N:], arm.forward_dynamics(x[:N], x[N:], np.zeros(N))], (0, 2),
                        np.r_[q0, qd0], method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
        cases.append((q0, qd0, ref.sol))
    return cases


@pytest.mark.parametrize("solver", [1, 2], ids=["dopri5", "rodas3"])
@pytest.mark.parametrize("tol", [1e-6, 1e-9])
def test_cs_trajectories_match_reference(damped, references, solver, tol):
    """Within 10x the requested tolerance, in the solver's own scaled norm, over 2 s."""
    path = damped[2]
    out = [f"q[{i + 1}]" for i in range(N)] + [f"qd[{i + 1}]" for i in range(N)]
    for trial, (q0, qd0, ref) in enumerate(references):
        start = {**{f"q[{i + 1}]": q0[i] for i in range(N)}, **{f"qd[{i + 1}]": qd0[i] for i in range(N)},
                 "solver.method": solver, "solver.rtol": tol, "solver.atol": tol}
        r = fmpy.simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=2.0, output_interval=0.02,
                              start_values=start, output=out)
        x = np.column_stack([r[o] for o in out])
        xr = ref(r["time"]).T
        scaled = np.abs(x - xr) / (tol + tol * np.abs(xr))
        assert scaled.max() <= 10, (trial, scaled.max())


def cs_instance(fmu, name, q1=0.0):
    _, unzip, md, vr = fmu
    s = FMU2Slave(guid=md.guid, unzipDirectory=str(unzip), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=name)
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.setReal([vr["q[1]"], vr["q[2]"], vr["q[3]"]], [q1, -0.5, 0.4])
    s.enterInitializationMode()
    s.exitInitializationMode()
    return s


def run(s, vr, t0, steps, h=0.01):
    qs = []
    for k in range(steps):
        s.setReal([vr["tau[2]"]], [20.0 * np.sin(3 * (t0 + k * h))])
        s.doStep(t0 + k * h, h)
        qs.append(s.getReal([vr[f"q[{i + 1}]"] for i in range(N)]))
    return np.array(qs)


def test_fmu_state_restores_bit_for_bit_and_serialises(fmu):
    vr = fmu[3]
    s = cs_instance(fmu, "a")
    run(s, vr, 0.0, 20)
    state = s.getFMUState()
    first = run(s, vr, 0.2, 30)
    s.setFMUState(state)
    again = run(s, vr, 0.2, 30)
    assert np.array_equal(first, again)
    blob = s.serializeFMUState(state)
    s2 = cs_instance(fmu, "b")
    s2.setFMUState(s2.deserializeFMUState(blob))
    assert np.array_equal(first, run(s2, vr, 0.2, 30))
    s.freeFMUState(state)
    for inst in (s, s2):
        inst.terminate()
        inst.freeInstance()


def test_instances_and_threads_are_independent(fmu):
    vr = fmu[3]
    alone = cs_instance(fmu, "alone")
    expected = run(alone, vr, 0.0, 50)
    a, b = cs_instance(fmu, "a"), cs_instance(fmu, "b", q1=1.0)  # b differs; interleave their steps
    res_a = []
    for k in range(50):
        res_a.append(run(a, vr, k * 0.01, 1)[0])
        run(b, vr, k * 0.01, 1)
    assert np.array_equal(np.array(res_a), expected)
    results = {}

    def worker(name):
        inst = cs_instance(fmu, name)
        results[name] = run(inst, vr, 0.0, 50)
        inst.terminate()
        inst.freeInstance()

    threads = [threading.Thread(target=worker, args=(f"t{i}",)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(np.array_equal(r, expected) for r in results.values())
    for inst in (alone, a, b):
        inst.terminate()
        inst.freeInstance()


def test_misuse_returns_error_and_logs(fmu):
    from test_runtime_c import Log

    _, unzip, md, vr = fmu
    log = Log()
    s = FMU2Slave(guid=md.guid, unzipDirectory=str(unzip), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="misuse")
    s.instantiate(callbacks=log.callbacks)
    with pytest.raises(FMICallException):
        s.doStep(0.0, 0.1)  # before initialisation
    assert "fmi2DoStep" in log.last()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    with pytest.raises(FMICallException):
        s.setReal([vr["tau[1]"]], [float("nan")])
    assert "tau[1]" in log.last()
    with pytest.raises(FMICallException):
        s.setReal([vr["der(qd[1])"]], [1.0])  # a derivative is not settable
    with pytest.raises(FMICallException):
        s.setReal([99999], [1.0])
    assert "99999" in log.last()
    with pytest.raises(FMICallException):
        s.setReal([vr["m_2"]], [3.0])  # a fixed parameter after initialisation
    assert "m_2" in log.last()
    s.doStep(0.0, 0.01)  # the instance is still usable
    s.terminate()
    s.freeInstance()
