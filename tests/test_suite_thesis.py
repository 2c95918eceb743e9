"""The thesis's integrator (acceleration held over the step, no iteration) as a
regression: it reproduces the growth the 1984 simulation saw, and the FMU's
error-controlled solvers remove it.

Independent sources: the closed forms sqrt(1 + (hw)^2/2) (undamped) and
hw < 4 zeta (damped), derived by hand in fmugen/suite/thesis.py, against the
scheme's amplification matrix measured by stepping it, and the energy of the
free PUMA from the arm's own energy function.
"""
import numpy as np
import pytest

from fmugen.suite import run_suite
from fmugen.suite.thesis import (amplification_matrix, damped_stability_limit, growth_per_step, spectral_radius,
                                 undamped_radius)


@pytest.mark.parametrize("hw", [0.01, 0.3, 1.0, 3.0])
def test_undamped_growth_is_sqrt_one_plus_half_hw_squared(hw):
    w = 7.0
    assert spectral_radius(w, 0.0, hw / w) == pytest.approx(undamped_radius(hw), rel=1e-13)
    assert undamped_radius(hw) > 1  # for every step
    # the growth the scheme shows over a long run (energy norm, renormalised)
    assert growth_per_step(w, 0.0, hw / w, steps=20000) == pytest.approx(undamped_radius(hw), rel=2e-4)
    # determinant: the area the step multiplies by
    assert np.linalg.det(amplification_matrix(w, 0.0, hw / w)) == pytest.approx(1 + hw * hw / 2, rel=1e-13)


@pytest.mark.parametrize("zeta", [0.02, 0.1, 0.3])
def test_damped_stable_only_below_4_zeta(zeta):
    w = 3.0
    lim = damped_stability_limit(zeta)
    assert spectral_radius(w, zeta, 0.98 * lim / w) < 1
    assert spectral_radius(w, zeta, 1.02 * lim / w) > 1
    assert spectral_radius(w, zeta, lim / w) == pytest.approx(1.0, abs=1e-12)


def test_thesis_case_against_fmu_solvers(tmp_path):
    rows = run_suite(["thesis_integrator"], quick=True, out=tmp_path, log=lambda *a: None)
    closed = [r for r in rows if r.method.startswith("thesis: ") and "PUMA" not in r.method]
    assert closed and all(r.outcome == "reproduced" for r in closed), [(r.method, r.message) for r in closed]
    arm = [r for r in rows if "free PUMA" in r.method]
    assert len(arm) == 2 and all("grows" in r.message for r in arm)
    # smaller steps slow the growth but do not remove it
    assert arm[0].error > arm[1].error > 1e-3
    fmu = [r for r in rows if r.method.startswith("DOPRI5")]
    assert fmu[0].outcome == "accurate" and fmu[0].error < 1e-5  # relative energy drift over 2 s
    assert (tmp_path / "thesis_integrator.png").exists()
