"""Solvers that tell the truth: Dormand-Prince says when a problem is stiff,
RK4 knows its stability limit from the model's Jacobian and says it with the
number.

Independent sources: the eigenvalues of the linearised rigs (numpy on the
exact Jacobian; the stiff set's values are tabulated in the components'
README tests) and the boundary of RK4's stability region found by
``fmugen.components.stable_step`` (bisection on |R(z)| = 1 in Python).
"""
import re

import numpy as np
import pytest
import sympy as sp
from fmpy import simulate_fmu
from fmpy.fmi1 import FMICallException

import fmugen
from fmugen.codegen.model import SymbolicModel, Variable
from fmugen.components import linearise, single_joint, stable_step

STEP = {"amp.theta_ref": 0.1}


def jacobian_at_rest(model):
    """df/dx at the start values (linearise may return the matrix or a state-space object)."""
    lin = linearise(model)
    return np.asarray(getattr(lin, "A", lin), dtype=float)


class Log:
    """fmpy logger that keeps the messages."""

    def __init__(self):
        self.messages = []

    def __call__(self, component, instance, status, category, message):
        self.messages.append(message.decode() if isinstance(message, bytes) else message)

    def matching(self, text):
        return [m for m in self.messages if text in m]


@pytest.fixture(scope="module")
def stiff_rig(tmp_path_factory):
    model = single_joint("stiff")
    path = fmugen.build_fmu(model, tmp_path_factory.mktemp("truth") / "stiff.fmu", fmi_type="cs").path
    return model, str(path)


def run(path, start, stop, dt, log, output=("joint.theta",)):
    return simulate_fmu(path, fmi_type="CoSimulation", stop_time=stop, output_interval=dt,
                        start_values=dict(STEP, **start), logger=log, output=list(output))


def test_dopri5_detects_stiffness_early_with_the_eigenvalue(stiff_rig):
    model, path = stiff_rig
    lam_max = np.max(np.abs(np.linalg.eigvals(jacobian_at_rest(model))))
    assert lam_max == pytest.approx(5e4, rel=1e-6)  # the driver pole of the stiff set
    log = Log()
    r = run(path, {"solver.method": 1}, 0.2, 0.01, log,
            output=("joint.theta", "solver.n_steps", "solver.stiffness_detected"))
    said = log.matching("problem is stiff")
    assert len(said) == 1, log.messages  # logged once
    lam = float(re.search(r"\|lambda\| = ([0-9.e+-]+)", said[0]).group(1))
    assert lam == pytest.approx(lam_max, rel=0.05)
    assert "solver.method = 2" in said[0]
    t_detect = float(re.search(r"stiff at t = ([0-9.e+-]+)", said[0]).group(1))
    # early: within the first 0.05 s, i.e. a few hundred steps, not after 100 000
    assert t_detect < 0.05
    assert r["solver.stiffness_detected"][-1] >= 1
    assert r["solver.stiffness_detected"][0] == 0


def test_dopri5_silent_on_a_non_stiff_problem(tmp_path):
    """The default set at a tight tolerance: accuracy, not stability, bounds the step."""
    model = single_joint("default")
    path = str(fmugen.build_fmu(model, tmp_path / "default.fmu", fmi_type="cs").path)
    log = Log()
    r = run(path, {"solver.method": 1, "solver.rtol": 1e-10, "solver.atol": 1e-10}, 0.3, 0.01, log,
            output=("joint.theta", "solver.stiffness_detected"))
    assert r["solver.stiffness_detected"][-1] == 0
    assert not log.matching("stiff")


def logged_limit(log):
    said = [m for m in log.matching("exceeds the RK4 stability limit") if "RK4: h =" in m]
    assert said, log.messages
    m = re.search(r"limit ~ ([0-9.e+-]+) (us|ms|s) \(largest \|lambda\| = ([0-9.e+-]+) 1/s", said[0])
    unit = {"us": 1e-6, "ms": 1e-3, "s": 1.0}[m.group(2)]
    return float(m.group(1)) * unit, float(m.group(3)), said


