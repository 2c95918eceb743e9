"""Issue 27: algebraic loops of direct-feedthrough FMUs, found from their ModelStructure.

Third-party gains (``tests/third_party_fmu.py``: ``y = a u + b + e t`` when read; C written by the test), wired
in a cycle u1 = y2, u2 = y1, have at every instant the fixed point
u1 = (c (b + e t) + d) / (1 - a c)  -- closed form, independent of the master.

* Newton solves it at t0 and at every communication point (to 1e-12 at coupling_tol 1e-13);
* Jacobi and Gauss-Seidel, which would run the loop as a delay of one macro step, refuse it in one line that
  names the FMUs, the couplings around the loop and the scheme that solves it (two and three FMUs);
* a loop of gain 1 (y = u, u = y) is refused as singular, under Newton and fixed-point iteration; a loop
  whose gain reaches 1 during the run stops there with a ``singular`` failure, not a NaN;
* a loop broken by an FMU whose output does not depend on its input (``dependencies=""``, a lag) is no
  algebraic loop and runs under every scheme, against the lag's closed form; an output without
  ``dependencies`` depends on every input (FMI 2.0 section 2.2.8), so the same lag declared that way closes
  the loop;
* a feedthrough chain of four gains without a loop is consistent at t0 (the old two passes left the last
  gain's output at 7 where the composition is 63).
"""
import math

import numpy as np
import pytest

from fmugen.cosim import run
from fmugen.cosim.errors import CosimError
from fmugen.cosim.master import Master
from fmugen.cosim.system import Coupling, CosimSystem, Recorded, Unit

from third_party_fmu import build_gain

A, B, E, C, D = 0.5, 1.0, 2.0, -2.0, 3.0
H, STOP = 0.01, 0.1


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("loops")
    return {"gain": build_gain(d, "gain"), "gain_all": build_gain(d, "gain_all", dependencies=None),
            "lag": build_gain(d, "lag", dependencies="", lag=True),
            "lag_all": build_gain(d, "lag_all", dependencies=None, lag=True)}


def ring(paths, params, name="ring"):
    """FMUs 0..n-1 in a cycle: unit i's u is unit i-1's y."""
    n = len(paths)
    names = [f"G{i + 1}" for i in range(n)]
    units = tuple(Unit(names[i], paths[i], "cs", params[i]) for i in range(n))
    couplings = tuple(Coupling((names[i - 1], "y"), (names[i], "u")) for i in range(n))
    recorded = tuple(Recorded(f"{nm}.y", nm, "y") for nm in names)
    return CosimSystem(name, units, couplings, recorded, 0.0, STOP, H, order=tuple(names))


def closed_form(t):
    u1 = (C * (B + E * t) + D) / (1 - A * C)
    return A * u1 + B + E * t, u1  # y1 = u2, y2 = u1


def test_newton_solves_the_loop_at_t0_and_every_communication_point(fmus):
    s = ring([fmus["gain"]] * 2, [{"a": A, "b": B, "e": E}, {"a": C, "b": D}])
    with Master(s, "newton", "linear") as m:
        assert [[m.coupling_labels[j] for j in lp] for lp in m.loops] == [["G2.y -> G1.u", "G1.y -> G2.u"]]
    r = run(s, scheme="newton", extrapolation="linear", coupling_tol=1e-13)
    assert r.ok, r.summary
    y1, y2 = closed_form(r.time)
    assert r.time[0] == 0.0 and len(r.time) == round(STOP / H) + 1
    assert np.max(np.abs(r["G1.y"] - y1) / np.maximum(1, np.abs(y1))) < 1e-12
    assert np.max(np.abs(r["G2.y"] - y2) / np.maximum(1, np.abs(y2))) < 1e-12


@pytest.mark.parametrize("scheme", ["jacobi", "gauss-seidel"])
def test_jacobi_and_gauss_seidel_refuse_the_loop_naming_it(fmus, scheme):
    for n in (2, 3):
        s = ring([fmus["gain"]] * n, [{"a": A, "b": B}] + [{"a": C, "b": D}] * (n - 1))
        with pytest.raises(CosimError) as info:
            run(s, scheme=scheme, extrapolation="hold")
        msg = str(info.value)
        names = ", ".join(f"'G{i + 1}'" for i in range(n))
        assert "\n" not in msg and msg.startswith("ring: algebraic loop through FMUs "), msg
        for i in range(n):
            assert f"G{(i - 1) % n + 1}.y -> G{i + 1}.u" in msg, msg
        assert f"FMUs {names}" in msg or all(f"'G{i + 1}'" in msg for i in range(n)), msg
        assert f"{scheme} would run the loop as a delay" in msg and "use scheme newton" in msg, msg


@pytest.mark.parametrize("scheme", ["newton", "iterative"])
def test_a_loop_of_gain_one_is_reported_singular(fmus, scheme):
    for b in (0.0, 1.0):  # every value a solution, or none
        s = ring([fmus["gain"]] * 2, [{"a": 1.0, "b": b}, {"a": 1.0}])
        with pytest.raises(CosimError) as info:
            run(s, scheme=scheme, extrapolation="linear")
        msg = str(info.value)
        assert "\n" not in msg and "is singular at the start time" in msg and "G1.y -> G2.u" in msg, msg
        assert "a loop gain of 1" in msg


