"""Sampled-data control of the split hydraulic joint (examples/scenes/single_joint_sampled.toml): the
analog amplifier replaced by lib:discrete_pi at 1 kHz.

* ctrl.u is piecewise constant and changes only at multiples of 1 ms (also at macro steps of 0.25 ms);
* the co-simulated closed loop for a small step (1 mrad) equals python-control's discrete-time
  simulation of the ZOH-discretised linearised plant (fmugen's linearisation of the plant part,
  control.c2d(..., "zoh")) with the same controller, to 1 % of the step;
* the sample period at which the loop loses stability, bisected by co-simulation with ctrl.T_s set,
  is the one the discrete-time eigenvalues predict (within 5 %).
"""
import dataclasses

import numpy as np
import pytest

import fmugen
from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.control import scene_model
from fmugen.control.linearize import linear_model
from fmugen.cosim import run

SCENE = "examples/scenes/single_joint_sampled.toml"
T_S, STEP = 1e-3, 1e-3  # the controller's period, the path's step [rad]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    sc = fmugen.load_scene(SCENE)
    return sc, sc.build(tmp_path_factory.mktemp("sampled"))


@pytest.fixture(scope="module")
def plant(built):
    import control

    sc, _ = built
    lm = linear_model(scene_model(sc, without=["ctrl", "path"]), outputs=["joint.theta"], inputs=["driver.u"])
    return control.ss(lm.A, lm.B, lm.C, lm.D)


def gains(sc):
    p = {v.name: v.start for v in sc.base_models["ctrl"].parameters}
    assert p["method"] == 0 and p["delay"] == 0  # forward Euler, no computation delay
    return p["K_p"], p["K_i"]


def closed_loop(P, T, Kp, Ki):
    """The ZOH plant with the forward-Euler PI u_k = K_p e_k + K_i I_k, I_(k+1) = I_k + T e_k."""
    import control

    C = control.ss([[1.0]], [[T]], [[Ki]], [[Kp]], T)
    return control.feedback(control.c2d(P, T, "zoh") * C, 1)


def test_ctrl_u_is_held_between_sample_instants(built):
    _, b = built
    for scheme, ex, H in (("gauss-seidel", "hold", 1e-3), ("jacobi", "linear", 2.5e-4)):
        r = run(b.system, scheme=scheme, extrapolation=ex, step=H)
        assert r.summary.failure is None
        u, t = r["ctrl.u"], r.time
        jumps = t[1:][np.abs(np.diff(u)) > 0]
        assert len(jumps) > 500, len(jumps)  # it moves ...
        assert np.all(np.abs(jumps / T_S - np.round(jumps / T_S)) < 1e-9), jumps  # ... only at k T_s
        if H < T_S:  # between instants the recorded value is exactly the one of the last instant
            k = np.floor(t / T_S + 1e-9).astype(int)
            at = {kk: uu for kk, uu, tt in zip(k, u, t) if abs(tt - kk * T_S) < 1e-12}
            assert all(uu == at[kk] for kk, uu in zip(k, u))


def test_closed_loop_equals_python_control_discrete_simulation(built, plant):
    import control

    sc, b = built
    Kp, Ki = gains(sc)
    N = int(round(sc.spec.stop / T_S)) + 1
    t = np.arange(N) * T_S
    path = ModelEvaluator(sc.base_models["path"])
    r = np.array([path.g(tk, np.zeros(0), np.zeros(0))[0] for tk in t])  # the reference at the instants
    assert abs(r[-1] - STEP) < 1e-15
    theta = control.forced_response(closed_loop(plant, T_S, Kp, Ki), t, r).outputs
    worst = {}
    for scheme, ex, H in (("gauss-seidel", "hold", 1e-3), ("jacobi", "linear", 2.5e-4)):
        res = run(b.system, scheme=scheme, extrapolation=ex, step=H)
        k = np.rint(res.time / T_S).astype(int)
        on = np.abs(res.time - k * T_S) < 1e-12
        worst[scheme] = float(np.abs(res["joint.theta"][on] - np.asarray(theta)[k[on]]).max() / STEP)
    print("closed loop against python-control, max |dtheta| / step:", worst)
    assert worst["gauss-seidel"] < 0.01 and worst["jacobi"] < 0.01, worst


def predicted_limit(P, Kp, Ki):
    """The sample period where the discrete closed loop's spectral radius reaches 1."""
    from scipy.optimize import brentq

    rho = lambda T: np.abs(np.linalg.eigvals(closed_loop(P, T, Kp, Ki).A)).max() - 1  # noqa: E731
    assert rho(0.001) < 0 and rho(0.2) < 0 and rho(0.5) > 0
    return brentq(rho, 0.2, 0.5, xtol=1e-7)


def grows(b, T):
    """Co-simulate 30 sample periods with ctrl.T_s = T (macro step 1 ms): does the held output grow?"""
    units = tuple(dataclasses.replace(u, start_values={**u.start_values, "ctrl.T_s": T}) if u.name == "chain"
                  else u for u in b.system.units)
    system = dataclasses.replace(b.system, units=units)
    # a slow sampled loop's jumps are no coupling divergence: the monitor is off, growth is judged here
    r = run(system, step=1e-3, stop=30 * T, detect_divergence=False, estimate=False)
    k = np.rint(r.time / T).astype(int)
    us = r["ctrl.u"][np.abs(r.time - k * T) < 1e-9]
    n = len(us)
    assert n == 31, n
    mid, last = np.abs(np.diff(us[n // 3:2 * n // 3])).max(), np.abs(np.diff(us[2 * n // 3:])).max()
    return last > mid or np.abs(us).max() >= 10.0 * (1 - 1e-12)  # growing, or driven to the limit


def test_stability_limit_of_the_sample_period(built, plant):
    sc, b = built
    Kp, Ki = gains(sc)
    T_pred = predicted_limit(plant, Kp, Ki)
    lo, hi = 200, 500  # [ms]: the macro step (1 ms) divides the period
    assert not grows(b, lo * 1e-3) and grows(b, hi * 1e-3)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if grows(b, mid * 1e-3) else (mid, hi)
    T_sim = 0.5 * (lo + hi) * 1e-3
    print(f"stability limit of T_s: predicted {T_pred * 1e3:.2f} ms, bisected by co-simulation {lo}..{hi} ms")
    assert abs(T_sim / T_pred - 1) < 0.05
