"""Sample clocks (time events): a sampled state feedback held between sample instants.

The plant x' = -a x + u with a zero-order-held feedback u = -K x(t_k), sampled every T from t = 0: between
instants u is constant, so exactly x_(k+1) = phi x_k + gamma u_k with phi = exp(-a T), gamma = (1 - phi)/a
and u_k = -K x_k.  The CS FMU steps exactly to every sample instant (a communication step of 2.5 T gives
the same samples), fmpy's ME run stops at each (nextEventTime), and the hybrid reference agrees; the held
output changes only at multiples of T.
"""
import numpy as np
import pytest
import sympy as sp

import fmugen
from fmugen.codegen.model import Clock, EventClause, Events, SymbolicModel, Variable

A, K, T, X0 = 2.0, 3.0, 0.1, 1.0


def sampled_model():
    x, a, k, Ts, u, tick = sp.symbols("x a k T_s u_held tick", real=True)
    states = [Variable("x", x, "1", "plant state", start=X0, output=True)]
    params = [Variable("a", a, "1/s", start=A, sign=">0"), Variable("K", k, "1", start=K),
              Variable("T_s", Ts, "s", "sample period", start=T, sign=">0")]
    held = Variable("u_held", u, "1", "the held feedback", start=0.0)
    flag = Variable("tick", tick, "1", "sample instant flag", start=0.0)
    events = Events(discrete=(held, flag), clauses=(EventClause(tick > 0, ((u, -k * x),), "sample"),),
                    clocks=(Clock(Ts, sp.Integer(0), flag),))
    y = Variable("u", sp.Symbol("u_out", real=True), "1", "controller output (held)")
    return SymbolicModel.from_equations("sampled_feedback", states, [], params, [-a * x + u], outputs=[y],
                                        output_exprs=[u], events=events)


def exact(n):
    phi = np.exp(-A * T)
    gam = (1 - phi) / A
    xs = [X0]
    for _ in range(n):
        xs.append((phi - gam * K) * xs[-1])
    return np.array(xs)


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    path = tmp_path_factory.mktemp("clock") / "sampled.fmu"
    fmugen.build_fmu(sampled_model(), path, fmi_type="both")
    return path


@pytest.mark.parametrize("H", [T, 2.5 * T], ids=["H=T", "H=2.5T"])
@pytest.mark.parametrize("method", [1, 2, 3], ids=["dopri5", "rodas3", "rk4"])
def test_cs_samples_at_every_instant(fmu, H, method):
    from fmpy import simulate_fmu

    sv = {"solver.method": method, "solver.rtol": 1e-12, "solver.atol": 1e-12}
    if method == 3:
        sv["solver.fixed_step"] = 1e-4
    r = simulate_fmu(str(fmu), fmi_type="CoSimulation", stop_time=2.0, output_interval=H, start_values=sv,
                     output=["x", "u"])
    k = np.rint(r["time"] / T).astype(int)
    on_grid = np.abs(r["time"] - k * T) < 1e-12
    tol = 1e-9 if method != 3 else 1e-8
    assert np.abs(r["x"][on_grid] - exact(20)[k[on_grid]]).max() < tol
    # the held output at a sample instant is already the new sample: u(t_k) = -K x_k
    assert np.abs(r["u"][on_grid] + K * exact(20)[k[on_grid]]).max() < tol


def test_me_under_fmpy_stops_at_each_sample_instant(fmu):
    from fmpy import simulate_fmu

    r = simulate_fmu(str(fmu), fmi_type="ModelExchange", stop_time=2.0, output_interval=0.025,
                     relative_tolerance=1e-10, output=["x", "u"])
    # the held output changes only at multiples of T
    jumps = r["time"][1:][np.abs(np.diff(r["u"])) > 1e-12]
    assert len(jumps) >= 19 and np.all(np.abs(jumps / T - np.round(jumps / T)) < 1e-9), jumps
    grid = np.abs(r["time"] / T - np.round(r["time"] / T)) < 1e-9
    k = np.rint(r["time"][grid] / T).astype(int)
    last = np.r_[r["time"][grid][1:] != r["time"][grid][:-1], True]  # the row after each event
    assert np.abs(r["x"][grid][last] - exact(20)[k[last]]).max() < 1e-7


def test_the_hybrid_reference_samples_too():
    from fmugen.cosim import solve_reference
    from fmugen.cosim.system import ReferenceProblem

    m = sampled_model()
    t = np.arange(21) * T
    ref = solve_reference(ReferenceProblem(model=m, x0=np.array([X0]), u=np.zeros(0), columns=["x", "u"],
                                           start_time=0.0, stop_time=2.0), times=t, cache=False)
    assert np.abs(ref["x"] - exact(20)).max() < 1e-10
    assert np.abs(ref["u"] + K * exact(20)).max() < 1e-10


def test_the_master_lands_on_every_sample_instant_or_refuses(fmu):
    """A sampled FMU under fmugen's master: a macro step that divides the sample period runs and reads the
    samples at its communication points; one that does not (or an adaptive run) is refused naming the
    FMU and its period."""
    from fmugen.cosim import run
    from fmugen.cosim.errors import CosimError
    from fmugen.cosim.system import CosimSystem, Recorded, Unit

    sysm = CosimSystem("sampled", (Unit("ctrl", fmu, "cs", {"solver.rtol": 1e-12, "solver.atol": 1e-12}),), (),
                       (Recorded("ctrl.x", "ctrl", "x"), Recorded("ctrl.u", "ctrl", "u")), 0.0, 1.0, T / 2)
    r = run(sysm, "jacobi", "hold", step=T / 2)
    k = np.rint(r.time / T).astype(int)
    on = np.abs(r.time - k * T) < 1e-12
    assert np.abs(r["ctrl.x"][on] - exact(10)[k[on]]).max() < 1e-9
    for kw in ({"step": 0.03}, {"step": 0.2}, {"step": T / 2, "adaptive": True}):
        with pytest.raises(CosimError, match="samples every 0.1 s"):
            run(sysm, "jacobi", "hold", **kw)
