"""A scene's groups as FMI 3.0 FMUs (``[scene] fmi_version = 3``, ``fmugen build scene.toml --fmi-version 3``).

The hydraulic joint cut in two (examples/scenes/single_joint_split.toml: the actuator chain in one FMU, the
joint inertia in the other) is built as FMI 2.0 and as FMI 3.0.  Each group's FMI 3.0 FMU must validate
against the FMI 3.0 schema and compute exactly what its FMI 2.0 twin computes: fmpy's ME and CS runs, with
the coupled inputs driven by the same tables, agree to 1e-12, and so do fmusim's (Reference-FMUs' importer,
built by tests/tools/build_fmusim.sh; skipped without it).
"""
from __future__ import annotations

import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu

from fmugen.cli import main as cli_main
from fmugen.fmi.platforms import host_platform
from fmugen.scene import load_scene
from fmugen.scene.errors import SceneError

ROOT = Path(__file__).resolve().parent.parent
SPLIT = ROOT / "examples" / "scenes" / "single_joint_split.toml"

pytestmark = pytest.mark.skipif(host_platform() != "linux64", reason="FMI 3.0 export: x86_64 Linux only so far")

#: inputs of each group while it runs alone: the joint swinging, the chain's torque a smooth push
INPUTS = {
    "chain": ("amp.theta", "actuator.w"),
    "joint": ("tau",),  # a group of one instance: its own names
}


def _table(names, stop=0.5, n=51):
    t = np.linspace(0.0, stop, n)
    rows = [t]
    for k, name in enumerate(names):
        rows.append({"theta": 0.05 * np.sin(4 * t), "w": 0.2 * np.cos(4 * t),
                     "tau": 200.0 * np.sin(3 * t + k)}[name.split(".")[-1]])
    return np.array(list(zip(*rows)), dtype=[("time", float)] + [(nm, float) for nm in names])


@pytest.fixture(scope="module")
def split_fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmi3_scene")
    out = {}
    for version in (2, 3):
        # fmi_type "me": both interfaces in each FMU (a scene's groups are Co-Simulation only by default)
        sets = {"scene.fmi_version": version, "fmus.chain.fmi_type": "me", "fmus.joint.fmi_type": "me"}
        built = load_scene(SPLIT, set=sets).build(d / f"v{version}", use_cache=False)
        out[version] = {g: Path(f.path) for g, f in built.fmus.items()}
    assert set(out[2]) == set(out[3]) == set(INPUTS)
    return out


def _same(r2, r3):
    assert r2.dtype.names == r3.dtype.names and len(r2) == len(r3) > 10
    return max(float(np.max(np.abs(r3[n] - r2[n]))) for n in r2.dtype.names)


@pytest.mark.parametrize("group", sorted(INPUTS))
def test_scene_group_fmi3_validates_and_has_the_fmi3_layout(split_fmus, group):
    p3 = split_fmus[3][group]
    assert validate_fmu(str(p3)) == []
    md = fmpy.read_model_description(str(p3), validate_variable_names=True, validate_model_structure=True)
    assert md.fmiVersion == "3.0"
    names = zipfile.ZipFile(p3).namelist()
    assert f"binaries/x86_64-linux/{group}.so" in names and "sources/buildDescription.xml" in names
    md2 = fmpy.read_model_description(str(split_fmus[2][group]))
    # the same variables, the FMI 3.0 ones with the runtime's Int32 counters and `time` besides
    assert {v.name for v in md2.modelVariables} <= {v.name for v in md.modelVariables}
    assert [v.name for v in md.modelVariables if v.causality == "input"] == list(INPUTS[group])


@pytest.mark.parametrize("fmi_type", ["ModelExchange", "CoSimulation"])
@pytest.mark.parametrize("group", sorted(INPUTS))
def test_scene_group_fmi3_results_equal_fmi2(split_fmus, group, fmi_type):
    kw = dict(fmi_type=fmi_type, stop_time=0.5, output_interval=0.005, input=_table(INPUTS[group]))
    if fmi_type == "ModelExchange":  # CVode at the scene's 1e-10 stalls on the input table's kinks
        kw["relative_tolerance"] = 1e-6
    r2 = fmpy.simulate_fmu(str(split_fmus[2][group]), **kw)
    r3 = fmpy.simulate_fmu(str(split_fmus[3][group]), **kw)
    assert _same(r2, r3) <= 1e-12
    moved = r3["theta"] if group == "joint" else r3["actuator.tau"]
    assert np.ptp(moved) > 1e-3  # the inputs drove it


