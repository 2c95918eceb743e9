"""``fmugen report SYSTEM.ssp``: error against run time for a system without a symbolic model.

A scene's report measures against the scene solved as one ODE (Radau at
1e-12).  An SSP of third-party FMUs has no equations fmugen can see, so the
reference here is **the master itself**: the most accurate scheme it has
(Newton coupling with cubic Hermite inputs, else Newton with linear inputs,
else Jacobi with held inputs -- the first the FMUs allow) at a step 16 times
below the smallest step of the sweep, and again at half that step.  The
difference of the two is the **self-convergence error estimate** of the
reference; it says how well the master converged, not how right the FMUs are
(an error shared by every run -- an FMU's internal solver, a wrong
parameter -- is invisible to it).  Every figure the report prints is labelled
so.
"""
from __future__ import annotations

import csv
import math
import numbers
import statistics
from pathlib import Path

import numpy as np

from ..cosim.errors import CosimError
from ..cosim.master import check_choices, run

#: tried in this order for the reference: the master's most accurate scheme the FMUs allow
REFERENCE_SCHEMES = (("newton", "cubic"), ("newton", "linear"), ("jacobi", "hold"))
REFINE = 16


def _error(result, ref, columns) -> float:
    """max over columns of max_t |run - reference| / max_t |reference| at the run's communication points."""
    worst = 0.0
    n = len(result.time)
    for c in columns:
        r = np.interp(result.time, ref.time, ref[c])
        scale = max(float(np.max(np.abs(ref[c]))), 1e-300)
        worst = max(worst, float(np.max(np.abs(result[c][:n] - r))) / scale)
    return worst


def self_convergence_reference(system, h_ref: float, stop: float, workers: int = 1):
    """(scheme, reference run at h_ref/2, self-convergence estimate, run at h_ref)."""
    last = None
    for scheme, ext in REFERENCE_SCHEMES:
        try:
            coarse = run(system, scheme, ext, step=h_ref, stop=stop, workers=workers)
        except CosimError as exc:  # this system's FMUs cannot do that scheme (no derivatives, no state)
            last = exc
            continue
        if not coarse.ok:
            last = CosimError(f"reference {scheme}/{ext} at {h_ref:g} s failed: {coarse.summary.failure}")
            continue
        fine = run(system, scheme, ext, step=h_ref / 2, stop=stop, workers=workers)
        if not fine.ok:
            last = CosimError(f"reference {scheme}/{ext} at {h_ref / 2:g} s failed: {fine.summary.failure}")
            continue
        cols = list(fine.columns)
        return f"{scheme}/{ext}", fine, _error(coarse, fine, cols), coarse
    raise CosimError(f"{system.name}: no reference run succeeded: {last}")


def report_ssp(system, steps, schemes, repeats: int = 1, stop=None, workers: int = 1, progress=None):
    """Rows (scheme, extrapolation, H, error or None, status, median wall s) and the reference's data."""
    def number(v, what):
        if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
            raise CosimError(f"report_ssp: {what} must be a finite number, got {v!r:.60}")
        return float(v)

    if isinstance(steps, (str, bytes)) or not hasattr(steps, "__iter__"):
        raise CosimError(f"report_ssp: steps must be a list of macro steps [s], got {steps!r:.60}")
    steps = sorted({number(h, "a step") for h in steps}, reverse=True)
    if not steps or min(steps) <= 0:
        raise CosimError("steps must be positive")
    if isinstance(schemes, (str, bytes)) or not all(isinstance(p, (tuple, list)) and len(p) == 2 for p in schemes):
        raise CosimError(f"report_ssp: schemes must be (scheme, extrapolation) pairs, got {schemes!r:.80}")
    schemes = [check_choices(s, e) for s, e in schemes]
    if isinstance(repeats, bool) or not isinstance(repeats, numbers.Integral) or not 1 <= repeats <= 1000:
        raise CosimError(f"report_ssp: repeats must be a whole number from 1 to 1000, got {repeats!r:.60}")
    stop = number(stop, "stop") if stop is not None else system.stop_time
    if not stop > system.start_time:
        raise CosimError(f"report_ssp: stop {stop!r} must be after the system's start time {system.start_time!r}")
    h_ref = min(steps) / REFINE
    if progress:
        progress(f"reference: the master at {h_ref:g} s and {h_ref / 2:g} s")
    ref_scheme, ref, estimate, _ = self_convergence_reference(system, h_ref, stop, workers)
    cols = list(ref.columns)
    rows = []
    for scheme, ext in schemes:
        for h in steps:
            walls, err, status = [], None, "ok"
            for _ in range(max(1, repeats)):
                try:
                    r = run(system, scheme, ext, step=h, stop=stop, workers=workers)
                except CosimError as exc:
                    status, err = f"refused: {exc}", None
                    break
                walls.append(r.summary.wall_time)
                s = r.summary
                # as the scene's report: a run that reached the stop time is measured, an unreliable one
                # labelled with its verdict; a failed one says why (it was "failed", and no error, for both)
                finished = r.ok or (s.failure is None and len(r.time) > 0
                                    and r.time[-1] >= stop - 1e-9 * max(1.0, abs(stop)))
                if not finished:
                    status = "failed: " + (str(s.failure).splitlines()[0] if s.failure else s.status)
                    break
                if not r.ok:
                    status = f"unreliable: {s.reliability}" if getattr(s, "reliability", "") else s.status
                err = _error(r, ref, cols)
            rows.append((scheme, ext, h, err, status, statistics.median(walls) if walls else math.nan))
            if progress:
                progress(f"{scheme}/{ext} H = {h:g}: {status}" + (f", error {err:.2e}" if err is not None else ""))
    return {"rows": rows, "reference": ref_scheme, "h_ref": h_ref / 2, "estimate": estimate, "columns": cols,
            "stop": stop}


