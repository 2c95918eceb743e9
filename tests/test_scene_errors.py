"""Everything a scene refuses, it refuses clearly: file, key, reason; exit 2; nothing written."""
import math
import textwrap
from pathlib import Path

import pytest

from fmugen.cli import main
from fmugen.scene import SceneError, load_scene, parse_sets

SPLIT = Path("examples/scenes/single_joint_split.toml")


def scene_text(**replace):
    text = SPLIT.read_text()
    for a, b in replace.items():
        assert a in text
        text = text.replace(a, b)
    return text


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


@pytest.mark.parametrize("old, new, message", [
    ('["joint.theta", "amp.theta"]', '["jont.theta", "amp.theta"]', r"no instance 'jont' \(did you mean 'joint'\?\)"),
    ('["joint.theta", "amp.theta"]', '["joint.thet", "amp.theta"]', r"joint has no variable 'thet' \(did you mean 'theta'\?\)"),
    ('["joint.theta", "amp.theta"]', '["amp.theta", "joint.theta"]', r"wrong direction: amp.theta is an input"),
    ('["joint.w", "actuator.w"]', '["joint.w", "actuator.Q_L"]', r"unit mismatch: joint.w is in \[rad/s\] but actuator.Q_L expects \[m3/s\]"),
    ('["valve.Q_L", "actuator.Q_L"]', '["valve.Q_L", "amp.theta_ref"]', r"unit mismatch: valve.Q_L is in \[m3/s\] but amp.theta_ref expects \[rad\]"),
    ('["actuator.tau", "joint.tau"]', '["actuator.tau", "joint.tau"], ["actuator.P_L", "joint.tau"]', r"unit mismatch"),
    ('["actuator.tau", "joint.tau"]', '["actuator.tau", "joint.tau"], ["actuator.tau", "joint.tau"]', r"already driven"),
    ('record = ["joint.theta",', 'record = ["joint.tau",', r"record: joint.tau is an input"),
    ('stop = 1.0', 'stop = -1.0', r"\[scene\] stop \(-1.0\) must be after start"),
    ('step = 1e-3 ', 'step = nan ', r"\[scene\] step must be a finite number"),
    ('members = ["joint"]', 'members = ["joint", "amp"]', r"instance 'amp' is in two FMUs"),
    ('members = ["joint"]', 'members = ["jiont"]', r"no instance 'jiont' \(did you mean 'joint'\?\)"),
    ('solver = "rodas3"\n\n[fmus.joint]', 'solver = "radau"\n\n[fmus.joint]', r"solver = 'radau'; choose one of"),
    ('joint = { type = "joint_inertia" }', 'joint = { type = "joint_inertia", parameters = { J = inf } }', r"parameters.J must be a finite number"),
    ('joint = { type = "joint_inertia" }', 'joint = { type = "joint_inerta" }', r"type = 'joint_inerta' is not a component type \(did you mean 'joint_inertia'\?\)"),
    ('joint = { type = "joint_inertia" }', 'joint = { type = "joint_inertia", colour = "red" }', r"unknown key 'colour'"),
])
def test_bad_scene_is_refused_naming_file_key_and_reason(tmp_path, old, new, message):
    p = write(tmp_path, scene_text(**{old: new}))
    with pytest.raises(SceneError, match=message) as exc:
        load_scene(p)
    assert str(p) in str(exc.value)


def test_algebraic_loop_is_named(tmp_path):
    # a static driver and a static valve feed the valve flow straight back into the amplifier
    text = scene_text(**{'driver = { type = "current_driver", kind = "lag" }':
                         'driver = { type = "current_driver", kind = "static" }',
                         '["joint.theta", "amp.theta"]': '{ from = "driver.i", to = "amp.theta", factor = 1.0 }'})
    with pytest.raises(SceneError, match=r"algebraic loop through .*amp\.theta.*driver\.u|algebraic loop through .*driver\.u.*amp\.theta"):
        load_scene(write(tmp_path, text))


def test_stated_conversion_passes_the_unit_check(tmp_path):
    text = scene_text(**{'["joint.theta", "amp.theta"]': '{ from = "joint.theta", to = "amp.theta", factor = 2.0 }'})
    sc = load_scene(write(tmp_path, text))
    m = sc.monolithic_model()
    assert m.nx == 6


