"""A user's component file (3 states, smoothed Stribeck sign, backlash dead zone and contact switch) driving the
PUMA's shoulder: built into FMUs, co-simulated with Newton coupling against the monolithic reference, trimmed
(against the arm's own gravity torque) and linearised."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.cosim import run, solve_reference

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "examples/scenes/puma_geared_drive.toml"
pytestmark = pytest.mark.usefixtures("private_reference_cache")


def test_user_component_with_the_arm_newton_against_the_reference(tmp_path):
    scene = fmugen.load_scene(SCENE, set={"scene.stop": 0.6})
    built = scene.build(tmp_path / "fmus")
    r = run(built.system, "newton", "cubic", step=0.01)
    assert r.ok, r.summary
    ref = solve_reference(scene.reference_problem(), times=r.time)
    err = np.max(np.abs(r["arm.q[2]"] - ref["arm.q[2]"]))
    assert err < 1e-5 and err > 100 * ref.error_of("arm.q[2]")  # 9.4e-7 rad over the 1.5 s run
    assert r["arm.q[2]"][-1] - r["arm.q[2]"][0] > 0.1  # it moved, through the backlash


def test_user_component_with_the_arm_trimmed_and_linearised():
    scene = fmugen.load_scene(SCENE)
    plant = fmugen.control.scene_model(scene, without=["path", "amp"])
    op = fmugen.trim(plant, at={"arm.q[2]": -0.4, "arm.qd[2]": 0.0}, free=["drive.u"])
    # holding still: k_m n i is the arm's gravity torque on joint 2 (the Manipulator's own evaluator),
    # u = R i (no back-emf at rest), the gear twisted by the backlash plus tau/c
    arm = fmugen.load_robot(ROOT / "robots/puma_thesis_com.toml")
    g2 = arm.bias(np.array([0.0, -0.4, 0.6, 0.0, 0.5, 0.0]), np.zeros(6))[1]
    x = dict(zip([v.name for v in plant.states], op.x))
    assert 0.5 * 100 * x["drive.i"] == pytest.approx(g2, rel=1e-8)
    assert op["drive.u"] == pytest.approx(0.5 * x["drive.i"], rel=1e-8)
    assert x["drive.phi_m"] / 100 + 0.4 == pytest.approx(-(1e-3 + abs(g2) / 1e5) * np.sign(-g2), rel=1e-6)
    lm = fmugen.linearize(plant, op)
    assert np.asarray(lm.A).shape == (5, 5) and np.all(np.isfinite(lm.A))
