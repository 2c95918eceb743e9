"""Modes, stiffness ratio and controllability/observability ranks against closed forms."""
import numpy as np
import pytest

from fmugen.control.analysis import modal_ranks, modes, stiffness_ratio


def test_second_order_mode_has_its_damping_and_frequency():
    wn, zeta = 10.0, 0.3  # x'' + 2 zeta wn x' + wn^2 x = 0
    A = np.array([[0.0, 1.0], [-wn**2, -2 * zeta * wn]])
    (l1, z1, w1), (l2, z2, w2) = modes(A)
    assert w1 == pytest.approx(wn, rel=1e-14) and w2 == pytest.approx(wn, rel=1e-14)
    assert z1 == pytest.approx(zeta, rel=1e-14) and z2 == pytest.approx(zeta, rel=1e-14)
    assert abs(l1.imag) == pytest.approx(wn * np.sqrt(1 - zeta**2), rel=1e-14)


def test_stiffness_ratio_leaves_out_rigid_body_and_unstable_modes():
    A = np.diag([-1.0, -1000.0, 0.0, 3.0])
    assert stiffness_ratio(A) == pytest.approx(1000.0, rel=1e-14)
    # a double integrator's rounding (|Re| ~ 1e-16 ||A||) is not a slow mode
    J = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -50.0]])
    assert stiffness_ratio(J + 1e-15 * np.random.default_rng(0).normal(size=(3, 3))) == pytest.approx(1.0, rel=1e-6)


def test_ranks_of_textbook_cases():
    # a double integrator (a Jordan block) is controllable from the force and observable from the position
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    assert modal_ranks(A, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])) == (2, 2)
    # ... but not observable from the velocity alone
    assert modal_ranks(A, np.array([[0.0], [1.0]]), np.array([[0.0, 1.0]])) == (2, 1)
    # two identical lags driven by one input: one direction (their difference) is lost
    A = -np.eye(2)
    assert modal_ranks(A, np.array([[1.0], [1.0]]), np.eye(2)) == (1, 2)
    assert modal_ranks(A, np.eye(2), np.array([[1.0, 1.0]])) == (2, 1)
    # widely spread scales (a pressure in Pa next to an angle): judged on the nominal-scaled state
    A = np.array([[-1.0, 1e-7], [0.0, -1e4]])  # x1 [rad] driven weakly by x2 [Pa]
    B = np.array([[0.0], [1e9]])
    C = np.array([[1.0, 0.0]])
    assert modal_ranks(A, B, C, state_scale=[1.0, 1e7]) == (2, 2)
