"""Model-Exchange FMUs of a system, integrated together as one ODE by the master.

All ME units of a system form one block: their continuous states are
concatenated into x, couplings between two ME units are evaluated at every
right-hand side call (so they are exact, not sampled at communication
points), and inputs from Co-Simulation units follow the same extrapolation
the CS units get (value at t_n plus slope).  Per macro step the block is one
more participant: it advances from t_n to t_n + H with scipy's Radau IIA
(L-stable, order 5) at ``rtol``/``atol`` (atol times each state's nominal),
using a Jacobian assembled from the FMUs' exact directional derivatives:

    d f_k / d x_k                         (unknowns der(x_k), knowns x_k)
    d f_k / d x_m = df_k/du_k * F * dy_m/dx_m   for every ME-to-ME coupling m -> k

Outputs of an ME unit are assumed not to depend on its inputs for ME-to-ME
couplings inside the block (no algebraic loop; the scenes' boundaries -- arm
outputs q, qd, actuator output tau -- satisfy this).
"""
from __future__ import annotations

from ctypes import byref

import numpy as np

from .units import UnitFailure, dptr, vr_array

ME_RTOL = 1e-10


class MEBlock:
    def __init__(self, master, units, rtol: float = ME_RTOL):
        from fmpy.fmi2 import fmi2EventInfo

        self.m = master
        self.units = units
        self.rtol = rtol
        self.n_rhs = 0
        self.n_jac = 0
        self.me_index = {u.name: i for i, u in enumerate(units)}
        off = 0
        for u in units:
            ev = fmi2EventInfo()
            f = u.fmu._functions
            st = f["fmi2NewDiscreteStates"](u.c, byref(ev))
            u.check(st, "fmi2NewDiscreteStates")
            u.enter_continuous_time()
            u.x_sl = slice(off, off + u.nx)
            off += u.nx
            u.x_vr_arr = vr_array(u.x_vrs)
            u.der_vr_arr = vr_array(u.der_vrs)
            u.xbuf = np.zeros(max(u.nx, 1))
            u.dbuf = np.zeros(max(u.nx, 1))
            u.x_ptr, u.d_ptr = dptr(u.xbuf), dptr(u.dbuf)
            u.ubuf = np.zeros(max(u.n_in, 1))
            u.ub_ptr = dptr(u.ubuf)
            u.ybuf = np.zeros(max(u.n_out, 1))
            u.yb_ptr = dptr(u.ybuf)
        self.nx = off
        self.nominal = np.concatenate([u.nominals for u in units]) if units else np.zeros(0)
        self.nominal = np.where(self.nominal > 0, self.nominal, 1.0)
        # for every input of an ME unit: where its value comes from
        self.links = []  # (me unit, local input index, kind, source) ; kind "cs": global U index; "me": (src unit, local out index)
        for u in units:
            for li, j in enumerate(range(u.in_sl.start, u.in_sl.stop)):
                src = master.units[master.u_src_unit[j]]
                if src.kind == "me":
                    yi = master.S[j] - src.out_sl.start
                    self.links.append((u, li, "me", (src, int(yi), float(master.F[j]), j)))
                else:
                    self.links.append((u, li, "cs", j))
        self.t_n = 0.0
        self.x = np.zeros(self.nx)
        # df/dx from fmi2GetDirectionalDerivative needs every unit to provide it; else scipy's differences
        self.exact_jacobian = all(getattr(u, "directional", True) for u in units)

    def warnings(self) -> list:
        """What the block does without, for the run's summary."""
        out = [f"Model-Exchange FMU {u.name!r} declares providesDirectionalDerivative=\"false\": the ME block's "
               f"Jacobian by finite differences (scipy), not exact" for u in self.units
               if not getattr(u, "directional", True)]
        out += [f"Model-Exchange FMU {u.name!r} declares {u.n_indicators} event indicators, which the ME block does "
                f"not watch: its state events are not located" for u in self.units
                if getattr(u, "n_indicators", 0) > 0]
        return out

    # -- evaluation -----------------------------------------------------------
    def start(self, t0: float) -> None:
        x = np.zeros(self.nx)
        for u in self.units:
            st = u._getX(u.c, u.x_ptr, u.nx)
            u.check(st, "fmi2GetContinuousStates")
            x[u.x_sl] = u.xbuf[: u.nx]
        self.x = x

    def _set_point(self, t, x) -> None:
        """Time and states of every ME unit, then their inputs (ME sources first read at this point)."""
        m = self.m
        for u in self.units:
            u.check(u._setTime(u.c, t), "fmi2SetTime")
            u.xbuf[: u.nx] = x[u.x_sl]
            u.check(u._setX(u.c, u.x_ptr, u.nx), "fmi2SetContinuousStates")
        for u in self.units:
            if u.n_out:
                u.check(u._getReal(u.c, u.out_vr, u.n_out, u.yb_ptr), "fmi2GetReal")
        dt = t - self.t_n
        for u, li, kind, src in self.links:
            if kind == "cs":
                u.ubuf[li] = m.Uset[src] + m.DUset[src] * dt
            else:
                su, yi, f, _ = src
                u.ubuf[li] = f * su.ybuf[yi]
        for u in self.units:
            if u.n_in:
                u.check(u._setReal(u.c, u.in_vr, u.n_in, u.ub_ptr), "fmi2SetReal")

    def rhs(self, t, x) -> np.ndarray:
        self._set_point(t, x)
        out = np.empty(self.nx)
        for u in self.units:
            u.check(u._getDer(u.c, u.d_ptr, u.nx), "fmi2GetDerivatives")
            out[u.x_sl] = u.dbuf[: u.nx]
        self.n_rhs += 1
        return out

    def _dirder(self, u, unknown_vrs, known_vrs, seed) -> np.ndarray:
        nu_, nk = len(unknown_vrs), len(known_vrs)
        res = np.zeros(max(nu_, 1))
        sd = np.ascontiguousarray(seed, dtype=float)
        st = u._dirDer(u.c, vr_array(unknown_vrs), nu_, vr_array(known_vrs), nk, dptr(sd), dptr(res))
        u.check(st, "fmi2GetDirectionalDerivative")
        return res[:nu_]

    def jac(self, t, x) -> np.ndarray:
        """df/dx of the whole block from directional derivatives (exact)."""
        self._set_point(t, x)
        J = np.zeros((self.nx, self.nx))
        for m_ in self.units:
            out_vrs = [m_.variables[v].valueReference for v in m_.out_names]
            feeds = [(u, li, src) for (u, li, kind, src) in self.links if kind == "me" and src[0] is m_]
            for i in range(m_.nx):
                e = np.zeros(1)
                e[0] = 1.0
                J[m_.x_sl, m_.x_sl.start + i] = self._dirder(m_, m_.der_vrs, [m_.x_vrs[i]], e)
                if feeds and out_vrs:
                    dy = self._dirder(m_, out_vrs, [m_.x_vrs[i]], e)
                    for u, li, (su, yi, f, _) in feeds:
                        in_vr = u.variables[u.in_names[li]].valueReference
                        col = self._dirder(u, u.der_vrs, [in_vr], np.array([f * dy[yi]]))
                        J[u.x_sl, m_.x_sl.start + i] += col
        self.n_jac += 1
        return J

    # -- a macro step -----------------------------------------------------------
    def step(self, t, H) -> int:
        """Advance the block from t to t + H; outputs at t + H into the master's Y.  Returns FMU calls."""
        from scipy.integrate import solve_ivp

        self.t_n = t
        n0 = self.n_rhs
        x0 = self._current_x()
        try:
            sol = solve_ivp(self.rhs, (t, t + H), x0, method="Radau", rtol=self.rtol, atol=self.rtol * self.nominal,
                            jac=self.jac if self.exact_jacobian else None, first_step=None)
        except UnitFailure:
            raise
        if not sol.success:
            u = self.units[0]
            raise UnitFailure(u.name, f"ME block (Radau) from t = {t:.9g} to {t + H:.9g}: {sol.message}", 2,
                              u.messages())
        x1 = sol.y[:, -1]
        self._set_point(t + H, x1)
        calls = 0
        for u in self.units:
            if u.n_out:
                u.check(u._getReal(u.c, u.out_vr, u.n_out, u.y_ptr), "fmi2GetReal")
                calls += 1
        self.m._do_steps += len(self.units)
        return calls + 3 * len(self.units) * (self.n_rhs - n0)

    def _current_x(self) -> np.ndarray:
        """States as the FMUs hold them (after a rollback they were restored inside the FMUs)."""
        x = np.empty(self.nx)
        for u in self.units:
            u.check(u._getX(u.c, u.x_ptr, u.nx), "fmi2GetContinuousStates")
            x[u.x_sl] = u.xbuf[: u.nx]
        return x
