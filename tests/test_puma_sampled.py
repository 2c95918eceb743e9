"""The thesis PUMA with six hydraulic chains under a 1 kHz dlqr controller per joint
(examples/scenes/puma_hydraulic_sampled.toml, written by examples/design_puma_sampled.py).

* the design: the six decentralised gains stabilise the *full* trimmed linearisation (all joints
  coupled, ZOH at 1 ms, with the integrators): spectral radius < 1; the shipped controller files carry
  the design's numbers;
* the nonlinear closed loop, Newton/linear at 1 ms over the whole 2 s move: holds the pose before the
  path starts (to 1e-9 rad), tracks the path within 1e-3 rad, ends on it within 1e-6 rad;
* every ctrl{k}.u changes only at multiples of 1 ms (Gauss-Seidel at 0.5 ms: held in between, exactly);
* Newton (cubic, linear) and Gauss-Seidel at 1 ms against the hybrid reference (a Radau piece per sample
  interval, rtol 1e-9) over the first 0.25 s (the hold and 50 ms of the move): joint angles within 1e-6,
  3e-5 and 5e-4 rad (REF_TOL).
"""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.components.equations import read_component_file
from fmugen.cosim import run, solve_reference

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "examples" / "scenes" / "puma_hydraulic_sampled.toml"
T_S = 1e-3
T_REF = 0.25  # the reference's span [s]: 250 sample intervals, the last 50 ms of them moving
REF_RTOL = 1e-9  # the reference's Radau tolerance (its confirming solve 1e-10): ~40 s, not the 1e-12 default
# [rad], joint angles at 1 ms against the hybrid reference (measured over 0.25 s: Newton/cubic 2.0e-7,
# Newton/linear 9.5e-6 (second order), Gauss-Seidel/linear 2.2e-4 -- the joint FMUs' samplers read the
# arm's angle and speed of the step's start, a delay of one macro step the reference does not have)
REF_TOL = {("newton", "cubic"): 1e-6, ("newton", "linear"): 3e-5, ("gauss-seidel", "linear"): 5e-4}
Q = [f"arm.q[{k}]" for k in range(1, 7)]


def _design_module():
    spec = importlib.util.spec_from_file_location("design_puma_sampled", ROOT / "examples" / "design_puma_sampled.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("design_puma_sampled", mod)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    sc = fmugen.load_scene(str(SCENE))
    return sc, sc.build(tmp_path_factory.mktemp("puma_sampled"))


@pytest.fixture(scope="module")
def newton(built):
    _, b = built
    r = run(b.system, scheme="newton", extrapolation="linear", step=T_S)  # the whole 2 s move
    assert r.summary.failure is None, r.summary
    return r


def paths(sc, t):
    out = {}
    for k in range(1, 7):
        ev = ModelEvaluator(sc.base_models[f"path{k}"])
        out[k] = np.array([ev.g(tt, np.zeros(0), np.zeros(0))[0] for tt in t])
    return out


def test_the_design_stabilises_the_full_linearisation_and_is_the_shipped_one():
    mod = _design_module()
    d = mod.design()
    rho, _ = mod.full_loop_radius(d)
    assert rho < 0.995, rho
    for j in d["joints"]:
        assert np.abs(j["poles"]).max() < 0.995
        comp = read_component_file(ROOT / "examples" / "components" / f"puma_sampled_ctrl{j['k']}.toml")
        p = {n: d.value for n, d in comp.declared.items() if d.kind == "parameter"}
        A, B, C, D = j["ctrl"]
        assert p["T_s"] == T_S
        assert abs(p["C_1_1"] / C[0, 0] - 1) < 1e-9
        for i in range(D.shape[1]):
            if D[0, i] != 0:
                assert abs(p[f"D_1_{i + 1}"] / D[0, i] - 1) < 1e-9, (j["k"], i)


def test_holds_the_pose_and_tracks_the_path(built, newton):
    sc, _ = built
    r = newton
    t = r.time
    ref = paths(sc, t)
    for k in range(1, 7):
        e = r[f"arm.q[{k}]"] - ref[k]
        assert np.abs(e[t <= 0.2]).max() < 1e-9, (k, np.abs(e[t <= 0.2]).max())  # at rest: the trim holds
        assert np.abs(e).max() < 1e-3, (k, np.abs(e).max())                        # along the move
        assert abs(e[-1]) < 1e-6, (k, e[-1])                                       # at the end
        assert abs(r[f"arm.q[{k}]"][-1] - ref[k][-1]) < 1e-6


def test_ctrl_u_changes_only_at_sample_instants(built):
    _, b = built
    r = run(b.system, scheme="gauss-seidel", extrapolation="linear", step=T_S / 2, stop=0.4)
    assert r.summary.failure is None, r.summary
    t = r.time
    for k in range(1, 7):
        u = r[f"ctrl{k}.u"]
        jumps = t[1:][np.abs(np.diff(u)) > 0]
        assert len(jumps) > 100, (k, len(jumps))  # it moves (the path starts at 0.2 s) ...
        assert np.all(np.abs(jumps / T_S - np.round(jumps / T_S)) < 1e-9), (k, jumps)  # ... only at k T_s
        off = np.abs(t / T_S - np.round(t / T_S)) > 1e-6  # the mid-interval points equal the point before
        idx = np.nonzero(off)[0]
        assert np.all(u[idx] == u[idx - 1]), k


@pytest.fixture(scope="module")
def reference(built):
    sc, _ = built
    sc = fmugen.load_scene(str(SCENE), set={"scene.stop": T_REF})
    t = np.linspace(0.0, T_REF, int(round(T_REF / T_S)) + 1)
    return solve_reference(sc.reference_problem(), times=t, cache=False, rtol=REF_RTOL)


@pytest.mark.parametrize("scheme,ext", list(REF_TOL))
def test_cosimulation_meets_the_hybrid_reference(built, reference, scheme, ext):
    _, b = built
    r = run(b.system, scheme=scheme, extrapolation=ext, step=T_S, stop=T_REF)
    assert r.summary.failure is None, r.summary
    k = np.rint(r.time / T_S).astype(int)
    err = max(float(np.abs(r[n] - reference[n][k]).max()) for n in Q)
    bound = max(reference.error_of(n) for n in Q)
    print(f"{scheme}/{ext} at 1 ms over {T_REF} s: max joint-angle error {err:.2e} rad "
          f"(reference's own error bound {bound:.1e})")
    assert err < REF_TOL[scheme, ext], err
