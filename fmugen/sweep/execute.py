"""Run a sweep on Dask: a local cluster by default, or the scheduler a user points at.

    result = fmugen.sweep.sweep("examples/scenes/single_joint_split.toml",
                                grid=["joint.J=1,2,4"], metrics=["final,peak"], out="out/sweep_J")

Steps: the points (:mod:`.points`); the FMUs built once with the swept
parameters kept settable (:mod:`.prepare`); each point's start values (the
state of rest solved on the client where the scene asks for one); the FMUs
and run settings scattered once to every worker (:mod:`.worker`); one task
per point; rows appended to the journal as points finish; the table and the
plot at the end (:mod:`.table`).  ``out`` holds ``sweep.json`` (what was
asked), ``points.csv`` (the journal), ``results.csv``, ``metrics.png`` and
``fmus/``.  Running the same sweep into the same ``out`` again skips the
points already in the journal (failed ones included: their reason is
recorded); a different sweep into the same folder is refused.

Cluster.  Without ``scheduler`` a ``dask.distributed.LocalCluster`` is
started with one single-threaded worker process per core (``workers``
overrides the count; ``processes=False`` gives one process with a thread
per worker -- the FMUs are thread-safe, but the master's Python loop holds
the GIL).  With ``scheduler="tcp://host:8786"`` the sweep runs on that
cluster's workers (``workers`` is then the cluster's business).  The
dashboard address is printed when the cluster serves one (bokeh installed).
"""
from __future__ import annotations

import json
import logging
import math
import os
import sys
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from ..scene import SceneError
from . import metrics as _metrics
from . import table as _table
from .errors import PointRefused, SweepError
from .points import make_points, parse_grid, parse_samples, point_key
from .prepare import SweepPlan, run_options
from .worker import make_bundle, run_point


@dataclass
class SweepResult:
    rows: list  # one dict per point, in point order
    names: tuple  # swept names
    metric_names: tuple
    out_dir: Path
    table: list  # paths of the table(s)
    plot: Optional[Path]
    ran: int  # points run by this call
    skipped: int  # points already in the journal
    wall_time: float  # of the points run by this call [s]

    @property
    def failed(self) -> list:
        return [r for r in self.rows if r["status"] != "ok"]

    def column(self, name: str) -> np.ndarray:
        return np.array([r[name] for r in self.rows], dtype=float)

    def statistics(self) -> list:
        """Per metric over the points that ran (status ok): (name, count, mean, std, min, median, max).

        The spread of a Monte-Carlo sweep (std: the sample standard deviation, ddof = 1).
        """
        out = []
        for m in self.metric_names:
            v = np.array([r[m] for r in self.rows if r["status"] == "ok"], dtype=float)
            v = v[np.isfinite(v)]
            if len(v):
                out.append((m, len(v), float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else math.nan,
                            float(v.min()), float(np.median(v)), float(v.max())))
            else:
                out.append((m, 0) + (math.nan,) * 5)
        return out


