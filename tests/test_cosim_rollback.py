"""Rollback and the adaptive macro step.

* a restored FMU state continues bit for bit (the macro step repeated after
  fmi2SetFMUstate gives identical states and outputs), for both FMUs, with
  input derivatives in force;
* the adaptive step meets its tolerance against the reference, its error
  follows the tolerance, it rolls back where the interface changes fast and
  the step sequence does not chatter.
"""
import numpy as np
import pytest

from cosim_rigs import reference_problem, split_system
from fmugen.cosim import Master, run, solve_reference


pytestmark = pytest.mark.usefixtures("private_reference_cache")


def _all_reals(unit):
    vrs = sorted({v.valueReference for v in unit.md.modelVariables
                  if v.type == "Real" and v.causality in ("local", "output", "input")})
    return unit.get_reals(vrs)


def test_restored_state_continues_bit_for_bit():
    with Master(split_system(stop=0.3), "gauss-seidel", "linear") as m:
        r = m.run(step=1e-3, stop=0.3)  # mid-transient: every state is moving
        assert r.ok
        t = r.time[-1]
        for u in m.units:
            before = _all_reals(u)
            s = u.new_state()
            m.DUset[:] = 3.0  # a nonzero input slope in force over the step
            runs = []
            for _ in range(2):
                assert u.restore(s) == 0
                assert np.array_equal(_all_reals(u), before)
                m._do(u, t, 2e-3, 0)
                runs.append(_all_reals(u))
            u.free_state(s)
            assert not np.array_equal(runs[0], before)  # the step did move the FMU
            assert np.array_equal(runs[0], runs[1])  # and repeats exactly


@pytest.fixture(scope="module")
def reference():
    return reference_problem("default", "step", 1.0)


def _adaptive(tol):
    return run(split_system("default", "step"), "gauss-seidel", "linear", step=1e-3, adaptive=True, tol=tol)


def test_adaptive_error_follows_the_tolerance_without_chattering(reference):
    errs = []
    for tol in (1e-2, 1e-3):
        r = _adaptive(tol)
        assert r.ok, r.summary
        ref = solve_reference(reference, times=r.time)
        errs.append(np.max(np.abs(r["joint.theta"] - ref["joint.theta"])))
        assert errs[-1] > 100 * ref.error_of("joint.theta")
        s = r.summary
        assert s.rollbacks >= 1  # the step at t = 0 meets the theta_ref jump inside the chain
        assert s.step_max > 20 * s.step_min  # H adapts: small in the transient, large at rest
        # no chattering: H changes on few steps and rarely reverses direction
        dlog = np.diff(np.log(np.diff(r.time)[:-1]))  # the last step is cut to hit stop
        changes = dlog[np.abs(dlog) > 1e-9]
        reversals = np.sum(np.diff(np.sign(changes)) != 0)
        assert len(changes) < 0.1 * s.macro_steps and reversals <= 5, (len(changes), reversals)
    # ten times tighter -> about ten times smaller error (the defect is a local error indicator)
    assert 4 < errs[0] / errs[1] < 25, errs
    assert errs[1] < 1e-5


def test_adaptive_is_deterministic_through_rollbacks():
    a, b = _adaptive(1e-3), _adaptive(1e-3)
    assert a.summary.rollbacks == b.summary.rollbacks >= 1
    assert np.array_equal(a.time, b.time) and np.array_equal(a.values, b.values)


def test_adaptive_newton_with_hermite_inputs_takes_steps_beyond_the_explicit_limits():
    # stiff split rig, smooth excitation: Gauss-Seidel/held is stable only below 5.5 ms.  The adaptive
    # Newton/quadratic step (defect of a third-order predictor) grows past that limit where the motion
    # allows and needs a fraction of the steps of Newton/linear at the same tolerance
    stop = 2.5
    par = run(split_system("stiff", "smooth", stop=stop), "newton", "quadratic", step=1e-3, adaptive=True,
              tol=1e-3, max_step=0.2)
    lin = run(split_system("stiff", "smooth", stop=stop), "newton", "linear", step=1e-3, adaptive=True,
              tol=1e-3, max_step=0.2)
    assert par.ok and lin.ok, (par.summary, lin.summary)
    assert par.summary.step_max > 2 * 5.54e-3
    assert par.summary.macro_steps < lin.summary.macro_steps / 3
    ref = solve_reference(reference_problem("stiff", "smooth", stop), times=par.time)
    err = np.max(np.abs(par["joint.theta"] - ref["joint.theta"]))
    assert 100 * ref.error_of("joint.theta") < err < 1e-6
