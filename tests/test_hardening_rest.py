"""Issue 27, class 3: the physics check at rest, for scenes that start from their given start values.

The unstable-physics diagnosis (:func:`fmugen.scene.equilibrium.unstable_modes`) ran only for
``initial = "equilibrium"``.  A scene started from given values at a state of rest with a sign error in
its position loop was built and co-simulated "ok" without a word.  Now given start values are judged
whenever they are a state of rest; when they are not, the build says so in one line.

The growing mode is checked against an independent computation: the eigenvalues of the coupled
Jacobian that :mod:`fmugen.scene.stability` assembles from each instance linearised on its own (another
code path than the monolithic model the diagnosis linearises).
"""
from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.cli import main
from fmugen.cosim import run
from fmugen.scene.stability import linearise_split

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"
SPLIT = SCENES / "single_joint_split.toml"


def _reversed(tmp_path) -> Path:
    """single_joint_split (initial = "given", at rest at zero) with the amplifier's gain negated:
    positive position feedback, a sign error of the loop."""
    scene = fmugen.load_scene(SPLIT)
    K = next(v.start for v in scene.base_models["amp"].parameters if v.name == "K_a")
    text = SPLIT.read_text().replace('amp = { type = "amplifier", control = "P" }',
                                     f'amp = {{ type = "amplifier", control = "P", parameters = {{ K_a = {-K!r} }} }}')
    assert f"K_a = {-K!r}" in text and 'initial = "given"' in text
    p = tmp_path / "split_reversed_gain.toml"
    p.write_text(text)
    return p


def test_a_sign_flipped_loop_started_at_rest_warns_with_its_mode(tmp_path):
    scene = fmugen.load_scene(_reversed(tmp_path))
    init = scene.initial
    assert init.mode == "given"
    assert len(init.unstable) == 1, init.report()
    sentence = init.unstable[0]
    assert "dominant states" in sentence and "joint.w" in sentence.split("dominant states")[1]
    # the growth rate against the stability module's own linearisation of the instances
    growth = float(np.max(np.linalg.eigvals(linearise_split(scene).exact_jacobian()).real))
    assert growth > 1.0
    lam = float(sentence.split("lambda = ")[1].split(" ")[0])
    assert lam == pytest.approx(growth, rel=1e-3)
    doubling = float(sentence.split("doubles every ")[1].split(" ")[0])
    assert doubling == pytest.approx(np.log(2) / growth, rel=1e-2)
    assert "warning: the state of rest is unstable: mode lambda" in init.report()


def test_the_warning_reaches_fmugen_build_and_the_cosimulation(tmp_path, capsys):
    path = _reversed(tmp_path)
    assert main(["build", str(path), "-o", str(tmp_path / "fmus")]) == 0
    out = capsys.readouterr().out
    assert "warning: the state of rest is unstable: mode lambda" in out, out
    scene = fmugen.load_scene(path)
    built = scene.build(tmp_path / "fmus")  # cached now
    assert built.system.rest_unstable == tuple(scene.initial.unstable)
    r = run(built.system, "jacobi", "hold", step=1e-3, stop=1.0)
    assert "unstable at rest" in str(r.summary) and "joint.w" in r.summary.physics
    # it does run away by itself: the physics, not the coupling (the right sign holds still at 0.1 rad)
    assert abs(r["joint.theta"][-1]) > 1.0 or r.summary.failure is not None


@pytest.mark.parametrize("name", ["single_joint_split", "single_joint_split_stiff"])
def test_shipped_scenes_started_at_rest_do_not_warn(name):
    init = fmugen.load_scene(SCENES / f"{name}.toml").initial
    assert init.mode == "given" and init.unstable == []
    report = init.report()
    assert "unstable" not in report
    assert "a state of rest with no growing mode" in report


def test_start_values_away_from_rest_are_said_to_be_so(tmp_path):
    """theta = 0.1 rad against a reference of 0: the amplifier drives a current at once -- not a state of
    rest, so stability is not judged, and the build output says so in one line."""
    scene = fmugen.load_scene(SPLIT, set={"joint.theta": 0.1})
    init = scene.initial
    assert init.unstable == []
    lines = [l for l in init.report().splitlines() if "not a state of rest" in l]
    assert len(lines) == 1, init.report()
    assert "largest derivative der(" in lines[0] and lines[0].endswith("stability not judged")
    # the derivative it names is the model's own, at the given start (amp.u = K_a (0 - 0.1) drives the driver)
    name = lines[0].split("der(")[1].split(")")[0]
    value = float(lines[0].split(") = ")[1].split(",")[0])
    from fmugen.codegen.evaluate import ModelEvaluator

    m = init.model
    x = np.array([init.values[v.name] for v in m.states])
    u = np.array([v.start or 0.0 for v in m.inputs])
    f = ModelEvaluator(m).f(scene.spec.start, x, u)
    assert f[[v.name for v in m.states].index(name)] == pytest.approx(value, rel=1e-2)