class Progress:
    """``12/100 done (1 failed), 3.1 runs/s, ETA 28 s`` on a terminal (rewritten in place), every 10 % otherwise."""

    def __init__(self, total: int, done: int, stream=None, enabled: bool = True):
        self.total, self.done, self.failed, self.ran = total, done, 0, 0
        self.refused = 0  # of the failed: refused by the value checks, never run
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = enabled and getattr(self.stream, "isatty", lambda: False)()
        self.t0 = time.perf_counter()
        self._last_decile = -1

    def line(self) -> str:
        dt = time.perf_counter() - self.t0
        rate = self.ran / dt if dt > 0 else 0.0
        left = self.total - self.done
        eta = f"{left / rate:.0f} s" if rate > 0 else "-"
        bad = f"{self.failed - self.refused} failed, {self.refused} refused" if self.refused else f"{self.failed} failed"
        return f"sweep: {self.done}/{self.total} done ({bad}), {rate:.3g} runs/s, ETA {eta}"

    def update(self, row: Optional[dict] = None) -> None:
        if row is not None:
            self.done += 1
            self.ran += 1
            self.failed += row["status"] != "ok"
            self.refused += row["status"] == "refused"
        if not self.enabled:
            return
        if self.tty:
            self.stream.write("\r" + self.line() + " " * 4)
            self.stream.flush()
        else:
            decile = int(10 * self.done / max(self.total, 1))
            if decile != self._last_decile:
                self._last_decile = decile
                print(self.line(), file=self.stream, flush=True)

    def close(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()

    def say(self, text: str) -> None:
        if self.enabled:
            print(("\n" if self.tty and self.ran else "") + text, file=self.stream, flush=True)


def _has_bokeh() -> bool:
    try:
        import bokeh  # noqa: F401
    except ImportError:
        return False
    return True


def start_client(scheduler: Optional[str] = None, workers: Optional[int] = None, processes: bool = True):
    """(client, cluster or None): a LocalCluster sized to the machine, or a client of ``scheduler``."""
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError) as exc:
            raise SweepError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc})") from None
    n = workers or os.cpu_count() or 1
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise SweepError(f"--workers: {workers!r} is not a positive integer")
    # ":0": the scheduler's HTTP server (the dashboard, with bokeh) on a free port, never a clash on 8787
    kw = dict(dashboard_address=":0", silence_logs=logging.ERROR)
    if processes:
        cluster = LocalCluster(n_workers=int(n), threads_per_worker=1, processes=True, **kw)
    else:
        cluster = LocalCluster(n_workers=1, threads_per_worker=int(n), processes=False, **kw)
    return Client(cluster), cluster


#: how long a sweep waits for a Dask scheduler to answer, at most [s]
SCHEDULER_TIMEOUT = 10.0


