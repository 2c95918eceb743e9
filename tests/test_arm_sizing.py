"""Actuator sets for any arm (fmugen.components.arm_sizing): the worst gravity torques equal the PUMA sizing's
independent numpy evaluation over the same poses; the proposals meet their stated rule and load as sets."""
from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.components import arm_sizing, hydraulic_actuator, sizing
from fmugen.components.parameters import load_parameter_set

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def puma_needs():
    grid = np.linspace(-math.pi, math.pi, 3)
    poses = np.array([[0, a, b, c, d, 0] for a, b, c, d in itertools.product(grid, grid, grid, grid)])
    return arm_sizing.requirements(ROOT / "robots/puma_thesis_com.toml", poses=poses), poses


def test_gravity_torques_equal_the_puma_sizing(puma_needs):
    needs, _ = puma_needs
    tau, _ = sizing.worst_case(3)  # hand-written DH frames and cross products over the same grid
    assert [n.tau_g for n in needs] == pytest.approx(list(tau), rel=1e-9, abs=1e-9)


def test_hydraulic_proposal_meets_its_rule_and_loads(puma_needs, tmp_path):
    needs, poses = puma_needs
    sets = arm_sizing.hydraulic_sets(needs)
    P_s = load_parameter_set("default").sections["servo_valve"]["P_s"]
    for nd, (s, n) in zip(needs, sets):
        stall = P_s * s["hydraulic_actuator"]["D_m"]
        assert stall >= 2 * nd.tau_g and stall >= 100.0 * nd.J  # the rule
        assert stall < 1.1 * max(2 * nd.tau_g, 100.0 * nd.J) + 1e-3 * P_s * 1e-6  # rounded up to 2 digits only
        assert n["no_load_speed"] >= 1.25 * nd.w_peak
    paths = arm_sizing.write_sets(sets, tmp_path, "puma")
    act = hydraulic_actuator(parameter_set=str(paths[1]))
    assert {v.name: v.start for v in act.parameters}["D_m"] == sets[1][0]["hydraulic_actuator"]["D_m"]
    assert "margin" in paths[1].read_text().splitlines()[2]


def test_trajectory_torques_and_electric_feasibility():
    arm = fmugen.load_robot(ROOT / "robots/puma_thesis_com.toml")
    t = np.linspace(0, 1, 201)
    Q = np.zeros((len(t), 6))
    Q[:, 1] = -0.4 + 0.3 * t**2  # joint 2 accelerating at 0.6 rad/s^2
    needs = arm_sizing.requirements(arm, poses=Q[::50], trajectory=(t, Q))
    ref = max(abs(arm.inverse_dynamics(q, np.r_[0, 0.6 * tk, 0, 0, 0, 0], np.r_[0, 0.6, 0, 0, 0, 0])[1])
              for tk, q in zip(t, Q))
    assert needs[1].tau_peak == pytest.approx(ref, rel=1e-9)  # second-order differences: exact on t^2
    assert needs[1].w_peak == pytest.approx(0.6, rel=1e-2)
    (s, n), = arm_sizing.electric_sets(needs[1:2])
    assert n["max_torque"] >= 1.5 * max(needs[1].tau_peak, needs[1].tau_g) and n["feasible"]
    (s, n), = arm_sizing.electric_sets(needs[1:2], w_m_max=1.0)
    assert not n["feasible"]


def test_cli_refuses_a_zero_margin_and_a_junk_trajectory(tmp_path):
    """--margin 0 was silently replaced by the default (``args.margin or 2.0``); a non-number in the
    trajectory CSV became nan and reached the written sets."""
    import subprocess
    import sys

    csv = tmp_path / "q.csv"
    csv.write_text("time,q1,q2,q3,q4,q5,q6\n" + "\n".join(f"{0.1 * k},0,x,0,0,0,0" for k in range(4)) + "\n")
    for extra, match in ((["--margin", "0"], "--margin positive"), (["--trajectory", str(csv)], "finite number")):
        out = subprocess.run([sys.executable, "-m", "fmugen.cli", "size", "robots/stanford_arm.toml", *extra, "--out",
                              str(tmp_path / "sets")], capture_output=True, text=True, cwd=ROOT)
        assert out.returncode == 2 and match in out.stderr, out.stderr
        assert not list((tmp_path / "sets").glob("*.toml"))


