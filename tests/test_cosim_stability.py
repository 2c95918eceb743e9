"""Stability limits of the non-iterative schemes on the split rigs, and divergence detection.

Two independent sources for the first unstable macro step H*: the shared
note's figures (LIMITS) and the spectral radius of the exact macro-step map of
the linearised split (each part advanced by its matrix exponential with held
or linearly extrapolated inputs; built here from the models' exact Jacobians,
not from the master).  The master must be stable at 0.8 H* and at 1.25 H* end
with a divergence report naming the coupling, before any value overflows.
"""
import numpy as np
import pytest
import scipy.linalg as sl

from cosim_rigs import LIMITS, _components, split_system
from fmugen.components import assemble, joint_inertia
from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.cosim import run

CASES = [(ps, sch, ex) for ps in ("default", "stiff") for (sch, ex) in LIMITS[ps]]


def _linear_parts(ps):
    comps, links = _components(ps, "step", False)
    chain = assemble("chain", comps, links, outputs=["actuator.tau"])
    Ac, Bc, Cc, _ = ModelEvaluator(chain).jacobians(0.0)
    ins = [v.name for v in chain.inputs]
    Bc = Bc[:, [ins.index("amp.theta"), ins.index("actuator.w")]]
    Aj, Bj, _, _ = ModelEvaluator(joint_inertia(parameter_set=ps, name="joint")).jacobians(0.0)
    return Ac, Bc, Cc, Aj, Bj[:, :1]  # joint states (theta, w) are its outputs


def _discrete(A, B, H):
    """x+ = Phi x + G0 u_n + G1 (u_n - u_{n-1}) for u(t_n + sH) = u_n + s (u_n - u_{n-1})."""
    n, m = B.shape
    M = np.zeros((n + 2 * m, n + 2 * m))
    M[:n, :n], M[:n, n:n + m], M[n:n + m, n + m:] = A * H, B * H, np.eye(m)
    E = sl.expm(M)
    return E[:n, :n], E[:n, n:n + m], E[:n, n + m:]


def spectral_radius(ps, scheme, extrapolation, H):
    Ac, Bc, Cc, Aj, Bj = _linear_parts(ps)
    nc, nj = len(Ac), len(Aj)
    Pc, G0c, G1c = _discrete(Ac, Bc, H)
    Pj, G0j, G1j = _discrete(Aj, Bj, H)
    if (scheme, extrapolation) == ("jacobi", "hold"):
        Z = np.block([[Pc, G0c], [G0j @ Cc, Pj]])
    elif (scheme, extrapolation) == ("jacobi", "linear"):
        n = nc + nj
        Z = np.zeros((2 * n, 2 * n))
        Z[:nc, :nc], Z[:nc, nc:n], Z[:nc, n + nc:] = Pc, G0c + G1c, -G1c
        Z[nc:n, nc:n], Z[nc:n, :nc], Z[nc:n, n:n + nc] = Pj, (G0j + G1j) @ Cc, -G1j @ Cc
        Z[n:, :n] = np.eye(n)
    else:  # Gauss-Seidel, joint first with tau_n held, then the chain with theta, w at t_{n+1} held
        Zj = np.hstack([G0j @ Cc, Pj])
        Z = np.vstack([np.hstack([Pc, np.zeros((nc, nj))]) + G0c @ Zj, Zj])
    return max(abs(np.linalg.eigvals(Z)))


@pytest.mark.parametrize("ps,scheme,ext", CASES)
def test_linear_analysis_brackets_the_notes_limit(ps, scheme, ext):
    H = LIMITS[ps][(scheme, ext)]
    assert spectral_radius(ps, scheme, ext, 0.8 * H) < 1.0
    assert spectral_radius(ps, scheme, ext, 1.25 * H) > 1.0
    # the note's figure is the crossing to within 4 %
    assert spectral_radius(ps, scheme, ext, 0.96 * H) < 1.0 < spectral_radius(ps, scheme, ext, 1.04 * H)


