"""Exact Jacobians stay finite exactly on the kinks of the smooth saturations (rails, stroke limit)."""
import numpy as np
import pytest

from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.components import amplifier, servo_valve


@pytest.mark.parametrize("x_v", [1.0, -1.0, 1.05, -0.95, 0.3])
def test_stroke_limited_valve_jacobian_is_finite_and_exact_on_the_limit(x_v):
    ev = ModelEvaluator(servo_valve(stroke_limit=True))
    x, u = np.array([x_v, 0.2]), np.array([0.005, 1e6])
    A = ev.jacobians(0.0, x, u)[0]
    h = 1e-7
    fd = np.array([(ev.f(0.0, x + h * e, u) - ev.f(0.0, x - h * e, u)) / (2 * h) for e in np.eye(2)]).T
    assert np.all(np.isfinite(A))
    # on the limit the one-sided slopes differ by the C^1 band's curvature * h: compare against the scale
    assert np.allclose(A, fd, rtol=1e-6, atol=1e-6 * np.abs(A).max())


@pytest.mark.parametrize("e", [10.0 / 15.909903, -10.0 / 15.909903])
def test_amplifier_rail_jacobian_is_finite_on_the_rail(e):
    ev = ModelEvaluator(amplifier(rails=True))
    D = ev.jacobians(0.0, None, np.array([e, 0.0]))[3]
    assert np.all(np.isfinite(D))
