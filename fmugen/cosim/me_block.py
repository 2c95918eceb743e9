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

Events: when a unit declares event indicators or announces a time event, the
block steps scipy's Radau itself (the same solver and settings) and after
every accepted step reads the indicators; a domain change (z > 0 against
z <= 0, FMI 2.0 sec. 3.1, FMI 3.0 sec. 3.1) is located by bisection on the
step's dense output to EVENT_TOL, the states are put at the right end of
the bracket (just past the crossing, where the FMU's guards see the new
side, as fmugen's runtime does inside a Co-Simulation step), every unit
enters event mode, updates its discrete states (fmi2NewDiscreteStates /
fmi3UpdateDiscreteStates) until none needs another round, and the
integration restarts from the states the FMUs hold.  The units are the same
for FMI 2.0 and FMI 3.0 (units.py, units3.py): this module calls their
methods, not the fmi2/fmi3 functions by name.  A block without indicators
and time events is integrated by one ``solve_ivp`` call per macro step, as
before events were handled.
"""
from __future__ import annotations

import numpy as np

from .units import UnitFailure, dptr, vr_array

ME_RTOL = 1e-10
#: a state event is located to EVENT_TOL x max(1, |t|) in time (as fmugen's runtime, FMUGEN_EVENT_TOL)
EVENT_TOL = 1e-13
#: the event iteration's rounds at one instant before the block gives up (a clause that keeps firing)
EVENT_MAX_ROUNDS = 100


class MEBlock:
    def __init__(self, master, units, rtol: float = ME_RTOL):
        self.m = master
        self.units = units
        self.rtol = rtol
        self.n_rhs = 0
        self.n_jac = 0
        self.me_index = {u.name: i for i, u in enumerate(units)}
        off = 0
        self.next_time = None  # the earliest time event the units announced
        for u in units:
            # after initialisation an ME FMU is in event mode: its discrete states, then continuous time
            self.next_time = _earliest(self.next_time, self._update(u))
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
        for u in units:
            u.nz = int(getattr(u, "n_indicators", 0) or 0)
            u.zbuf = np.zeros(max(u.nz, 1))
            u.z_ptr = dptr(u.zbuf)
        self.nz = sum(u.nz for u in units)
        self.events = bool(self.nz) or self.next_time is not None
        self.event_times = []  # the instants of the events the block handled (also in steps rolled back)
        self._next_at = {}  # the announced time event at the start of a step from t (a rollback comes back)

    def warnings(self) -> list:
        """What the block does without, for the run's summary."""
        out = [f"Model-Exchange FMU {u.name!r} declares providesDirectionalDerivative=\"false\": the ME block's "
               f"Jacobian by finite differences (scipy), not exact" for u in self.units
               if not getattr(u, "directional", True)]
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
        if self.events:
            x1 = self._step_events(t, H, x0)
        else:
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

    # -- events -------------------------------------------------------------------
    def _update(self, u):
        """u's event iteration (u in event mode): discrete-state updates until none is needed.  Returns the
        next time event it announces, or None."""
        for _ in range(EVENT_MAX_ROUNDS):
            need, _changed, _nominals, nxt = u.update_discrete_states()
            if not need:
                return nxt
        raise UnitFailure(u.name, f"the event iteration ({EVENT_MAX_ROUNDS} rounds of discrete-state updates, "
                                  f"each asking for another)", 3, u.messages(), u.STATUS)

    def _indicators(self, t, x) -> np.ndarray:
        """Every unit's event indicators at (t, x), concatenated."""
        self._set_point(t, x)
        out = []
        for u in self.units:
            if u.nz:
                u.check(u._getZ(u.c, u.z_ptr, u.nz), "fmi2GetEventIndicators")
                out.append(u.zbuf[: u.nz].copy())
        return np.concatenate(out) if out else np.zeros(0)

    def _side_ahead(self, t, x):
        """The indicators' domains (z > 0) a moment after (t, x) along the flow, and that moment: just after
        an event an indicator sits at its zero, and its domain there is the one the trajectory enters (a
        ball sent up from h = -1e-13 is in h > 0; taking h <= 0 would miss its next fall when one step spans
        the flight).  Before that moment the domains are not compared (a first step of 1e-13 s would end
        below the ground still, and be taken for the ball rising through it)."""
        delta = 1e3 * EVENT_TOL * max(1.0, abs(t))
        f = self.rhs(t, x)
        return self._indicators(t + delta, x + delta * f) > 0, t + delta

    def _handle_event(self, t, x) -> np.ndarray:
        """The event at (t, x): every unit to event mode, its discrete states updated, back to continuous
        time.  Returns the states the units hold after it (re-initialised or not)."""
        self._set_point(t, x)
        nxt = None
        for u in self.units:
            u.enter_event_mode()
        for u in self.units:
            nxt = _earliest(nxt, self._update(u))
        for u in self.units:
            u.reenter_continuous_time()
            nominals = u.get_nominals()
            if not np.array_equal(nominals, u.nominals):
                u.nominals = nominals
                self.nominal = np.where(np.concatenate([v.nominals for v in self.units]) > 0,
                                        np.concatenate([v.nominals for v in self.units]), 1.0)
        self.next_time = nxt
        self.event_times.append(t)
        return self._current_x()

    def _locate(self, dense, ta, tb, side) -> float:
        """The earliest time in (ta, tb] where an indicator has left its domain ``side``, to EVENT_TOL."""
        tol = EVENT_TOL * max(1.0, abs(tb))
        while tb - ta > tol:
            tm = 0.5 * (ta + tb)
            if tm <= ta or tm >= tb:
                break
            if np.any((self._indicators(tm, dense(tm)) > 0) != side):
                tb = tm
            else:
                ta = tm
        return tb

    def _step_events(self, t, H, x):
        """The block from t to t + H with its state and time events; returns the states at t + H."""
        from scipy.integrate import Radau

        if t in self._next_at:  # a step repeated from t (rollback, shadow window): the time event it had
            self.next_time = self._next_at[t]
        else:
            if len(self._next_at) > 256:
                self._next_at.clear()
            self._next_at[t] = self.next_time
        t_end = t + H
        tc = t
        side, ahead = self._side_ahead(tc, x)
        same, last = 0, None  # events at one instant in a row (a time event announced for now, again and again)
        while True:
            bound = t_end
            # a time event up to the step's end (within EVENT_TOL) is handled in this step: the outputs at
            # t + H are those after it
            timed = self.next_time is not None and self.next_time <= t_end + EVENT_TOL * max(1.0, abs(t_end))
            if timed:
                bound = min(max(self.next_time, tc), t_end)
            if bound > tc:
                solver = Radau(self.rhs, tc, x, bound, rtol=self.rtol, atol=self.rtol * self.nominal,
                               jac=self.jac if self.exact_jacobian else None)
                hit = None
                while solver.status == "running":
                    msg = solver.step()
                    if solver.status == "failed":
                        u = self.units[0]
                        raise UnitFailure(u.name, f"ME block (Radau) from t = {tc:.9g} to {bound:.9g}: {msg}", 2,
                                          u.messages())
                    t1, x1 = solver.t, solver.y
                    if self.nz and t1 > ahead and np.any((self._indicators(t1, x1) > 0) != side):
                        dense = solver.dense_output()
                        te = self._locate(dense, max(solver.t_old, ahead), t1, side)
                        hit = (te, dense(te) if te < t1 else x1)
                        break
                    self._set_point(t1, x1)
                    enter = False
                    for u in self.units:  # the FMU may ask for an event after an accepted step
                        enter = u.completed_integrator_step() or enter
                    if enter:
                        hit = (t1, x1)
                        break
                if hit is None:
                    tc, x = bound, solver.y
                    if not timed:
                        return x
                else:
                    tc, x = hit
            same = same + 1 if tc == last else 0
            last = tc
            if same >= EVENT_MAX_ROUNDS:
                u = self.units[0]
                raise UnitFailure(u.name, f"ME block: {EVENT_MAX_ROUNDS} events at t = {tc:.17g} in a row (a time "
                                          f"event announced for the instant it was handled at?)", 3, u.messages(),
                                  u.STATUS)
            x = self._handle_event(tc, x)
            side, ahead = self._side_ahead(tc, x)
            if tc >= t_end:
                return x

    def _current_x(self) -> np.ndarray:
        """States as the FMUs hold them (after a rollback they were restored inside the FMUs)."""
        x = np.empty(self.nx)
        for u in self.units:
            u.check(u._getX(u.c, u.x_ptr, u.nx), "fmi2GetContinuousStates")
            x[u.x_sl] = u.xbuf[: u.nx]
        return x


def _earliest(a, b):
    return b if a is None else (a if b is None else min(a, b))
