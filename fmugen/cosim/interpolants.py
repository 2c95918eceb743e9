"""Input interpolants: what an FMU is told its inputs do during a macro step [t_n, t_n + H].

Two families, as in the co-simulation literature (Kübler & Schiehlen 2000; Busch 2016):

* **extrapolation** from past communication points (:class:`InputHistory`), for the non-iterated schemes and as
  the predictor of the iterated ones: ``hold`` (zero-order hold, order 1), ``linear`` (through U_{n-1}, U_n:
  order 2), ``quadratic`` (through U_{n-2..n}; the parabola goes to the FMUs as first and second input
  derivatives: order 3 under Jacobi);
* **interpolation** between the step's two ends (:func:`interpolate_to`), for the iterated schemes, whose
  unknowns are the values (and with Hermite inputs the sources' slopes) at t_{n+1}: the line (trapezoidal,
  A-stable), the L-stable parabola arriving with the end slope (Radau IIA's (1,2) Padé stability function),
  a cubic Hermite with a damped start slope (``CUBIC_THETA``).

The values reach the FMUs as the value at t_n plus input derivatives (fmi2SetRealInputDerivatives, orders
1-3); an FMU without ``canInterpolateInputs`` gets the extrapolant's midpoint value (:func:`midpoint_values`).
"""
from __future__ import annotations

import numpy as np

EXTRAPOLATIONS = ("hold", "linear", "quadratic", "cubic")
ORDER = {"hold": 0, "linear": 1, "quadratic": 2, "cubic": 3}  # polynomial degree of the inputs over a step

# iterated schemes, cubic inputs: weight of the source's own slope at t_n in the cubic Hermite interpolant's
# start slope (the rest from the L-stable parabola).  On the split test x' = lambda u, u = x the scheme's
# stability function is A-stable with |R(-inf)| = theta / (2 - theta): 1 (the (2,2) Pade approximant, fourth
# order) lets a mode far faster than the step ring undamped -- it did on the PUMA's wrist at 40 ms, measured --
# while 0.8 damps it by a third per step and keeps most of the cubic's accuracy (third order)
CUBIC_THETA = 0.8


class InputHistory:
    """The coupled values at the last three communication points and the polynomial extrapolant through them.

    ``predict(H)`` writes the extrapolant's slope (and, quadratic, second derivative) at t_n into the
    buffers the FMUs read and returns its value at t_n + H: the predictor P(t_{n+1}).  ``push(t, U)``
    makes an accepted step's values the newest point.
    """

    def __init__(self, nu, ext, t0, DU, DDU, hold_only):
        self.nu, self.ext = nu, ext
        self.U = np.zeros((3, max(nu, 1)))  # U at t_n, t_{n-1}, t_{n-2}
        self.t = [t0, t0, t0]
        self.n = 1  # points available
        self.U0, self.U1, self.U2 = self.U[0, :nu], self.U[1, :nu], self.U[2, :nu]
        self.DU, self.DDU = DU[:nu], DDU  # slope, curvature buffers the FMUs read
        self.pred = np.zeros(max(nu, 1))[:nu]
        self.hold_only = hold_only  # zero-order hold of a non-iterated scheme: P = U_n, no slopes, one row

    def copy(self):
        """An independent history with the same points, writing into the same slope buffers."""
        other = InputHistory(self.nu, self.ext, 0.0, self.DU, self.DDU, self.hold_only)
        other.DU = self.DU  # the (nu-long) view itself
        other.U[:] = self.U
        other.t = list(self.t)
        other.n = self.n
        return other

    def predict(self, H):
        if self.hold_only:
            return self.U0  # held: the prediction of U_{n+1} is U_n (the slopes stay zero)
        ext, n, DU, nu = self.ext, self.n, self.DU, self.nu
        U0, U1, U2 = self.U0, self.U1, self.U2
        if ext == 0 or n == 1:
            DU[:] = 0.0
        elif ext == 1 or n == 2:
            np.subtract(U0, U1, out=DU)
            DU /= self.t[0] - self.t[1]
        else:  # quadratic: P(t_n + s) = U_n + P'(t_n) s + P'' s^2 / 2 through the last three points
            h1, h2 = self.t[0] - self.t[1], self.t[1] - self.t[2]
            d1 = (U0 - U1) / h1
            d2 = (U1 - U2) / h2
            c2 = (d1 - d2) / (h1 + h2)
            DU[:] = d1 + c2 * h1
            self.DDU[:nu] = 2.0 * c2
        P = self.pred
        np.multiply(DU, H, out=P)
        if ext >= 2 and n >= 3:
            P += 0.5 * H * H * self.DDU[:nu]
        P += U0
        return P

    def restart(self) -> None:
        """Forget every point but the newest: an FMU reported an event in the last step, so its outputs
        may have jumped, and an extrapolant through points on both sides of the jump would carry it
        across (a slope of jump / H).  The next steps rebuild the history from this point on."""
        self.n = 1

    def push(self, t, U):
        if self.hold_only:
            self.U0[:] = U
            return
        self.U2[:] = self.U1
        self.U1[:] = self.U0
        self.U0[:] = U
        self.t[2], self.t[1], self.t[0] = self.t[1], self.t[0], t
        if self.n < 3:
            self.n += 1


def interpolate_to(Z, U0, dU0, H, nu, kind, DU, DDU, DDDU) -> None:
    """Inputs over an iterated macro step, from the unknowns Z -- slopes into DU, curvatures into DDU, third
    derivatives into DDDU (``kind``: 1 line, 2 Hermite parabola, 3 cubic Hermite):

    - linear: the line from U_n to Z = V at t_n + H (trapezoidal: A-stable, second order);
    - quadratic: the parabola from U_n to V that arrives with the sources' slope V' (Z = [V, V']).  The
      slope at the end, not at the start, keeps it L-stable: on x' = lambda u, u = x it is the (1, 2)
      Pade approximant, Radau IIA's third-order stability function (with the slope at the start the
      same test gives |R| -> inf, and the PUMA's wrist diverged: measured);
    - cubic: the cubic Hermite interpolant of U_n, V, V' and a start slope blended from the sources' slope
      at t_n (dU0) and the parabola's (CUBIC_THETA)."""
    A = Z[:nu] - U0[:nu]
    if kind == 3:
        # start slope: theta x the source's own slope at t_n + (1 - theta) x the L-stable parabola's
        Vd = Z[nu:]
        d0 = CUBIC_THETA * dU0[:nu] + (1.0 - CUBIC_THETA) * (2.0 * A / H - Vd)
        DU[:nu] = d0
        DDU[:nu] = 2.0 * (3.0 * A / H - 2.0 * d0 - Vd) / H
        DDDU[:nu] = 6.0 * (d0 + Vd - 2.0 * A / H) / (H * H)
    elif kind == 2:
        Vd = Z[nu:]
        b = (Vd * H - A) / (H * H)
        DU[:nu] = 2.0 * A / H - Vd
        DDU[:nu] = 2.0 * b
    else:
        DU[:nu] = A / H


def midpoint_values(U, DU, no_interp, H) -> None:
    """FMUs without input derivatives: pass the extrapolant's midpoint value, held."""
    U[no_interp] += 0.5 * H * DU[no_interp]
