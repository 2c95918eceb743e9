"""Error against run time: co-simulation schemes x macro steps against the reference.

For every setting (scheme, extrapolation, macro step H) the system is run
once to warm up and ``repeats`` times to time it (median wall time), and its
recorded columns are compared with the reference
(:func:`fmugen.cosim.reference.solve_reference`, solved once on the grid of
the smallest H so that every communication point of every run is a reference
point):

* ``err_final``: |error| at the stop time;
* ``err_linf``, ``err_rms``: max and RMS |error| at the communication points
  (the coupling error; the reference is solved at every one of them);
* ``err_dense``: max |error| on a dense grid of >= 1000 points with the run
  interpolated between its communication points by cubic Hermite from the
  FMUs' own output slopes (:mod:`fmugen.cosim.dense`; linearly for an FMU
  that gives none) -- what a user of the result sees, interpolation included,
  and at fourth order the interpolation does not hide the coupling error;
* ``digits``: correct digits, -log10 max |err| / (atol + |y_ref|) with
  atol = 1e-3 max |y_ref|;
* ``order``: observed order over the halving H -> H/2 of the same scheme.

The error measure is the largest over the columns in radians (joint angles)
when there are any, else over all columns relative to each column's range.
An error closer than 100x to the reference's own estimate is not reported
(``below_reference`` = True, error NaN).  The monolithic FMU of the scene
(one CS FMU, same step) can be added as a row.  Outputs: the table (printed),
``report.csv``, ``work_precision.png`` (log error against log wall time, one
curve per scheme).
"""
from __future__ import annotations

import csv
import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from .dense import hermite
from .errors import CosimError
from .master import Master, check_choices
from .reference import ReferenceSolution, solve_reference
from .system import CosimSystem, ReferenceProblem

DEFAULT_SCHEMES = (("jacobi", "hold"), ("jacobi", "linear"), ("gauss-seidel", "hold"),
                   ("gauss-seidel", "linear"), ("newton", "linear"))
REFUSE_FACTOR = 100.0
MAX_REFERENCE_POINTS = 400_001


@dataclass
class Row:
    label: str
    scheme: str
    extrapolation: str
    step: float
    status: str = "ok"
    err_final: float = math.nan
    err_linf: float = math.nan  # max |error| at the communication points
    err_rms: float = math.nan  # RMS at the communication points
    err_dense: float = math.nan  # max |error| on the dense grid (run interpolated linearly)
    digits: float = math.nan
    order: float = math.nan
    wall_median: float = math.nan
    real_time_factor: float = math.nan
    macro_steps: int = 0
    rollbacks: int = 0
    iterations: int = 0
    fmu_calls: int = 0
    threads: int = 1  # threads that stepped the FMUs (workers > 1 and sweeps costly enough)
    below_reference: bool = False
    failure: str = ""
    wall_first: float = math.nan  # the untimed first run's wall time (a failed run's only one: up to its failure)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Report:
    system: str
    rows: list
    reference_error: float
    reference_settings: dict
    target: float
    measure: str
    coarsest: dict = field(default_factory=dict)  # scheme label -> Row meeting the target at the largest H
    equal_time: dict = field(default_factory=dict)  # scheme label -> error at the common wall time
    common_wall: float = math.nan

    def table(self) -> str:
        head = (f"{'setting':<24} {'H [s]':>9} {'status':>8} {'err_final':>10} {'err_Linf':>10} {'err_RMS':>10} {'err_dense':>10} "
                f"{'digits':>6} {'order':>6} {'wall [s]':>9} {'x real':>7} {'steps':>7} {'rollb':>5} "
                f"{'iters':>6} {'FMU calls':>9} {'thr':>3}  reason (runs that did not end ok)")
        lines = [f"{self.system}: error on {self.measure} against the reference "
                 f"(its own error estimate {self.reference_error:.2g}; errors below "
                 f"{REFUSE_FACTOR * self.reference_error:.2g} are not reported)", head, "-" * len(head)]

        def g(v, fmt):
            ok = isinstance(v, (int, float)) and not (isinstance(v, float) and math.isnan(v))
            return format(v, fmt) if ok else format("-", ">" + fmt.rstrip("gfd").split(".")[0])

        for r in self.rows:
            lines.append(f"{r.label:<24} {r.step:>9.3g} {r.status:>8} {g(r.err_final, '10.3g')} {g(r.err_linf, '10.3g')} "
                         f"{g(r.err_rms, '10.3g')} {g(r.err_dense, '10.3g')} {g(r.digits, '6.2f')} {g(r.order, '6.2f')} "
                         f"{g(r.wall_median, '9.4f')} {g(r.real_time_factor, '7.1f')} {r.macro_steps:>7d} "
                         f"{r.rollbacks:>5d} {r.iterations:>6d} {r.fmu_calls:>9d} {r.threads:>3d}"
                         + (f"  {_reason(r.failure)}" if r.failure else ""))
        lines.append("")
        lines.append(f"coarsest macro step meeting {self.target:g} ({self.measure}, L-inf):")
        for lab, r in self.coarsest.items():
            lines.append(f"  {lab:<24} " + (f"H = {r.step:.4g} s, wall {r.wall_median:.4g} s, "
                                            f"{r.real_time_factor:.1f}x real time"
                                            + (" (error below the reference's resolution)" if r.below_reference else "")
                                            if r else "none of the steps tried"))
        if self.equal_time:
            lines.append(f"error at equal wall time {self.common_wall:.4g} s (log-log interpolation):")
            for lab, e in self.equal_time.items():
                lines.append(f"  {lab:<24} " + (f"{e:.3g}" if e == e else "outside the measured range"))
        return "\n".join(lines)


