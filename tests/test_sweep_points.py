"""Sweep points and metrics: grids, seeded samples, the distribution parser (never evaluated), metrics
against closed forms.  No cluster here (tests/test_sweep_dask.py runs sweeps)."""
import math

import numpy as np
import pytest

from fmugen.sweep import SweepError, make_points, parse_distribution, point_key
from fmugen.sweep.metrics import compute, parse_metrics, settling_time
from fmugen.sweep.points import parse_grid, parse_samples


def test_grid_is_the_cartesian_product_first_name_slowest():
    pts = make_points(parse_grid(["joint.J=1,2,4", "amp.K_a=10,2e1"]))
    assert pts == [{"joint.J": a, "amp.K_a": b} for a in (1.0, 2.0, 4.0) for b in (10.0, 20.0)]


def test_samples_are_numpys_draws_for_the_seed_and_reproducible():
    spec = parse_samples(["actuator.beta_e=normal(1.6e9, 5e7)", "joint.J=uniform(1,3)", "amp.K_a=lognormal(2.7,0.1)"])
    a = make_points(samples=spec, n=50, seed=7)
    b = make_points(samples=spec, n=50, seed=7)
    assert a == b
    assert make_points(samples=spec, n=50, seed=8) != a
    # the same draws from numpy directly: one generator, column by column in the order given
    rng = np.random.default_rng(7)
    beta, J, K = rng.normal(1.6e9, 5e7, 50), rng.uniform(1, 3, 50), rng.lognormal(2.7, 0.1, 50)
    assert [p["actuator.beta_e"] for p in a] == list(beta)
    assert [p["joint.J"] for p in a] == list(J)
    assert [p["amp.K_a"] for p in a] == list(K)
    big = make_points(samples={"x.y": parse_distribution("normal(10, 2)")}, n=20000, seed=1)
    v = np.array([p["x.y"] for p in big])
    assert abs(v.mean() - 10) < 4 * 2 / math.sqrt(len(v)) and abs(v.std() - 2) < 0.05


def test_grid_and_samples_together_give_every_sample_at_every_grid_point():
    pts = make_points({"joint.J": (1.0, 2.0)}, parse_samples(["amp.K_a=uniform(5,6)"]), n=3, seed=0)
    assert len(pts) == 6 and [p["joint.J"] for p in pts] == [1.0] * 3 + [2.0] * 3
    assert [p["amp.K_a"] for p in pts[:3]] == [p["amp.K_a"] for p in pts[3:]]


@pytest.mark.parametrize("text", [
    "__import__('os').system('echo owned')",
    "normal(1, __import__('os'))",
    "normal(1e9, 5e7); import os",
    "eval('1')",
    "normal(1,2)(3)",
    "normal(1, 2) or exit()",
    "normal(1.0.0, 2)",
    "normal(1, 0x10)",
    "normal(1, 2, 3)",
    "gamma(1, 2)",
    "normal(nan, 1)",
    "normal(1, inf)",
    "normal(1, -2)",
    "uniform(3, 1)",
    "lognormal(0, 0)",
    "triangular(0, 5, 1)",
    "",
])
def test_the_distribution_parser_refuses_code_and_nonsense(text):
    with pytest.raises(SweepError) as e:
        parse_samples([f"actuator.beta_e={text}"])
    assert "actuator.beta_e" in str(e.value)


def test_the_distribution_parser_reads_numbers_only():
    d = parse_distribution(" normal( 1.6e9 , 5E7 ) ")
    assert (d.kind, d.args) == ("normal", (1.6e9, 5e7))
    assert parse_distribution("triangular(-1, 0, .5)").args == (-1.0, 0.0, 0.5)


@pytest.mark.parametrize("items,what", [
    (["joint.J=1,x"], "not a number"),
    (["joint.J=1,,2"], "comma-separated"),
    (["joint.J"], "NAME="),
    (["J=1,2"], "not a scene parameter name"),
    (["joint.J=1", "joint.J=2"], "twice"),
    (["joint.J=1e999"], "finite"),
])
def test_bad_grids_are_refused_by_name(items, what):
    with pytest.raises(SweepError, match=what):
        parse_grid(items)


def test_sampling_needs_n_and_a_seed():
    s = parse_samples(["joint.J=uniform(1,2)"])
    with pytest.raises(SweepError, match="--seed"):
        make_points(samples=s, n=3)
    with pytest.raises(SweepError, match="-n"):
        make_points(samples=s, n=0, seed=1)
    with pytest.raises(SweepError, match="--grid"):
        make_points()


