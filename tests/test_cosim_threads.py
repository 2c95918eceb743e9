"""FMUs stepped side by side on threads (``workers``): the same results, bit for bit, and the same failures.

The split rig's sweeps cost far less than the hand-over threshold, so the master keeps them on one thread
unless the threshold is lowered -- which these tests do to exercise the threaded path; the PUMA at 40 ms
is costly enough by itself.
"""
import numpy as np
import pytest

import fmugen.cosim.executor as executor
from cosim_rigs import split_system
from fmugen.cosim import CosimError, run


@pytest.fixture
def threads_always(monkeypatch):
    monkeypatch.setattr(executor, "PARALLEL_MIN_COST", 0.0)


def test_cheap_sweeps_stay_on_one_thread():
    r = run(split_system(stop=0.2), "jacobi", "linear", step=1e-3, workers=2)
    assert r.ok and r.summary.threads == 1


@pytest.mark.parametrize("scheme,ext,adaptive", [("jacobi", "linear", False), ("newton", "cubic", False),
                                                 ("iterative", "quadratic", False), ("jacobi", "linear", True),
                                                 ("newton", "quadratic", True)])
def test_threads_give_the_one_thread_result_bit_for_bit(threads_always, scheme, ext, adaptive):
    one = run(split_system(stop=0.3), scheme, ext, step=2e-3, adaptive=adaptive, tol=1e-2, workers=1)
    two = run(split_system(stop=0.3), scheme, ext, step=2e-3, adaptive=adaptive, tol=1e-2, workers=2)
    # (tol also judges the non-adaptive runs' error estimates: the same verdict either way)
    assert one.summary.failure is None and one.summary.status == two.summary.status, (one.summary, two.summary)
    if adaptive:  # rollbacks restore FMUs that threads stepped
        assert one.summary.rollbacks >= 1
    assert two.summary.threads == 2 and one.summary.threads == 1
    assert np.array_equal(one.time, two.time) and np.array_equal(one.values, two.values)
    for k in ("macro_steps", "rollbacks", "iterations", "do_steps", "fmu_calls"):
        assert getattr(one.summary, k) == getattr(two.summary, k), k


def test_an_fmu_that_discards_on_a_thread_is_reported_as_on_one(threads_always, monkeypatch):
    # Jacobi/held far above its limit on the stiff rig, without the divergence check: the chain's solver
    # discards at t = 0.52 s, on a thread from the second sweep on
    monkeypatch.setattr(executor, "TIMED_SWEEPS", 1)
    runs = [run(split_system("stiff", "step", stop=1.0), "jacobi", "hold", step=0.02, workers=w,
                detect_divergence=False) for w in (1, 2)]
    assert runs[1].summary.threads == 2
    for r in runs:
        f = r.summary.failure
        assert r.summary.status == "failed" and f.cause == "fmu-failure" and f.unit == "chain"
        assert "fmi2Discard" in f.message and f.time > 0.1
    assert str(runs[0].summary.failure) == str(runs[1].summary.failure)
    assert np.array_equal(runs[0].values, runs[1].values)


def test_workers_below_one_are_refused():
    with pytest.raises(CosimError, match="workers must be >= 1"):
        run(split_system(), "jacobi", workers=0)
