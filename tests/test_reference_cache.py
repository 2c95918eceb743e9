"""The reference solution is cached independently of its output grid (issue 18).

What is stored is the Radau solve's dense output; another grid is evaluated from it without solving
again, and gives what a fresh solve on that grid gives.  The stored polynomials are checked against
scipy's own dense output.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cosim_rigs import reference_problem
from fmugen.cosim.reference import DenseOutput, solve_reference

pytestmark = pytest.mark.usefixtures("private_reference_cache")


def test_dense_output_equals_scipys():
    lam = np.array([[-50.0, 20.0], [-20.0, -1.0]])
    sol = solve_ivp(lambda t, x: lam @ x + np.array([np.sin(7 * t), 0.0]), (0.0, 2.0), [1.0, -0.5], method="Radau",
                    rtol=1e-10, atol=1e-12, dense_output=True)
    t = np.concatenate([np.linspace(0, 2, 3001), sol.t])  # between steps and at every step point
    np.testing.assert_allclose(DenseOutput.of(sol)(t), sol.sol(t), rtol=1e-14, atol=1e-15)


def test_another_grid_comes_from_the_cache_and_equals_a_fresh_solve():
    p = reference_problem(stop=0.05)
    a = solve_reference(p, times=np.linspace(0, 0.05, 1001))
    assert not a.cached and a.settings["error_points"] > 1001
    grid = np.linspace(0, 0.05, 1337)  # not a sub-grid of the first
    b = solve_reference(p, times=grid)
    assert b.cached and np.array_equal(b.time, grid) and np.array_equal(b.error, a.error)
    fresh = solve_reference(p, times=grid, cache=False)
    assert not fresh.cached
    np.testing.assert_allclose(b.values, fresh.values, rtol=1e-14, atol=1e-14 * np.max(np.abs(fresh.values)))
    # and the first grid's values are the dense output's at those points
    np.testing.assert_array_equal(solve_reference(p, times=a.time).values, a.values)