def test_rk4_refuses_a_step_beyond_the_limit_with_it(stiff_rig):
    model, path = stiff_rig
    h_limit = stable_step(np.linalg.eigvals(jacobian_at_rest(model)), "rk4")
    assert h_limit == pytest.approx(55.7e-6, rel=1e-3)
    log = Log()
    with pytest.raises(FMICallException):  # refused at once: fmi2Discard before any step (issue 19)
        run(path, {"solver.method": 3, "solver.fixed_step": 60e-6}, 0.05, 6e-5 * 10, log)
    limit, lam, said = logged_limit(log)
    assert limit == pytest.approx(h_limit, rel=5e-3)
    assert lam == pytest.approx(5e4, rel=1e-3)
    assert "h = 60 us" in said[0]
    assert "at t = 0)" in said[0]
    assert len(said) == 1  # one refusal, no step taken, no blow-up after it
    discard = log.matching("discarded")
    assert discard and "exceeds the RK4 stability limit ~ 55.7 us" in discard[0]
    assert "was not taken" in discard[0] and "last good point t = 0 " in discard[0]


def test_rk4_quiet_inside_the_limit(stiff_rig):
    model, path = stiff_rig
    h_limit = stable_step(np.linalg.eigvals(jacobian_at_rest(model)), "rk4")
    log = Log()
    r = run(path, {"solver.method": 3, "solver.fixed_step": 0.9 * h_limit}, 0.02, 1e-3, log)
    assert np.all(np.isfinite(r["joint.theta"]))
    assert not log.matching("stability limit")


def test_rk4_limit_of_the_real_opamp(tmp_path):
    """The op-amp pole (-3.95e5 1/s) sets the limit at ~7 us (actuator-chain note)."""
    model = single_joint("stiff", control="PI", opamp="real")
    ev = np.linalg.eigvals(jacobian_at_rest(model))
    h_limit = stable_step(ev, "rk4")
    path = str(fmugen.build_fmu(model, tmp_path / "opamp.fmu", fmi_type="cs").path)
    log = Log()
    with pytest.raises(FMICallException):
        run(path, {"solver.method": 3, "solver.fixed_step": 1.2 * h_limit}, 2e-3, 1e-4, log)
    limit, lam, _ = logged_limit(log)
    assert lam == pytest.approx(np.max(np.abs(ev)), rel=1e-3)
    assert limit == pytest.approx(h_limit, rel=5e-3)


def oscillator(omega, zeta):
    """x'' + 2 zeta omega x' + omega^2 x = 0: a dominant complex pair."""
    x, v, w, z = sp.symbols("x v omega zeta", real=True)
    return SymbolicModel.from_equations(
        "oscillator",
        states=[Variable("x", x, "m", start=1.0), Variable("v", v, "m/s", start=0.0, nominal=omega)],
        inputs=[],
        parameters=[Variable("omega", w, "rad/s", start=omega), Variable("zeta", z, "1", start=zeta)],
        derivatives=[v, -2 * z * w * v - w**2 * x])


@pytest.mark.parametrize("zeta", [0.0, 0.5, 0.9])
def test_rk4_limit_for_a_complex_pair(tmp_path, zeta):
    """The limit follows the eigenvalue's ray: 2.828/omega undamped, 2.62/omega at 120 degrees."""
    omega = 1000.0
    lam = -zeta * omega + 1j * omega * np.sqrt(1 - zeta**2)
    h_limit = stable_step([lam], "rk4")
    path = str(fmugen.build_fmu(oscillator(omega, zeta), tmp_path / f"osc{zeta}.fmu", fmi_type="cs").path)
    log = Log()
    h = 1.05 * h_limit  # communication steps of 10 h, so that h is the step taken
    try:
        simulate_fmu(path, fmi_type="CoSimulation", stop_time=50 * h, output_interval=10 * h, logger=log,
                     start_values={"solver.method": 3, "solver.fixed_step": h}, output=["x"])
    except FMICallException:
        pass
    limit, modulus, _ = logged_limit(log)
    assert modulus == pytest.approx(omega, rel=1e-6)
    assert limit == pytest.approx(h_limit, rel=5e-3)
    # and inside the limit no warning
    log = Log()
    h = 0.95 * h_limit
    simulate_fmu(path, fmi_type="CoSimulation", stop_time=50 * h, output_interval=10 * h, logger=log,
                 start_values={"solver.method": 3, "solver.fixed_step": h}, output=["x"])
    assert not log.matching("stability limit")
