"""The master split into modules (schemes, interpolants, step-size controller, monitor, executor) gives the
results of the single-module master bit for bit: fingerprints of 30 runs (tests/master_golden.py: recorded
arrays, every summary counter, the failure text) recorded with the master at commit 59795fa, before the split.

A fingerprint depends on the FMUs' compiled code too: on a machine whose C compiler rounds differently they
would all change together; the master's restructuring changes none of them.
"""
import pytest

import fmugen.cosim.executor as executor
from master_golden import CASES, fingerprint, run_case

EXPECTED = {
    'jacobi/hold': '834c473caedd6b820e61a6a1',  # ok 150 steps
    'jacobi/linear': '7bf9fbd43590bcdae961f222',  # ok 150 steps
    'jacobi/quadratic': 'bb5cc58b7f8561c057408617',  # ok 150 steps
    'gauss-seidel/hold': '96a0b69a410548f9cdc2064d',  # ok 150 steps
    'gauss-seidel/linear': 'f99c18f1b57449bbe64d659d',  # ok 150 steps
    'gauss-seidel/quadratic': '07dbacf08805faec61a073fb',  # ok 150 steps
    'iterative/linear': '36abb990cf68326923d84b52',  # ok 150 steps
    'iterative/quadratic': 'd1b5133df1f5e5e10c21e0de',  # ok 150 steps
    'iterative/cubic': 'ab12ac9c2640bf1ab4c5eaf5',  # ok 150 steps
    'newton/linear': '6bad368752c7669e34d1ec84',  # ok 150 steps
    'newton/quadratic': 'e466f8e79f7a2f60000c0b5a',  # ok 150 steps
    'newton/cubic': 'c254d6f223259b3b3ac80db6',  # ok 150 steps
    'stiff newton/cubic 20ms': 'f89ee3eb3fd9e8fb3ae3351d',  # ok 20 steps
    'adaptive jacobi/linear': '4746fa73b7b69d5fb15ee91c',  # ok 469 steps
    'adaptive newton/quadratic': '0b07ae052f09c7da38a91c15',  # ok 273 steps
    'adaptive gauss-seidel/hold': '947eaf5d147fdbd8b60a11c0',  # failed 54 steps
    'diverged jacobi/hold': '37abd1caf236cba04890e1fd',  # failed 105 steps
    'diverged gauss-seidel/hold': '205bd0270b9bba656ea0784e',  # failed 15 steps
    'fmu-failure': 'afc7e5e1e5f841d96e3e2ad1',  # failed 26 steps
    'not-converged': '681da70f12288bf05b1daf0a',  # failed 0 steps
    'amp newton/linear': '6f075e79b719731893f4bd82',  # ok 60 steps
    'amp gauss-seidel/linear': 'cecdf61ec296938d3cf9bfa1',  # ok 300 steps
    'mixed me jacobi/linear': '417f14eedc9816cce17aa21b',  # failed 25 steps
    'mixed me newton/linear': 'cc7159fc76a0eb9fb35f221f',  # ok 40 steps
    'threads newton/cubic': '8f9b9d644c0d7f0470ca69f5',  # ok 150 steps
    'threads adaptive jacobi/linear': '14d040849823321003b88775',  # ok 469 steps
    'no-interp jacobi/linear': 'f2cf4e62871cad787d6dd637',  # ok 150 steps
    'no-interp gauss-seidel/quadratic': '223386ff036d3ece1d066193',  # ok 150 steps
    'no-interp newton/linear': 'e44be6bced7719945a546acd',  # ok 150 steps
    'no-interp iterative/linear': '583592e3521c39b34dddd938',  # ok 150 steps
}


def test_every_case_has_a_recorded_fingerprint():
    assert set(EXPECTED) == set(CASES)


@pytest.mark.parametrize("name", list(EXPECTED))
def test_the_restructured_master_gives_the_recorded_results_bit_for_bit(name, monkeypatch):
    if name.startswith("threads"):
        monkeypatch.setattr(executor, "PARALLEL_MIN_COST", 0.0)
    r = run_case(name)
    if name.startswith("threads"):
        assert r.summary.threads == 2
    assert fingerprint(r) == EXPECTED[name], r.summary
