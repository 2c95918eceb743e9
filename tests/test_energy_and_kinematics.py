"""Physics checks independent of both formulations: energy, power, kinematics."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fmugen
from fmugen.dynamics.manipulator import Manipulator
from fmugen.robot.chain import n_link_chain
from numeric_oracle import relative_motion, numeric


@pytest.fixture(scope="module")
def puma():
    return fmugen.load_robot("robots/puma_thesis_com.toml")


def test_energy_is_conserved_without_torque(puma):
    """tau = 0, no damping: KE + PE constant to 1e-8 relative over 2 s (DOP853, rtol 1e-12)."""
    q0 = np.array([0.3, -0.6, 0.4, 0.2, 0.9, -0.5])
    qd0 = np.array([0.5, -0.3, 0.8, 1.0, -0.7, 1.2])
    zero = np.zeros(6)

    def rhs(t, x):
        return np.r_[x[6:], puma.forward_dynamics(x[:6], x[6:], zero)]

    sol = solve_ivp(rhs, (0, 2), np.r_[q0, qd0], method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
    assert sol.success
    E = [sum(puma.energy(x[:6], x[6:])) for x in sol.sol(np.linspace(0, 2, 41)).T]
    KE0, PE0 = puma.energy(q0, qd0)
    scale = abs(KE0) + abs(PE0)
    drift = np.max(np.abs(np.array(E) - E[0])) / scale
    assert drift < 1e-8, drift
    # the motion is not trivial: energy is exchanged between KE and PE
    KE_end, _ = puma.energy(*np.split(sol.y[:, -1], 2))
    assert abs(KE_end - KE0) > 1e-3 * scale


@pytest.mark.parametrize("case", ["puma", "chain_rpr"])
def test_power_balance(case, puma):
    """d(KE + PE)/dt = qd . tau along the motion, at random states (damping-free arms)."""
    arm = puma if case == "puma" else Manipulator(n_link_chain(5, "RPR", seed=2))
    rng = np.random.default_rng(11)
    n = arm.n
    for _ in range(3):
        q, qd, tau = rng.normal(size=(3, n))
        qdd = arm.forward_dynamics(q, qd, tau)
        dt = 1e-4

        def energy_at(s):  # Taylor-consistent state at time s (third-order terms don't matter at O(dt^2))
            return sum(arm.energy(q + qd * s + qdd * s * s / 2, qd + qdd * s))

        # 5-point stencil: truncation error O(dt^4), far below the tolerance
        dEdt = (8 * (energy_at(dt) - energy_at(-dt)) - (energy_at(2 * dt) - energy_at(-2 * dt))) / (12 * dt)
        power = qd @ tau
        assert abs(dEdt - power) <= 1e-6 * (abs(power) + np.abs(qd) @ np.abs(tau))


def fk_oracle(robot, q):
    """Product of numpy DH transforms (independent of fmugen's kinematics)."""
    links, _, modified = numeric(robot)
    T = np.eye(4)
    for L, qi in zip(links, q):
        R, r, *_ = relative_motion(L, qi, modified)
        A = np.eye(4)
        A[:3, :3], A[:3, 3] = R, r
        T = T @ A
    return T


@pytest.mark.parametrize("name", ["puma_thesis_com", "stanford_arm"])
def test_fk_and_jacobian_against_finite_differences(name):
    arm = fmugen.load_robot(f"robots/{name}.toml")
    rng = np.random.default_rng(5)
    for _ in range(3):
        q = rng.normal(size=arm.n)
        T = arm.fk(q)
        assert np.allclose(T, fk_oracle(arm.robot, q), atol=1e-13)
        J = arm.jacobian(q)
        assert J.shape == (6, arm.n)
        eps = 1e-6
        for k in range(arm.n):
            dq = np.zeros(arm.n)
            dq[k] = eps
            Tp, Tm = arm.fk(q + dq), arm.fk(q - dq)
            v = (Tp[:3, 3] - Tm[:3, 3]) / (2 * eps)
            Rdot = (Tp[:3, :3] - Tm[:3, :3]) / (2 * eps)
            W = Rdot @ T[:3, :3].T  # skew(omega)
            w = np.array([W[2, 1], W[0, 2], W[1, 0]])
            assert np.allclose(J[:3, k], v, atol=1e-8), (k, J[:3, k], v)
            assert np.allclose(J[3:, k], w, atol=1e-8), (k, J[3:, k], w)
