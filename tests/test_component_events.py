"""Events in component files ([discrete], [indicators], [[when]]): parsing and refusals, the shipped
hybrid blocks as SymbolicModels with Events, and their behaviour against closed forms -- simulated by
a small hybrid simulator written here on scipy (the Events semantics of fmugen/codegen/model.py,
independent of fmugen's C runtime) -- and, once the generated C has events, the FMUs under fmpy."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import DOP853

import fmugen
from fmugen.codegen.program import Assign
from fmugen.components.base import TIME
from fmugen.components.equations import library_names, load_component, read_component_file
from fmugen.errors import InputFileError

ROOT = Path(__file__).resolve().parent.parent
BALL = ROOT / "examples" / "components" / "bouncing_ball.toml"
HYBRID = ["backlash", "end_stop", "limiter", "relief_valve_hysteresis", "stick_slip"]


# ============================================================================= a hybrid simulator
class Hybrid:
    """The Events semantics on scipy: DOP853 (rtol = atol = 1e-12) between events; after every step
    the indicators' domains (z > 0 or not) at the step's end are compared with the current ones, and
    on a change the earliest crossing is bisected on the step's dense output to the first double at
    which the domain has changed ("just after the crossing"); there every guard and value is evaluated
    with the values of the round, the assignments of the firing clauses applied in order, and rounds
    repeat until nothing changes (at most 100).  The iteration also runs at t = 0 (FMI 2.0: an FMU
    leaves initialisation in event mode) and at each input breakpoint (an input that jumps).

    ``inputs``: [(t_start, u(t) -> list)], piecewise: piece k is used on [t_k, t_{k+1}] (also at its
    end); ``overrides``: parameter values; ``starts``: state / discrete start values.
    """

    MAX_ROUNDS = 100

    def __init__(self, model, inputs=((0.0, lambda t: []),), overrides=None, starts=None):
        ev = model.events
        assert ev is not None
        overrides, starts = dict(overrides or {}), dict(starts or {})
        params = {p.symbol: sp.Float(overrides.pop(p.name, p.start)) for p in model.parameters}
        assert not overrides, overrides
        env = {}
        for st in model.program.steps:  # the straight-line program, inlined
            assert isinstance(st, Assign)
            env[st.symbol] = st.expr.xreplace(env)
        self.model = model
        self.xs = [v.symbol for v in model.states] or [sp.Symbol("_dummy", real=True)]  # scipy needs a state
        self.us = [v.symbol for v in model.inputs]
        self.ds = [v.symbol for v in ev.discrete]
        args = [TIME, *self.xs, *self.us, *self.ds]
        # every event expression must read states, inputs, parameters, discrete states and t only
        allowed = set(args) | set(params)
        for e in ev.expressions():
            assert e.free_symbols <= allowed, (e, e.free_symbols - allowed)

        def fn(e):
            return sp.lambdify(args, sp.sympify(e).xreplace(env).xreplace(params), "math")

        self.f = [fn(e) for e in model.derivatives] or [fn(0)]
        self.g = {v.name: fn(e) for v, e in zip(model.outputs, model.output_exprs)}
        self.z = [(n, fn(e)) for n, e in ev.indicators]
        where = {s: ("x", k) for k, s in enumerate(self.xs)} | {s: ("d", k) for k, s in enumerate(self.ds)}
        self.clauses = [(c.name, fn(c.guard), [(*where[tgt], fn(val)) for tgt, val in c.assign]) for c in ev.clauses]
        self.x0 = [float(starts.pop(v.name, v.start)) for v in model.states] or [0.0]
        self.d0 = [float(starts.pop(v.name, v.start)) for v in ev.discrete]
        assert not starts, starts
        self.inputs = sorted(inputs, key=lambda p: p[0])

    # -- pieces ------------------------------------------------------------
    def _vals(self, t, x, u, d):
        return (t, *x, *u, *d)

    def domains(self, t, x, u, d):
        return [z(*self._vals(t, x, u, d)) > 0 for _, z in self.z]

    def iterate(self, t, x, d, u):
        """The event iteration at t: (x, d, names of the clauses that changed something, per round)."""
        fired = []
        for _ in range(self.MAX_ROUNDS):
            vals = self._vals(t, x, u, d)
            active = [(name, assign) for name, guard, assign in self.clauses if guard(*vals)]
            nx, nd = list(x), list(d)
            for _name, assign in active:
                for kind, k, value in assign:
                    (nx if kind == "x" else nd)[k] = float(value(*vals))
            if nx == x and nd == d:
                return x, d, fired
            fired.append([name for name, _ in active])
            x, d = nx, nd
        raise AssertionError(f"the event iteration at t = {t} did not end in {self.MAX_ROUNDS} rounds")

    def _crossing(self, z, interp, a, b, before, u, d):
        """The first double in (a, b] at which indicator z's domain is no longer ``before``."""
        def changed(s):
            return (z(*self._vals(s, interp(s), u(s), d)) > 0) != before
        while True:
            m = 0.5 * (a + b)
            if m <= a or m >= b:
                return b
            if changed(m):
                b = m
            else:
                a = m

    def run(self, t_end, max_step=np.inf):
        """Simulate [0, t_end]; ``self.events``: (t, [fired names per round]) of every event (also the
        harmless ones, with no round), ``self.segments``: (t0, t1, x(t), d) between events."""
        self.events, self.segments = [], []
        pieces = [(max(p[0], 0.0), p[1]) for p in self.inputs if p[0] < t_end]
        t, x, d = 0.0, list(self.x0), list(self.d0)
        for k, (t_piece, u) in enumerate(pieces):
            t_stop = pieces[k + 1][0] if k + 1 < len(pieces) else t_end
            # an event at the start (k = 0) and wherever the input jumps and an indicator's domain with it
            if k == 0 or self.domains(t, x, u(t), d) != dom:
                x, d, fired = self.iterate(t, x, d, u(t))
                self.events.append((t, fired))
            dom = self.domains(t, x, u(t), d)
            while t < t_stop:
                solver = DOP853(lambda s, y, d=d, u=u: [f(*self._vals(s, y, u(s), d)) for f in self.f], t, x,
                                t_stop, rtol=1e-12, atol=1e-12, max_step=max_step)
                while solver.status == "running":
                    t_old = solver.t
                    msg = solver.step()
                    assert solver.status != "failed", msg
                    interp = solver.dense_output()
                    new = self.domains(solver.t, solver.y, u(solver.t), d)
                    if new == dom:
                        self.segments.append((t_old, solver.t, interp, list(d)))
                        t, x = solver.t, list(solver.y)
                        continue
                    t_ev = min(self._crossing(z, interp, t_old, solver.t, dom[i], u, d)
                               for i, (_, z) in enumerate(self.z) if new[i] != dom[i])
                    self.segments.append((t_old, t_ev, interp, list(d)))
                    t = t_ev
                    x, d, fired = self.iterate(t, [float(v) for v in interp(t)], d, u(t))
                    self.events.append((t, fired))
                    dom = self.domains(t, x, u(t), d)
                    break
        self.pieces = pieces
        return self

    # -- results -------------------------------------------------------------
    def fired(self, name):
        """Times of the events at which clause ``name`` fired."""
        return np.array([t for t, rounds in self.events if any(name in r for r in rounds)])

    def _at(self, t):
        for t0, t1, interp, d in reversed(self.segments):  # the later segment at an event (right limit)
            if t0 <= t <= t1:
                return np.asarray(interp(t), float), d
        raise ValueError(f"t = {t} not simulated")

    def u_at(self, t):
        return [p for p in self.pieces if p[0] <= t][-1][1](t)

    def state(self, name, t):
        return np.array([self._at(s)[0][self._index(name)] for s in np.atleast_1d(t)])

    def discrete(self, name, t):
        k = [v.name for v in self.model.events.discrete].index(name)
        return np.array([self._at(s)[1][k] for s in np.atleast_1d(t)])

    def output(self, name, t):
        out = []
        for s in np.atleast_1d(t):
            x, d = self._at(s)
            out.append(self.g[name](*self._vals(s, x, self.u_at(s), d)))
        return np.array(out, float)

    def _index(self, name):
        return [v.name for v in self.model.states].index(name)


