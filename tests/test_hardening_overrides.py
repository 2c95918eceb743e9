"""Hardening, third round: an override passes the physical checks a file value gets, and no
number, nesting or zero crashes a command.

Paths by which a value arrives: a file, a scene's ``parameters`` and ``start`` tables,
``--set`` (scene, robot, assembly), a sweep point.  Each must refuse what a file would
refuse, with the place named; values beyond the double range, TOML nested thousands deep
and zeros folded into a denominator give one clear line (exit 2), never a traceback.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest

import fmugen
from fmugen.cli import main
from fmugen.errors import FmugenError
from fmugen.scene import SceneError, load_scene

ROOT = Path(__file__).resolve().parents[1]
SPLIT = ROOT / "examples" / "scenes" / "single_joint_split.toml"
STIFF = ROOT / "examples" / "single_joint_stiff.toml"
HUGE = "7" + "3" * 330  # an integer beyond the double range (TOML and --set read it as an int)

ARM = """
[robot]
name = "ratio_arm"
gravity = [0, 0, -9.81]
[parameters]
m1 = 3.0
k = 1.5
[[links]]
name = "l1"
joint = "revolute"
a = 0.4
alpha = 0
d = 0
theta = 0
mass = "m1/k"
com = [-0.2, 0, 0]
inertia = [0.002, 0.05, 0.05]
[[links]]
name = "l2"
joint = "revolute"
a = 0.3
alpha = 0
d = 0
theta = 0
mass = 1.25
com = [-0.15, 0, 0]
inertia = [0.001, 0.02, 0.02]
"""

SCENE = """
[scene]
name = "ratio"
stop = {stop}
start = {start}
step = {step}
[instances.arm]
robot = "arm.toml"
{extra}
[fmus.arm]
members = ["arm"]
"""


def _files(tmp_path, extra="", start="0.0", stop="0.2", step="1e-3") -> Path:
    (tmp_path / "arm.toml").write_text(ARM)
    p = tmp_path / "scene.toml"
    p.write_text(SCENE.format(extra=extra, start=start, stop=stop, step=step))
    return p


def _cli(capsys, *argv) -> str:
    assert main(list(argv)) == 2
    err = capsys.readouterr().err
    assert err.startswith("fmugen: ") and err.count("\n") == 1 and "Traceback" not in err, err
    return err


# ----------------------------------------------------------------- one check on every path
@pytest.mark.parametrize("value", ["-0.37", "0", "-1e-300"])
def test_a_component_value_is_checked_whatever_path_it_takes(tmp_path, capsys, value):
    text = SPLIT.read_text()
    # start table
    p = tmp_path / "s.toml"
    p.write_text(text.replace('joint = { type = "joint_inertia" }',
                              f'joint = {{ type = "joint_inertia", start = {{ J = {value} }} }}'))
    assert "start.J" in _cli(capsys, "info", str(p))
    # parameters table
    p.write_text(text.replace('joint = { type = "joint_inertia" }',
                              f'joint = {{ type = "joint_inertia", parameters = {{ J = {value} }} }}'))
    assert "J = " in _cli(capsys, "info", str(p))
    # --set on a scene, and on an assembly file
    assert "J" in _cli(capsys, "info", str(SPLIT), "--set", f"joint.J={value}")
    err = _cli(capsys, "info", str(STIFF), "--set", f"valve.P_s={value}")
    assert "--set valve.P_s" in err and "> 0" in err
    # --set of a suite run on a user's file (start values by FMI name)
    err = _cli(capsys, "suite", str(STIFF), "--set", f"valve.P_s={value}", "--quick", "--out", str(tmp_path / "sx"))
    assert "--set valve.P_s" in err and not (tmp_path / "sx").exists()


@pytest.mark.parametrize("value", ["-0.05", "0"])
def test_a_robot_override_is_checked_like_the_file(tmp_path, capsys, value):
    scene = _files(tmp_path)
    err = _cli(capsys, "info", str(scene), "--set", f"arm.m1={value}")
    assert "--set arm.m1" in err and "mass" in err and "positive" in err
    err = _cli(capsys, "info", str(tmp_path / "arm.toml"), "--set", f"m1={value}")
    assert "--set" in err and "link 1 (l1): mass" in err
    p = _files(tmp_path, extra=f"parameters = {{ m_2 = {value} }}")
    assert "link 2 (l2): mass" in _cli(capsys, "info", str(p))
    # an override that makes a link's inertia unrealisable (the triangle inequality)
    p = _files(tmp_path, extra="parameters = { I_2_xx = 0.5 }")
    assert "not a realisable rigid body" in _cli(capsys, "info", str(p))


def test_a_zero_folded_into_a_denominator_names_the_value(tmp_path, capsys):
    # through the scene (start or parameters): refused before any code is generated
    err = _cli(capsys, "info", str(_files(tmp_path, extra="start = { k = 0.0 }")))
    assert "mass" in err and "k = 0.0" in err and "zoo" not in err
    # the model layer refuses to fold it even when asked directly (never zoo in C)
    arm = fmugen.load_robot(tmp_path / "arm.toml")
    m = arm.state_space_model().with_starts({"k": 0.0})
    with pytest.raises(FmugenError, match=r"k = 0 the equations divide by zero"):
        m.with_parameters_folded(["k"])


def test_a_sweep_point_failing_the_checks_is_refused_not_run(tmp_path):
    from fmugen.sweep.errors import PointRefused
    from fmugen.sweep.prepare import SweepPlan

    plan = SweepPlan(SPLIT, ["joint.J", "actuator.V_t"], tmp_path / "fmus")
    plan.check_point(0, {"joint.J": 0.4, "actuator.V_t": 1e-4})
    with pytest.raises(PointRefused, match=r"refused: point 1: joint.J = -0.2 is not > 0"):
        plan.task(1, "k", {"joint.J": -0.2, "actuator.V_t": 1e-4})
    with pytest.raises(PointRefused, match=r"actuator.V_t = 0.0"):
        plan.check_point(2, {"joint.J": 0.4, "actuator.V_t": 0.0})
    arm = SweepPlan(_files(tmp_path), ["arm.k"], tmp_path / "fmus2")
    arm.check_point(0, {"arm.k": 3.0})
    with pytest.raises(PointRefused, match=r"l1.*mass"):
        arm.check_point(1, {"arm.k": -2.0})


# ----------------------------------------------------------------- crashes
def test_integers_beyond_the_double_range_are_clear_errors(tmp_path, capsys):
    assert "digits" in _cli(capsys, "info", str(SPLIT), "--set", f"joint.J={HUGE}")
    assert "stop" in _cli(capsys, "info", str(_files(tmp_path, stop=HUGE)))
    assert "step" in _cli(capsys, "info", str(_files(tmp_path, step=HUGE)))
    assert "locked" in _cli(capsys, "info", str(_files(tmp_path, extra=f'locked = {{ "q[2]" = {HUGE} }}')))
    assert "start.k" in _cli(capsys, "info", str(_files(tmp_path, extra=f"start = {{ k = {HUGE} }}")))
    text = SPLIT.read_text().replace('["joint.w", "actuator.w"]',
                                     f'{{ from = "joint.w", to = "actuator.w", factor = {HUGE} }}')
    p = tmp_path / "f.toml"
    p.write_text(text)
    assert "factor" in _cli(capsys, "info", str(p))
    pset = tmp_path / "p.toml"
    pset.write_text(f"[joint_inertia]\nJ = {HUGE}\n")
    p.write_text(SPLIT.read_text().replace('parameter_set = "default"', 'parameter_set = "p.toml"'))
    assert "p.toml" in _cli(capsys, "info", str(p))
    assert "digits" in _cli(capsys, "info", str(tmp_path / "arm.toml"), "--set", f"k={HUGE}")


@pytest.mark.parametrize("kind", ["scene", "robot", "parameter set", "assembly"])
def test_toml_nested_thousands_deep_is_a_clear_error(tmp_path, capsys, kind):
    deep = "[" * 2600 + "]" * 2600
    p = tmp_path / "deep.toml"
    head = {"scene": "[scene]\nname = \"x\"\n", "robot": "[robot]\nname = \"x\"\n",
            "parameter set": "", "assembly": "[assembly]\nname = \"x\"\n"}[kind]
    p.write_text(f"{head}v = {deep}\n")
    if kind == "parameter set":
        from fmugen.components.parameters import load_parameter_set

        with pytest.raises(FmugenError, match="nested too deeply"):
            load_parameter_set(p)
        return
    assert "nested too deeply" in _cli(capsys, "info", str(p))


def test_a_run_where_no_macro_step_fits_is_refused(tmp_path, capsys):
    err = _cli(capsys, "info", str(_files(tmp_path, start="1e15", stop=repr(1e15 + 0.125), step="1e-3")))
    assert "no macro step fits" in err
    err = _cli(capsys, "info", str(_files(tmp_path, stop="1e300", step="1e-3")))
    assert "macro steps" in err and "1e+303" in err
    with pytest.raises(SceneError, match="no macro step fits"):
        load_scene(_files(tmp_path), set={"scene.start": 3e16, "scene.stop": 3e16 + 8})
