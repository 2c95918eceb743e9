"""Regularised non-smooth functions, branch-free (only ``fabs`` in C).

Generated code must not branch on state values: an implicit solver's Newton
iteration and the exact Jacobians need functions that are at least C^1, and
``if``/ternaries on states make the Jacobian jump.  Everything here is built
from ``Abs`` (printed as ``fabs``) and arithmetic, so the C code is one
straight expression and every derivative is finite.

Building blocks (``eps > 0`` is the width of the regularised band):

* :func:`huber` -- C^1 absolute value: |d| for |d| >= eps,
  d^2/(2 eps) + eps/2 inside.  Written as |d| + (eps - m)^2/(2 eps) with
  m = min(|d|, eps) = (|d| + eps - ||d| - eps|)/2.
* :func:`smooth_relu` -- (d + huber(d))/2: exactly max(d, 0) outside the band.
* :func:`smooth_clip` -- x - relu(x - L) + relu(-L - x): exactly x for
  |x| <= L - eps and exactly +-L for |x| >= L + eps; at most eps/4 off
  inside the bands.  Used for amplifier rails and the valve stroke limit.
* :func:`smooth_lower_bound` -- p_min + relu(p - p_min): the cavitation floor.
* :func:`regroot` -- a signed square root sgn(x) sqrt(|x|), exact for
  |x| >= delta and an odd cubic a x + b x^3 inside (a = 5/(4 sqrt(delta)),
  b = -1/(4 delta^(5/2)), chosen so value and slope match at |x| = delta).
  Near zero it is linear with the finite slope a: the plain root's infinite
  Jacobian at zero pressure drop is gone.  Modelica.Fluid.Utilities.regRoot
  (x/(x^2+delta^2)^(1/4)) is C-infinity but never exact; this one is exact
  outside the band, which keeps the orifice law unchanged away from null.

Why the C^1 clip rather than ``U_max*tanh(u/U_max)``: tanh distorts the
linear range (0.8 % at 16 % of the rail, 7.6 % at half stroke), so a chain
with rails would not reproduce the unlimited chain's responses; the clip is
exactly linear up to L - eps and has slope 1 at rest, so the linearisation and
the eigenvalue tests are untouched by switching the rails on.
"""
from __future__ import annotations

import sympy as sp


def _min_abs(y, eps):
    """min(|y|, eps) without a branch, for eps > 0."""
    ay = sp.Abs(y)
    return (ay + eps - sp.Abs(ay - eps)) / 2


def _max_abs(y, eps):
    """max(|y|, eps) without a branch, for eps > 0."""
    ay = sp.Abs(y)
    return (ay + eps + sp.Abs(ay - eps)) / 2


def huber(d, eps):
    """C^1 approximation of |d|: exact for |d| >= eps, quadratic inside."""
    m = _min_abs(d, eps)
    return sp.Abs(d) + (eps - m) ** 2 / (2 * eps)


def smooth_relu(d, eps):
    """C^1 max(d, 0), exact for |d| >= eps."""
    return (d + huber(d, eps)) / 2


def smooth_clip(x, limit, eps):
    """C^1 saturation of x to [-limit, limit]; exact for |x| <= limit - eps."""
    return x - smooth_relu(x - limit, eps) + smooth_relu(-limit - x, eps)


def smooth_lower_bound(p, p_min, eps):
    """C^1 max(p, p_min), exact for |p - p_min| >= eps."""
    return p_min + smooth_relu(p - p_min, eps)


def regroot(x, delta):
    """Regularised signed square root sgn(x) sqrt(|x|) (C^1, branch-free).

    Written as x * h(|x|) with h(y) = 1/sqrt(max(y, delta)) + a + b min(y,
    delta)^2 - 1/sqrt(delta), which equals 1/sqrt(y) for y >= delta and
    a + b y^2 below; dimension: sqrt of the dimension of x.

    >>> import sympy as sp
    >>> float(regroot(sp.Float(4.0), sp.Float(1.0)))
    2.0
    """
    a = sp.Rational(5, 4) / sp.sqrt(delta)
    b = -sp.Rational(1, 4) / delta ** sp.Rational(5, 2)
    m = _min_abs(x, delta)
    h = 1 / sp.sqrt(_max_abs(x, delta)) + a + b * m**2 - 1 / sp.sqrt(delta)
    return x * h


def smooth_sign(x, x_eps):
    """C-infinity sign(x): x / sqrt(x^2 + x_eps^2) (Coulomb friction)."""
    return x / sp.sqrt(x**2 + x_eps**2)
