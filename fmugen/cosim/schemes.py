"""The coupling schemes: how one macro step [t_n, t_n + H] is taken.

U is the vector of all coupled inputs, Y the outputs they come from (U = F * Y[S]).

* :class:`Jacobi`: every FMU steps from the values at t_n (they could all run at once: the executor);
* :class:`GaussSeidel`: the FMUs step one after another in ``order``; an input whose source has already
  stepped is its value at t_{n+1} (held) or the line from U_n to it (with extrapolation; its midpoint, held, for
  an FMU that cannot interpolate);
* :class:`FixedPoint` and :class:`Newton` (the *iterated* or *implicit* schemes, waveform relaxation over one
  step): all FMUs are saved (fmi2GetFMUstate), the end values V = U_{n+1} are predicted, every FMU steps with
  its inputs interpolated between U_n and V (:func:`~fmugen.cosim.interpolants.interpolate_to`), and V is
  corrected -- V <- G(V), or Newton on R(V) = G(V) - V = 0 -- with the FMUs restored before every repetition,
  until |R| < ``coupling_tol`` relative to the signals.

Newton's interface Jacobian dG/dV is the sensitivity of a whole macro step, which the FMUs' directional
derivatives (partials of f and g) do not give: it comes from **finite differences of rolled-back steps**, one
re-step of FMU k per input of FMU k (dG is block-sparse: an FMU's outputs depend only on its own inputs; an
fmugen FMU without states gives its columns exactly, by fmi2GetDirectionalDerivative), reused across macro
steps while Newton converges fast (modified Newton) and refreshed by Broyden's rank-one secant update from
each iterate (15-25 % fewer iterations on the PUMA: the steps' own adaptive solvers make G rough at their
tolerance, which caps the contraction of a frozen Jacobian).
"""
from __future__ import annotations

import math

import numpy as np

from .interpolants import interpolate_to, midpoint_values
from .units import UnitFailure, dptr, vr_array

SCHEMES = ("jacobi", "gauss-seidel", "iterative", "newton")


class Jacobi:
    """Every FMU steps from the values at t_n (the inputs' extrapolants are already in the buffers)."""

    implicit = False

    def __init__(self, m):
        self.m = m

    def step(self, t, H, ext, no_prior) -> int:
        """One sweep over the FMUs; their outputs at t_n + H are in ``m.Y``.  Returns the FMU calls."""
        m = self.m
        if m.any_no_interp and ext:
            midpoint_values(m.Uset[: m.nu], m.DUset[: m.nu], m.no_interp[: m.nu], H)
        calls = m.executor.sweep(t, H, no_prior)
        if m.me_block is not None:
            calls += m.me_block.step(t, H)
        return calls


class GaussSeidel(Jacobi):
    """The FMUs one after another; a later FMU sees its earlier sources' new values."""

    def step(self, t, H, ext, no_prior) -> int:
        m = self.m
        if m.any_no_interp and ext:
            midpoint_values(m.Uset[: m.nu], m.DUset[: m.nu], m.no_interp[: m.nu], H)
        Uset, DUset, DDUset, Y, S, F, U0 = m.Uset, m.DUset, m.DDUset, m.Y, m.S, m.F, m.U_n
        calls = 0
        for k, u in zip(m.gs_k, m.gs_units):
            idx = m.gs_new[k]
            if len(idx):
                new = F[idx] * Y[S[idx]]
                if ext == 0:
                    Uset[idx] = new  # the source's value at t_{n+1}, held
                    DUset[idx] = 0.0
                elif not getattr(u, "can_interpolate", False):  # the line's midpoint, held (as every extrapolant)
                    DUset[idx] = (new - U0[idx]) / H
                    Uset[idx] = U0[idx] + 0.5 * H * DUset[idx]
                else:  # the line from U_n to the source's U_{n+1} (a parabola through U_{n-1} as well
                    # destabilises the PUMA's wrist coupling at 2 ms: measured, so it stays a line)
                    Uset[idx] = U0[idx]
                    DUset[idx] = (new - U0[idx]) / H
                DDUset[idx] = 0.0
            if u.kind == "me":
                if u is m._first_me:
                    calls += m.me_block.step(t, H)
            else:
                calls += m._do(u, t, H, no_prior)
        return calls