def test_a_loop_broken_by_a_state_runs_as_before(fmus):
    """u_lag = y_gain, u_gain = y_lag: T y' = a y + b - y, y(t) = y_inf (1 - exp(-(1 - a) t / T))."""
    T, a, b = 0.1, 0.5, 1.0
    s = ring([fmus["gain"], fmus["lag"]], [{"a": a, "b": b}, {"T": T}])
    with Master(s, "jacobi", "hold") as m:
        assert m.loops == []
    exact = lambda t: b / (1 - a) * (1 - np.exp(-(1 - a) * t / T))  # noqa: E731
    errors = {}
    for scheme, ext in (("jacobi", "hold"), ("gauss-seidel", "linear"), ("newton", "linear")):
        r = run(s, scheme=scheme, extrapolation=ext, stop=0.3, estimate=False)
        assert r.ok, (scheme, r.summary)
        errors[scheme] = float(np.max(np.abs(r["G2.y"] - exact(r.time))))
    # first order held (5.4e-2), second order with the line (Gauss-Seidel 4.5e-3, Newton 1.5e-4) at 10 ms
    assert errors["jacobi"] < 0.1 and errors["gauss-seidel"] < 1e-2 and errors["newton"] < 5e-4, errors
    # the same lag declaring no dependencies attribute: FMI 2.0 says its output depends on its input, a loop
    s_all = ring([fmus["gain"], fmus["lag_all"]], [{"a": a, "b": b}, {"T": T}])
    with pytest.raises(CosimError, match="algebraic loop through FMUs 'G2', 'G1'|algebraic loop through FMUs 'G1'"):
        run(s_all, scheme="jacobi", extrapolation="hold")
    assert run(s_all, scheme="newton", extrapolation="linear", stop=0.3, estimate=False).ok


def test_newton_meets_the_loop_where_the_initial_guess_is_far(fmus):
    """Start values far from the fixed point: t0's Newton (set/get, no step) moves them there."""
    s = ring([fmus["gain_all"]] * 2, [{"a": A, "b": B, "u": 1e3}, {"a": C, "b": D, "u": -7e2}])
    r = run(s, scheme="newton", extrapolation="linear", coupling_tol=1e-13, stop=2 * H)
    assert r.ok, r.summary
    y1, y2 = closed_form(0.0)
    assert math.isclose(r["G1.y"][0], y1, rel_tol=1e-12) and math.isclose(r["G2.y"][0], y2, rel_tol=1e-12)


def test_a_loop_whose_gain_reaches_one_stops_singular(tmp_path):
    """G1's gain a = 0.5 + 5 t meets G2's c = 1 at t = 0.1 (a c = 1 with b != 0: no solution there)."""
    rising = build_gain(tmp_path, "rising", cflags=["-DGAIN_RATE=5.0"])
    s = ring([rising, build_gain(tmp_path, "plain")], [{"a": 0.5, "b": 1.0}, {"a": 1.0}])
    r = run(s, scheme="newton", extrapolation="linear", stop=0.2, estimate=False)
    f = r.summary.failure
    assert r.summary.status == "failed" and f is not None and f.cause == "singular", r.summary
    assert "is singular" in f.message and "a loop gain of 1" in f.message and "G1.y -> G2.u" in f.coupling
    assert 0.085 <= f.time < 0.1 + 1e-12 and np.all(np.isfinite(r.values)), (f.time, r.values[-1])
    # up to there the run met the loop: u1 = b / (1 - a(t))
    t = r.time
    assert np.max(np.abs(r["G2.y"] - 1.0 / (1 - (0.5 + 5 * t)))) < 1e-6 * np.max(np.abs(r["G2.y"]))


def test_a_loop_through_a_model_exchange_fmu_is_refused_under_every_scheme():
    """The ME block evaluates ME couplings once per right-hand side: a loop through it is not solved
    (loops.check_scheme on the master's interface tables)."""
    from types import SimpleNamespace as NS

    from fmugen.cosim.loops import check_scheme

    for scheme in ("newton", "iterative", "jacobi"):
        m = NS(system=NS(name="mixed"), scheme=scheme, loops=[[0, 1]], u_owner=np.array([0, 1]),
               u_src_unit=np.array([1, 0]), units=[NS(name="cs", kind="cs"), NS(name="me", kind="me")],
               coupling_labels=("me.y -> cs.u", "cs.y -> me.u"))
        with pytest.raises(CosimError, match=r"^mixed: algebraic loop through FMUs 'me', 'cs' \(me.y -> cs.u, "
                                             r"cs.y -> me.u\): Model-Exchange FMU 'me' is in it"):
            check_scheme(m)


def test_a_long_feedthrough_chain_is_consistent_at_t0(fmus):
    """G1 -> G2 -> G3 -> G4, gains without a loop: the values at t0 are the composition (two passes of
    set/get carried a value over one coupling only: G4 read its input before G2's output had reached G3)."""
    names = ["G1", "G2", "G3", "G4"]
    units = (Unit("G1", fmus["gain"], "cs", {"a": 2.0, "b": 1.0, "u": 3.0}),) + tuple(
        Unit(n, fmus["gain"], "cs", {"a": 2.0, "b": 1.0}) for n in names[1:])
    s = CosimSystem("chain", units, tuple(Coupling((a, "y"), (b, "u")) for a, b in zip(names, names[1:])),
                    tuple(Recorded(f"{n}.y", n, "y") for n in names), 0.0, STOP, H)
    with Master(s, "jacobi", "hold") as m:
        assert m.loops == [] and m.init_passes == 3  # three coupled inputs in a row
    r = run(s, scheme="jacobi", extrapolation="hold", estimate=False)
    y = 3.0
    for n in names:
        y = 2 * y + 1
        assert r[n + ".y"][0] == y, (n, r[n + ".y"][0], y)