@pytest.mark.parametrize("ps,scheme,ext", CASES)
def test_stable_below_and_divergence_reported_above(ps, scheme, ext):
    H = LIMITS[ps][(scheme, ext)]
    stable = run(split_system(ps, stop=5.0), scheme, ext, step=0.8 * H)
    assert stable.ok, stable.summary
    theta = stable["joint.theta"]
    # the position loop settled on the 0.1 rad step (the reference value)
    assert abs(theta[-1] - 0.1) < 1e-3
    assert np.max(np.abs(theta[-len(theta) // 5:] - 0.1)) < 1e-3

    unstable = run(split_system(ps, stop=5.0), scheme, ext, step=1.25 * H)
    s = unstable.summary
    assert s.status == "failed" and s.failure.cause == "diverged", s
    assert s.failure.coupling in ("chain.actuator.tau -> joint.tau", "joint.theta -> chain.amp.theta",
                                  "joint.w -> chain.actuator.w")
    assert "stability limit" in s.failure.message
    # stopped before overflow, results up to the failure returned and finite
    assert s.failure.time < 5.0
    assert len(unstable.time) == s.macro_steps + 1 and np.all(np.isfinite(unstable.values))
    assert np.max(np.abs(unstable["joint.theta"])) < 10.0


# ---------------------------------------------------------------------------------------------------------
# The limit a scene's build states (fmugen.scene.stability, issue 29) against the master's own runs: the FMUs
# linearised on their own, one held-input Jacobi macro step as the master takes it -- outputs read after the
# step with the inputs still held, so a coupling through direct feedthrough is delayed a step, not exact.

from pathlib import Path  # noqa: E402

import fmugen  # noqa: E402
from fmugen.scene.stability import jacobi_hold_limit, linearise_split  # noqa: E402

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"

# One joint driven by a RobotR3-style axis (P/PI cascade, current-controlled motor with an elastic gear) in
# its own FMU, the joint inertia in another: the motor's gear torque c (phi_m - ratio theta) + d (...) depends
# on the joint's theta, w, the axis FMU's inputs (direct feedthrough; puma_electric's split in small).  The
# motor's regularised Coulomb friction is off (R_v0 = 0): at rest its slope is a damping that any motion
# leaves, so with it the rig is linear only for motor speeds far below w_fric; without it, exactly linear.
ELECTRIC_RIG = """
[scene]
name = "electric_joint_split"
description = "one joint, RobotR3-style axis with elastic gear, and the joint inertia in separate FMUs"
start = 0.0
stop = 1.0
step = 1e-3
tolerance = 1e-10
initial = "given"
record = ["joint.theta", "joint.w", "mot.tau"]
connections = [
  ["path.q_ref", "ctl.q_ref"], ["path.qd_ref", "ctl.qd_ref"], ["mot.phi_m", "ctl.phi_m"], ["mot.w_m", "ctl.w_m"],
  ["ctl.i_ref", "mot.i_ref"], ["joint.theta", "mot.theta"], ["joint.w", "mot.w"], ["mot.tau", "joint.tau"],
]

[instances.path]
type = "ptp_trajectory"
parameters = { q_begin = 0.0, q_end = 0.1, qd_max = 1.0, qdd_max = 10.0, t_start = 0.05 }

[instances]
ctl = { type = "controller", speed_loop = "PI" }
mot = { type = "dc_motor", current_loop = "second_order", elasticity = true, parameters = { R_v0 = 0.0 } }
joint = { type = "joint_inertia" }

[fmus.drive]
members = ["path", "ctl", "mot"]

[fmus.joint]
members = ["joint"]
"""


def _scene(name, tmp_path):
    if name == "electric_joint_split":
        path = tmp_path / "electric_joint_split.toml"
        path.write_text(ELECTRIC_RIG)
        return fmugen.load_scene(path)
    return fmugen.load_scene(SCENES / f"{name}.toml")


def _settled(r) -> float:
    """Motion (deviation from the final value) in the run's last tenth over that in its first half."""
    V = np.asarray(r.values, dtype=float)
    dev = np.abs(V - V[-1])
    n = len(V)
    return float(np.max(dev[-n // 10:].max(axis=0) / np.maximum(dev[: n // 2].max(axis=0), 1e-300)))


@pytest.mark.parametrize("name", ["single_joint_split", "single_joint_split_stiff", "electric_joint_split"])
def test_stated_jacobi_limit_is_bracketed_by_the_masters_runs(name, tmp_path):
    """The build's limit H* (FMU descriptions, summary, SSP) is the analysis', and fmugen's master with
    Jacobi/held inputs settles at 0.9 H* over 10x the scene's horizon and reports a divergence at 1.1 H*."""
    scene = _scene(name, tmp_path)
    built = scene.build(tmp_path / "fmus", progress=lambda *a: None)
    limit = built.jacobi_limit
    assert 0 < limit < 1.0 and limit == jacobi_hold_limit(scene)
    t0, horizon = scene.spec.start, scene.spec.stop - scene.spec.start
    below = run(built.system, "jacobi", "hold", step=0.9 * limit, stop=t0 + 10 * horizon, estimate=False)
    assert below.summary.status == "ok", below.summary
    assert np.all(np.isfinite(below.values)) and _settled(below) < 1e-2
    above = run(built.system, "jacobi", "hold", step=1.1 * limit, stop=t0 + 10 * horizon, estimate=False)
    s = above.summary
    assert s.status == "failed" and s.failure.cause == "diverged", s
    if name == "electric_joint_split":  # the feedthrough coupling, delayed by Jacobi, is the one that goes
        assert s.failure.coupling == "drive.mot.tau -> joint.tau"


def test_split_linearisation_sees_feedthrough_and_couples_to_the_monolithic_jacobian(tmp_path):
    """The FMUs' linearisations coupled instantaneously give the monolithic model's Jacobian (to round-off);
    the electric rig's gear torque feeds through (c ratio^2 on theta), the split hydraulic rig has none."""
    from fmugen.codegen.evaluate import ModelEvaluator

    for name in ("single_joint_split", "electric_joint_split"):
        scene = _scene(name, tmp_path)
        lin = linearise_split(scene)
        m = scene.initial.model
        x0 = np.array([scene.initial.values[v.name] for v in m.states])
        u0 = np.array([v.start if v.start is not None else 0.0 for v in m.inputs])
        A = ModelEvaluator(m).jacobians(scene.spec.start, x0, u0)[0]
        ix = [lin.states.index(v.name) for v in m.states]
        assert np.allclose(lin.exact_jacobian()[np.ix_(ix, ix)], A, rtol=0, atol=1e-12 * np.max(np.abs(A)))
        feed = {c: np.abs(lin.Dv[k]).max() for k, c in enumerate(lin.couplings)}
        if name == "single_joint_split":  # no output of either FMU depends on its inputs
            assert max(feed.values()) == 0.0
        else:
            assert feed["mot.tau -> joint.tau"] == pytest.approx(43.0 * 105.0 ** 2, rel=1e-12)  # c ratio^2
            assert feed["joint.theta -> mot.theta"] == feed["joint.w -> mot.w"] == 0.0


def test_puma_electric_split_limit_is_the_wrist_feedthrough():
    """Issue 29: the split puma_electric was stated stable below 15.6 ms (feedthrough taken as exact) and
    diverged at 1 ms and 0.1 ms on the wrist.  Now: a few microseconds (examples/check_jacobi_limits.py: stable
    at 0.9x, diverging at 1.1x), and the growing mode just above it is the wrist coupling's."""
    scene = fmugen.load_scene(SCENES / "puma_electric.toml", set={"scene.monolithic": False})
    lin = linearise_split(scene)
    limit = jacobi_hold_limit(scene, lin=lin)
    assert 1e-6 < limit < 3e-6
    w, V = np.linalg.eig(lin.step_matrix(1.1 * limit))
    v = np.abs(V[:, np.argmax(np.abs(w))])
    names = lin.states + lin.couplings
    assert names[int(np.argmax(v))] == "mot6.tau -> arm.tau[6]"