def table(rep, target: float) -> str:
    lines = [f"reference: fmugen's master, {rep['reference']} at H = {rep['h_ref']:g} s (no symbolic model: a "
             f"self-convergence reference, not an independent solution)",
             f"self-convergence error estimate of the reference (difference to H = {2 * rep['h_ref']:g} s, relative "
             f"to each column's magnitude): {rep['estimate']:.2e}",
             "error: max over the columns " + ", ".join(rep["columns"]) + " of max |run - reference| / max |reference| "
             "at the communication points",
             f"{'scheme':<22} {'H [s]':>10} {'error':>10} {'wall [s]':>9}  status"]
    for scheme, ext, h, err, status, wall in rep["rows"]:
        e = "-" if err is None else f"{err:.2e}"
        if err is not None and err < 10 * rep["estimate"]:
            e += "*"
        lines.append(f"{scheme + '/' + ext:<22} {h:10.4g} {e:>10} {wall:9.3g}  {status}")
    lines.append("* within 10x the reference's estimate: not resolved")
    best = {}
    for scheme, ext, h, err, status, wall in rep["rows"]:
        if err is not None and err <= target and status == "ok":
            key = f"{scheme}/{ext}"
            best[key] = max(best.get(key, 0.0), h)
    lines.append(f"coarsest step meeting {target:g}: " + (", ".join(f"{k} {v:g} s" for k, v in best.items()) or "none"))
    return "\n".join(lines)


def cmd_report_ssp(args) -> int:
    import sys

    from ..cosim.report import DEFAULT_SCHEMES
    from .cli import system_from_args

    if args.internal:
        raise CosimError(f"{args.scene}: --internal sets fmugen's internal solvers of a scene's FMUs; an SSP's FMUs "
                         f"are run as bound (change solver.method in the archive's .ssv or with --set)")
    schemes = [tuple(s.split("/", 1)) if "/" in s else (s, "hold") for s in args.schemes.split(",")] \
        if args.schemes else DEFAULT_SCHEMES
    schemes = [check_choices(*sc) for sc in schemes]
    system = system_from_args(args)
    from ..cosim.run_arguments import check_args, run_flags
    from ..cosim.settings import resolve
    from .cli import scene_like

    workers = resolve(system.settings, **run_flags(args)).workers  # its settings, then the flags (checked)
    check_args(args, scene_like(system))
    H = float(system.step)
    steps = [float(h) for h in args.steps.split(",")] if args.steps else [8 * H, 4 * H, 2 * H, H, H / 2]
    rep = report_ssp(system, steps, schemes, repeats=args.repeats, stop=args.stop, workers=workers,
                     progress=lambda s: print("  " + s, file=sys.stderr, flush=True))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    text = table(rep, args.target)
    (out / "report.txt").write_text(text + "\n")
    with open(out / "report.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scheme", "extrapolation", "step", "error", "status", "wall_time", "reference",
                    "reference_step", "reference_estimate"])
        for row in rep["rows"]:
            w.writerow(list(row) + [rep["reference"], rep["h_ref"], rep["estimate"]])
    print(text)
    print(f"wrote {out / 'report.txt'}, {out / 'report.csv'}")
    return 0
