"""The fmugen cosim / reference / report commands on a shipped scene (the split stiff rig)."""
import csv
from pathlib import Path

import numpy as np
import pytest

from fmugen.cli import main

ROOT = Path(__file__).resolve().parents[1]
SCENE = str(ROOT / "examples" / "scenes" / "single_joint_split_stiff.toml")


pytestmark = pytest.mark.usefixtures("private_reference_cache")


def _csv(path):
    with open(path) as fh:
        rows = list(csv.reader(fh))
    return rows[0], np.array(rows[1:], dtype=float)


def test_cosim_and_reference_agree(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["cosim", SCENE, "--scheme", "gauss-seidel", "--extrapolation", "linear", "--step", "5e-4",
                 "--stop", "0.3", "--out", str(out)]) == 0
    head, data = _csv(out / "results.csv")
    assert head == ["time", "joint.theta", "joint.w", "actuator.tau", "actuator.P_L"]
    assert data[-1, 0] == pytest.approx(0.3) and len(data) == 601
    z = np.load(out / "results.npz")
    assert z["results"].dtype.names == tuple(head)
    assert np.array_equal(z["results"]["joint.theta"], data[:, 1])
    assert (out / "results.png").stat().st_size > 0
    assert "gauss-seidel/linear: ok; 600 macro steps" in (out / "summary.txt").read_text()

    ref_dir = tmp_path / "ref"
    assert main(["reference", SCENE, "--stop", "0.3", "--points", "1201", "--out", str(ref_dir)]) == 0
    rhead, ref = _csv(ref_dir / "reference.csv")
    assert rhead == head and len(ref) == 1201
    assert "error estimate per column" in (ref_dir / "reference.txt").read_text()
    # the co-simulation at 0.5 ms against the reference (both on the 0.25 ms grid): the path moves
    # the joint by 0.1 rad; Gauss-Seidel with linear extrapolation is within 1e-6 rad of it
    err = np.max(np.abs(data[:, 1] - ref[::2, 1]))
    assert err < 1e-6
    assert np.max(np.abs(ref[:, 1])) > 0.01  # the joint did move


def test_cosim_failure_writes_results_and_exits_nonzero(tmp_path, capsys):
    out = tmp_path / "fail"
    rc = main(["cosim", SCENE, "--scheme", "gauss-seidel", "--extrapolation", "hold", "--step", "0.01",
               "--out", str(out)])
    assert rc == 1
    err = capsys.readouterr().err
    assert "diverged" in err and "coupling chain.actuator.tau -> joint.tau" in err
    head, data = _csv(out / "results.csv")
    assert 1 < len(data) < 101 and np.all(np.isfinite(data))
    assert "failed" in (out / "summary.txt").read_text()


def test_bad_scheme_exits_2(tmp_path, capsys):
    assert main(["cosim", SCENE, "--scheme", "leapfrog", "--out", str(tmp_path)]) == 2
    assert "unknown scheme 'leapfrog'" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["cosim", SCENE, "--scheme", "jacobi", "--extrapolation", "cubic"],
                                  ["report", SCENE, "--schemes", "newton/linear,gauss-seidel/cubic"]])
def test_scheme_that_cannot_take_cubic_inputs_is_refused_before_anything_is_written(tmp_path, capsys, argv):
    out = tmp_path / "out"
    assert main(argv + ["--out", str(out)]) == 2
    assert "need an iterated scheme" in capsys.readouterr().err
    assert not out.exists()


def test_report(tmp_path):
    out = tmp_path / "report"
    assert main(["report", SCENE, "--steps", "0.002,0.001", "--schemes", "gauss-seidel/linear,jacobi/hold",
                 "--repeats", "1", "--stop", "0.3", "--out", str(out)]) == 0
    with open(out / "report.csv") as fh:
        rows = list(csv.DictReader(fh))
    labels = [r["label"] for r in rows]
    assert labels == ["gauss-seidel/linear"] * 2 + ["jacobi/hold"] * 2 + ["monolithic FMU"] * 2
    gs = [r for r in rows if r["label"] == "gauss-seidel/linear"]
    assert all(r["status"] == "ok" for r in gs)
    assert abs(float(gs[1]["order"]) - 2.0) < 0.3
    assert float(gs[1]["err_linf"]) < float(gs[0]["err_linf"])
    assert (out / "work_precision.png").stat().st_size > 0
    assert "coarsest macro step meeting" in (out / "report.txt").read_text()


def test_report_sweeps_internal_solvers(tmp_path):
    out = tmp_path / "report_internal"
    assert main(["report", SCENE, "--steps", "0.001", "--schemes", "gauss-seidel/linear", "--repeats", "1",
                 "--stop", "0.2", "--internal", "rodas3:1e-10,dopri5:1e-9", "--no-monolithic", "--out", str(out)]) == 0
    with open(out / "report.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["label"] for r in rows] == ["gauss-seidel/linear rodas3 1e-10", "gauss-seidel/linear dopri5 1e-09"]
    # both internal solvers far below the coupling error: the same coupling error to 1 %
    e = [float(r["err_linf"]) for r in rows]
    assert abs(e[0] - e[1]) < 0.01 * e[0]
