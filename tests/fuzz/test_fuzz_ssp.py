"""A short seeded run of the SSP fuzzer (``fuzz_ssp.py``, issue 27): mutated numbers, structures,
archives and random damage, each case refused in one line naming the archive, the file inside it and
the field, or honoured with the value it states; ``pytest -s`` prints the table of counts per class.
The long run is ``python tests/fuzz/fuzz_ssp.py --cases 2000``."""
import os

import pytest

from fuzz_ssp import CLASSES, Runner

CASES = int(os.environ.get("FUZZ_SSP_CASES", "150"))
SEED = int(os.environ.get("FUZZ_SEED", "20261203"))


@pytest.mark.filterwarnings("ignore:Duplicate name")
def test_ssp_fuzz_has_no_findings(tmp_path):
    r = Runner(SEED, tmp_path)
    r.run(CASES)
    print()
    print(r.table())
    assert all(r.counts[c]["cases"] >= CASES // len(CLASSES) for c in CLASSES)
    # both oracles of the number class were exercised: values refused and values honoured
    assert r.counts["number"]["refused"] > 0 and r.counts["number"]["accepted"] > 0
    assert not r.findings, "\n".join(r.findings[:20])


def test_the_battery_finds_pythons_number_grammar(tmp_path, monkeypatch):
    """The oracle can fail: with float() in place of the xs:double grammar in the SSD/SSV reader (what
    the readers did before), the same battery reports 1_5, Arabic-Indic digits or 'infinity' accepted."""
    import math

    import fmugen.ssp.ssd as ssd
    from fmugen.errors import InputFileError

    def python_float(text, where, finite=True):
        try:
            x = float(text)
        except ValueError:
            raise InputFileError(f"{where}: {text!r} is not a number") from None
        if finite and not math.isfinite(x):
            raise InputFileError(f"{where}: {text!r} is not finite")
        return x

    monkeypatch.setattr(ssd, "parse_xs_double", python_float)
    r = Runner(SEED, tmp_path)
    for n in range(120):
        r.number(n)
    assert r.counts["number"]["silent-wrong"] > 0, r.table()
    assert any("accepted, must be refused" in f for f in r.findings)
