"""Third-party FMUs with direct feedthrough (tests/feedthrough_fmu.py: hand-written C, built here): a spring's
force computed from the inputs, with and without canInterpolateInputs, against the matrix exponential.

An FMU that cannot interpolate is stepped with its inputs held at the extrapolant's (or the iterated step's
line's) midpoint value; its outputs at t_{n+1} must be read with the inputs at t_{n+1}.  Read with the midpoint
still set, every output lagged by H/2: all schemes first order, Newton/linear 0.32 (relative) off at 1 ms and
7.8 at 5 ms, where it is now 8.6e-4 and 2.1e-2 (python tests/feedthrough_fmu.py prints the table)."""
import dataclasses

import numpy as np
import pytest

from feedthrough_fmu import build_system, error
from fmugen.cosim import run


@pytest.fixture(scope="module")
def systems(tmp_path_factory):
    d = tmp_path_factory.mktemp("feedthrough")
    return {interp: build_system(d / ("interp" if interp else "held"), interp, stop=0.1) for interp in (False, True)}


def _errors(system, scheme, ext, steps):
    out = []
    for h in steps:
        r = run(system, scheme, ext, step=h, estimate=False)
        assert r.ok, (scheme, ext, h, r.summary.failure)
        out.append(error(r))
    return out


@pytest.mark.parametrize("interp", [False, True], ids=["held-inputs", "interpolating"])
def test_observed_orders_against_the_exact_solution(systems, interp):
    """Held inputs first order, extrapolated or iterated second order, whether the FMU interpolates or
    holds the midpoint value (Gauss-Seidel: the midpoint of the line to the source's new value)."""
    system = systems[interp]
    for scheme, ext, order, steps in [("jacobi", "hold", 1, (5e-4, 2.5e-4)),
                                      ("gauss-seidel", "hold", 1, (5e-4, 2.5e-4)),
                                      ("jacobi", "linear", 2, (1e-3, 5e-4)),
                                      ("gauss-seidel", "linear", 2, (1e-3, 5e-4)),
                                      ("iterative", "linear", 2, (1e-3, 5e-4)),
                                      ("newton", "linear", 2, (2e-3, 1e-3))]:
        e = _errors(system, scheme, ext, steps)
        p = np.log2(e[0] / e[1])
        assert abs(p - order) < 0.3, (scheme, ext, e, p)
        if order == 2:
            assert e[-1] < 4e-3, (scheme, ext, e)


def test_newton_where_held_jacobi_diverges(systems):
    """At H = 2 ms held-input Jacobi diverges (a report names the coupling); Newton/linear on the FMU that
    cannot interpolate is stable, within 5e-3 of the exact solution and within 2.5x of the interpolating
    FMU's error (holding the midpoint costs a constant factor, not an order), with one Newton correction per
    step (the system is linear: the interface Jacobian is exact)."""
    held, interp = (dataclasses.replace(systems[k], stop_time=0.2) for k in (False, True))
    jh = run(held, "jacobi", "hold", step=2e-3, estimate=False)
    assert not jh.ok and jh.summary.failure.cause == "diverged"
    nw = run(held, "newton", "linear", step=2e-3, estimate=False)
    assert nw.ok and nw.summary.iterations <= nw.summary.macro_steps
    e_held, e_interp = error(nw), error(run(interp, "newton", "linear", step=2e-3, estimate=False))
    assert e_held < 5e-3 and e_held < 2.5 * e_interp, (e_held, e_interp)
    big = run(held, "newton", "linear", step=5e-3, estimate=False)
    assert big.ok and error(big) < 5e-2


def test_adaptive_newton_jacobian_with_the_steps_inputs(systems):
    """Adaptive Newton recomputes the interface Jacobian away from rest (every new H): each column is a
    re-step with all the FMU's inputs held at their midpoint, as in the step itself.  With the other input
    left at its start value the columns were wrong by O(H v'/delta): 32639 steps, 289855 Jacobians."""
    r = run(systems[False], "newton", "linear", step=1e-3, adaptive=True, tol=1e-2, estimate=False)
    assert r.ok and r.summary.macro_steps < 1000 and r.summary.jacobians < 200, r.summary
    assert error(r) < 1e-2
