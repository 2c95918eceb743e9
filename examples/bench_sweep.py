"""Benchmark: parameter sweeps on Dask -- runs per second against workers, the Dask path's per-run
overhead against a bare serial loop, and the memory of a worker.

The scene (default examples/scenes/single_joint_split.toml) is built once;
every run is one co-simulation of it with another ``joint.J`` (a grid of
``--points`` values), exactly what ``fmugen sweep`` submits
(:func:`fmugen.sweep.worker.run_point`).

1. Serial: the same runs in this process, one after another
   (``fmugen.cosim.master.run``, no Dask): seconds per run.
2. Dask, for k = 1 .. ``--max-workers`` worker processes (one thread each)
   on a LocalCluster: the FMUs scattered once and extracted by each worker
   in a warm-up round, then ``--points`` runs timed from submission to the
   last result.  Reported: runs/s, speed-up over k = 1 and the parallel
   efficiency (runs/s at k) / (k x runs/s at 1) -- the goal is >= 0.8 up
   to the number of cores; and the per-run overhead of the Dask path,
   (wall time x k / runs) - serial seconds per run.  Wall-clock figures
   need an otherwise idle machine; the CPU seconds per run of the whole
   Dask path (client, scheduler, nannies, workers) against the serial
   loop's CPU seconds per run give the overhead whatever else runs.
3. Memory: resident set size of each worker process after its runs
   (``psutil`` in the worker), and of this client process.

Other work on the machine skews every figure: the load average is printed.

Run:  python examples/bench_sweep.py [--points 40] [--max-workers N] [--stop 1.0] [--scene FILE]
"""
import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _rss() -> int:
    import psutil

    return psutil.Process().memory_info().rss


def _cpu_tree() -> float:
    """CPU seconds of this process and its children (the local cluster's scheduler runs in this
    process, its nannies and workers are children): a measure of work that other load does not skew."""
    import psutil

    me = psutil.Process()
    total = sum(me.cpu_times()[:2])
    for c in me.children(recursive=True):
        try:
            total += sum(c.cpu_times()[:2])
        except psutil.Error:
            pass
    return total


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--scene", default=str(HERE / "scenes" / "single_joint_split.toml"))
    ap.add_argument("--name", default="joint.J", help="the swept parameter")
    ap.add_argument("--low", type=float, default=1.0)
    ap.add_argument("--high", type=float, default=4.0)
    ap.add_argument("--points", type=int, default=40, help="runs per measurement")
    ap.add_argument("--max-workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--stop", type=float, default=None, help="simulated time per run [s] (default: the scene's)")
    args = ap.parse_args(argv)

    from dask.distributed import Client, LocalCluster, wait

    from fmugen.cosim.master import run
    from fmugen.sweep.metrics import parse_metrics
    from fmugen.sweep.points import point_key
    from fmugen.sweep.prepare import SweepPlan, point_system, run_options
    from fmugen.sweep.worker import make_bundle, run_point

    tmp = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    plan = SweepPlan(args.scene, [args.name], tmp / "fmus").build()
    # every run does the whole work: the master's divergence monitor could stop a borderline run early
    opts = run_options(plan.system.settings, {"detect_divergence": False})
    if args.stop:
        opts["stop"] = args.stop
    wanted = parse_metrics(None, [r.column for r in plan.system.recorded])
    values = np.linspace(args.low, args.high, args.points)
    tasks = [plan.task(i, point_key({args.name: float(v)}), {args.name: float(v)}) for i, v in enumerate(values)]
    print(f"scene {plan.scene.name}: {len(plan.system.units)} FMUs, {args.points} runs of {args.name} in "
          f"[{args.low:g}, {args.high:g}], options {opts}; {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.2f}")

    # 1. serial
    run(point_system(plan.system, tasks[0]), **opts)  # warm-up: extract, load the libraries
    t0, c0 = time.perf_counter(), time.process_time()
    for t in tasks:
        res = run(point_system(plan.system, t), **opts)
        assert res.ok, res.summary
    serial = (time.perf_counter() - t0) / len(tasks)
    serial_cpu = (time.process_time() - c0) / len(tasks)
    print(f"\nserial loop: {serial * 1e3:.1f} ms per run ({1 / serial:.2f} runs/s), "
          f"{serial_cpu * 1e3:.1f} ms CPU per run\n")

    # 2. + 3. Dask
    bundle = make_bundle(plan, opts, wanted)
    print(f"{'workers':>7} {'runs/s':>8} {'speed-up':>8} {'efficiency':>10} {'overhead/run':>12} "
          f"{'CPU/run':>9} {'CPU overhead':>12} {'worker RSS':>16} {'load':>5}")
    rate1 = None
    rows = []
    for k in range(1, args.max_workers + 1):
        with LocalCluster(n_workers=k, threads_per_worker=1, processes=True, dashboard_address=None,
                          silence_logs=40) as cluster, Client(cluster) as client:
            shipped = client.scatter(bundle, broadcast=True, hash=False)
            # warm-up: every worker writes and extracts the FMUs once
            warm = [client.submit(run_point, shipped, tasks[i % len(tasks)], pure=False,
                                  workers=[w]) for i, w in enumerate(client.scheduler_info()["workers"])]
            wait(warm)
            t0, c0 = time.perf_counter(), _cpu_tree()
            futs = [client.submit(run_point, shipped, t, pure=False) for t in tasks]
            out = client.gather(futs)
            wall = time.perf_counter() - t0
            cpu = (_cpu_tree() - c0) / len(tasks)  # client + scheduler + nannies + workers, per run
            assert all(r["status"] == "ok" for r in out), [r["failure"] for r in out if r["status"] != "ok"]
            rss = list(client.run(_rss).values())
        rate = len(tasks) / wall
        rate1 = rate1 or rate
        overhead = wall * k / len(tasks) - serial
        rows.append((k, rate, rate / rate1, rate / (k * rate1), overhead, statistics.median(rss)))
        print(f"{k:>7} {rate:>8.2f} {rate / rate1:>8.2f} {rate / (k * rate1):>10.2f} {overhead * 1e3:>9.1f} ms "
              f"{cpu * 1e3:>6.1f} ms {(cpu - serial_cpu) * 1e3:>9.1f} ms "
              f"{statistics.median(rss) / 2**20:>10.0f} MiB/wk {os.getloadavg()[0]:>5.2f}")
    print(f"\nclient process RSS {_rss() / 2**20:.0f} MiB; serial loop {1 / serial:.2f} runs/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
