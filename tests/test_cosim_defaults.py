"""Defaults that hold: the cheap shipped scenes, run with their own settings (no [cosim] table: Gauss-Seidel,
linear, the scene's 1 ms step) over ten times their horizon, end ``ok`` -- stable, the error estimate not
growing -- and within 1e-4 rad of the monolithic reference, within 10x of their stated error estimate.
(The PUMA's: ``python examples/cosim_defaults_check.py``.)"""
from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.cosim import run, solve_reference

pytestmark = pytest.mark.usefixtures("private_reference_cache")
SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"


@pytest.mark.parametrize("name", ["single_joint_split"])  # (the stiff set holds too: examples/cosim_defaults_check.py)
def test_the_scenes_own_settings_hold_over_ten_times_its_horizon(name, tmp_path):
    scene = fmugen.load_scene(SCENES / f"{name}.toml")
    T = 10 * (scene.spec.stop - scene.spec.start)
    r = run(scene.build(tmp_path).system, stop=T)
    s = r.summary
    assert s.status == "ok" and r.time[-1] == pytest.approx(T), s
    assert s.error_trend != "growing" and s.estimate_samples >= 6
    ref = solve_reference(scene.reference_problem() if scene.spec.stop == T else _longer(scene, T), times=r.time)
    err = float(np.max(np.abs(r["joint.theta"] - ref["joint.theta"])))
    est = s.error_estimates["joint.theta"]
    assert err < 1e-4 and err < 10 * est, (err, est)


def _longer(scene, T):
    from fmugen.cosim import ReferenceProblem

    p = scene.reference_problem()
    return ReferenceProblem(p.model, p.x0, p.u, p.columns, p.start_time, T, p.nominals)
