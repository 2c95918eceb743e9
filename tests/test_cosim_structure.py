"""The master split into modules (schemes, interpolants, step-size controller, monitor, executor) gives the
results of the single-module master it replaced bit for bit: 29 runs (tests/master_golden.py) against what the
old master (commit 59795fa) gave on the same FMUs, stored in tests/data/master_59795fa.npz -- the recorded
arrays, every summary counter, the failure's time, cause, FMU and coupling.
"""
import numpy as np
import pytest

import fmugen.cosim.executor as executor
from master_golden import CASES, counters, fmu_sources_key, run_case, stored_results

STORED = stored_results()


def test_every_case_has_stored_results():
    assert sorted(STORED) == sorted(CASES)


@pytest.mark.parametrize("name", list(CASES))
def test_the_restructured_master_gives_the_old_masters_results_bit_for_bit(name, monkeypatch):
    if name.startswith("threads"):  # the split rig's sweeps are too cheap for threads unless told
        monkeypatch.setattr(executor, "PARALLEL_MIN_COST", 0.0)
    new, system = run_case(name)
    old = STORED[name]
    if name.startswith("threads"):
        assert new.summary.threads == 2
    same_fmus = fmu_sources_key(system) == old["fmu_sources"]
    why = "" if same_fmus else (" -- the FMUs' sources differ from those the results were stored with, so the "
                                "difference may be theirs (tests/data/README.md)")
    assert counters(new) == old["counters"], f"{new.summary}{why}"
    assert list(new.columns) == old["columns"]
    t, v = np.asarray(new.time, float), np.asarray(new.values, float)
    assert t.shape == old["time"].shape and v.shape == old["values"].shape, why
    diff = np.nanmax(np.abs(v - old["values"])) if v.size else 0.0
    assert np.array_equal(t, old["time"]) and np.array_equal(v, old["values"], equal_nan=True), \
        f"largest difference {diff:.3g}{why}"
