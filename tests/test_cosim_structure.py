"""The master split into modules (schemes, interpolants, step-size controller, monitor, executor) gives the
results of the single-module master it replaced bit for bit: 29 runs (tests/master_golden.py) with both
masters on the same FMUs -- the recorded arrays, every summary counter, the failure's time, cause, FMU and
coupling.  The old master is kept unchanged in tests/legacy/master_59795fa.py (commit 59795fa).
"""
import pytest

import fmugen.cosim.executor as executor
from master_golden import CASES, fingerprint, legacy_master, run_case


@pytest.mark.parametrize("name", list(CASES))
def test_the_restructured_master_gives_the_old_masters_results_bit_for_bit(name, monkeypatch):
    if name.startswith("threads"):  # the split rig's sweeps are too cheap for threads unless told
        monkeypatch.setattr(executor, "PARALLEL_MIN_COST", 0.0)
        monkeypatch.setattr(legacy_master(), "PARALLEL_MIN_COST", 0.0)
    new, old = run_case(name), run_case(name, legacy=True)
    if name.startswith("threads"):
        assert new.summary.threads == 2
    assert fingerprint(new) == fingerprint(old), (new.summary, old.summary)