def _reason(failure: str) -> str:
    """The first line of a failure report, without its fixed opening: ``t = 0.05 s (diverged) [...]: ...``."""
    text = str(failure).splitlines()[0] if failure else ""
    return text[len("co-simulation stopped at "):] if text.startswith("co-simulation stopped at ") else text


def _measure_columns(system: CosimSystem, columns: Optional[Sequence[str]]):
    names = [r.column for r in system.recorded]
    if columns:
        bad = [c for c in columns if c not in names]
        if bad:
            raise CosimError(f"report: unknown column(s) {bad}; recorded: {names}")
        return list(columns), "the chosen columns"
    rad = [r.column for r in system.recorded if r.physical_unit == "rad"]
    if rad:
        return rad, "angles [rad]"
    return names, "all columns (relative to each column's range)"


def _errors(time, values, ref: ReferenceSolution, cols, slopes=None):
    """(final, L-inf and RMS at the communication points, L-inf on the dense grid, digits), max over columns."""
    h = ref.time[1] - ref.time[0]
    idx = np.rint((time - ref.time[0]) / h).astype(int)
    ok = np.all((idx >= 0) & (idx < len(ref.time)))
    exact = ok and np.allclose(ref.time[np.clip(idx, 0, len(ref.time) - 1)], time,
                               atol=1e-9 * max(1.0, abs(ref.time[-1])))
    dense = np.linspace(ref.time[0], time[-1], min(len(ref.time), 2001))
    didx = np.rint((dense - ref.time[0]) / h).astype(int)
    fin = linf = rms2 = dense_inf = 0.0
    digits = math.inf
    td = ref.time[didx]
    Yd = hermite(time, values, slopes, td) if len(time) > 1 else np.repeat(values[:1], len(td), axis=0)
    for c, j, s in cols:
        yref = ref.values[:, j]
        y = values[:, c]
        ref_cp = yref[idx] if exact else np.interp(time, ref.time, yref)
        e_cp = np.abs(y - ref_cp)
        e_d = np.abs(Yd[:, c] - yref[didx])
        fin = max(fin, e_cp[-1] / s)
        linf = max(linf, e_cp.max() / s)
        rms2 = max(rms2, float(np.mean(e_cp ** 2)) / s ** 2)
        dense_inf = max(dense_inf, e_d.max() / s)
        atol = 1e-3 * max(np.max(np.abs(yref)), 1e-300)  # near zero crossings, digits relative to the range
        digits = min(digits, -math.log10(max(float(np.max(e_cp / (atol + np.abs(ref_cp)))), 1e-300)))
    return fin, linf, math.sqrt(rms2), dense_inf, digits


SOLVER_IDS = {"dopri5": 1, "rodas3": 2, "rk4": 3}


