"""Main job: the thesis system -- the PUMA and its six hydraulic actuator chains -- co-simulated and reported.

1. Builds ``examples/scenes/puma_hydraulic.toml``: one FMU for the arm, one
   per joint chain (path, op-amp, current driver, servo valve, actuator), all
   starting at rest with the arm held against gravity.
2. Solves the same scene as one ODE (the monolithic model) with Radau at
   1e-12, confirmed by a tenfold tighter solve: the reference.
3. Co-simulates it with fmugen's master -- Jacobi and Gauss-Seidel with held,
   linearly and quadratically extrapolated inputs, Newton coupling with linear,
   Hermite-parabola and cubic inputs -- over a halving sequence of macro steps
   (40 ms down to 0.625 ms), plus the scene as one monolithic FMU, and
   reports error against run time (median of ``--repeats`` runs after a
   warm-up): ``OUT/thesis/report.txt`` (printed), ``report.csv``,
   ``work_precision.png``.
4. Keeps the arm-only, torque-driven study of the thesis (the arm FMU's
   internal solvers, fmpy's CVode, the thesis's own integrator) as rows of the
   same CSV (``study = arm only``), from ``examples/puma_fmu_vs_reference.py``.
5. Ends with the summary: the coarsest co-simulation that holds 1e-4 rad on
   all six joints, its wall time against real time, and how Jacobi and
   Gauss-Seidel with held inputs and the monolithic FMU compare; then the
   Gauss-Seidel/held stability limit bisected between the report's steps, and
   the iterated schemes' coarsest 1e-4 rad steps as multiples of it.

    python examples/thesis_system.py --out out [--repeats 5] [--quick]
"""
from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fmugen.cli import main as fmugen_main  # noqa: E402

SCENE = ROOT / "examples" / "scenes" / "puma_hydraulic.toml"
SCHEMES = ("jacobi/hold,jacobi/linear,jacobi/quadratic,gauss-seidel/hold,gauss-seidel/linear,gauss-seidel/quadratic,"
           "newton/linear,newton/quadratic,newton/cubic")
# macro steps: halvings from 40 ms (exact comparison points on one reference grid)
STEPS = "0.04,0.02,0.01,0.005,0.0025,0.00125,0.000625"