def probe_scheduler(address: str, timeout: float = SCHEDULER_TIMEOUT) -> None:
    """Refuse (before anything is written) a scheduler address that does not answer as a Dask
    scheduler within ``timeout``: nothing listening, a host that drops packets, a server that
    says nothing (an HTTP server waits for a request) or sends what is not a Dask handshake
    (whose first 8 bytes are its length, a few hundred bytes).  ``tcp://`` addresses (and bare
    ``host:port``) are probed; other transports are left to Dask, with its own timeout."""
    import socket
    import struct

    text = str(address).strip()
    proto, _, rest = text.rpartition("://")
    if proto not in ("", "tcp"):
        return
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise SweepError(f"--scheduler {address!r}: expected tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout) as sock:
            sock.settimeout(timeout)
            head = b""
            while len(head) < 8:
                chunk = sock.recv(8 - len(head))
                if not chunk:
                    break
                head += chunk
    except socket.timeout:
        raise SweepError(f"--scheduler {address}: no answer within {timeout:g} s (not a Dask scheduler, or "
                         f"unreachable)") from None
    except OSError as exc:
        raise SweepError(f"--scheduler {address}: cannot reach the Dask scheduler "
                         f"({exc.strerror or exc})") from None
    size = struct.unpack("<Q", head)[0] if len(head) == 8 else 0
    if not 0 < size <= 2**20:
        raise SweepError(f"--scheduler {address}: answered, but not as a Dask scheduler (its first message "
                         f"announces {size} bytes)")


def _check_run_options(opts: dict, scene=None) -> None:
    """The co-simulation settings a sweep runs every point with, checked once before any build or run."""
    from ..cosim.errors import CosimError
    from ..cosim.master import check_choices

    try:
        if "scheme" in opts or "extrapolation" in opts or scene is not None:
            check_choices(opts.get("scheme", "gauss-seidel"), opts.get("extrapolation", "hold"))
    except CosimError as exc:
        raise SweepError(f"--scheme/--extrapolation: {exc}") from None
    step = opts.get("step")
    if step is not None:
        from .. import arguments

        h = arguments.positive(step, "--step", "a positive macro step [s]")
        if scene is not None:
            from ..scene.file import check_time_grid

            check_time_grid(scene.spec.start, scene.spec.stop, min(h, scene.spec.stop - scene.spec.start),
                            "--step:")


def _manifest(scene_path, sets, names, points_spec, options, wanted, band) -> dict:
    import hashlib

    return {"scene": str(Path(scene_path).resolve()),
            "scene_sha256": hashlib.sha256(Path(scene_path).read_bytes()).hexdigest(),
            "set": {k: v for k, v in sorted((sets or {}).items())}, "names": list(names), "points": points_spec,
            "options": {k: options[k] for k in sorted(options)}, "metrics": [f"{c}:{m}" for c, m in wanted],
            "band": band}


def _check_manifest(path: Path, new: dict) -> None:
    if path.is_file():
        old = json.loads(path.read_text())
        diff = [k for k in ("scene", "scene_sha256", "set", "names", "options", "metrics", "band")
                if json.dumps(old.get(k), sort_keys=True, default=str) != json.dumps(new.get(k), sort_keys=True, default=str)]
        if diff:
            raise SweepError(f"{path.parent}: holds another sweep (its {', '.join(diff)} differ); "
                             f"use another --out folder or remove this one")
    path.write_text(json.dumps(new, indent=1, default=str))


def sweep(scene, grid=None, sample=None, n: Optional[int] = None, seed: Optional[int] = None,
          metrics: Optional[Sequence[str]] = None, out="sweep", scheduler: Optional[str] = None,
          workers: Optional[int] = None, processes: bool = True, sets=None, options: Optional[dict] = None,
          band: float = 0.02, save_runs: bool = False, client=None, progress: Optional[bool] = None,
          plot: bool = True, allow_factories: bool = False) -> SweepResult:
    """Run ``scene`` (a scene file) at every point of a grid or a Monte-Carlo sample; see the module docstring.

    grid: ``["joint.J=1,2,4", ...]`` or ``{"joint.J": [1, 2, 4]}``; sample:
    ``["actuator.beta_e=normal(1.6e9,5e7)"]`` or a dict, with ``n`` draws and
    ``seed``; metrics: ``["final,peak", "joint.theta:error"]`` (default
    final, peak, settling of every recorded column); sets: ``--set``
    overrides of the base scene; options: keywords of
    :func:`fmugen.cosim.master.run` over the scene's ``[cosim]`` table;
    band: settling band (fraction of the final change); save_runs: also
    write each point's recorded series to ``out/runs/<key>.npz``; client: an
    existing ``dask.distributed.Client`` (then scheduler and workers are not
    used); progress: on stderr (default: when stderr is a terminal);
    allow_factories: run Python factories the scene names (see :func:`fmugen.load_scene`).
    """
    from ..scene import parse_sets

    sets = parse_sets(sets)
    g, s = parse_grid(grid), parse_samples(sample)
    points = make_points(g, s, n, seed)
    names = tuple(g) + tuple(s)
    if not (isinstance(band, (int, float)) and 0 < band < 1):
        raise SweepError(f"--band: {band!r} must lie between 0 and 1")
    # every argument before anything is written: workers, scheme, the scheduler's answer
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise SweepError(f"--workers {workers!r}: a number of worker processes >= 1 (leave it out for one "
                         f"per core)")
    _check_run_options(options or {})
    if scheduler and client is None:
        probe_scheduler(scheduler)
    from .. import arguments

    out = arguments.output_folder(out, "--out", inputs=[scene])
    show = sys.stderr.isatty() if progress is None else bool(progress)
    say = (lambda t: print(t, file=sys.stderr, flush=True)) if show else (lambda t: None)
    try:
        if str(scene).lower().endswith(".ssp"):  # an SSP archive: its FMUs as they are (fmugen/ssp/sweep.py)
            from ..ssp.sweep import SspSweepPlan

            plan = SspSweepPlan(scene, names, out / "fmus", sets=sets)
        else:
            plan = SweepPlan(scene, names, out / "fmus", sets=sets, allow_factories=allow_factories)
    except SceneError as exc:
        raise SweepError(str(exc)) from None
    # everything that can be refused is refused before the build
    opts = run_options(plan.scene.spec.cosim, options)
    _check_run_options(opts, plan.scene)
    wanted = _metrics.parse_metrics(metrics, plan.columns)
    mnames = tuple(_metrics.metric_names(wanted))
    spec = {"grid": {k: list(v) for k, v in g.items()}, "sample": {k: str(d) for k, d in s.items()},
            "n": n, "seed": seed}
    out.mkdir(parents=True, exist_ok=True)  # the first thing written, after every check
    _check_manifest(out / "sweep.json", _manifest(scene, sets, names, spec, opts, wanted, band))
    say(f"sweep: {len(points)} point{'s' if len(points) != 1 else ''} over {', '.join(names)}; "
        f"building the FMUs once")
    try:
        plan.build()
    except SceneError as exc:
        raise SweepError(str(exc)) from None
    cols = _table.header(names, mnames)
    journal = _table.Journal(out / "points.csv", cols)
    keys, order = [], {}
    for i, p in enumerate(points):
        k = point_key(p)
        keys.append(k)
        order.setdefault(k, i)  # a repeated point runs once
    todo = [i for i, k in enumerate(keys) if order[k] == i and k not in journal]
    distinct = len(order)
    skipped = distinct - len(todo)
    prog = Progress(distinct, skipped, enabled=show)
    if skipped:
        prog.say(f"sweep: {skipped} of {distinct} points already done in {out / 'points.csv'}; running {len(todo)}")
    runs_dir = out / "runs"
    if save_runs:
        runs_dir.mkdir(exist_ok=True)

    def record(row):
        run = row.pop("run", None)
        if save_runs and run is not None:
            t, v, c = run
            np.savez(runs_dir / f"{row['key']}.npz", time=t, values=v, columns=np.array(c))
        row.update({nm: points[row["index"]][nm] for nm in names})
        for m in mnames:  # a lost task has no metrics
            row.setdefault(m, math.nan)
        journal.append(row)
        prog.update(row)

    tasks = []
    for i in todo:
        try:
            tasks.append(plan.task(i, keys[i], points[i]))
        except (SceneError, SweepError) as exc:  # refused, or no state of rest at this point: recorded, not run
            status = "refused" if isinstance(exc, PointRefused) else "error"
            record({"index": i, "key": keys[i], "status": status, "failure": str(exc).replace("\n", " | "),
                    "wall_time": 0.0, "macro_steps": 0, "worker": "client",
                    **{m: math.nan for m in mnames}})
    w0 = time.perf_counter()
    own = cluster = None
    try:
        if tasks:
            if client is None:
                client, cluster = start_client(scheduler, workers, processes)
                own = True
            try:
                link = client.dashboard_link if (scheduler or _has_bokeh()) else None
            except Exception:
                link = None
            nw = len(client.scheduler_info().get("workers", {}))
            prog.say(f"sweep: {len(tasks)} runs on {nw} Dask worker(s) at {client.scheduler.address}"
                     + (f"; dashboard: {link}" if link else "; no dashboard (install bokeh for one)"))
            _run_on(client, make_bundle(plan, opts, wanted, band, save_runs), tasks, record, prog)
    except KeyboardInterrupt:
        prog.say(f"sweep: interrupted; {len(journal.rows)} points are in {out / 'points.csv'}: "
                 f"run the same command again to continue")
        raise
    finally:
        prog.close()
        journal.close()
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    wall = time.perf_counter() - w0
    rows = []
    for i, k in enumerate(keys):
        if order[k] != i:
            continue
        r = dict(journal.rows[k])
        r["index"] = i
        r.update({nm: points[i][nm] for nm in names})
        rows.append(r)
    paths = _table.write_table(rows, cols, out)
    pl = _table.plot(rows, names, mnames, out / "metrics.png", plan.scene.name) if plot and rows else None
    return SweepResult(rows, names, mnames, out, paths, pl, len(tasks), skipped, wall)


def _run_on(client, bundle, tasks, record, prog) -> None:
    """One Dask task per point; rows recorded as they finish; a lost task is recorded with its reason."""
    from dask.distributed import as_completed

    shipped = client.scatter(bundle, broadcast=True, hash=False)
    prog.t0 = time.perf_counter()  # the rate counts runs, not the cluster's start-up
    tag = uuid.uuid4().hex[:8]
    futures = {client.submit(run_point, shipped, t, key=f"fmugen-sweep-{t.key}-{tag}", pure=False): t
               for t in tasks}
    try:
        for fut in as_completed(futures):
            t = futures[fut]
            try:
                row = fut.result()
            except Exception as exc:  # the worker died (a crash in an FMU), or the task was lost
                row = {"index": t.index, "key": t.key, "status": "error",
                       "failure": f"{type(exc).__name__}: {exc}".replace("\n", " | "),
                       "wall_time": math.nan, "macro_steps": 0, "worker": ""}
            fut.release()
            record(row)
    except BaseException:
        client.cancel(list(futures))
        raise