def with_internal_solver(system: CosimSystem, method: str, tol: float) -> CosimSystem:
    """The same system with every CS FMU's internal solver set to ``method`` at rtol = atol = ``tol``."""
    from dataclasses import replace

    if method not in SOLVER_IDS:
        raise CosimError(f"unknown internal solver {method!r}; choose one of {', '.join(SOLVER_IDS)}")
    if not (tol > 0 and math.isfinite(tol)):
        raise CosimError(f"internal tolerance must be finite and positive, not {tol}")
    units = tuple(replace(u, start_values=dict(u.start_values, **{"solver.method": SOLVER_IDS[method],
                                                                   "solver.rtol": tol, "solver.atol": tol}))
                  if str(u.fmi_type).lower() == "cs" else u for u in system.units)
    return replace(system, units=units)


def make_report(system: CosimSystem, problem: ReferenceProblem, steps: Sequence[float],
                schemes: Sequence[tuple] = DEFAULT_SCHEMES, repeats: int = 5, target: float = 1e-4,
                columns: Optional[Sequence[str]] = None, extra_rows: Sequence = (), stop: Optional[float] = None,
                progress=None, internal: Sequence[tuple] = (), workers: int = 1, settings=None) -> Report:
    """Sweep ``schemes`` x ``steps`` (each a multiple of the smallest by a power of 2 is best: exact
    comparison points) and measure every run against the reference of ``problem``.

    ``extra_rows``: (label, system) pairs run like the schemes at each step with Jacobi (e.g. the
    monolithic FMU as a one-unit system).  ``internal``: (solver, tolerance) pairs -- the sweep is then
    repeated with every CS FMU's internal solver set to each (``dopri5``, ``rodas3``, ``rk4``).
    ``workers``: threads per run (see :class:`fmugen.cosim.master.Master`).  ``settings``: a
    :class:`fmugen.cosim.settings.RunSettings` whose other settings every run takes (iterations, coupling
    tolerance, workers, ...: the scene's ``[cosim]`` as ``fmugen report`` resolves it); scheme,
    extrapolation and step are the sweep's.
    """
    if settings is not None:
        workers = settings.workers
    order = settings.order if settings is not None else None
    options = {k: v for k, v in (settings.run_keywords() if settings is not None else {}).items()
               if k not in ("step", "stop")}
    if repeats < 1:
        raise CosimError("repeats must be >= 1")
    steps = sorted({float(h) for h in steps}, reverse=True)
    if not steps or min(steps) <= 0:
        raise CosimError("steps must be positive")
    schemes = [check_choices(s, e) for s, e in schemes]  # refused before any run, not mid-sweep
    t0 = problem.start_time
    t1 = float(stop) if stop is not None else problem.stop_time
    hmin = min(steps)
    n = int(round((t1 - t0) / hmin))
    if n + 1 > MAX_REFERENCE_POINTS:
        n = MAX_REFERENCE_POINTS - 1
    ref_problem = problem if t1 == problem.stop_time else ReferenceProblem(
        problem.model, problem.x0, problem.u, problem.columns, t0, t1, problem.nominals)
    ref = solve_reference(ref_problem, times=np.linspace(t0, t1, n + 1))
    names, measure = _measure_columns(system, columns)
    pos = [r.column for r in system.recorded]
    cols = []
    for c in names:
        j = list(ref.columns).index(c)
        s = 1.0 if measure.startswith("angles") or columns else max(np.ptp(ref.values[:, j]), 1e-300)
        cols.append((pos.index(c), j, s))
    ref_err = max(ref.error[j] / s for _, j, s in cols)
    rows = []
    if internal:  # the sweep x internal solvers and tolerances: (method, tol) pairs
        runs = [(f"{s}/{e} {meth} {tl:g}", with_internal_solver(system, meth, tl), s, e)
                for meth, tl in internal for s, e in schemes]
    else:
        runs = [(f"{s}/{e}", system, s, e) for s, e in schemes]
    runs += [(lab, sysm, "jacobi", "hold") for lab, sysm in extra_rows]
    for label, sysm, scheme, ext in runs:
        prev = None
        for H in steps:
            if progress:
                progress(f"{label} H = {H:.4g}")
            walls = []
            result = None
            # the scene's Gauss-Seidel order, for the systems of its FMUs (not the monolithic one)
            same = order and sorted(order) == sorted(u.name for u in sysm.units)
            mkw = {"workers": workers, "order": order if same else None}
            with Master(sysm, scheme, ext, **mkw) as m:  # warm-up: loads and instantiates; not timed
                result = m.run(step=H, stop=t1, dense=True, **options)  # with the slopes for the dense error
            s = result.summary
            # ok, or ended with a verdict other than a failure (unreliable): it reached the stop time and is measured
            finished = result.ok or (s.failure is None and len(result.time) > 0
                                     and result.time[-1] >= t1 - 1e-9 * max(1.0, abs(t1)))
            if finished:
                for _ in range(repeats):
                    with Master(sysm, scheme, ext, **mkw) as m:
                        r2 = m.run(step=H, stop=t1, **options)
                    walls.append(r2.summary.wall_time)
            row = Row(label, scheme, ext, H, s.status, macro_steps=s.macro_steps, rollbacks=s.rollbacks,
                      iterations=s.iterations, fmu_calls=s.fmu_calls, threads=s.threads,
                      failure=(str(s.failure).splitlines()[0] if s.failure else
                               f"unreliable: {s.reliability}" if getattr(s, "reliability", "") else ""),
                      wall_first=s.wall_time)
            if finished:
                row.wall_median = statistics.median(walls)
                row.real_time_factor = (t1 - t0) / row.wall_median if row.wall_median > 0 else math.inf
                fin, linf, rms, dense, dig = _errors(result.time, result.values, ref, cols, result.slopes)
                row.err_final, row.err_linf, row.err_rms, row.err_dense, row.digits = fin, linf, rms, dense, dig
                if linf < REFUSE_FACTOR * ref_err:
                    row.below_reference = True
                    row.err_final = row.err_linf = row.err_rms = row.digits = math.nan
                if prev is not None and prev.status == "ok" and not prev.below_reference and not row.below_reference \
                        and abs(prev.step / H - 2.0) < 1e-9:
                    row.order = math.log2(prev.err_linf / row.err_linf) if row.err_linf > 0 else math.nan
            rows.append(row)
            prev = row
    rep = Report(system.name, rows, ref_err, ref.settings, target, measure)
    labels = list(dict.fromkeys(r.label for r in rows))
    for lab in labels:
        ok = [r for r in rows if r.label == lab and r.status == "ok" and (r.err_linf <= target or r.below_reference)]
        rep.coarsest[lab] = max(ok, key=lambda r: r.step) if ok else None
    walls = [r.wall_median for r in rows if r.status == "ok" and r.err_linf == r.err_linf]
    if walls:
        rep.common_wall = float(statistics.median(walls))
        for lab in labels:
            pts = sorted((r.wall_median, r.err_linf) for r in rows
                         if r.label == lab and r.status == "ok" and r.err_linf == r.err_linf and r.err_linf > 0)
            if len(pts) >= 2 and pts[0][0] <= rep.common_wall <= pts[-1][0]:
                lw = np.log([p[0] for p in pts])
                le = np.log([p[1] for p in pts])
                order = np.argsort(lw)
                rep.equal_time[lab] = float(np.exp(np.interp(math.log(rep.common_wall), lw[order], le[order])))
            else:
                rep.equal_time[lab] = math.nan
    return rep