def merge_arm_study(report_csv: Path, arm_csv: Path) -> None:
    """Append the arm-only study's rows to the scene report's CSV, with a ``study`` column."""
    with open(report_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    fields = ["study"] + list(rows[0].keys()) if rows else ["study"]
    for r in rows:
        r["study"] = "thesis system (co-simulation)"
    with open(arm_csv, newline="") as fh:
        for a in csv.DictReader(fh):
            rows.append({"study": "arm only (torque-driven)", "system": "puma_thesis", "label": a["method"],
                         "step": a["tolerance"], "status": "ok" if a["note"] != "diverged" else "failed",
                         "err_linf": a["max_err_rad"], "err_final": a["final_err_rad"], "err_rms": a["rms_err_rad"],
                         "digits": a["correct_digits"], "wall_median": a["median_seconds"],
                         "measure": "angles [rad]"})
    with open(report_csv, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def summary(report_csv: Path, target: float, stop: float = 2.0) -> str:
    with open(report_csv, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["study"].startswith("thesis")]

    def f(r, k):
        try:
            return float(r[k])
        except (TypeError, ValueError):
            return float("nan")

    lines = [f"Thesis system, {stop:g} s, error on the six joint angles against the reference (target {target:g} rad):"]
    best = {}
    for r in rows:
        if r["status"] != "ok":
            continue
        e = f(r, "err_linf")
        ok = e <= target or r.get("below_reference") == "True"
        if ok and (r["label"] not in best or f(r, "step") > f(best[r["label"]], "step")):
            best[r["label"]] = r
    for lab in dict.fromkeys(r["label"] for r in rows):
        stable = [f(r, "step") for r in rows if r["label"] == lab and r["status"] == "ok"]
        failed = [f(r, "step") for r in rows if r["label"] == lab and r["status"] != "ok"]
        b = best.get(lab)
        text = (f"H = {f(b, 'step') * 1e3:g} ms: {f(b, 'err_linf'):.2g} rad in {f(b, 'wall_median'):.3f} s "
                f"({f(b, 'real_time_factor'):.1f}x real time)" if b else f"never within {target:g} rad")
        ms = lambda hs: ", ".join(f"{h * 1e3:g}" for h in sorted(hs))  # noqa: E731
        lim = f"; ran at H = {ms(stable)} ms" if stable else "; failed at every H tried"
        lim += f", failed (reported) at {ms(failed)} ms" if failed and stable else ""
        lines.append(f"  {lab:<22} {text}{lim}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out"))
    ap.add_argument("--repeats", type=int, default=5, help="timed runs per setting after a warm-up (median)")
    ap.add_argument("--quick", action="store_true", help="fewer settings and no arm-only study (for the tests)")
    args = ap.parse_args(argv)
    out = args.out / "thesis"
    steps = "0.04,0.004,0.002,0.001" if args.quick else STEPS
    schemes = "gauss-seidel/hold,gauss-seidel/linear,newton/linear,newton/cubic" if args.quick else SCHEMES
    # two threads: the FMUs of a costly sweep (Newton at large steps) step side by side; cheap sweeps stay
    # on one thread (the master decides from their measured cost), so the other rows are unchanged
    rc = fmugen_main(["report", str(SCENE), "--out", str(out), "--steps", steps, "--schemes", schemes,
                      "--repeats", str(args.repeats), "--workers", "2"] + (["--stop", "0.5"] if args.quick else []))
    if rc != 0:
        return rc
    print((out / "report.txt").read_text())
    report_csv = out / "report.csv"
    if not args.quick:
        import puma_fmu_vs_reference

        arm_dir = args.out / "arm_only"
        print("\nArm only, torque-driven as in the thesis (examples/puma_fmu_vs_reference.py):")
        puma_fmu_vs_reference.main(["--out", str(arm_dir), "--repeat", str(args.repeats)])
        merge_arm_study(report_csv, arm_dir / "puma_error_vs_time.csv")
    else:
        merge_arm_study(report_csv, _empty_arm_csv(out))
    text = summary(report_csv, 1e-4, 0.5 if args.quick else 2.0)
    text += "\n" + held_limit_line(report_csv, 0.5 if args.quick else None)
    (out / "summary.txt").write_text(text + "\n")
    print("\n" + text)
    print(f"\nwrote {out / 'report.txt'}, {report_csv}, {out / 'work_precision.png'}, {out / 'summary.txt'}")
    return 0


def stability_limit(system, scheme: str, extrapolation: str, stable: float, unstable: float, stop=None,
                    rel: float = 0.02) -> tuple:
    """Bisect the largest macro step at which ``scheme/extrapolation`` runs to the end without a failure
    (the divergence check on), between a step that ran and one that failed: (largest stable, smallest failed)."""
    from fmugen.cosim import run

    while unstable - stable > rel * stable:
        H = 0.5 * (stable + unstable)
        if run(system, scheme, extrapolation, step=H, stop=stop).summary.failure is None:  # ran to the end
            stable = H
        else:
            unstable = H
    return stable, unstable


def held_limit_line(report_csv: Path, stop=None) -> str:
    """The Gauss-Seidel/held stability limit bisected between the report's steps, and the coarsest step of each
    iterated scheme that holds 1e-4 rad as a multiple of it (the issue's "10x" goal)."""
    import fmugen

    with open(report_csv, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["study"].startswith("thesis")]
    gs = [r for r in rows if r["label"] == "gauss-seidel/hold"]
    # stable = ran to the end (an "unreliable" verdict is about accuracy, not stability), as the bisection
    ok = [float(r["step"]) for r in gs if r["status"] != "failed"]
    bad = [float(r["step"]) for r in gs if r["status"] == "failed" and (not ok or float(r["step"]) > max(ok))]
    if not ok or not bad:
        return "Gauss-Seidel/held: no stability limit between the steps tried"
    over = {"scene.stop": stop} if stop else {}
    built = fmugen.load_scene(SCENE, set=over).build(Path(report_csv).parent / "fmus")
    lo, hi = stability_limit(built.system, "gauss-seidel", "hold", max(ok), min(bad))
    lines = [f"Gauss-Seidel/held: largest stable macro step {lo * 1e3:.3g} ms (fails at {hi * 1e3:.3g} ms, "
             f"bisected to 2 %)"]
    for lab in dict.fromkeys(r["label"] for r in rows if r["label"].startswith(("newton", "iterative"))):
        good = [float(r["step"]) for r in rows if r["label"] == lab and r["status"] == "ok"
                and (float(r["err_linf"] or "nan") <= 1e-4 or r.get("below_reference") == "True")]
        if good:
            lines.append(f"  {lab:<22} holds 1e-4 rad at H = {max(good) * 1e3:g} ms: {max(good) / lo:.1f}x that limit")
    return "\n".join(lines)


def _empty_arm_csv(out: Path) -> Path:
    p = out / "arm_only_empty.csv"
    p.write_text("method,tolerance,median_seconds,max_err_rad,final_err_rad,rms_err_rad,correct_digits,note\n")
    return p


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
