"""The runnable examples: the main job and the derivation benchmark actually run."""
import csv
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_main_job_reports_error_against_run_time(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "puma_fmu_vs_reference.py"), "--out", str(tmp_path),
                        "--repeat", "1"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    rows = list(csv.DictReader(open(tmp_path / "puma_error_vs_time.csv")))
    err = {(row["method"], float(row["tolerance"])): float(row["max_err_rad"]) for row in rows}
    # the FMU's explicit solver converges with its tolerance ...
    assert err[("CS dopri5", 1e-10)] < 1e-5
    assert err[("CS dopri5", 1e-10)] < err[("CS dopri5", 1e-6)]
    assert err[("CS rodas3 (implicit)", 1e-10)] < 1e-5
    # ... the ME FMU's derivatives, integrated tightly, are exact ...
    assert err[("ME + scipy Radau", 1e-9)] < 1e-6
    # ... and the thesis's constant-acceleration scheme is far off even at h = 0.4 ms
    assert min(v for (m, _), v in err.items() if m == "thesis scheme") > 1e-2
    assert (tmp_path / "puma_error_vs_time.png").exists()


def test_derivation_benchmark_runs():
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "bench_derivation.py"), "--sizes", "2", "4", "6",
                        "--repeat", "1"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "fitted growth exponent" in r.stdout and "PUMA" in r.stdout


def test_thesis_system_main_job_quick(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "thesis_system.py"), "--out", str(tmp_path),
                        "--quick", "--repeats", "1"], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    rows = list(csv.DictReader(open(tmp_path / "thesis" / "report.csv")))
    err = {(row["label"], float(row["step"])): (row["status"], float(row["err_linf"] or "nan")) for row in rows}
    # Gauss-Seidel with linearly extrapolated inputs holds 1e-4 rad at 1 ms on all six joints, and it
    # converges at second order, better than held inputs at the same step
    assert err[("gauss-seidel/linear", 0.001)][0] == "ok" and err[("gauss-seidel/linear", 0.001)][1] < 1e-4
    assert err[("gauss-seidel/linear", 0.001)][1] < err[("gauss-seidel/hold", 0.001)][1] / 10
    assert err[("newton/linear", 0.004)][1] < 1e-4
    # the goal: Newton with cubic Hermite inputs holds 1e-4 rad at 40 ms, where Gauss-Seidel with
    # held inputs diverges (its limit, bisected, is 3.4 ms: more than 10x)
    assert err[("newton/cubic", 0.04)][0] == "ok" and err[("newton/cubic", 0.04)][1] < 1e-4
    assert err[("gauss-seidel/hold", 0.004)][0] == "failed"
    summary = (tmp_path / "thesis" / "summary.txt").read_text()
    assert "thesis system" in summary.lower()
    limit = float(summary.split("largest stable macro step ")[1].split(" ms")[0])
    assert 2.0 < limit < 4.0 and 40.0 / limit > 10
