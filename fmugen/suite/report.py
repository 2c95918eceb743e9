"""The suite's outputs: the printed table, ``suite.csv``, a plot per case, and
the summary a user needs to choose a solver (the cheapest method meeting the
accuracy goal per case, and its cost against the others)."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

FIELDS = ("case", "method", "outcome", "error", "allowed", "steps", "rejected", "f_evals", "jac_evals",
          "stiffness_detected", "wall_ms", "message")


def write_csv(path: Path, rows) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(FIELDS)
        for r in rows:
            w.writerow([r.case, r.method, r.outcome, f"{r.error:.3e}", f"{r.allowed:.3e}", r.steps, r.rejected,
                        r.f_evals, r.jac_evals, r.stiffness_detected, f"{r.wall * 1e3:.3f}", r.message])


def print_table(rows, log=print) -> None:
    log(f"\n{'case':24} {'method':36} {'outcome':10} {'error':>9} {'allowed':>8} {'steps':>7} {'rej':>5} "
        f"{'f evals':>8} {'jac':>6} {'stiff':>5} {'ms':>8}  message")
    for r in rows:
        msg = r.message if len(r.message) <= 110 else r.message[:107] + "..."
        log(f"{r.case:24} {r.method[:36]:36} {r.outcome:10} {r.error:9.2e} {r.allowed:8.1e} {r.steps:7d} "
            f"{r.rejected:5d} {r.f_evals:8d} {r.jac_evals:6d} {r.stiffness_detected:5d} {r.wall * 1e3:8.2f}  {msg}")
    n_silent = sum(r.outcome == "SILENT" for r in rows)
    log(f"\n{len(rows)} runs: {sum(r.outcome == 'accurate' for r in rows)} accurate, "
        f"{sum(r.outcome == 'detected' for r in rows)} detected, {n_silent} SILENT")


def cheapest(rows, goal: float) -> dict:
    """Per trajectory case: (cheapest accurate run meeting ``goal``, [(other run meeting it, time ratio)])."""
    out = {}
    for case in dict.fromkeys(r.case for r in rows):
        ok = [r for r in rows if r.case == case and r.outcome == "accurate" and r.error <= goal
              and "rk4_limit" in r.extra and r.wall > 0]
        if not ok:
            continue
        best = min(ok, key=lambda r: r.wall)
        others = [(r.method, r.wall / best.wall) for r in ok if r is not best]
        out[case] = (best, others)
    return out


def summary(rows, log=print, goal: float = 1e-6) -> None:
    log(f"\nCheapest method meeting {goal:g} (rad or m) per case, wall time inside fmi2DoStep:")
    for case, (best, others) in cheapest(rows, goal).items():
        rel = ", ".join(f"{m} {x:.1f}x" for m, x in others) or "no other setting meets it"
        log(f"  {case:24} {best.method:30} {best.wall * 1e3:8.2f} ms  (others meeting it: {rel})")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_trajectories(path: Path, case, t, y_ref, runs) -> None:
    plt = _plt()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    a1.plot(t, y_ref[:, 0], "k-", lw=2.5, label="reference (Radau 1e-12)")
    for label, r in runs:
        a1.plot(r.t, r.values[:, 0], lw=1, label=label)
        err = np.max(np.abs(r.values[:, :y_ref.shape[1]] - y_ref[:len(r.t)]), axis=1)
        a2.semilogy(r.t, np.maximum(err, 1e-17), lw=1, label=label)
    a1.set_ylabel(case.compare[0])
    lo, hi = np.min(y_ref[:, 0]), np.max(y_ref[:, 0])
    pad = 0.5 * (hi - lo) + 1e-3
    a1.set_ylim(lo - pad, hi + pad)
    a1.legend(fontsize=7)
    a1.set_title(f"{case.name}: {case.title}"[:110], fontsize=8)
    a2.set_ylabel("max error over compared variables")
    a2.set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_energy(path: Path, case, curves) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for label, t, dE in curves:
        ax.semilogy(t, np.maximum(np.abs(dE), 1e-17), lw=1, label=label)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("|E(t) - E(0)| / (|KE0| + |PE0|)")
    ax.set_title(f"{case.name}: {case.title}"[:110], fontsize=8)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
