"""Regularised functions: exact outside their bands, C^1 across, finite slopes."""
import numpy as np
import pytest
import sympy as sp

from fmugen.components.smooth import huber, regroot, smooth_clip, smooth_lower_bound, smooth_relu, smooth_sign

x = sp.Symbol("x", real=True)
DELTA = 1e5  # Pa, the shipped dp_reg


def num(expr):
    return sp.lambdify(x, expr, "numpy")


def test_regroot_exact_outside_band():
    f = num(regroot(x, DELTA))
    xs = np.concatenate([np.geomspace(DELTA, 1e8, 50), -np.geomspace(DELTA, 1e8, 50)])
    assert np.allclose(f(xs), np.sign(xs) * np.sqrt(np.abs(xs)), rtol=1e-14, atol=0)


def test_regroot_c1_at_threshold():
    f, df = num(regroot(x, DELTA)), num(sp.diff(regroot(x, DELTA), x))
    for edge in (DELTA, -DELTA):
        h = 1e-6 * DELTA
        # value and slope continuous: one-sided limits agree with the root's
        assert f(edge - h) == pytest.approx(f(edge + h), rel=1e-5)
        assert df(edge - h) == pytest.approx(df(edge + h), rel=1e-5)
        assert df(edge + np.sign(edge) * h) == pytest.approx(0.5 / np.sqrt(abs(edge)), rel=1e-5)
    # the symbolic derivative agrees with central finite differences inside and outside
    for x0 in (0.3 * DELTA, -0.7 * DELTA, 3 * DELTA, -5 * DELTA):
        h = 1e-4 * DELTA
        assert df(x0) == pytest.approx((f(x0 + h) - f(x0 - h)) / (2 * h), rel=1e-6)


def test_regroot_finite_slope_at_zero_and_odd():
    f, df = num(regroot(x, DELTA)), num(sp.diff(regroot(x, DELTA), x))
    # slope at 0 is a = 5/(4 sqrt(delta)), finite (the plain root's is infinite)
    assert np.isfinite(df(0.0)) and df(0.0) == pytest.approx(1.25 / np.sqrt(DELTA), rel=1e-12)
    xs = np.linspace(-2 * DELTA, 2 * DELTA, 101)
    assert np.allclose(f(-xs), -f(xs), rtol=0, atol=1e-12)
    assert np.all(np.diff(f(xs)) > 0)  # monotone


def test_clip_relu_huber_bounds():
    L, eps = 10.0, 0.5
    clip = num(smooth_clip(x, L, eps))
    inner = np.linspace(-(L - eps), L - eps, 101)
    assert np.allclose(clip(inner), inner, rtol=0, atol=1e-13)  # linear (to rounding) below the band
    outer = np.concatenate([np.linspace(L + eps, 100, 20), np.linspace(-100, -L - eps, 20)])
    assert np.allclose(clip(outer), np.sign(outer) * L, rtol=0, atol=1e-12)
    band = np.linspace(L - eps, L + eps, 101)
    assert np.all(np.abs(clip(band) - np.minimum(band, L)) <= eps / 4 + 1e-12)
    dclip = num(sp.diff(smooth_clip(x, L, eps), x))
    for edge in (L - eps, L + eps, -L + eps, -L - eps):
        assert dclip(edge - 1e-9) == pytest.approx(dclip(edge + 1e-9), abs=1e-6)
    relu, hub = num(smooth_relu(x, eps)), num(huber(x, eps))
    assert relu(3.0) == 3.0 and relu(-3.0) == 0.0 and hub(-2.0) == 2.0
    assert hub(0.0) == pytest.approx(eps / 2)
    lb = num(smooth_lower_bound(x, -1e5, 2e4))
    assert lb(-5e5) == pytest.approx(-1e5) and lb(3e6) == 3e6


def test_smooth_sign():
    s = num(smooth_sign(x, 0.1))
    assert s(0.0) == 0.0 and s(10.0) == pytest.approx(10 / np.sqrt(100.01))
    assert s(-10.0) == pytest.approx(-s(10.0))


def test_generated_expressions_are_branch_free():
    # only Abs (fabs in C), no Piecewise/sign/Heaviside in the function values
    for e in (regroot(x, DELTA), smooth_clip(x, 10, 0.5), smooth_lower_bound(x, 0, 1)):
        assert not e.has(sp.Piecewise, sp.sign, sp.Heaviside, sp.Max, sp.Min)
