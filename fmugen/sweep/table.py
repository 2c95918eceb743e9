"""The results of a sweep on disk: an append-only journal, the table, the plot.

``points.csv`` is the journal: one row per finished point, appended and
flushed as each point finishes, so an interrupted sweep keeps what it did
(a half-written last line is ignored when read back).  Values are written
with ``repr`` (shortest round-trip form): the numbers read back are the
numbers computed, bit for bit.

``results.csv`` (and ``results.parquet`` when pyarrow is installed) is the
table of the sweep as asked, in point order: the swept values, the status
(``ok``, ``failed``: the run stopped early, ``error``: it could not run, or
had no state of rest), the reason, every metric, the run's wall time and
macro steps, the worker.  ``metrics.png`` plots every metric against every
swept parameter.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Sequence

FIXED_BEFORE = ("index", "key")
FIXED_AFTER = ("status", "failure")
WORK = ("wall_time", "macro_steps", "worker")


def header(names: Sequence[str], metric_names: Sequence[str]) -> list:
    return [*FIXED_BEFORE, *names, *FIXED_AFTER, *metric_names, *WORK]


def _text(v) -> str:
    if isinstance(v, float):
        return repr(v)
    return str(v)


def _value(col: str, text: str, names) -> object:
    if col in ("key", "status", "failure", "worker"):
        return text
    if col in ("index", "macro_steps"):
        return int(text) if text else 0
    return float(text) if text else math.nan


class Journal:
    """``points.csv``: rows of finished points, keyed by point key."""

    def __init__(self, path, columns: Sequence[str]):
        self.path = Path(path)
        self.columns = list(columns)
        self.rows = {}
        if self.path.is_file():
            with open(self.path, newline="") as fh:
                reader = csv.reader(fh)
                head = next(reader, None)
                if head is not None and head != self.columns:
                    from .errors import SweepError

                    raise SweepError(f"{self.path}: the journal's columns differ from this sweep's "
                                     f"({', '.join(head)}); use another --out folder")
                for rec in reader:
                    if len(rec) != len(self.columns):
                        continue  # a line cut short by an interruption: that point runs again
                    try:
                        row = {c: _value(c, t, ()) for c, t in zip(self.columns, rec)}
                    except ValueError:
                        continue
                    self.rows[row["key"]] = row
        fresh = not self.path.is_file() or self.path.stat().st_size == 0
        self._fh = open(self.path, "a", newline="")
        if not fresh:
            # a line cut short by an interruption: start the next row on a line of its own
            with open(self.path, "rb") as rb:
                rb.seek(-1, 2)
                if rb.read(1) != b"\n":
                    self._fh.write("\n")
        self._w = csv.writer(self._fh)
        if fresh:
            self._w.writerow(self.columns)
            self._fh.flush()

    def __contains__(self, key) -> bool:
        return key in self.rows

    def append(self, row: dict) -> None:
        self._w.writerow([_text(row.get(c, "")) for c in self.columns])
        self._fh.flush()
        self.rows[row["key"]] = {c: row.get(c) for c in self.columns}

    def close(self) -> None:
        self._fh.close()


def write_table(rows: Sequence[dict], columns: Sequence[str], out_dir) -> list:
    """``results.csv`` (and ``results.parquet`` with pyarrow) in ``out_dir``; returns the paths."""
    out = Path(out_dir)
    paths = [out / "results.csv"]
    tmp = out / "results.csv.part"
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow([_text(r.get(c, "")) for c in columns])
    tmp.replace(paths[0])
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return paths
    data = {c: [r.get(c) for r in rows] for c in columns}
    pq.write_table(pa.table(data), out / "results.parquet")
    paths.append(out / "results.parquet")
    return paths


def plot(rows: Sequence[dict], names: Sequence[str], metric_names: Sequence[str], path, title: str = "") -> Path:
    """Every metric (rows of panels) against every swept parameter (columns); failed points as red marks."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metric_names = list(metric_names)[:16]
    nr, nc = max(1, len(metric_names)), max(1, len(names))
    fig, axes = plt.subplots(nr, nc, figsize=(3.2 * nc + 1, 2.2 * nr + 0.8), squeeze=False)
    ok = [r for r in rows if r.get("status") == "ok"]
    bad = [r for r in rows if r.get("status") != "ok"]
    for i, m in enumerate(metric_names):
        for j, p in enumerate(names):
            ax = axes[i][j]
            ax.plot([r[p] for r in ok], [r[m] for r in ok], ".", ms=4)
            if bad:  # where the failures are, along the parameter axis
                ax.plot([r[p] for r in bad], [0.02] * len(bad), "x", color="red", ms=5,
                        transform=ax.get_xaxis_transform())
            if i == nr - 1:
                ax.set_xlabel(p)
            if j == 0:
                ax.set_ylabel(m, fontsize=8)
            ax.tick_params(labelsize=7)
    fig.suptitle(f"{title}: {len(ok)} ok, {len(bad)} failed (red x)" if title else
                 f"{len(ok)} ok, {len(bad)} failed (red x)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.35 / fig.get_figheight()))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
