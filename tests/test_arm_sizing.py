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
