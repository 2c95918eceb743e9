"""What a scene's FMUs tell any importer: the scene's internal solver and tolerances and the state of rest
(inputs included) as start values, the system's inputs made explicit, prune honoured, stale FMUs removed."""
import json
from pathlib import Path

import fmpy
import pytest

import fmugen
from fmugen.cli import main

ROOT = Path(__file__).resolve().parents[1]
SPLIT = ROOT / "examples" / "scenes" / "single_joint_split.toml"
TAU_LOAD = 50.0


def _scene_file(tmp_path, extra_scene="", joint="joint = { type = \"joint_inertia\" }"):
    text = SPLIT.read_text().replace('initial = "given"', 'initial = "equilibrium"' + extra_scene)
    text = text.replace('joint = { type = "joint_inertia" }', joint)
    text = text.replace('path = { type = "ptp_trajectory"', 'path = { type = "ptp_trajectory"')
    p = tmp_path / "scene.toml"
    p.write_text(text)
    return p


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    d = tmp_path_factory.mktemp("iface")
    f = _scene_file(d, '\ninputs = ["joint.tau_load"]',
                    f'joint = {{ type = "joint_inertia", start = {{ tau_load = {TAU_LOAD} }} }}')
    out = d / "out"
    out.mkdir()
    # an earlier build's FMU (listed in the folder's manifest) and a file of the user's (not listed)
    (out / "old_group.fmu").write_bytes(b"stale")
    (out / "mine.fmu").write_bytes(b"user")
    (out / ".fmugen-build.json").write_text(json.dumps({"fmus": ["old_group.fmu", "../escape.fmu"]}))
    (d / "escape.fmu").write_bytes(b"outside")
    scene = fmugen.load_scene(f)
    return d, scene, scene.build(out)


def _starts(fmu):
    md = fmpy.read_model_description(str(fmu))
    return md, {v.name: v for v in md.modelVariables}


def test_inputs_start_at_rest_and_solver_baked(built):
    d, scene, b = built
    md, v = _starts(b.fmus["joint"].path)
    # at rest the joint does not accelerate: J w' = tau - B_m w - tau_load = 0 with w = 0, so tau = tau_load
    assert v["tau"].causality == "input"
    assert abs(float(v["tau"].start) - TAU_LOAD) < 1e-8 * TAU_LOAD
    assert v["tau_load"].causality == "input" and float(v["tau_load"].start) == TAU_LOAD  # [scene] inputs
    _, c = _starts(b.fmus["chain"].path)
    assert abs(float(c["amp.theta"].start) - scene.initial.values["joint.theta"]) < 1e-15
    for fmu in (b.fmus["joint"].path, b.fmus["chain"].path):
        md, v = _starts(fmu)
        assert (v["solver.method"].start, float(v["solver.rtol"].start), float(v["solver.atol"].start)) == \
            ("2", 1e-10, 1e-10)
        assert md.defaultExperiment.stepSize == "0.001"
        # the binary's own defaults are what the XML says: an importer that sets nothing gets RODAS3 at 1e-10
        from fmpy.fmi2 import FMU2Slave

        fmu2 = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(fmu)),
                         modelIdentifier=md.coSimulation.modelIdentifier, instanceName="x")
        fmu2.instantiate()
        fmu2.setupExperiment()
        fmu2.enterInitializationMode()
        fmu2.exitInitializationMode()
        assert fmu2.getInteger([v["solver.method"].valueReference]) == [2]
        assert fmu2.getReal([v["solver.rtol"].valueReference, v["solver.atol"].valueReference]) == [1e-10, 1e-10]
        fmu2.terminate()
        fmu2.freeInstance()


def test_summary_names_inputs_and_stale_files(built):
    d, scene, b = built
    text = b.summary()
    assert "inputs of the system: joint.tau_load" in text
    assert "held-input Jacobi" in text
    assert b.stale == ["old_group.fmu"]
    out = b.out_dir
    assert not (out / "old_group.fmu").exists()
    assert (out / "mine.fmu").read_bytes() == b"user"  # not ours: kept
    assert (d / "escape.fmu").read_bytes() == b"outside"  # a manifest never reaches outside the folder
    assert json.loads((out / ".fmugen-build.json").read_text())["fmus"] == ["chain.fmu", "joint.fmu"]


def test_prune_false_in_the_file_is_honoured(tmp_path, capsys):
    f = _scene_file(tmp_path, "\nprune = false")
    scene = fmugen.load_scene(f)
    assert scene.system_inputs() == ["joint.tau_load"]
    assert main(["info", str(f)]) == 0
    out = capsys.readouterr().out
    assert "inputs tau, tau_load" in out  # with pruning tau_load would be fixed
    assert main(["info", str(SPLIT)]) == 0
    assert "inputs tau;" in capsys.readouterr().out


def test_refusals(tmp_path, capsys):
    assert main(["build", str(SPLIT), "--fmi-type", "both", "-o", str(tmp_path / "x")]) == 2
    assert "--fmi-type does not apply to a scene" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    f = _scene_file(tmp_path, '\ninputs = ["joint.tau"]')
    with pytest.raises(ValueError, match="driven by a connection"):
        fmugen.load_scene(f)
    f = _scene_file(tmp_path, '\ninputs = ["joint.theta"]')
    with pytest.raises(ValueError, match="is a state, not an input"):
        fmugen.load_scene(f)