def test_locked_joint_that_does_not_exist(tmp_path):
    text = Path("examples/scenes/puma_hydraulic.toml").read_text().replace(
        'formulation = "newton_euler"', 'formulation = "newton_euler"\nlocked = { "q[7]" = 0.1 }')
    p = tmp_path / "examples" / "scenes"
    p.mkdir(parents=True)
    f = p / "s.toml"
    f.write_text(text.replace("../../robots/", str(Path("robots").resolve()) + "/"))
    with pytest.raises(SceneError, match=r"\[instances.arm\].*locked joint\(s\) \[7\] do not exist \(joints 1..6\)"):
        load_scene(f).base_models


@pytest.mark.parametrize("sets, message", [
    (["joint.JJ=5"], r"'JJ' is not a parameter, state, input or discrete state of joint \(did you mean 'J'\?\)"),
    (["jont.J=5"], r"no instance 'jont' \(did you mean 'joint'\?\)"),
    (["joint.J=nan"], r"not a finite number"),
    (["joint.J=1e999"], r"not a finite number"),
    (["scene.stopp=2"], r"no key 'stopp' in \[scene\] \(did you mean 'stop'\?\)"),
    (["J"], r"expected NAME=VALUE"),
])
def test_bad_set_is_refused(sets, message):
    with pytest.raises(SceneError, match=message):
        load_scene(SPLIT, set=sets).base_models


def test_parse_sets_reads_toml_scalars_and_words_never_code():
    got = parse_sets(["a.b=5", "c=1e-3", "d.e=true", "f.g=PI", "h.i=\"x y\""])
    assert got == {"a.b": 5, "c": 1e-3, "d.e": True, "f.g": "PI", "h.i": "x y"}
    with pytest.raises(SceneError):
        parse_sets(["a=__import__('os').system('true')"])
    with pytest.raises(SceneError):
        parse_sets({"a": math.inf})


def test_cli_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys):
    p = write(tmp_path, scene_text(**{'["joint.w", "actuator.w"]': '["joint.w", "actuator.Q_L"]'}))
    out = tmp_path / "out"
    assert main(["build", str(p), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "unit mismatch" in err and str(p) in err
    assert not out.exists() or not list(out.iterdir())
    assert main(["build", str(tmp_path / "missing.toml"), "-o", str(out)]) == 2
    assert main(["info", str(SPLIT), "--set", "joint.nope=1"]) == 2


def test_equilibrium_refused_above_stall_torque(tmp_path):
    # default set: stall torque P_s D_m = 14 MPa * 1.5e-5 m3/rad = 210 N.m; ask the joint to hold 500 N.m
    text = scene_text(**{'joint = { type = "joint_inertia" }': 'joint = { type = "joint_inertia", start = { tau_load = 500.0 } }',
                         'initial = "given"': 'initial = "equilibrium"'})
    with pytest.raises(SceneError, match=r"initial = \"equilibrium\".*(stall torque|no state of rest)"):
        load_scene(write(tmp_path, text)).initial


def test_user_factory_needs_permission_and_then_works(tmp_path, monkeypatch):
    (tmp_path / "my_parts.py").write_text(
        "from fmugen.components import joint_inertia\n"
        "def heavy_joint(name, parameter_set='default', overrides=None, scale=1.0):\n"
        "    o = dict(overrides or {}); o.setdefault('J', 2.0 * scale)\n"
        "    return joint_inertia(parameter_set=parameter_set, overrides=o, name=name)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    text = scene_text(**{'joint = { type = "joint_inertia" }':
                         'joint = { factory = "my_parts:heavy_joint", options = { scale = 3.0 } }'})
    p = write(tmp_path, text)
    with pytest.raises(SceneError, match=r"factory = 'my_parts:heavy_joint' runs Python code.*--allow-factories"):
        load_scene(p)
    sc = load_scene(p, allow_factories=True)
    assert {v.name: v.start for v in sc.base_models["joint"].parameters}["J"] == 6.0
