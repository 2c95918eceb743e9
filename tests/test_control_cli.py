"""``fmugen linearize``: the written .npz equals the API's matrices; errors are one clear line."""
import numpy as np
import pytest

import fmugen
from fmugen.cli import main
from fmugen.control import linearize, trim

Q0 = [0.3, -0.5, 0.8, 0.2, -0.4, 0.6]


def test_puma_held_at_a_pose(tmp_path, capsys):
    out = tmp_path / "puma.npz"
    rc = main(["linearize", "robots/puma_thesis_com.toml", "--at", "q=" + ",".join(map(str, Q0)),
               "--at", "qd=0", "--trim", "tau", "--outputs", "q,p_ee", "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "12 states, 6 inputs, 9 outputs" in text and "controllability rank 12/12" in text
    assert "stiffness ratio" in text and "damping" in text
    z = np.load(out)
    arm = fmugen.load_robot("robots/puma_thesis_com.toml")
    assert np.allclose(z["u0"], arm.bias(np.array(Q0), np.zeros(6)), rtol=1e-12, atol=1e-9)
    model = arm.state_space_model(outputs=("p_ee",))
    ref = linearize(model, trim(model, at={"q": Q0, "qd": 0.0}, free=["tau"]), outputs=["q", "p_ee"])
    for k in "ABCD":
        assert np.array_equal(z[k], getattr(ref, k))
    assert list(z["states"]) == [f"q[{i}]" for i in range(1, 7)] + [f"qd[{i}]" for i in range(1, 7)]
    assert list(z["outputs"])[-3:] == ["p_ee[1]", "p_ee[2]", "p_ee[3]"]
    assert np.allclose(z["y0"][-3:], arm.fk(np.array(Q0))[:3, 3], atol=1e-12)
    # the printed eigenvalues are A's
    assert f"{np.max(np.linalg.eigvals(z['A']).real):.6g}" in text


def test_open_loop_scene(tmp_path, capsys):
    """A scene with its path source removed: the amplifier's reference becomes an input."""
    out = tmp_path / "sj.npz"
    rc = main(["linearize", "examples/scenes/single_joint_split.toml", "--without", "path",
               "--at", "amp.theta_ref=0.1", "--at", "joint.tau_load=50", "--inputs", "amp.theta_ref",
               "--outputs", "joint.theta", "--out", str(out)])
    assert rc == 0
    z = np.load(out)
    assert list(z["inputs"]) == ["amp.theta_ref"] and list(z["outputs"]) == ["joint.theta"]
    assert "joint.tau_load" in list(z["all_inputs"])
    # P_L holds the load: tau_load / D_m (default set, D_m = 1.5e-5 m3/rad)
    states = list(z["states"])
    assert z["x0"][states.index("actuator.P_L")] == pytest.approx(50.0 / 1.5e-5, rel=1e-12)
    # P position servo under a constant load: the load fixes P_L, hence the spool opening and the
    # error that commands it, so a change of reference moves the joint by as much: static gain 1
    A, B, C, D = (z[k] for k in "ABCD")
    G = (D - C @ np.linalg.solve(A, B))[0, 0]
    assert G == pytest.approx(1.0, rel=1e-9)


@pytest.mark.parametrize("argv, message", [
    (["--at", "qq=1", "--trim", "tau"], "no state/input/output named 'qq'"),
    (["--at", "q=1,2", "--trim", "tau"], "'q' has 6 element"),
    (["--at", "q=a", "--trim", "tau"], "VALUES must be comma-separated numbers"),
    (["--at", "q=0", "--at", "qd=0.1", "--trim", "tau"], "no operating point found"),
    (["--without", "amp"], "--without applies to scenes only"),
])
def test_bad_requests_are_one_line_errors(tmp_path, capsys, argv, message):
    rc = main(["linearize", "robots/puma_thesis_com.toml", *argv, "--out", str(tmp_path / "x.npz")])
    assert rc == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "x.npz").exists()


def test_no_trim_and_set(tmp_path):
    """--no-trim linearises where told (here a moving arm); --set changes a parameter of the file."""
    out = tmp_path / "moving.npz"
    rc = main(["linearize", "robots/puma_thesis_com.toml", "--no-trim", "--at", "q=" + ",".join(map(str, Q0)),
               "--at", "qd=0.5", "--at", "tau=10", "--set", "m_3=7.5", "--out", str(out)])
    assert rc == 0
    z = np.load(out)
    model = fmugen.load_robot("robots/puma_thesis_com.toml").state_space_model(outputs=())
    ref = linearize(model, np.r_[Q0, np.full(6, 0.5)], np.full(6, 10.0), parameter_values={"m_3": 7.5})
    assert np.array_equal(z["A"], ref.A) and np.array_equal(z["B"], ref.B)
    assert np.isnan(z["residual"])
    rc = main(["linearize", "robots/puma_thesis_com.toml", "--no-trim", "--set", "m_3=heavy",
               "--out", str(tmp_path / "y.npz")])
    assert rc == 2