def test_point_key_is_the_values_not_their_order():
    assert point_key({"a.b": 1.0, "c.d": 2.0}) == point_key({"c.d": 2.0, "a.b": 1.0})
    assert point_key({"a.b": 1.0}) != point_key({"a.b": 1.0 + 2.0 ** -52})


def test_settling_time_of_a_first_order_step_is_tau_ln50():
    tau, dt = 0.1, 1e-4
    t = np.arange(0, 1 + dt / 2, dt)
    y = 1 - np.exp(-t / tau)
    # band 2 % of the final change y(1) - y(0); exact crossing exp(-t/tau) = 0.02 y(1) + exp(-1/tau)
    t_exact = -tau * math.log(0.02 * y[-1] + math.exp(-1 / tau))
    assert abs(settling_time(t, y, 0.02) - t_exact) <= dt
    assert settling_time(t, np.full_like(t, 3.0)) == 0.0


def test_peak_final_error_of_a_damped_oscillation():
    t = np.linspace(0, 2, 2001)
    zeta, wn = 0.2, 20.0
    wd = wn * math.sqrt(1 - zeta ** 2)
    y = 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta ** 2) * np.sin(wd * t))
    vals = np.column_stack([y, -y])
    ref = vals + np.array([1e-3, 0.0])
    m = compute(t, vals, ("a.y", "b.y"), parse_metrics(["final,peak", "a.y:error"], ("a.y", "b.y")), reference=ref)
    overshoot = math.exp(-zeta * math.pi / math.sqrt(1 - zeta ** 2))  # closed form of the first peak
    assert abs(m["a.y:peak"] - (1 + overshoot)) < 1e-4
    assert m["b.y:peak"] == -m["a.y:peak"]  # signed
    assert m["a.y:final"] == y[-1]
    assert m["a.y:error"] == pytest.approx(1e-3, rel=1e-9)
    assert set(m) == {"a.y:final", "b.y:final", "a.y:peak", "b.y:peak", "a.y:error"}


def test_metrics_names_are_checked():
    with pytest.raises(SweepError, match="unknown metric"):
        parse_metrics(["fianl"], ("a.y",))
    with pytest.raises(SweepError, match="not recorded"):
        parse_metrics(["x.z:final"], ("a.y",))


def test_progress_on_a_terminal_counts_done_failed_and_gives_an_eta():
    import io

    from fmugen.sweep.execute import Progress

    class Tty(io.StringIO):
        def isatty(self):
            return True

    s = Tty()
    p = Progress(total=10, done=2, stream=s)
    p.t0 -= 2.0  # two seconds in
    p.update({"status": "ok"})
    p.update({"status": "failed"})
    last = s.getvalue().split("\r")[-1]
    # 2 runs in ~2 s: 1 run/s, 6 points left
    assert "4/10 done (1 failed)" in last and "ETA 6 s" in last


def test_grid_spacings_are_numpys():
    g = parse_grid(["joint.J=linspace(1, 4, 7)", "actuator.beta_e=geomspace(1e8,1e10,5)"])
    assert g["joint.J"] == tuple(np.linspace(1, 4, 7))
    assert g["actuator.beta_e"] == tuple(np.geomspace(1e8, 1e10, 5))
    for bad, what in (("linspace(1,4)", "three numbers"), ("linspace(1,4,2.5)", "whole number"),
                      ("geomspace(0,1,3)", "same sign"), ("linspace(1,4,__import__('os'))", "whole number")):
        with pytest.raises(SweepError, match=what):
            parse_grid([f"joint.J={bad}"])


def test_statistics_over_the_points_that_ran():
    from fmugen.sweep.execute import SweepResult

    rows = [{"status": "ok", "a.y:final": v} for v in (1.0, 2.0, 4.0)] + [{"status": "failed", "a.y:final": math.nan}]
    r = SweepResult(rows, ("x.p",), ("a.y:final",), None, [], None, 4, 0, 0.0)
    ((name, n, mean, std, lo, med, hi),) = r.statistics()
    assert (name, n, lo, med, hi) == ("a.y:final", 3, 1.0, 2.0, 4.0)
    assert mean == pytest.approx(7 / 3) and std == pytest.approx(math.sqrt(((1 - 7/3)**2 + (2 - 7/3)**2 + (4 - 7/3)**2) / 2))