def between(events, t, margin=1e-9):
    """The sample times t that are not within ``margin`` of an event (values there are one-sided)."""
    ev = np.asarray(events)
    return np.array([s for s in t if ev.size == 0 or np.min(np.abs(ev - s)) > margin])


# ============================================================================= parsing and refusals
HYBRID_FILE = """
[component]
name = "h"
equations = ["der(x) = v", "der(v) = if m == 0 then -g else -g - k*v", "a = e*v"]
[parameters]
g = { value = 9.81, unit = "m/s2" }
e = { value = 0.5, unit = "1" }
k = { value = 0.1, unit = "1/s" }
[states]
x = { unit = "m", start = 1.0 }
v = { unit = "m/s", start = 0.0 }
[intermediates]
a = { unit = "m/s" }
[discrete]
m = { start = 0, unit = "1", description = "bounces so far (capped at 1)" }
[indicators]
ground = "x"
[[when]]
name = "bounce"
condition = "x <= 0 and v < 0"
set = { v = "-a", m = "1" }
"""


def write(tmp_path, text, name="h.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_a_hybrid_file_builds_events_with_intermediates_inlined(tmp_path):
    m = load_component(write(tmp_path, HYBRID_FILE))
    x, v, mm, e = sp.symbols("x v m e", real=True)
    ev = m.events
    assert [d.name for d in ev.discrete] == ["m"] and ev.discrete[0].start == 0.0 and ev.discrete[0].unit == "1"
    assert ev.indicators == (("ground", x),)
    (c,) = ev.clauses
    assert c.name == "bounce" and c.guard == sp.And(sp.Le(x, 0), sp.Lt(v, 0))
    assert c.assign == ((v, -e * v), (mm, sp.Integer(1)))  # the intermediate a = e v inlined
    # the discrete state is a constant to the Jacobian: the mode's Jacobian
    sim = Hybrid(m)
    assert sim.f[1](0.0, 1.0, 2.0, 0.0) == -9.81 and sim.f[1](0.0, 1.0, 2.0, 1.0) == pytest.approx(-9.81 - 0.2)
    # a smooth file has no events
    assert load_component("lib:stribeck").events is None


@pytest.mark.parametrize("old, new, where, why", [
    # targets and units
    ('set = { v = "-a", m = "1" }', 'set = { y = "0" }', r"\[\[when\]\] 1 \(bounce\) set y",
     r"unknown target: 'y' is not declared"),
    ('set = { v = "-a", m = "1" }', 'set = { g = "1" }', r"\[\[when\]\] 1 \(bounce\) set g",
     r"unknown target: 'g' is a parameter"),
    ('set = { v = "-a", m = "1" }', 'set = { a = "0" }', r"set a", r"unknown target: 'a' is an intermediate"),
    ('set = { v = "-a", m = "1" }', 'set = { v = "x", m = "1" }', r"set v = 'x'",
     r"the value is \[m\] but v is in \[m/s\]"),
    ('set = { v = "-a", m = "1" }', 'set = { v = "-a", m = "x" }', r"set m = 'x'",
     r"the value is \[m\] but m is in \[1\]"),
    ('set = { v = "-a", m = "1" }', 'set = { v = 2.5, m = "1" }', r"set v = '2.5'", r"\[1\] but v is in \[m/s\]"),
    ('set = { v = "-a", m = "1" }', 'set = { v = true, m = "1" }', r"set v", r"expression string or a number"),
    ('set = { v = "-a", m = "1" }', 'set = {}', r"\[\[when\]\] 1 \(bounce\)", r"needs set ="),
    ('set = { v = "-a", m = "1" }', 'set = { v = "v if x > 0 else 0", m = "1" }', r"set v",
     r"must start an expression"),
    # conditions
    ('condition = "x <= 0 and v < 0"', 'condition = "x"', r"\[\[when\]\] 1 \(bounce\) condition 'x'",
     r"a condition must be a comparison"),
    ('condition = "x <= 0 and v < 0"', 'condition = "x <= 0 and v"', r"condition", r"'v' is not one"),
    ('condition = "x <= 0 and v < 0"', 'condition = "not v"', r"condition", r"a condition must be a comparison"),
    ('condition = "x <= 0 and v < 0"', 'condition = "x < v"', r"condition 'x < v' is dimensionally inconsistent",
     r"'x' is \[m\] but 'v' is \[m.s-1\]"),
    ('condition = "x <= 0 and v < 0"', 'condition = "x == 0"', r"condition 'x == 0'", r"for equality"),
    ('condition = "x <= 0 and v < 0"', 'condition = "der(x) < 0"', r"condition",
     r"call of 'der' is not allowed .*only a left-hand side"),
    ('condition = "x <= 0 and v < 0"', 'condition = "smooth(x < 0, x) and v < 0"', r"condition",
     r"smooth\(...\) is only the whole condition of an if"),
    ('condition = "x <= 0 and v < 0"', 'condition = "print(x) < 0"', r"condition", r"unknown name\(s\) print"),
    ('condition = "x <= 0 and v < 0"', 'condition = "1 > 0"', r"condition '1 > 0'", r"is always true"),
    ('condition = "x <= 0 and v < 0"', 'condition = "x in (0, 1)"', r"condition",
     r"the comparison .in. is not allowed"),
    ('condition = "x <= 0 and v < 0"', 'condition = "x.real <= 0"', r"condition", r"attribute access is not allowed"),
    ('condition = "x <= 0 and v < 0"', "condition = \"'a' < 'b'\"", r"condition", r"not a real number"),
    ('condition = "x <= 0 and v < 0"', 'condition = "x <= 0 && v < 0"', r"condition", r"syntax error"),
    ('condition = "x <= 0 and v < 0"', 'condition = true', r"\[\[when\]\] 1 \(bounce\)", r"needs condition"),
    ('condition = "x <= 0 and v < 0"', 'guard = "x <= 0"', r"\[\[when\]\] 1 \(bounce\)", r"unknown key\(s\) guard"),
    # injection
    ('condition = "x <= 0 and v < 0"', """condition = "__import__('os').system('true') > 0" """, r"condition",
     r"unknown name\(s\) __import__"),
    ('ground = "x"', """ground = "__import__('os')" """, r"\[indicators\] ground", r"unknown name\(s\) __import__"),
    ('set = { v = "-a", m = "1" }', """set = { v = "eval('1')*v", m = "1" }""", r"set v", r"unknown name\(s\) eval"),
    ('condition = "x <= 0 and v < 0"', 'condition = "(lambda: 1)() > 0"', r"condition", r"lambda"),
    ('condition = "x <= 0 and v < 0"', 'condition = "x <= 0; import os"', r"condition", r"syntax error|cannot read"),
    # indicators
    ('ground = "x"', 'ground = "y"', r"\[indicators\] ground = 'y'", r"unknown name\(s\) y"),
    ('ground = "x"', 'ground = "x - v"', r"\[indicators\] ground = 'x - v' is dimensionally inconsistent",
     r"'x' is \[m\] but 'v' is \[m.s-1\]"),
    ('ground = "x"', 'ground = "x <= 0"', r"\[indicators\] ground", r"an indicator is a quantity, not a condition"),
    ('ground = "x"', 'ground = "sign(x)"', r"\[indicators\] ground", r"must be continuous"),
    ('ground = "x"', 'ground = "if v > 0 then x else -x"', r"\[indicators\] ground", r"must be continuous"),
    ('ground = "x"', 'ground = "g*m"', r"\[indicators\] ground", r"depends on no state, input or time"),
    ('ground = "x"', 'x = "x"', r"\[indicators\] x", r"also a declared state"),
    ('ground = "x"', 'ground = 1.0', r"\[indicators\] ground", r"must be an expression string"),
    # discrete states
    ('m = { start = 0, unit = "1",', 'm = { unit = "1",', r"\[discrete\] m", r"needs a start value"),
    ('m = { start = 0, unit = "1",', 'm = { start = 0, unit = "1", value = 2,', r"\[discrete\] m",
     r"unknown key\(s\) value"),
    ('m = { start = 0, unit = "1",', 'm = { start = 0, unit = "bar",', r"\[discrete\] m", r"coherent SI"),
    ('set = { v = "-a", m = "1" }', 'set = { v = "-a" }', r"\[discrete\] m", r"never set by a \[\[when\]\] clause"),
    ('[indicators]\nground = "x"\n', '', r"\[\[when\]\] clauses but no \[indicators\]", r"no event would ever run"),
    ('[[when]]', '[when]', r"\[when\]", r"write \[\[when\]\]"),
    # the equations may switch exactly on discrete states and parameters only
    ('"der(v) = if m == 0 then -g else -g - k*v"', '"der(v) = if m == 0 and v > 0 then -g else -g - k*v"',
     r"equation 'der\(v\)", r"one comparison"),
    ('"der(v) = if m == 0 then -g else -g - k*v"', '"der(v) = -g*sign(x)"', r"equation 'der\(v\)",
     r"jump on a state.*make the switch an event"),
])
def test_malformed_hybrid_files_are_refused_in_one_line(tmp_path, old, new, where, why):
    assert old in HYBRID_FILE
    p = write(tmp_path, HYBRID_FILE.replace(old, new))
    with pytest.raises(InputFileError) as exc:
        read_component_file(p)
    msg = str(exc.value)
    assert "\n" not in msg, msg
    assert msg.startswith(f"{p}: "), msg
    assert re.search(where, msg), (where, msg)
    assert re.search(why, msg), (why, msg)


def test_exact_switches_on_discrete_states_and_parameters_are_kept(tmp_path):
    text = HYBRID_FILE.replace(
        '"a = e*v"', '"a = e*v*abs(m - 1/2)*2 + (if not (m != 0 or e > 0.9) then 0*v else 0*v)"').replace(
        'ground = "x"', 'ground = "if m == 0 and e < 1 then x else x + 0*v"')
    m = load_component(write(tmp_path, text))
    sim = Hybrid(m)
    ((_, z),) = sim.z
    assert z(0.0, 2.0, 3.0, 0.0) == 2.0 and z(0.0, 2.0, 3.0, 1.0) == 2.0
    (_, guard, assign), = sim.clauses
    assert guard(0.0, -1e-12, -3.0, 0.0) is True and guard(0.0, 1e-12, -3.0, 0.0) is False
    assert assign[0][2](0.0, 0.0, -3.0, 0.0) == pytest.approx(1.5)  # -a = -e v |m - 1/2| 2
    # chained comparisons are conjunctions; an if in an assigned value may test states (evaluated once)
    text = HYBRID_FILE.replace('condition = "x <= 0 and v < 0"', 'condition = "v < 0 <= -x"').replace(
        'set = { v = "-a", m = "1" }', 'set = { v = "if v < -a then -a else 0", m = "1" }')
    c = load_component(write(tmp_path, text)).events.clauses[0]
    x, v = sp.symbols("x v", real=True)
    assert c.guard == sp.And(sp.Lt(v, 0), sp.Le(0, -x))
    assert c.assign[0][1].has(sp.Piecewise)


def test_every_shipped_hybrid_block_builds_a_model_with_events():
    assert set(HYBRID) <= set(library_names())
    for name in HYBRID + [str(BALL)]:
        m = load_component(name if name.endswith(".toml") else f"lib:{name}")
        ev = m.events
        assert ev is not None and ev.indicators and ev.clauses, name
        allowed = ({v.symbol for g in (m.states, m.inputs, m.parameters, ev.discrete) for v in g} | {TIME})
        for e in ev.expressions():  # no program symbols: intermediates are inlined
            assert e.free_symbols <= allowed, (name, e)
        targets = {v.symbol for v in m.states} | {v.symbol for v in ev.discrete}
        assert all(t in targets for c in ev.clauses for t, _ in c.assign), name
        assert all(isinstance(c.guard, sp.logic.boolalg.Boolean) for c in ev.clauses), name
        assert all(d.start is not None for d in ev.discrete), name
        assert m.dfdx is not None and m.dfdx.shape == (len(m.states), len(m.states))
    for name in set(library_names()) - set(HYBRID) - {"discrete_pi", "discrete_pid", "discrete_state_feedback", "sampler"}:
        assert load_component(f"lib:{name}").events is None, name


# ============================================================================= closed forms
G, E, H0 = 9.81, 0.7, 1.0


def ball_bounce_times(n):
    t = [math.sqrt(2 * H0 / G)]
    for k in range(1, n):
        t.append(t[-1] + 2 * E**k * math.sqrt(2 * G * H0) / G)
    return np.array(t)


def test_bouncing_ball_bounce_times_equal_the_closed_form():
    t_ref = ball_bounce_times(10)
    sim = Hybrid(load_component(BALL)).run(t_ref[-1] + 0.01)
    t_b = sim.fired("bounce")
    assert len(t_b) == 10
    assert np.max(np.abs(t_b - t_ref)) < 1e-9
    # between bounces the ball is above the ground; the speed after bounce k is e^k sqrt(2 g h0)
    for k in range(9):
        mid = 0.5 * (t_ref[k] + t_ref[k + 1])
        assert sim.state("v", mid)[0] == pytest.approx(E ** (k + 1) * math.sqrt(2 * G * H0) - G * (mid - t_ref[k]),
                                                       abs=1e-9)
        assert sim.state("h", mid)[0] > 0


STICK = dict(J=0.05, T_c=2.0, T_s=3.0, b=0.02)


def test_stick_slip_below_breakaway_stays_exactly():
    sim = Hybrid(load_component("lib:stick_slip"), inputs=[(0.0, lambda t: [2.5])]).run(100.0)
    t = np.linspace(0, 100, 201)
    assert np.all(sim.state("phi", t) == 0.0) and np.all(sim.state("w", t) == 0.0)
    assert np.all(sim.discrete("mode", t) == 0.0)
    assert np.all(sim.output("tau_f", t) == 2.5)  # the constraint torque
    assert sim.events == [(0.0, [])]  # nothing ever happens


def sliding(tau, t, w0=0.0, T=STICK):
    """w(t) while sliding forward (mode 1) under constant tau from w0: J w' = tau - T_c - b w."""
    w_inf = (tau - T["T_c"]) / T["b"]
    return w_inf + (w0 - w_inf) * np.exp(-T["b"] * t / T["J"])


def test_stick_slip_breakaway_and_sliding_equal_the_closed_form():
    tau = 3.5
    sim = Hybrid(load_component("lib:stick_slip"), inputs=[(0.0, lambda t: [tau])]).run(100.0)
    assert sim.events[0] == (0.0, [["breakaway"]])  # at t = 0: |tau| > T_s
    t = np.linspace(0.01, 100, 400)
    J, T_c, b = STICK["J"], STICK["T_c"], STICK["b"]
    w = (tau - T_c) / b * (1 - np.exp(-b * t / J))
    phi = (tau - T_c) / b * (t - J / b * (1 - np.exp(-b * t / J)))
    assert np.max(np.abs(sim.state("w", t) / w - 1)) < 1e-9
    assert np.max(np.abs(sim.state("phi", t) / phi - 1)) < 1e-9
    assert np.all(sim.discrete("mode", t) == 1.0)
    assert sim.output("tau_f", [50.0])[0] == pytest.approx(T_c + b * sim.state("w", 50.0)[0], rel=1e-14)
    # backwards: the same, mirrored
    sim = Hybrid(load_component("lib:stick_slip"), inputs=[(0.0, lambda t: [-tau])]).run(10.0)
    assert np.max(np.abs(sim.state("w", t[t < 10]) / -w[t < 10] - 1)) < 1e-9


def test_stick_slip_sticks_when_the_speed_reaches_zero_and_reverses_under_a_large_torque():
    J, T_c, b = STICK["J"], STICK["T_c"], STICK["b"]
    w1 = sliding(3.5, 1.0)
    # drive removed at t = 1: decelerates (J w' = -T_c - b w) and sticks at w = 0
    sim = Hybrid(load_component("lib:stick_slip"), inputs=[(0.0, lambda t: [3.5]), (1.0, lambda t: [0.0])]).run(6.0)
    t_stop = 1.0 + J / b * math.log((w1 + T_c / b) / (T_c / b))
    (t_s,) = sim.fired("stick")
    assert t_s == pytest.approx(t_stop, abs=1e-10)
    phi_s = sim.state("phi", t_s + 1e-9)[0]
    after = np.linspace(t_s + 1e-6, 6.0, 50)
    assert np.all(sim.state("phi", after) == phi_s) and np.all(sim.state("w", after) == 0.0)
    assert np.all(sim.discrete("mode", after) == 0.0)
    # a reversed drive beyond breakaway at t = 1: decelerates (J w' = tau - T_c - b w), reverses at w = 0
    tau = -3.5
    sim = Hybrid(load_component("lib:stick_slip"), inputs=[(0.0, lambda t: [3.5]), (1.0, lambda t: [tau])]).run(6.0)
    t_rev = 1.0 + J / b * math.log((w1 + (T_c - tau) / b) / ((T_c - tau) / b))
    (t_r,) = sim.fired("reverse")
    assert t_r == pytest.approx(t_rev, abs=1e-10) and not sim.fired("stick").size
    after = np.linspace(t_r + 0.01, 6.0, 50)
    w_back = (tau + T_c) / b * (1 - np.exp(-b * (after - t_r) / J))  # J w' = tau + T_c - b w
    assert np.max(np.abs(sim.state("w", after) / w_back - 1)) < 1e-8
    assert np.all(sim.discrete("mode", after) == -1.0)
    # stuck below breakaway, then a step above it: breakaway exactly at the step
    sim = Hybrid(load_component("lib:stick_slip"), inputs=[(0.0, lambda t: [2.9]), (2.0, lambda t: [3.1])]).run(3.0)
    assert list(sim.fired("breakaway")) == [2.0]
    assert sim.state("phi", 2.0)[0] == 0.0
    assert sim.state("w", 2.5)[0] == pytest.approx(sliding(3.1, 0.5), rel=1e-9)


def test_backlash_contact_is_a_damped_spring_and_opens_when_it_stops_pushing():
    # the load held (phi_L = w_L = 0), no drive, no viscous friction: the motor crosses the gap at w0,
    # meets a spring-damper for part of a period, leaves at the first zero of the contact force
    J, c, d, bg, w0 = 1e-3, 1e4, 2.0, 1e-3, 1.0
    m = load_component("lib:backlash")
    sim = Hybrid(m, inputs=[(0.0, lambda t: [0.0, 0.0, 0.0])], overrides={"b_m": 0.0},
                 starts={"w_m": w0}).run(8e-3)
    (t_c,) = sim.fired("close_fwd")
    (t_o,) = sim.fired("open_fwd")
    assert t_c == pytest.approx(bg / w0, abs=1e-15)
    s, wn = d / (2 * J), math.sqrt(c / J)
    wd = math.sqrt(wn**2 - s**2)
    s_o = (math.pi - math.atan(d * wd / (c - d * s))) / wd  # c x + d x' = 0, x = w0/wd e^{-s t} sin(wd t)
    assert t_o - t_c == pytest.approx(s_o, abs=1e-12)
    x_o = w0 / wd * math.exp(-s * s_o) * math.sin(wd * s_o)
    v_o = w0 * math.exp(-s * s_o) * (math.cos(wd * s_o) - s / wd * math.sin(wd * s_o))
    assert x_o > 0 and v_o < 0  # it leaves still inside the contact zone, receding: the force stopped pushing
    assert sim.state("w_m", t_o + 1e-5)[0] == pytest.approx(v_o, rel=1e-9)
    # in contact the torque is the spring-damper's, outside exactly 0
    mid = t_c + s_o / 2
    xm = w0 / wd * math.exp(-s * (mid - t_c)) * math.sin(wd * (mid - t_c))
    vm = w0 * math.exp(-s * (mid - t_c)) * (math.cos(wd * (mid - t_c)) - s / wd * math.sin(wd * (mid - t_c)))
    assert sim.output("tau", mid)[0] == pytest.approx(c * xm + d * vm, rel=1e-9)
    (t_b,) = sim.fired("close_bwd")  # it crosses the gap back and meets the other side
    assert t_b == pytest.approx(t_o + (bg + x_o + bg) / -v_o, abs=1e-12)
    free = np.concatenate([np.linspace(0, t_c, 20, endpoint=False)[1:], np.linspace(t_o, t_b, 20)[1:-1]])
    assert np.all(sim.output("tau", free) == 0.0) and np.all(sim.discrete("contact", free) == 0.0)
    assert np.all(sim.output("tau", np.linspace(t_b, 8e-3, 20)[1:]) <= 0)  # the backward contact pushes back


def test_end_stop_restitution_then_rest():
    # free flight at constant speed (b = 0, tau = 0) between stops 2 rad apart: impact k at speed e^(k-1) w0;
    # a rebound at most w_rest ends at rest on the stop
    e, w0, w_rest = 0.5, 2.0, 0.05
    m = load_component("lib:end_stop")
    sim = Hybrid(m, inputs=[(0.0, lambda t: [0.0])], overrides={"b": 0.0, "e": e, "w_rest": w_rest},
                 starts={"w": w0}).run(100.0)
    t_ref = [1.0 / w0]
    for k in range(1, 6):
        t_ref.append(t_ref[-1] + 2.0 / (e**k * w0))
    hits = np.sort(np.concatenate([sim.fired("bounce_max"), sim.fired("bounce_min"), sim.fired("rest_min"),
                                   sim.fired("rest_max")]))
    assert np.max(np.abs(hits - t_ref)) < 1e-9
    assert len(sim.fired("bounce_max")) == 3 and len(sim.fired("bounce_min")) == 2
    (t_rest,) = sim.fired("rest_min")  # the 6th impact, at q_min: rebound e^6 w0 = 0.031 < w_rest
    assert t_rest == pytest.approx(t_ref[5], abs=1e-9)
    after = np.linspace(t_rest + 1e-6, 100.0, 30)
    assert np.all(sim.state("q", after) == -1.0) and np.all(sim.state("w", after) == 0.0)
    assert np.all(sim.discrete("rest", after) == -1.0)
    t = between(hits, np.linspace(0, t_rest, 500))
    assert np.all(np.abs(sim.state("q", t)) <= 1.0)


def test_end_stop_inelastic_rests_while_pushed_and_leaves_when_pulled():
    J, tau = 0.05, 1.0
    m = load_component("lib:end_stop")
    sim = Hybrid(m, inputs=[(0.0, lambda t: [tau]), (1.0, lambda t: [-tau])], overrides={"b": 0.0, "e": 0.0}
                 ).run(3.0)
    (t_hit,) = sim.fired("rest_max")
    assert t_hit == pytest.approx(math.sqrt(2 * J * 1.0 / tau), abs=1e-10)  # q = tau t^2/(2 J) reaches 1
    resting = np.linspace(t_hit + 1e-6, 1.0 - 1e-6, 20)
    assert np.all(sim.state("q", resting) == 1.0) and np.all(sim.state("w", resting) == 0.0)
    assert np.all(sim.output("tau_s", resting) == tau)  # the stop takes the drive torque
    assert list(sim.fired("leave")) == [1.0]  # pulled away at t = 1
    (t_low,) = sim.fired("rest_min")  # q = 1 - tau (t - 1)^2/(2 J) reaches -1, pulled into it: rests there
    assert t_low == pytest.approx(1.0 + math.sqrt(4 * J / tau), abs=1e-10)
    assert sim.state("q", 0.9 * 1.0 + 0.1 * t_low)[0] == pytest.approx(1 - tau * (0.1 * (t_low - 1)) ** 2 / (2 * J),
                                                                          abs=1e-12)
    assert np.all(sim.state("q", np.linspace(t_low + 1e-6, 3.0, 10)) == -1.0)
    assert not sim.fired("bounce_max").size and not sim.fired("bounce_min").size


def test_relief_valve_hysteresis_opens_at_p_open_and_reseats_at_p_close():
    # a triangular pressure 0 -> 200 bar -> 0 over 2 T: opens at 150 bar rising, reseats at 130 bar falling
    T, P_max, p_open, p_close, x_max, T_v = 0.1, 200e5, 150e5, 130e5, 2e-3, 2e-3
    m = load_component("lib:relief_valve_hysteresis")
    sim = Hybrid(m, inputs=[(0.0, lambda t: [P_max * t / T]), (T, lambda t: [P_max * (2 - t / T)])]).run(2 * T)
    (t_o,) = sim.fired("pop_open")
    (t_c,) = sim.fired("reseat")
    assert t_o == pytest.approx(T * p_open / P_max, abs=1e-13)
    assert t_c == pytest.approx(T * (2 - p_close / P_max), abs=1e-13)
    # one indicator whose threshold is the current state's: no event at the other threshold's crossings
    assert [t for t, _ in sim.events] == [0.0, t_o, t_c]
    x_c = x_max * (1 - math.exp(-(t_c - t_o) / T_v))
    for t in (0.5 * t_o, t_o + 1e-3, t_o + 0.02, t_c - 1e-4, t_c + 1e-3, 2 * T):
        x = (0.0 if t < t_o else x_max * (1 - math.exp(-(t - t_o) / T_v)) if t < t_c
             else x_c * math.exp(-(t - t_c) / T_v))
        assert sim.state("x", t)[0] == pytest.approx(x, rel=1e-9, abs=1e-12 * x_max), t
    P = sim.u_at(t_o + 0.02)[0]
    q_ref = 0.61 * 1.5e-2 * sim.state("x", t_o + 0.02)[0] * math.sqrt(2 * P / 870.0)
    assert sim.output("Q", t_o + 0.02)[0] == pytest.approx(q_ref, rel=1e-6)  # |P| smooth only below dp_eps


def test_limiter_is_an_exact_clamp_with_events_at_the_corners():
    m = load_component("lib:limiter")
    sim = Hybrid(m, inputs=[(0.0, lambda t: [2 * math.sin(t)])]).run(10.0, max_step=0.05)
    # 2 sin t crosses +-1 at pi/6 (up), 5 pi/6 (down), 7 pi/6, 11 pi/6, ... (+ 2 pi k)
    pi = math.pi
    for name, ref in (("to_max", [pi / 6, pi / 6 + 2 * pi]), ("to_min", [7 * pi / 6, 7 * pi / 6 + 2 * pi]),
                      ("release", [5 * pi / 6, 11 * pi / 6, 5 * pi / 6 + 2 * pi])):
        assert len(sim.fired(name)) == len(ref) and np.max(np.abs(sim.fired(name) - ref)) < 1e-12, name
    t = between(np.concatenate([sim.fired(n) for n in ("to_max", "to_min", "release")]), np.linspace(0, 10, 1001))
    assert np.array_equal(sim.output("y", t), np.clip(2 * np.sin(t), -1.0, 1.0))  # exactly
    # an input outside the limits at the start: the initial event iteration sets the mode
    sim = Hybrid(m, inputs=[(0.0, lambda t: [-3.0])]).run(1.0)
    assert sim.events[0] == (0.0, [["to_min"]]) and np.all(sim.output("y", [0.0, 0.5, 1.0]) == -1.0)


# ============================================================================= the FMUs (fmugen's runtime)
def generated_c_has_events() -> bool:
    """Whether the C generator emits the event functions (the runtime's part of this feature)."""
    try:
        from fmugen.codegen.c_code import generate_c

        return "indicators" in generate_c(load_component(BALL)).source
    except Exception:
        return False


needs_events = pytest.mark.skipif(not generated_c_has_events(), reason="the generated C has no events yet")


def bounce_times_from_samples(t, h, v, g=G):
    """The last bounce before each sample, from (h, v) on the free-flight parabola: the ball left the
    ground at speed v_b = sqrt(v^2 + 2 g h), at t_b = t - (v_b - v)/g."""
    v_b = np.sqrt(v**2 + 2 * g * h)
    return t - (v_b - v) / g


@pytest.fixture(scope="module")
def ball_fmu(tmp_path_factory):
    path = tmp_path_factory.mktemp("ball") / "bouncing_ball.fmu"
    fmugen.build_fmu(load_component(BALL), path, fmi_type="both")
    return path


def _check_bounces(res, tol, min_bounces):
    t_ref = ball_bounce_times(12)
    after = res["time"] > t_ref[0] + 1e-6  # samples after the first bounce
    t_b = bounce_times_from_samples(res["time"][after], res["h"][after], res["v"][after])
    nearest = np.argmin(np.abs(t_b[:, None] - t_ref[None, :]), axis=1)
    assert np.max(np.abs(t_b - t_ref[nearest])) < tol
    assert len(set(nearest)) >= min_bounces
    assert np.all(res["h"] > -1e-9)


@needs_events
@pytest.mark.parametrize("method", [1, 2, 3])
def test_bouncing_ball_fmu_co_simulation_bounce_times(ball_fmu, method):
    from fmpy import simulate_fmu

    start = {"solver.method": method}
    if method == 3:
        start["solver.fixed_step"] = 1e-3
    res = simulate_fmu(str(ball_fmu), fmi_type="CoSimulation", stop_time=2.5, output_interval=0.1,
                       start_values=start, output=["h", "v"])
    # every sample between bounces (0.1 s apart) dates its bounce to 1e-9 s: 8 of the first 11 seen
    _check_bounces(res, 1e-9, 8)
    res = simulate_fmu(str(ball_fmu), fmi_type="CoSimulation", stop_time=2.48, output_interval=0.005,
                       start_values=start, output=["h", "v"])
    _check_bounces(res, 1e-9, 10)  # all of the first 10


@needs_events
def test_bouncing_ball_fmu_model_exchange(ball_fmu):
    from fmpy import simulate_fmu

    # fmpy's CVode locates the crossings (the FMU gives the indicators and does the event iteration)
    res = simulate_fmu(str(ball_fmu), fmi_type="ModelExchange", stop_time=2.5, output_interval=0.1,
                       relative_tolerance=1e-10, output=["h", "v"])
    _check_bounces(res, 1e-7, 8)


@needs_events
def test_stick_slip_fmu_co_simulation(tmp_path):
    from fmpy import simulate_fmu

    path = tmp_path / "stick_slip.fmu"
    fmugen.build_fmu(load_component("lib:stick_slip"), path, fmi_type="both")
    for method in (1, 2):
        res = simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=100.0, output_interval=1.0,
                           start_values={"tau": 2.5, "solver.method": method}, output=["phi", "w", "tau_f"])
        assert np.all(res["phi"] == 0.0) and np.all(res["w"] == 0.0) and np.all(res["tau_f"] == 2.5)
        res = simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=10.0, output_interval=0.1,
                           start_values={"tau": 3.5, "solver.method": method, "solver.rtol": 1e-10,
                                         "solver.atol": 1e-10}, output=["w"])
        t = res["time"][1:]
        assert np.max(np.abs(res["w"][1:] / sliding(3.5, t) - 1)) < 1e-7
