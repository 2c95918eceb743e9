"""`fmugen suite --quick`: the stiff and extreme cases through every CS solver,
judged against scipy Radau at rtol 1e-12 (confirmed by a second solve).

Goal: every run accurate or a failure detected with the FMU's own message --
no SILENT failure (wrong result, status OK, no warning).
"""
import csv

import numpy as np
import pytest

from fmugen.cli import main as fmugen_main
from fmugen.suite import run_suite
from fmugen.suite.cases import get_case
from fmugen.suite.classify import ACCURATE, DETECTED, SILENT, Validity, classify, promise, violations
from fmugen.suite.cases import Method, RK4, DOPRI5


@pytest.fixture(scope="module")
def stiff_rows(tmp_path_factory):
    out = tmp_path_factory.mktemp("suite")
    rows = run_suite(["stiff_P", "stiff_PI_opamp", "comm_step_large", "puma_light_wrist"], quick=True, out=out,
                     log=lambda *a: None)
    return out, rows


def by(rows, case, method_prefix):
    hit = [r for r in rows if r.case == case and r.method.startswith(method_prefix)]
    assert hit, (case, method_prefix, [(r.case, r.method) for r in rows])
    return hit


def test_no_silent_failure(stiff_rows):
    _, rows = stiff_rows
    silent = [(r.case, r.method, r.message) for r in rows if r.outcome == SILENT]
    assert not silent


def test_stiff_sets_accurate_with_error_control_and_stiffness_said(stiff_rows):
    _, rows = stiff_rows
    for case in ("stiff_P", "stiff_PI_opamp", "comm_step_large"):
        (dp,) = by(rows, case, "DOPRI5")
        (ro,) = by(rows, case, "RODAS3")
        assert dp.outcome == ACCURATE and ro.outcome == ACCURATE
        assert dp.error < 1e-6 and ro.error < 1e-6  # rad, against the Radau reference
        # Dormand-Prince said it was stiff, and the implicit solver needed far fewer steps
        assert dp.stiffness_detected >= 1 and "solver.method = 2" in dp.message
        assert ro.steps * 3 < dp.steps
    # the real op-amp: stiffness ratio 1.4e5 -> the explicit solver is > 10x the work of RODAS3
    (dp,) = by(rows, "stiff_PI_opamp", "DOPRI5")
    (ro,) = by(rows, "stiff_PI_opamp", "RODAS3")
    assert dp.f_evals > 10 * ro.f_evals


def test_rk4_inside_limit_accurate_outside_detected_with_the_number(stiff_rows):
    _, rows = stiff_rows
    for case in ("stiff_P", "stiff_PI_opamp"):
        inside = [r for r in by(rows, case, "RK4") if "(0.5 h_lim)" in r.method]
        outside = [r for r in by(rows, case, "RK4") if "(1.2 h_lim)" in r.method]
        assert inside[0].outcome == ACCURATE and inside[0].error < 1e-6
        assert outside[0].outcome == DETECTED
        assert "exceeds the RK4 stability limit" in outside[0].message
        # the limit the FMU found is the one numpy's eigenvalues give
        h_lim = outside[0].extra["rk4_limit"]
        quoted = outside[0].message.split("stability limit ~ ")[1].split(" ")
        assert float(quoted[0]) * {"us": 1e-6, "ms": 1e-3}[quoted[1].rstrip(",")] == pytest.approx(h_lim, rel=5e-3)


def test_light_wrist_puma(stiff_rows):
    _, rows = stiff_rows
    for r in by(rows, "puma_light_wrist", ""):
        assert r.outcome == ACCURATE, (r.method, r.message)
    assert by(rows, "puma_light_wrist", "DOPRI5")[0].error < 1e-5


def test_outputs_written(stiff_rows):
    out, rows = stiff_rows
    table = list(csv.DictReader(open(out / "suite.csv")))
    assert len(table) == len(rows)
    assert {t["outcome"] for t in table} <= {ACCURATE, DETECTED}
    for case in ("stiff_P", "stiff_PI_opamp", "comm_step_large", "puma_light_wrist"):
        assert (out / f"{case}.png").stat().st_size > 1000


def test_load_above_stall_is_flagged(tmp_path):
    """5000 N.m on the stiff set (stall torque 210 N.m): the load pressure
    reaches ~27 P_s.  The solvers integrate the ODE accurately; the suite
    must not call that a success: the FMU's warning names actuator.P_L."""
    rows = run_suite(["load_above_stall"], quick=True, out=tmp_path, plots=False, log=lambda *a: None)
    for r in rows:
        # the runtime's validity monitor names the variable and its range
        assert r.outcome == DETECTED, (r.method, r.message)
        assert "actuator.P_L" in r.message and "validity range" in r.message


def test_classify_rules():
    rng = Validity("P", -1.0, 1.0, "range")
    vals = np.array([[0.0], [2.0]])
    assert violations(vals, ["P"], [rng])[0][1] == 2.0
    assert classify(False, "discarded: x", [], np.inf, 1.0, [])[0] == DETECTED
    assert classify(True, "", [], 0.5, 1.0, [])[0] == ACCURATE
    assert classify(True, "", [], 2.0, 1.0, [])[0] == SILENT
    assert classify(True, "", ["RK4: h = 1 exceeds"], 2.0, 1.0, [])[0] == DETECTED
    assert classify(True, "", [], 0.5, 1.0, violations(vals, ["P"], [rng]))[0] == SILENT
    assert classify(True, "", ["P left its range"], 0.5, 1.0, violations(vals, ["P"], [rng]))[0] == DETECTED
    assert promise(Method(DOPRI5, 1e-6), 0.1) == pytest.approx(1.1e-4)
    assert promise(Method(RK4, rk4_factor=0.5), 0.1, ref_uncertainty=1.0) == 10.0


def test_cli_runs_a_named_case_and_an_assembly_file(tmp_path, capsys):
    rc = fmugen_main(["suite", "--cases", "comm_step_large", "--quick", "--out", str(tmp_path / "a"), "--no-plots"])
    assert rc == 0
    assert (tmp_path / "a" / "suite.csv").exists()
    assert "comm_step_large" in capsys.readouterr().out
    with pytest.raises(KeyError):
        get_case("no_such_case")
    rc = fmugen_main(["suite", "--cases", "no_such_case", "--out", str(tmp_path / "b")])
    assert rc == 2 and "unknown suite case" in capsys.readouterr().err


def test_cli_runs_a_users_assembly_file(tmp_path, capsys):
    """fmugen suite FILE.toml: the user's own model, judged the same way."""
    from pathlib import Path

    f = Path(__file__).resolve().parents[1] / "examples" / "single_joint_stiff.toml"
    rc = fmugen_main(["suite", str(f), "--quick", "--out", str(tmp_path), "--no-plots", "--set", "amp.theta_ref=0.1"])
    table = list(csv.DictReader(open(tmp_path / "suite.csv")))
    assert rc == 0 and len(table) == 4
    assert {t["outcome"] for t in table} <= {ACCURATE, DETECTED}
    assert any(t["outcome"] == DETECTED and "stability limit" in t["message"] for t in table)
    rc = fmugen_main(["suite", str(f), "--out", str(tmp_path), "--set", "amp.theta_ref"])
    assert rc == 2 and "NAME=NUMBER" in capsys.readouterr().err
