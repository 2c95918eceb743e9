"""A short seeded run of the input fuzzer (``fuzz_inputs.py``, issue 19): scene
files, ``--set`` values, sweep grids and the master with misbehaving FMUs.
Every case must succeed or raise a one-line FmugenError; the long run is
``python tests/fuzz/fuzz_inputs.py --cases 2000``."""
import os
import re

from fuzz_inputs import Runner

CASES = int(os.environ.get("FUZZ_INPUT_CASES", "80"))
SEED = int(os.environ.get("FUZZ_SEED", "20261202"))


def test_inputs_fuzz_has_no_findings(tmp_path):
    r = Runner(SEED, tmp_path)  # every mutation, huge integers and 3000-deep nesting included
    r.run(CASES)
    print(r.report())
    assert all(r.counts[k] >= CASES // 4 for k in r.counts)
    assert not r.findings, "\n".join(r.findings[:20])


def test_a_table_where_a_name_is_expected_is_refused(tmp_path):
    """Found by this fuzzer (seed 20261202, case 452): ``solver = {}`` was looked up in a dict
    (TypeError: unhashable type) instead of refused."""
    import pytest

    from fuzz_inputs import SCENE
    from fmugen.errors import FmugenError
    from fmugen.scene import load_scene

    text = SCENE.read_text()
    for old, new, said in (('solver = "rodas3"', "solver = {}", "solver = {}"),
                           ('type = "joint_inertia"', "type = [1]", "type = [1] is not a component type")):
        path = tmp_path / "s.toml"
        path.write_text(text.replace(old, new, 1))
        with pytest.raises(FmugenError, match=re.escape(said)):
            load_scene(path)


def test_a_sweep_counts_its_points_before_making_them():
    """Two grids of a million values each were 1e12 points (the issue's unbounded sweep): refused at
    once with the number; a small grid is still its Cartesian product."""
    import time

    import pytest

    from fmugen.sweep.errors import SweepError
    from fmugen.sweep.points import MAX_POINTS, make_points

    big = {"joint.J": tuple(range(10 ** 6)), "joint.B_m": tuple(range(10 ** 6))}
    t0 = time.perf_counter()
    with pytest.raises(SweepError, match=r"1000000 x 1000000 = 1e\+12 points, more than 1e\+06"):
        make_points(big)
    assert time.perf_counter() - t0 < 5
    assert len(make_points({"joint.J": (1.0, 2.0), "joint.B_m": (0.0, 0.1, 0.2)})) == 6
    assert MAX_POINTS == 10 ** 6
