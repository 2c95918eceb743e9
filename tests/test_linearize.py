"""Linearisation for python-control: exact Jacobians against independent numbers."""
import warnings

import control
import numpy as np
import pytest

import fmugen
from fmugen.control.linearize import linearize
from fmugen.components.assembly import load_assembly

# actuator-chain.md, "default, P": eigenvalues of the linearised one-joint rig at rest
DEFAULT_P = [-10.541594, -6.1155814 + 54.32192j, -6.1155814 - 54.32192j, -439.76686 + 448.7483j,
             -439.76686 - 448.7483j, -2399.9995]


def test_single_joint_poles_equal_the_shared_note():
    sys = linearize(load_assembly("examples/single_joint_default.toml"))
    poles = np.sort_complex(control.poles(sys))
    ref = np.sort_complex(np.array(DEFAULT_P))
    assert np.allclose(poles, ref, rtol=1e-6)
    # names survive, '.' replaced by '_'
    assert any(name.startswith("joint_") for name in sys.state_labels)


@pytest.fixture(scope="module")
def puma():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fmugen.load_robot("robots/puma_thesis_com.toml")


def test_puma_linearisation_matches_finite_differences(puma):
    rng = np.random.default_rng(4)
    q, qd, tau = rng.normal(size=(3, 6))
    x = np.r_[q, qd]
    sys = linearize(puma.state_space_model(), x=x, u=tau)
    A, B, C = sys.A, sys.B, sys.C

    def f(z):
        return np.r_[z[6:12], puma.forward_dynamics(z[:6], z[6:12], z[12:])]

    z = np.r_[x, tau]
    J = np.zeros((12, 18))
    for k in range(18):
        e = np.zeros(18)
        e[k] = 1e-6
        J[:, k] = (f(z + e) - f(z - e)) / 2e-6
    scale = np.abs(J).max()
    assert np.abs(A - J[:, :12]).max() <= 1e-6 * scale
    assert np.abs(B - J[:, 12:]).max() <= 1e-6 * scale
    # outputs: q, qd (identity) then p_ee, whose rows are the linear Jacobian of the end effector
    assert np.array_equal(C[:12], np.eye(12))
    assert np.allclose(C[12:15, :6], puma.jacobian(q)[:3], atol=1e-12)


def test_lqr_on_the_linearised_arm_stabilises_the_upright_pose(puma):
    """A control designer's use: LQR about an (unstable) pose held by gravity torques."""
    q0 = np.array([0.0, -0.3, 0.2, 0.0, 0.4, 0.0])
    tau0 = puma.bias(q0, np.zeros(6))
    sys = linearize(puma.state_space_model(outputs=()), x=np.r_[q0, np.zeros(6)], u=tau0)
    assert np.max(control.poles(sys).real) > 0.1  # open loop: the arm falls
    K, _, _ = control.lqr(sys, np.eye(12), 1e-3 * np.eye(6))
    assert np.max(np.linalg.eigvals(sys.A - sys.B @ K).real) < 0
