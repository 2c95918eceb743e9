"""examples/control_design_puma.py: LQR gains designed on the linearisation hold on the nonlinear plant.

For a reference step of size h the nonlinear response differs from the
linear prediction by O(h^2) when A, B are the true Jacobians at the trimmed
point (an error in them would leave an O(h) difference).  Checked on the
PUMA hydraulic scene with steps small enough that no servo spool crosses
its null (2e-4 and 4e-4 rad: the difference grows by 4), and for a
working-size 0.01 rad step (spools cross null, where the orifice law has a
kink): below 1 % of the step.
"""
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("control_design_puma", ROOT / "examples" / "control_design_puma.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def puma_design(example):
    return example.design(ROOT / "examples" / "scenes" / "puma_hydraulic.toml")


def test_trim_holds_the_pose_and_the_loop_is_stable(puma_design):
    d = puma_design
    assert np.allclose(d["op"].x[d["pos_index"]], [0.3, -0.5, 0.8, 0.2, -0.4, 0.6], atol=0)
    assert d["op"].max_residual < 1e-9
    assert d["poles"].real.max() < -1.0
    # the prefilter gives unit static gain from each reference to its joint
    assert np.allclose(d["sys_cl"].dcgain(), np.eye(6), atol=1e-9)


def test_nonlinear_response_follows_the_linear_prediction_to_second_order(example, puma_design):
    # steps small enough that no spool crosses its null (where the flow law has a kink)
    h = 2e-4
    _, lin1, nl1 = example.compare(puma_design, joint=2, step=h, t_end=0.4, n=201, rtol=1e-10)
    _, lin2, nl2 = example.compare(puma_design, joint=2, step=2 * h, t_end=0.4, n=201, rtol=1e-10)
    e1, e2 = np.abs(nl1 - lin1).max(), np.abs(nl2 - lin2).max()
    assert e1 < 1e-3 * h
    assert 3.6 < e2 / e1 < 4.4  # O(h^2)
    assert abs(nl1[-1, 1] - h) < 1e-3 * h  # the joint reached its reference


def test_a_working_size_step_stays_within_one_percent(example, puma_design):
    """0.01 rad: spools 2 and 3 cross null, the difference grows to O(h) but stays small."""
    h = 0.01
    _, lin, nl = example.compare(puma_design, joint=2, step=h, t_end=0.4, n=201)
    assert np.abs(nl - lin).max() < 0.01 * h


def test_the_one_joint_rig_runs_from_the_command_line(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "control_design_puma.py"),
                        "--scene", str(ROOT / "examples" / "scenes" / "single_joint_split.toml"),
                        "--positions", "joint.theta", "--pose", "0.2", "--at", "joint.tau_load=50",
                        "--joint", "1", "--duration", "0.4", "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    for f in ("bode.png", "step.png", "nonlinear_vs_linear.png", "nonlinear_vs_linear.csv"):
        assert (tmp_path / f).stat().st_size > 0
    data = np.genfromtxt(tmp_path / "nonlinear_vs_linear.csv", delimiter=",", skip_header=1)
    assert np.abs(data[:, 1] - data[:, 2]).max() < 0.03 * 0.02  # default step 0.02 rad
    h = subprocess.run([sys.executable, str(ROOT / "examples" / "control_design_puma.py"), "--help"],
                       capture_output=True, text=True)
    assert h.returncode == 0 and "LQR" in h.stdout


def test_amplifier_gain_design_checked_in_the_cosimulation_master(example):
    """Part B on the one-joint split scene: the chosen K_a speeds up the slowest mode, and the
    co-simulated scene (two FMUs, fmugen.cosim.run) follows the closed scene's linear prediction."""
    scene = ROOT / "examples" / "scenes" / "single_joint_split.toml"
    g = example.amplifier_gains(scene)
    assert g["rate"] > 1.1 * g["rate0"]  # 6.1 -> 7.6 1/s
    # an optimum: 10 % more or less gain makes the slowest mode slower
    G = g["plant"]
    for f in (0.9, 1.1):
        assert example.slowest_decay(G.A - G.B @ np.diag(f * g["K"]) @ G.C) < g["rate"]
    move = 0.01
    t, lin, cos, pos = example.cosim_against_linear(scene, g, joint=1, move=move, stop=0.5)
    assert pos == "joint.theta"
    assert abs(cos[-1, 0] - cos[0, 0]) > 0.9 * move  # it moved
    assert np.abs(cos - lin).max() < 0.02 * move
