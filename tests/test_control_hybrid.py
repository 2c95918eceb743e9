"""Linearising a hybrid model: the mode the operating point is in, and it says which.

lib:stick_slip (J = 0.05, b = 0.02): stuck (mode = 0) the shaft is held, A = 0 and B = 0 (no input moves
it); sliding (mode = 1) dw/dt = (tau - T_c - b w)/J, so A has the eigenvalue -b/J = -0.4 1/s and B = 1/J.
"""
import numpy as np

from fmugen.components.equations import library_path, load_component
from fmugen.control.linearize import linear_model


def test_each_mode_linearises_to_its_own_equations():
    m = load_component(library_path("stick_slip"))
    stuck = linear_model(m, x=[0.0, 0.0], u=[1.0])
    assert stuck.mode == {"mode": 0.0}
    assert np.all(stuck.A == 0.0) and np.all(stuck.B == 0.0)
    sliding = linear_model(m, x=[0.0, 1.0], u=[1.0], parameter_values={"mode": 1.0})
    assert sliding.mode == {"mode": 1.0}
    assert np.allclose(np.sort(np.linalg.eigvals(sliding.A)), [-0.4, 0.0], atol=1e-14)
    assert np.allclose(sliding.B[:, 0], [0.0, 1 / 0.05], atol=1e-14)


def test_the_cli_says_which_mode(capsys, tmp_path):
    from fmugen.cli import main

    assert main(["linearize", "lib:stick_slip", "--set", "mode=1", "--no-trim", "--out", str(tmp_path / "l.npz")]) == 0
    assert "linearised in the mode it is in: mode = 1" in capsys.readouterr().out