def test_a_horizontal_base_axis_is_swept_too(tmp_path):
    """Horn's 2R arm with gravity along -x0 (its base axis horizontal): q1 = 0 hangs link 1 along gravity,
    so a grid that keeps q1 = 0 (the docstring said this was checked; it was assumed) finds only link 2's
    m g l/2.  The worst joint-1 torque is the straight arm held horizontally, 2 m g l (closed form)."""
    text = (ROOT / "robots/horn_2link.toml").read_text().replace('gravity = [0, "-g", 0]', 'gravity = ["-g", 0, 0]')
    for name, value in (("m", 1.5), ("l", 0.7), ("g", 9.81)):
        text = text.replace(f'{name} = {{ unit', f'{name} = {{ value = {value}, unit', 1)
    (tmp_path / "arm.toml").write_text(text)
    need = arm_sizing.requirements(tmp_path / "arm.toml", n_grid=5)
    assert need[0].tau_g == pytest.approx(2 * 1.5 * 9.81 * 0.7, rel=1e-12)
    assert need[1].tau_g == pytest.approx(1.5 * 9.81 * 0.7 / 2, rel=1e-12)
    arm = fmugen.load_robot(ROOT / "robots/puma_thesis_com.toml")  # vertical base axis: q1 stays 0
    assert set(arm_sizing.pose_grid(arm, 3)[:, 0]) == {0.0}


def test_symbolic_parameters_take_set_values(tmp_path):
    """Horn's arm keeps m, l, g symbolic: fmugen size takes them by --set (it had no way to, and its message
    named a Python keyword); the worst torques are the closed forms 2 m g l and m g l/2 (arm horizontal)."""
    import subprocess
    import sys

    need = arm_sizing.requirements(ROOT / "robots/horn_2link.toml", params={"m": 1.5, "l": 0.7, "g": 9.81})
    assert [n.tau_g for n in need] == pytest.approx([2 * 1.5 * 9.81 * 0.7, 1.5 * 9.81 * 0.7 / 2], rel=1e-12)
    cmd = [sys.executable, "-m", "fmugen.cli", "size", "robots/horn_2link.toml", "--out", str(tmp_path / "s")]
    out = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 2 and "need a value: --set m=VALUE" in out.stderr
    out = subprocess.run(cmd + ["--set", "m=1.5", "--set", "l=0.7", "--set", "g=9.81"], capture_output=True,
                         text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert "worst gravity torque 20.6," in (tmp_path / "s" / "joint1.toml").read_text()  # 2 m g l = 20.601


def test_a_prismatic_joint_gets_a_linear_cylinder(tmp_path):
    """The Stanford arm's joint 3 slides: its set sizes the linear cylinder's A_p and the moving mass M (the
    set used to carry only D_m [m3/rad] and J [kg.m2], which a linear cylinder and a prismatic joint ignore,
    so they ran on the default's A_p and M).  The cylinder built from the set has stall force P_s A_p
    >= 2 x the worst gravity force and M = the worst mass along the joint."""
    from fmugen.components import joint_inertia

    needs = arm_sizing.requirements(ROOT / "robots/stanford_arm.toml", n_grid=3)
    assert [n.revolute for n in needs] == [True, True, False, True, True, True]
    sets = arm_sizing.hydraulic_sets(needs)
    paths = arm_sizing.write_sets(sets, tmp_path, "stanford")
    cyl = {v.name: v.start for v in hydraulic_actuator(kind="linear", parameter_set=str(paths[2])).parameters}
    P_s = load_parameter_set("default").sections["servo_valve"]["P_s"]
    assert P_s * cyl["A_p"] >= 2 * needs[2].tau_g > 0
    mass = {v.name: v.start for v in joint_inertia(kind="prismatic", parameter_set=str(paths[2])).parameters}
    assert mass["M"] == pytest.approx(needs[2].J, abs=1e-4)
    assert "prismatic: a linear cylinder" in paths[2].read_text() and "A_p" not in paths[1].read_text().split("[")[0]