class FixedPoint:
    """The macro step implicit in the coupling, iterated V <- G(V) (converges where the coupling is weak)."""

    implicit = True

    def __init__(self, m, coupling_tol, max_iterations):
        self.m = m
        self.tol = coupling_tol
        self.max_iterations = max_iterations
        self.sweep = Jacobi(m)

    def step(self, t, H, Z, states, scale, G, Unew, summ):
        """Iterate the macro step from the guess Z (the unknowns at t_n + H).  Returns (calls, iterations,
        residual relative to coupling_tol, R); the step converged when the residual is <= 1."""
        m, nu, hermite = self.m, self.m.nu, self.m.hermite
        U0 = m.U_n
        calls = 0
        it = 0
        err_prev = math.inf
        w = np.concatenate([scale[:nu], scale[:nu] / H]) if hermite else scale[:nu]
        self.begin(H)
        while True:
            if it > 0:
                calls += m._restore_all(states)
            m.Uset[:nu] = U0[:nu]
            interpolate_to(Z, U0, m.dU0, H, nu, m.input_kind, m.DUset, m.DDUset, m.DDDUset)
            calls += self.sweep.step(t, H, 1, 0)
            calls += m._gather(Unew, G)
            R = G - Z
            den = self.tol * np.maximum(scale[:nu], np.abs(Z[:nu]))
            err = float(np.max(np.abs(R[:nu]) / den)) if nu else 0.0
            if hermite and nu:  # a slope's error moves the input by about H times it
                err = max(err, float(np.max(np.abs(R[nu:]) * H / den)))
            if err <= 1.0 or it >= self.max_iterations or not math.isfinite(err):
                return calls, it, err, R
            it += 1
            Z, c = self.correct(t, H, Z, G, R, err, err_prev, states, scale, w, summ)
            calls += c
            err_prev = err

    def begin(self, H) -> None:
        pass

    def correct(self, t, H, Z, G, R, err, err_prev, states, scale, w, summ):
        return G.copy(), 0


class Newton(FixedPoint):
    """Newton on R(V) = G(V) - V with the interface Jacobian by finite differences of rolled-back steps,
    kept across macro steps while it contracts fast and Broyden-updated in between."""

    def __init__(self, m, coupling_tol, max_iterations):
        super().__init__(m, coupling_tol, max_iterations)
        self.M = None  # (I - dG/dZ)^-1
        self.M_H = None  # the step it was computed for
        self.Z_prev = self.R_prev = None

    def begin(self, H) -> None:
        if self.M is not None and self.M_H is not None and abs(H - self.M_H) > 1e-12 * H:
            self.M = None  # the step's sensitivity depends on H
        self.Z_prev = self.R_prev = None

    def correct(self, t, H, Z, G, R, err, err_prev, states, scale, w, summ):
        calls = 0
        if self.M is None or err > 0.5 * err_prev:
            self.M, calls = interface_jacobian(self.m, t, H, self.m.U_n, Z, G, states, scale)
            self.M_H = H
            summ.jacobians += 1
        elif self.Z_prev is not None:  # between fresh Jacobians: secant updates
            self.M = broyden(self.M, Z - self.Z_prev, R - self.R_prev, w)
        self.Z_prev, self.R_prev = Z, R
        return Z + self.M @ R, calls


def algebraic_columns(m, u, rows, Jg) -> int:
    """dG/dV of an FMU whose outputs depend only on its inputs now (``u.algebraic``): its exact directional
    derivatives at the end of the step, one seed per input, no re-step.  Returns the number of calls."""
    out_idx = m.S[rows] - u.out_sl.start
    unknowns = vr_array([u.out_vr[i] for i in out_idx])
    seed = np.zeros(u.n_in)
    dv = np.zeros(len(rows))
    for i, j in enumerate(range(u.in_sl.start, u.in_sl.stop)):
        seed[:] = 0.0
        seed[i] = 1.0
        st = u._dirDer(u.c, unknowns, len(rows), u.in_vr, u.n_in, dptr(seed), dptr(dv))
        if st > 1:
            raise UnitFailure(u.name, "fmi2GetDirectionalDerivative", st, u.messages())
        # outputs are read with the inputs at the step's end, also from an FMU that held their midpoint (_do)
        Jg[rows, j] = m.F[rows] * dv
    return u.n_in