@pytest.mark.parametrize("interface", ["me", "cs"])
def test_fmusim_runs_the_scene_groups_as_fmi2(split_fmus, tmp_path, interface):
    from test_fmi3_export import _fmusim, _run_fmusim

    exe = _fmusim()
    for group in sorted(INPUTS):
        table = _table(INPUTS[group])
        csv = tmp_path / f"{group}_input.csv"
        np.savetxt(csv, np.array(table.tolist()), delimiter=",", comments="",
                   header=",".join(f'"{n}"' for n in table.dtype.names))
        # the stiff hydraulic chain needs an implicit solver: fmusim's CVode (its Euler blows up at 10 ms)
        extra = ("--input-file", str(csv), "--solver", "cvode", "--tolerance", "1e-6")
        r2, _ = _run_fmusim(exe, split_fmus[2][group], tmp_path, interface, 0.5, extra)
        r3, log3 = _run_fmusim(exe, split_fmus[3][group], tmp_path, interface, 0.5, extra)
        calls = [ln for ln in log3.splitlines() if ln.startswith("fmi3")]
        assert calls and all(ln.endswith("-> OK") for ln in calls), [c for c in calls if not c.endswith("-> OK")]
        assert _same(r2, r3) <= 1e-12, (group, interface)
        assert max(np.ptp(r3[n]) for n in r3.dtype.names[1:]) > 1e-3  # the input file drove it


def test_cli_builds_a_scene_as_fmi3_and_refuses_what_it_cannot(tmp_path, capsys):
    assert cli_main(["build", str(SPLIT), "--fmi-version", "3", "-o", str(tmp_path / "cli")]) == 0
    for group in INPUTS:
        assert fmpy.read_model_description(str(tmp_path / "cli" / f"{group}.fmu")).fmiVersion == "3.0"
    capsys.readouterr()
    # both the flag and --set: refused, naming both; a version that is not 2 or 3: refused naming the file
    assert cli_main(["build", str(SPLIT), "--fmi-version", "3", "--set", "scene.fmi_version=2",
                     "-o", str(tmp_path / "x")]) != 0
    assert "--fmi-version and --set scene.fmi_version" in capsys.readouterr().err
    for bad in ("4", "3.5", "true", "'three'"):
        with pytest.raises(SceneError, match=r"single_joint_split.toml: \[scene\] fmi_version"):
            load_scene(SPLIT, set=[f"scene.fmi_version={bad}"])


def test_report_of_an_fmi3_scene_runs_fmi3_fmus_and_its_monolithic_fmu_is_fmi3(tmp_path):
    """fmugen report on the scene with fmi_version = 3: the groups' FMUs and the monolithic reference FMU
    are FMI 3.0, and the rows equal those of the FMI 2.0 report (the same runtime, bit for bit; extrapolated
    inputs reach the FMI 3.0 FMUs through the intermediate update, tests/test_fmi3_input_interpolation.py)."""
    import csv

    rows = {}
    for version in (2, 3):
        out = tmp_path / f"report{version}"
        assert cli_main(["report", str(SPLIT), "--set", f"scene.fmi_version={version}", "--steps", "0.002",
                         "--schemes", "gauss-seidel/linear", "--repeats", "1", "--stop", "0.2",
                         "--out", str(out)]) == 0
        with open(out / "report.csv") as fh:
            rows[version] = list(csv.DictReader(fh))
        fmus = sorted((out / "fmus").glob("*.fmu"))
        assert {fmpy.read_model_description(str(f)).fmiVersion for f in fmus} == {f"{version}.0"}, fmus
    assert [r["label"] for r in rows[3]] == ["gauss-seidel/linear", "monolithic FMU"]
    assert all(r["status"] == "ok" for r in rows[3])
    for r2, r3 in zip(rows[2], rows[3]):
        assert r3["err_linf"] == r2["err_linf"], (r2["label"], r2["err_linf"], r3["err_linf"])