def write_report(rep: Report, out_dir) -> dict:
    """report.txt, report.csv and work_precision.png in ``out_dir``; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"table": out / "report.txt", "csv": out / "report.csv", "plot": out / "work_precision.png"}
    paths["table"].write_text(rep.table() + "\n")
    fields = list(Row("", "", "", 0.0).as_dict())
    with open(paths["csv"], "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=["system", "measure", "reference_error", *fields])
        w.writeheader()
        for r in rep.rows:
            w.writerow({"system": rep.system, "measure": rep.measure, "reference_error": rep.reference_error,
                        **r.as_dict()})
    plot_work_precision(rep, paths["plot"])
    return paths


# --------------------------------------------------------------------------
# the work-precision plot
# --------------------------------------------------------------------------
#: the look of each coupling scheme in every plot: a marker and a colour family per scheme (ColorBrewer
#: sequential ramps, darker for higher extrapolation orders), a line style per extrapolation
SCHEME_MARKERS = {"jacobi": "o", "gauss-seidel": "s", "iterative": "^", "newton": "D"}
SCHEME_COLOURS = {
    "jacobi": ("#6baed6", "#3182bd", "#08519c", "#08306b"),  # blues
    "gauss-seidel": ("#74c476", "#31a354", "#006d2c", "#00441b"),  # greens
    "iterative": ("#9e9ac8", "#756bb1", "#54278f", "#3f007d"),  # purples
    "newton": ("#fd8d3c", "#e6550d", "#a63603", "#7f2704"),  # oranges
}
EXTRAPOLATION_ORDER = ("hold", "linear", "quadratic", "cubic")
EXTRAPOLATION_LINES = {"hold": "-", "linear": "--", "quadratic": "-.", "cubic": ":"}
_OTHER_COLOURS = ("#000000", "#8c510a", "#c51b7d", "#666666", "#01665e")  # the monolithic FMU, then the rest
_OTHER_MARKERS = ("*", "P", "X", "v", "h")


def scheme_style(label: str, others: Optional[list] = None) -> dict:
    """Matplotlib style of a report row label: ``scheme/extrapolation`` (a trailing internal-solver setting,
    as in ``newton/cubic rodas3 1e-10``, keeps the scheme's colour and marker, hollow), anything else
    (``monolithic FMU``) black stars first; ``others`` lists the labels of that kind seen so far."""
    head, _, rest = label.partition(" ")
    scheme, _, ext = head.partition("/")
    if scheme in SCHEME_MARKERS and ext in EXTRAPOLATION_ORDER:
        style = {"color": SCHEME_COLOURS[scheme][EXTRAPOLATION_ORDER.index(ext)],
                 "marker": SCHEME_MARKERS[scheme], "linestyle": EXTRAPOLATION_LINES[ext]}
        if rest:
            style["markerfacecolor"] = "none"
        return style
    others = others if others is not None else []
    if label not in others:
        others.append(label)
    k = others.index(label)
    return {"color": _OTHER_COLOURS[k % len(_OTHER_COLOURS)], "marker": _OTHER_MARKERS[k % len(_OTHER_MARKERS)],
            "linestyle": "-"}


def _h_ms(h: float) -> str:
    return f"{h * 1e3:.3g}"


class _Labels:
    """Small text labels next to markers, placed where they overlap no label placed before: the first of a few
    offsets that is free, or none (a point among others of its curve keeps its marker and loses its number)."""

    OFFSETS = ((4, 2), (4, -9), (-4, 2), (-4, -9), (0, 5), (0, -12))  # points, right/left of the marker

    def __init__(self, fig):
        self.fig, self.boxes = fig, []

    def add(self, ax, x, y, text, colour, fontsize=6.0, offsets=OFFSETS) -> None:
        px, py = ax.transData.transform((x, y)) * 72.0 / self.fig.dpi  # points on the figure
        w, h = 0.6 * fontsize * len(text), fontsize
        for dx, dy in offsets:
            x0 = px + dx if dx >= 0 else px + dx - w
            box = (x0, py + dy, x0 + w, py + dy + h)
            if all(box[2] < b[0] or box[0] > b[2] or box[3] < b[1] or box[1] > b[3] for b in self.boxes):
                self.boxes.append(box)
                ax.annotate(text, (x, y), textcoords="offset points", xytext=(dx, dy), fontsize=fontsize,
                            color=colour, ha="left" if dx >= 0 else "right")
                return


def plot_work_precision(rep: Report, path) -> None:
    """Max error at the communication points against median wall time, log-log, one curve per setting in its
    fixed style (:func:`scheme_style`), points numbered with their macro step H in ms where there is room.
    Runs that stopped (failed) go to a strip below, one row per setting at the wall time they ran, each
    numbered, the steps listed at the row's end; the target and the reference's limit are labelled lines; the
    legend sits right of the axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = list(dict.fromkeys(r.label for r in rep.rows))
    others: list = []
    styles = {lab: scheme_style(lab, others) for lab in labels}
    failed = {lab: [r for r in rep.rows if r.label == lab and r.status != "ok"
                    and not (r.err_linf == r.err_linf and r.wall_median == r.wall_median)
                    and r.wall_first == r.wall_first and r.wall_first > 0] for lab in labels}
    failed = {lab: rs for lab, rs in failed.items() if rs}
    strip = 0.4 * len(failed) + 0.5 if failed else 0.0
    fig = plt.figure(figsize=(11.0, 6.5 + strip))
    grid = fig.add_gridspec(2 if failed else 1, 1, height_ratios=[6.5, strip] if failed else [1], hspace=0.08)
    ax = fig.add_subplot(grid[0])
    points, rings = [], []
    for lab in labels:
        st = styles[lab]
        rows = [r for r in rep.rows if r.label == lab]
        pts = [(r.wall_median, r.err_linf, r.step) for r in rows
               if r.status == "ok" and r.err_linf == r.err_linf and r.err_linf > 0]
        ax.loglog([p[0] for p in pts], [p[1] for p in pts], label=lab, ms=5, lw=1.2, **st)
        points += [(w, e, _h_ms(h), st["color"]) for w, e, h in pts]
        for r in rows:  # measured but not ok (unreliable): where it landed, a large hollow ring
            if r.status != "ok" and r.err_linf == r.err_linf and r.err_linf > 0 and r.wall_median == r.wall_median:
                ax.loglog([r.wall_median], [r.err_linf], "o", mfc="none", mec=st["color"], ms=10, mew=1.2)
                rings.append((r.wall_median, r.err_linf, f"{_h_ms(r.step)} {r.status}", st["color"]))
    limit = REFUSE_FACTOR * rep.reference_error
    for y, text, ls, colour in ((rep.target, f"target {rep.target:g}", "--", "k"),
                                (limit, f"below: not measured (100 x the reference's error estimate "
                                        f"{rep.reference_error:.1g})", ":", "grey")):
        ax.axhline(y, color=colour, ls=ls, lw=0.9)
        ax.annotate(text, (0.995, y), xycoords=("axes fraction", "data"), textcoords="offset points",
                    xytext=(0, 2), ha="right", va="bottom", fontsize=7, color=colour)
    ax.set_ylabel(f"max error at communication points, {rep.measure}")
    ax.set_title(f"{rep.system}: error against run time (numbers at the points: macro step H in ms)")
    ax.grid(True, which="major", alpha=0.35)
    ax.grid(True, which="minor", alpha=0.1)
    handles, names = ax.get_legend_handles_labels()
    ax.legend(handles, names, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0,
              title="scheme / inputs", title_fontsize=8)
    xlabel = "wall time [s] (median of the timed runs; failed runs: up to the failure)"
    axf = None
    if failed:
        axf = fig.add_subplot(grid[1], sharex=ax)
        rows_f = list(failed)
        for i, lab in enumerate(rows_f):
            st = styles[lab]
            walls = [r.wall_first for r in failed[lab]]
            axf.semilogx(walls, [i] * len(walls), linestyle="none", marker="x", color=st["color"], ms=7, mew=1.5)
            axf.annotate(f"failed at H = {', '.join(_h_ms(r.step) for r in failed[lab])} ms", (1.01, i),
                         xycoords=("axes fraction", "data"), va="center", fontsize=7, color=st["color"])
        axf.set_yticks(range(len(rows_f)), rows_f, fontsize=7)
        for tick, lab in zip(axf.get_yticklabels(), rows_f):
            tick.set_color(styles[lab]["color"])
        axf.set_ylim(len(rows_f) - 0.5, -0.5)
        axf.set_title("failed (x: the run stopped with a failure, at the wall time it ran)", fontsize=8, loc="left")
        axf.grid(True, axis="x", which="major", alpha=0.35)
        axf.grid(True, axis="x", which="minor", alpha=0.1)
        plt.setp(ax.get_xticklabels(), visible=False)
        axf.set_xlabel(xlabel)
    else:
        ax.set_xlabel(xlabel)
    # numbers last, on the final limits, each where it overlaps none placed before (rings' verdicts first)
    fig.canvas.draw()
    ax.set_xlim(ax.get_xlim())
    ax.set_ylim(ax.get_ylim())
    placer = _Labels(fig)
    for x, y, text, colour in rings + points:
        placer.add(ax, x, y, text, colour)
    if axf is not None:
        for i, lab in enumerate(failed):
            for r in failed[lab]:
                placer.add(axf, r.wall_first, i, _h_ms(r.step), styles[lab]["color"], 5.5,
                           offsets=((0, 4), (0, -10), (5, 4), (5, -10), (-5, 4), (-5, -10)))
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
