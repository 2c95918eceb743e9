"""A short seeded run of the reader fuzzer (``fuzz_readers.py``, issue 27): URDF files, component files,
``connect`` statements and the analysis cache.  Every case must succeed or be refused in one line naming
the file (and the field); a mutation with a known answer must give it.  Run with ``-s`` for the counts
per surface and class; the long run is ``python tests/fuzz/fuzz_readers.py --cases 2000``."""
import json
import os
import re

import pytest

from fuzz_readers import CLASSES, RIG, RIG_PAIRS, Runner

CASES = int(os.environ.get("FUZZ_READER_CASES", "160"))
SEED = int(os.environ.get("FUZZ_SEED", "20261203"))


def test_readers_fuzz_has_no_findings(tmp_path, monkeypatch):
    monkeypatch.setenv("FMUGEN_CACHE", str(tmp_path / "cache"))  # never the user's own cache
    r = Runner(SEED, tmp_path)
    r.run(CASES)
    print("\n" + r.table())
    assert not r.findings, "\n".join(r.findings[:20])
    for surface in CLASSES:
        cases = sum(c[0] for c in r.counts[surface].values())
        refused = sum(c[2] for c in r.counts[surface].values())
        assert cases >= CASES // 5 and refused > 0, (surface, cases, refused)
    # the classes whose cases must all be refused were refused every time (no silent acceptance)
    for surface, cls in (("urdf", "number"), ("urdf", "non-finite"), ("urdf", "count"), ("connect", "shape"),
                         ("cache", "edit-value"), ("cache", "truncate")):
        c = r.counts[surface].get(cls)
        if c:
            assert c[1] == 0 and c[2] == c[0], (surface, cls, c)


def test_a_no_break_space_beside_der_is_refused(tmp_path):
    """Found by this fuzzer (seed 20261203, case 685): the left side of an equation was str.strip()ped,
    so ``"der(phi\\u00a0) = w"`` read as der(phi)."""
    from fmugen.components.equations import load_component
    from fmugen.errors import FmugenError

    from fuzz_readers import LIBRARY

    p = tmp_path / "stribeck.toml"
    p.write_text((LIBRARY / "stribeck.toml").read_text().replace('"der(phi) = w"', '"der(phi\u00a0) = w"'),
                 encoding="utf-8")
    with pytest.raises(FmugenError, match=re.escape(str(p)) + r".*equation 1 .*non-ASCII character '\\xa0'"):
        load_component(p)


def test_a_connect_end_with_a_newline_is_refused_in_one_line(tmp_path):
    """Found by this fuzzer (seed 20261203, case 742): the end was echoed raw, a message of two lines."""
    from fmugen.scene import SceneError, load_scene

    p = tmp_path / "rig.toml"
    p.write_text(RIG.format(connect=json.dumps([RIG_PAIRS[0], ["a\nb.flange", "valve.port"]])))
    with pytest.raises(SceneError) as exc:
        load_scene(p)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{p}: [scene] connect[1]: 'a\\nb.flange' is not a name")


def test_a_forged_cache_record_never_writes_outside_its_folder(tmp_path, monkeypatch):
    """A record that is consistent (its digest recomputed) but names a group '../evil' is not served: group
    names become file names in the output folder."""
    from fmugen.scene import analysis_cache as ac

    monkeypatch.setenv("FMUGEN_CACHE", str(tmp_path / "cache"))
    r = Runner(1, tmp_path)
    r._cache_setup()
    scene_path, key, rec, raw, record, fmus = r._cache
    assert ac.cached_analysis(scene_path).record == record  # the record as written is served
    forged = json.loads(raw)
    g = next(iter(forged["fmus"]))
    forged["fmus"]["../evil"] = forged["fmus"].pop(g)
    forged["fmus"]["../evil"]["report"]["group"] = "../evil"
    for u in forged["system"]["units"]:
        u["name"] = "../evil"
    forged["digest"] = ac._seal(key, forged)
    rec.write_text(json.dumps(forged))
    assert ac.cached_analysis(scene_path) is None
    edited = json.loads(raw)
    edited["x0"] = {k: v + 1.0 for k, v in edited["x0"].items()}  # an edit without a new digest
    rec.write_text(json.dumps(edited))
    assert ac.cached_analysis(scene_path) is None
    assert not list(tmp_path.glob("evil*"))