def interface_jacobian(m, t, H, U0, Zg, G, states, scale):
    """M = (I - dG/dZ)^-1 by finite differences of rolled-back steps, one FMU at a time (Z: the coupled
    values at t_n + H, and with Hermite inputs their slopes there); an algebraic FMU's columns come from
    its directional derivatives.  Returns (M, FMU calls)."""
    nu = m.nu
    herm = m.hermite
    size = len(Zg)
    Jg = np.zeros((size, size))
    calls = 0
    Y, DY, Uset = m.Y, m.DY, m.Uset
    Y_base, DY_base = Y.copy(), DY.copy()
    Gp = np.zeros(size)
    Up = np.zeros(max(nu, 1))
    Vg = Zg[:nu]
    for k, u in enumerate(m.units):
        if not u.n_in or u.kind == "me":
            continue
        rows = np.nonzero(m.u_src_unit[:nu] == k)[0]
        if not len(rows):
            continue
        if not herm and getattr(u, "algebraic", False):
            calls += algebraic_columns(m, u, rows, Jg)
            continue
        if herm:
            rows = np.concatenate([rows, rows + nu])
        cols = list(range(u.in_sl.start, u.in_sl.stop))
        if herm:
            cols += [j + nu for j in cols]
        for c in cols:
            j = c % nu if nu else c
            ref = scale[j] / H if c >= nu else scale[j]
            delta = 1e-6 * max(abs(Zg[c]), ref)
            u.restore(states[k])
            Uset[:nu] = U0[:nu]
            Zp = Zg.copy()
            Zp[c] += delta
            interpolate_to(Zp, U0, m.dU0, H, nu, m.input_kind, m.DUset, m.DDUset, m.DDDUset)
            if m.no_interp[j]:  # every input of this FMU held at its midpoint, as in the step (not only column j)
                midpoint_values(Uset[:nu], m.DUset[:nu], m.no_interp[:nu], H)
            calls += 1 + m._do(u, t, H, 0)
            calls += m._gather(Up, Gp, (u,))
            Jg[rows, c] = (Gp[rows] - G[rows]) / delta
            Y[u.out_sl] = Y_base[u.out_sl]
            DY[u.out_sl] = DY_base[u.out_sl]
    if m.me_block is not None:
        me_k = [k for k, u in enumerate(m.units) if u.kind == "me"]
        rows = np.nonzero(np.isin(m.u_src_unit[:nu], me_k))[0]
        cols = [j for u in m.me_block.units for j in range(u.in_sl.start, u.in_sl.stop)
                if m.units[m.u_src_unit[j]].kind != "me"]
        for j in cols:
            delta = 1e-6 * max(abs(Vg[j]), scale[j])
            for k in me_k:
                m.units[k].restore(states[k])
            Uset[:nu] = U0[:nu]
            Vp = Vg.copy()
            Vp[j] += delta
            interpolate_to(Vp, U0, m.dU0, H, nu, m.input_kind, m.DUset, m.DDUset, m.DDDUset)
            calls += len(me_k) + m.me_block.step(t, H)
            Jg[rows, j] = (m.F[rows] * Y[m.S[rows]] - G[rows]) / delta
            for k in me_k:
                Y[m.units[k].out_sl] = Y_base[m.units[k].out_sl]
    if m.loops:  # an algebraic loop with a gain of 1 has no unique solution: reported, not inverted
        from .loops import SingularLoop, singular_loop

        bad = singular_loop(m, Jg[:nu, :nu], np.asarray(scale[:nu], dtype=float))
        if bad is not None:
            raise SingularLoop(*bad)
    # Newton on R(Z) = G(Z) - Z: Z <- Z + (I - dG/dZ)^-1 R
    return np.linalg.inv(np.eye(size) - Jg), calls


def broyden(M, s, y, w):
    """Broyden's good update of M ~ (I - dG/dZ)^-1 = -(dR/dZ)^-1 from the secant pair (s, y) = (dZ, dR),
    in coordinates scaled by w: M+ = M - (s + M y) s' M / (s' M y)."""
    Mh = M * (w[None, :] / w[:, None])
    sh, yh = s / w, y / w
    Msy = Mh @ yh
    sM = sh @ Mh
    den = float(sh @ Msy)
    if not math.isfinite(den) or abs(den) < 1e-12 * float(np.linalg.norm(sh) * np.linalg.norm(Msy)):
        return M
    Mh = Mh - np.outer(sh + Msy, sM) / den
    return Mh * (w[:, None] / w[None, :])
