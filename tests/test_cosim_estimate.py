"""The a-posteriori estimate of the coupling error (fmugen/cosim/accuracy.py: step-halving shadow windows on a
sample of steps): it leaves the run bit for bit unchanged, it is within 10x of the error measured against the
monolithic reference (and not below a tenth of it), and a run whose estimate exceeds the user's tolerance ends
``unreliable``, not ``ok``."""
import numpy as np
import pytest

from cosim_rigs import reference_problem, split_system
from fmugen.cosim import run, solve_reference

pytestmark = pytest.mark.usefixtures("private_reference_cache")


@pytest.fixture(scope="module")
def ref():
    return solve_reference(reference_problem("default", "smooth", 2.0), times=np.linspace(0.0, 2.0, 4001))


def _err(r, ref):
    idx = np.rint(r.time / 5e-4).astype(int)
    return float(np.max(np.abs(r["joint.theta"] - ref["joint.theta"][idx])))


@pytest.mark.parametrize("scheme,ext,H", [("jacobi", "hold", 2e-3), ("gauss-seidel", "linear", 4e-3),
                                          ("newton", "cubic", 2e-2)])
def test_the_estimate_is_within_10x_of_the_measured_error(ref, scheme, ext, H):
    r = run(split_system("default", "smooth", stop=2.0), scheme, ext, step=H)
    assert r.ok and r.summary.estimate_samples >= 1, r.summary
    est = r.summary.error_estimates["joint.theta"]
    err = _err(r, ref)
    assert err > 100 * ref.error_of("joint.theta")
    assert est / 20 < err < 10 * est, (err, est)


@pytest.mark.parametrize("scheme,ext,H", [("gauss-seidel", "linear", 4e-3), ("newton", "cubic", 2e-2)])
def test_the_shadow_windows_leave_the_run_bit_for_bit(scheme, ext, H):
    on = run(split_system("default", "smooth", stop=1.0), scheme, ext, step=H)
    off = run(split_system("default", "smooth", stop=1.0), scheme, ext, step=H, estimate=False)
    assert on.summary.estimate_samples >= 1 and off.summary.estimate_samples == 0
    assert np.array_equal(on.time, off.time) and np.array_equal(on.values, off.values)


def test_an_estimate_above_the_users_tolerance_is_unreliable_not_ok(ref):
    system = split_system("default", "smooth", stop=2.0)
    loose = run(system, "newton", "cubic", step=2e-2, tol=1e-3)
    tight = run(system, "newton", "cubic", step=2e-2, tol=1e-5)
    assert loose.summary.status == "ok" and loose.ok
    assert tight.summary.status == "unreliable" and not tight.ok and tight.summary.failure is None
    assert "exceeds the tolerance" in tight.summary.reliability
    # the same trajectory: only the verdict differs
    assert np.array_equal(loose.values, tight.values)


def test_without_a_tolerance_an_estimate_as_large_as_the_signal_is_unreliable():
    """A coupling that wrecked the answer early and then levelled off has no growing trend; its estimate,
    as large as the signal itself, still says that no digit is known (accuracy.NO_DIGIT)."""
    from fmugen.cosim.accuracy import NO_DIGIT, ErrorEstimate

    def finished(local_error, tol=None):
        e = ErrorEstimate("jacobi", "hold", n_steps=1200, columns=["q"], rtol=1e-8)
        for k in range(12):  # twelve windows, each of the same (steady) local error: no trend
            t = 0.1 * k
            e.started(t, 1e-3, (np.zeros(1), np.zeros(1)), 100 * k)
            for n in range(e.window):
                e.accepted(1e-3, np.full(1, local_error if n == e.window - 1 else 0.0), 100 * k + n + 1)
        values = np.ones((10, 1))  # the signal's largest value is 1
        return e.finish(values, tol, 1200)

    estimate, rel, trend, growth, verdict = finished(2.0 * NO_DIGIT)
    assert trend != "growing" and rel > NO_DIGIT and "no digit" in verdict
    assert finished(2.0 * NO_DIGIT, tol=1e3)[4] is None  # the user's own tolerance rules when given
    assert finished(1e-4)[4] is None  # an estimate well below the signal: ok


def _window_errors(nominal, values, errors):
    """An ErrorEstimate fed six windows whose end differs from the run by ``errors`` (per column)."""
    from fmugen.cosim.accuracy import ErrorEstimate

    est = ErrorEstimate("jacobi", "hold", 600, ("a", "b"), 1e-10, nominal)
    for k in range(6):
        est.pending = (0.01 * k, 1e-3, (np.zeros(2), np.asarray(errors, dtype=float)), 1)
        est.mid = np.zeros(2)
        est.accepted(1e-3, np.zeros(2), 100 * (k + 1))
    return est.finish(np.asarray(values, dtype=float), None, 600)


def test_a_signal_at_rest_is_judged_against_its_nominal_not_its_round_off():
    """A column that stays at round-off (the PUMA wrist's motor torque at rest, 1e-14 N.m) with a window error
    of the same size: judged against its declared nominal (here 1; FMI's default), no verdict; the other
    column, a real signal with half its size lost in one window, still ends unreliable."""
    values = [[1e-14, 2.0], [-1.2e-14, 2.0]]
    verdict = _window_errors([1.0, 1.0], values, [1.2e-14, 1e-9])[4]
    assert verdict is None
    verdict = _window_errors([1.0, 1.0], values, [1.2e-14, 1.5])[4]
    assert verdict is not None and " in b," in verdict
    # a declared nominal far below the signal's size changes nothing: the largest value is the scale
    verdict = _window_errors([1e-20, 1e-20], values, [1.2e-14, 1e-9])[4]
    assert verdict is not None and " in a," in verdict  # 1.2e-14 of 1.2e-14: no digit known, as before
