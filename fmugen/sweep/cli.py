"""``fmugen sweep``: a parameter study of a scene on Dask.

    fmugen sweep SCENE.toml --grid NAME=v1,v2,... [--grid ...] | --sample NAME=dist(...) -n N --seed S
                 [--metrics final,peak,settling,error | COLUMN:METRIC] --out DIR
                 [--scheduler ADDRESS] [--workers K] [--threads] [--set NAME=VALUE ...]
                 [--scheme S] [--extrapolation E] [--step H] [--coupling-tol E] [--iterations N]
                 [--no-divergence-check] [--save-runs]

Builds the scene's FMUs once (swept parameters kept settable), runs every
point on a Dask local cluster (one worker process per core) or on the
scheduler at ADDRESS, and writes DIR/results.csv (Parquet too with pyarrow),
DIR/metrics.png and the journal DIR/points.csv: the same command again skips
the points already done.  Distributions: normal(mean,std), uniform(low,high),
lognormal(mu,sigma), triangular(low,mode,high) -- parsed, never evaluated.
"""
from __future__ import annotations

import sys


def add_parser(sub) -> None:
    """Register ``sweep`` on the ``fmugen`` command's subparsers."""
    p = sub.add_parser("sweep", help="run a scene over a parameter grid or Monte-Carlo sample (Dask)",
                       description=__doc__.split("\n\n")[2].strip())
    p.add_argument("scene", help="scene TOML file")
    p.add_argument("--grid", action="append", default=[], metavar="NAME=v1,v2,...",
                   help="values of a scene parameter (repeatable: the Cartesian product), e.g. joint.J=1,2,4")
    p.add_argument("--sample", action="append", default=[], metavar="NAME=DIST(...)",
                   help="a distribution of a scene parameter (repeatable), e.g. actuator.beta_e=normal(1.6e9,5e7)")
    p.add_argument("-n", type=int, default=None, help="number of Monte-Carlo samples")
    p.add_argument("--seed", type=int, default=None, help="seed of the samples (required with --sample)")
    p.add_argument("--metrics", action="append", default=None, metavar="LIST",
                   help="final, peak, settling, error (L-inf against the reference: a reference solve per "
                        "point), for every recorded column or COLUMN:METRIC; default final,peak,settling")
    p.add_argument("--band", type=float, default=0.02, help="settling band, fraction of the final change")
    p.add_argument("--out", required=True, metavar="DIR", help="results folder (reused: done points are skipped)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a running dask.distributed scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, metavar="K",
                   help="local cluster: worker processes (default: one per core)")
    p.add_argument("--threads", action="store_true", help="local cluster: threads in one process, not processes")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="change the base scene")
    p.add_argument("--scheme", default=None, help="co-simulation scheme (default: the scene's [cosim])")
    p.add_argument("--extrapolation", default=None, help="input extrapolation (default: the scene's [cosim])")
    p.add_argument("--step", type=float, default=None, help="macro step [s] (default: the scene's)")
    p.add_argument("--coupling-tol", type=float, default=None,
                   help="iterated schemes: convergence of the coupled values (default: the scene's [cosim])")
    p.add_argument("--iterations", type=int, default=None,
                   help="iterated schemes: most iterations per macro step (default: the scene's [cosim])")
    p.add_argument("--no-divergence-check", action="store_true",
                   help="do not stop a run whose coupling the master judges divergent")
    p.add_argument("--save-runs", action="store_true", help="also write each point's series to DIR/runs/KEY.npz")
    p.add_argument("--no-plot", action="store_true", help="no DIR/metrics.png")
    p.add_argument("--allow-factories", action="store_true",
                   help="run the Python factories the scene names (they are code: only for files you trust)")
    p.set_defaults(func=run)


def run(args) -> int:
    from .execute import sweep

    if not args.grid and not args.sample:
        from .errors import SweepError

        raise SweepError("fmugen sweep: give --grid NAME=v1,v2,... or --sample NAME=dist(...) -n N --seed S")
    options = {k: v for k, v in (("scheme", args.scheme), ("extrapolation", args.extrapolation),
                                 ("step", args.step), ("coupling_tol", args.coupling_tol),
                                 ("max_iterations", args.iterations)) if v is not None}
    if args.no_divergence_check:
        options["detect_divergence"] = False
    try:
        r = sweep(args.scene, grid=args.grid, sample=args.sample, n=args.n, seed=args.seed, metrics=args.metrics,
                  out=args.out, scheduler=args.scheduler, workers=args.workers, processes=not args.threads,
                  sets=args.set, options=options, band=args.band, save_runs=args.save_runs, progress=True,
                  plot=not args.no_plot, allow_factories=args.allow_factories)
    except KeyboardInterrupt:
        return 130
    bad = r.failed
    refused = sum(row["status"] == "refused" for row in bad)
    print(f"{len(r.rows)} points ({r.ran} run now in {r.wall_time:.1f} s, {r.skipped} done before): "
          f"{len(r.rows) - len(bad)} ok, {len(bad) - refused} failed, {refused} refused (not run)")
    for row in bad[:5]:
        vals = ", ".join(f"{n}={row[n]:.6g}" for n in r.names)
        print(f"  {'refused' if row['status'] == 'refused' else 'failed'}: {vals}: {row['failure'][:300]}")
    if len(bad) > 5:
        print(f"  ... {len(bad) - 5} more in the table")
    stats = r.statistics()
    if stats:
        w = max(len(s[0]) for s in stats)
        print(f"{'metric':<{w}} {'n':>5} {'mean':>12} {'std':>11} {'min':>12} {'median':>12} {'max':>12}")
        for name, n, mean, std, lo, med, hi in stats:
            print(f"{name:<{w}} {n:>5} {mean:>12.6g} {std:>11.4g} {lo:>12.6g} {med:>12.6g} {hi:>12.6g}")
    print("table: " + ", ".join(str(p) for p in r.table) + (f"; plot: {r.plot}" if r.plot else ""))
    sys.stdout.flush()
    return 0
