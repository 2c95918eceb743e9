"""Is the stated held-input Jacobi stability limit right?  Every shipped split scene, run just below and above.

For every scene in ``examples/scenes/*.toml`` with two or more FMU groups (a monolithic one with
``--set scene.monolithic=false``), this computes the limit H* that the build writes into the FMUs, summaries
and SSP archives (``fmugen.scene.stability.jacobi_hold_limit``: the FMUs linearised separately at the
scene's initial state, one held-input Jacobi macro step as the master takes it), and co-simulates with
fmugen's master, scheme ``jacobi``, extrapolation ``hold``:

* at 0.9 H* over 10x the scene's horizon: must stay stable -- no failure, values finite, and the motion
  settled (its size in the last tenth of the run below half its size in the first half);
* at 1.1 H*: must diverge -- an FMU fails or values go non-finite, or the motion does not settle (it grows,
  or goes on as a limit cycle where a nonlinearity bounds it) -- over 10x the horizon or longer: as long as
  the linearisation says a disturbance takes to grow 1e8-fold at 1.1 H* (slowly growing modes).

When the master's divergence monitor stops a run, the same run is repeated without it and that run decides
(the table shows both): the monitor's alarm is what a user sees, but it can come early, or be false.

Two variants of each scene:

* ``near rest``: every point-to-point move scaled to 1 % of its length (q_end = q_begin + 0.01 (q_end -
  q_begin)): the run stays where the linearisation holds, and the move still excites every mode.  This is
  the check of the limit; a disagreement here makes the exit status 1.
* ``as shipped``: the scene's own move.  The pose changes the limit (the PUMA's inertia), so above H* a
  scene may settle where it is stable again: informational, except that 0.9 H* must stay stable too.

Also printed: the limit linearised along each variant's own run (the monolithic model by scipy's Radau,
21 points over the scene's horizon; the smallest, and at the end) -- where it differs from the limit at the
start, the runs follow it, not the stated limit.  A run longer than ``--max-steps`` macro steps is cut there
(puma_electric split: H* of a few microseconds); the horizon each run covered is printed.  The column ``old``
is the analysis before issue 29 (blocks of the monolithic model's Jacobian, feedthrough taken as exact).

    python examples/check_jacobi_limits.py [SCENE.toml ...] [--max-steps 1000000] [--variant near-rest|as-shipped|both]
        [--no-along] [--out out/check_jacobi_limits]

Exit status 1 on any disagreement: a stated limit other than the analysis', a run at 0.9 H* that does not
stay stable, a near-rest run at 1.1 H* that does not diverge.  Takes about 10 minutes on 2 cores.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "examples" / "scenes"


def old_limit(scene, rel=0.01):
    """The analysis before issue 29: held-input Jacobi on the blocks of the monolithic model's Jacobian."""
    import numpy as np
    import scipy.linalg as sl

    from fmugen.codegen.evaluate import ModelEvaluator

    model = scene.initial.model
    groups = {}
    for k, v in enumerate(model.states):
        groups.setdefault(scene.group_of(v.name.split(".", 1)[0]), []).append(k)
    blocks = [np.array(ix) for ix in groups.values()]
    if len(blocks) < 2:
        return math.inf
    x0 = np.array([scene.initial.values[v.name] for v in model.states])
    u = np.array([v.start if v.start is not None else 0.0 for v in model.inputs])
    A = np.asarray(ModelEvaluator(model).jacobians(scene.spec.start, x0, u)[0], dtype=float)

    def stable(H):
        Z = np.zeros_like(A)
        for ix in blocks:
            m = len(ix)
            M = np.zeros((2 * m, 2 * m))
            M[:m, :m], M[:m, m:] = A[np.ix_(ix, ix)] * H, np.eye(m) * H
            E = sl.expm(M)
            c = A[ix, :].copy()
            c[:, ix] = 0.0
            Z[ix, :] = E[:m, m:] @ c
            Z[np.ix_(ix, ix)] = E[:m, :m]
        rj = max(abs(np.linalg.eigvals(Z)))
        rx = max(abs(np.linalg.eigvals(sl.expm(A * H))))
        return rj <= max(1.0, rx) * (1 + 1e-7)

    h_max = scene.spec.stop - scene.spec.start
    lo, H = None, scene.spec.step
    if stable(H):
        lo = H
        while True:
            H *= 2
            if H > h_max:
                return math.inf
            if not stable(H):
                hi = H
                break
            lo = H
    else:
        hi = H
        while lo is None:
            H /= 2
            if H < 1e-9:
                return 0.0
            if stable(H):
                lo = H
            else:
                hi = H
    while hi - lo > rel * lo:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return hi


def split_scene(path):
    """(scene with >= 2 FMU groups, the --set it needed) or (None, None)."""
    import fmugen

    scene = fmugen.load_scene(path)
    sets = {}
    if len(scene.groups) < 2 and scene.spec.monolithic:
        sets = {"scene.monolithic": False}
        scene = fmugen.load_scene(path, set=sets)
    return (scene, sets) if len(scene.groups) >= 2 else (None, None)


def near_rest_sets(scene, fraction=0.01) -> dict:
    """--set values scaling every ptp_trajectory's move to ``fraction`` of its length."""
    out = {}
    for name, ins in scene.spec.instances.items():
        if ins.kind == "component" and ins.source == "ptp_trajectory":
            p = {v.name: v.start for v in scene.base_models[name].parameters}
            q0, q1 = float(p["q_begin"]), float(p["q_end"])
            out[f"{name}.q_end"] = q0 + fraction * (q1 - q0)
    return out


def limits_along(scene, points=21):
    """The limit linearised at ``points`` states of the scene's own run (the monolithic model by scipy's Radau
    at rtol 1e-6 over [start, stop]): (smallest, at the end).  The stated limit is the one at the start."""
    import numpy as np
    from scipy.integrate import solve_ivp

    from fmugen.codegen.evaluate import ModelEvaluator
    from fmugen.scene.stability import jacobi_hold_limit, linearise_split

    m = scene.initial.model
    ev = ModelEvaluator(m)
    x0 = np.array([scene.initial.values[v.name] for v in m.states])
    u = np.array([v.start if v.start is not None else 0.0 for v in m.inputs])
    ts = np.linspace(scene.spec.start, scene.spec.stop, points)
    sol = solve_ivp(lambda t, x: ev.f(t, x, u), (ts[0], ts[-1]), x0, method="Radau", t_eval=ts, rtol=1e-6,
                    atol=1e-9, jac=lambda t, x: ev.jacobians(t, x, u)[0])
    if sol.status != 0:
        return math.nan, math.nan
    out = []
    for k, tk in enumerate(sol.t):
        values = {v.name: float(sol.y[i, k]) for i, v in enumerate(m.states)}
        out.append(jacobi_hold_limit(scene, lin=linearise_split(scene, values, tk)))
    return min(out), out[-1]


def motion_ratio(r):
    """How much of the motion is left at the end: over the recorded columns, the largest ratio of the motion in
    the run's last tenth to that in its first half (motion: deviation from the last tenth's median; inf: values
    not finite).  A stable run settles (ratio << 1); an unstable one grows, or oscillates on at the size of the
    signals where a nonlinearity (a valve's flow, a rail) bounds it: a limit cycle (ratio ~ 1 or more)."""
    import numpy as np

    V = np.asarray(r.values, dtype=float)
    if V.ndim == 1:
        V = V[:, None]
    if len(V) < 20:
        return math.nan
    if not np.all(np.isfinite(V)):
        return math.inf
    last = V[-max(len(V) // 10, 2):]
    dev = np.abs(V - np.median(last, axis=0))
    first = dev[: len(V) // 2].max(axis=0)
    end = dev[-len(last):].max(axis=0)
    floor = 1e-9 * np.maximum(np.abs(V).max(axis=0), 1e-300)
    return float(np.max(end / np.maximum(first, floor)))


SETTLED = 0.5  # a run whose motion at the end is below this fraction of its motion in the first half settled


def one_run(system, H, T, t0, detect=True):
    """What Jacobi/held at H does up to t0 + T (a dict)."""
    from fmugen.cosim import run

    w0 = time.perf_counter()
    r = run(system, "jacobi", "hold", step=H, stop=t0 + T, estimate=False, detect_divergence=detect)
    s = r.summary
    failed = s.status == "failed"
    return {"failed": failed, "cause": s.failure.cause if failed else "", "at": s.failure.time if failed else None,
            "where": (s.failure.coupling or s.failure.unit or "") if failed else "", "ratio": motion_ratio(r),
            "reached": float(r.time[-1]) - t0, "T": T, "wall": time.perf_counter() - w0, "steps": s.macro_steps}


def judged(v) -> str:
    """"diverged" or "stable" from a run without the divergence monitor: an FMU failed or the values went
    non-finite, or the motion did not settle; else stable."""
    if v["failed"] or not v["ratio"] < SETTLED:
        return "diverged"
    return "stable"


def describe(v) -> str:
    if v["failed"]:
        return f"failed: {v['cause']} at t = {v['at']:.4g} s on {v['where']}"
    return f"ran to the end, motion left {v['ratio']:.2g}"


def probe(system, H, T, t0, log, label):
    """The run as a user gets it (divergence monitor on) and, when the monitor stopped it, the same run without
    the monitor, which decides: the monitor's alarm can be early or false.  Returns (verdict, monitored run,
    unmonitored run or None)."""
    v = one_run(system, H, T, t0)
    log(f"  {label}: {describe(v)}; {v['steps']} steps in {v['wall']:.1f} s")
    if v["failed"] and v["cause"] == "diverged":
        u = one_run(system, H, T, t0, detect=False)
        log(f"  {label}, without the divergence monitor: {describe(u)}; {u['steps']} steps in {u['wall']:.1f} s")
        return judged(u), v, u
    return judged(v), v, None


def check_scene(path, variants, max_steps, out, log, along=True):
    import fmugen
    from fmugen.scene.stability import jacobi_hold_limit, linearise_split

    scene, sets = split_scene(path)
    if scene is None:
        return []
    lin = linearise_split(scene)
    limit = jacobi_hold_limit(scene, lin=lin)
    old = old_limit(scene)
    rows = []
    horizon = scene.spec.stop - scene.spec.start
    t0 = scene.spec.start
    for variant in variants:
        vsets = dict(sets)
        if variant == "near rest":
            vsets.update(near_rest_sets(scene))
        vscene = fmugen.load_scene(path, set=vsets)
        w0 = time.perf_counter()
        built = vscene.build(Path(out) / f"{scene.name}_{variant.replace(' ', '_')}", progress=lambda *a: None)
        log(f"{scene.name} [{variant}]: built in {time.perf_counter() - w0:.1f} s; stated limit "
            f"{built.jacobi_limit:.4g} s (before issue 29: {old:.4g} s), DefaultExperiment step "
            f"{built.default_step:.3g} s")
        row = {"scene": scene.name, "split": f"{len(scene.groups)} FMUs" + (", monolithic=false" if sets else ""),
               "variant": variant, "limit": limit, "old": old, "stated": built.jacobi_limit,
               "along": limits_along(vscene) if along else (math.nan, math.nan)}
        if along:
            log(f"  the limit linearised along the scene's own run: smallest {row['along'][0]:.4g} s, at the end "
                f"{row['along'][1]:.4g} s")
        rows.append(row)
        if not math.isfinite(limit) or limit <= 0:
            continue
        rho, _ = lin.spectral_radii(1.1 * limit)
        rate = math.log(rho) / (1.1 * limit) if rho > 1 else 0.0  # predicted growth [1/s] at 1.1 H*
        for key, k, T in (("below", 0.9, 10 * horizon),
                          ("above", 1.1, max(10 * horizon, math.log(1e8) / rate if rate > 0 else 0.0))):
            H = k * limit
            T_run = min(T, max_steps * H)
            cut = f" (cut from {T:.4g} s by --max-steps)" if T_run < T else ""
            verdict, v, u = probe(built.system, H, T_run, t0, log, f"{k:.1f} H* = {H:.4g} s over {T_run:.4g} s{cut}")
            row[key] = {"verdict": verdict, "run": v, "unmonitored": u, "T": T_run, "cut": T_run < T}
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="*", help="scene files (default: examples/scenes/*.toml)")
    ap.add_argument("--max-steps", type=int, default=1_000_000, help="macro steps per run at most (default 1e6)")
    ap.add_argument("--variant", choices=("near-rest", "as-shipped", "both"), default="both")
    ap.add_argument("--no-along", action="store_true",
                    help="skip the limit linearised along each scene's own run (the columns 'min'/'end')")
    ap.add_argument("--out", default=str(ROOT / "out" / "check_jacobi_limits"), help="folder for the built FMUs")
    args = ap.parse_args(argv)
    variants = {"near-rest": ["near rest"], "as-shipped": ["as shipped"], "both": ["near rest", "as shipped"]}[
        args.variant]
    sys.path.insert(0, str(ROOT))
    paths = [Path(p) for p in args.scenes] or sorted(SCENES.glob("*.toml"))

    def log(msg):
        print(msg, flush=True)

    rows = []
    w0 = time.perf_counter()
    for p in paths:
        rows += check_scene(p, variants, args.max_steps, args.out, log, not args.no_along)
    bad = []
    print()
    head = (f"{'scene':<24} {'split':<24} {'variant':<10} {'limit [s]':>9} {'old [s]':>9} {'min [s]':>9} "
            f"{'end [s]':>9}  {'0.9x: stable?':<40} {'1.1x: diverged?':<40}")
    print(head)
    print("-" * len(head))

    def cell(c, want):
        if c is None:
            return "-"
        v, u = c["run"], c["unmonitored"]
        ok = c["verdict"] == want
        if u is None:
            how = f"{v['cause']} t={v['at']:.3g}" if v["failed"] else f"motion left {v['ratio']:.2g}"
        else:  # the monitor stopped it; the unmonitored run decided
            how = (f"monitor t={v['at']:.3g}; unmonitored: " +
                   (f"{u['cause']} t={u['at']:.3g}" if u["failed"] else f"motion left {u['ratio']:.2g}"))
        return f"{'yes' if ok else 'NO'} ({how}{', T=%.3g s' % c['T'] if c['cut'] else ''})"

    for r in rows:
        b, a = r.get("below"), r.get("above")
        if math.isfinite(r["limit"]) and abs(r["stated"] - r["limit"]) > 1e-9 * r["limit"]:
            bad.append(f"{r['scene']} [{r['variant']}]: the build states {r['stated']:.4g} s, the analysis "
                       f"{r['limit']:.4g} s")
        if b is not None and b["verdict"] != "stable":
            bad.append(f"{r['scene']} [{r['variant']}]: not stable at 0.9x the limit")
        if a is not None and a["verdict"] != "diverged" and r["variant"] == "near rest":
            bad.append(f"{r['scene']} [near rest]: no divergence at 1.1x the limit")
        print(f"{r['scene']:<24} {r['split']:<24} {r['variant']:<10} {r['limit']:>9.4g} {r['old']:>9.4g} "
              f"{r['along'][0]:>9.4g} {r['along'][1]:>9.4g}  {cell(b, 'stable'):<40} {cell(a, 'diverged'):<40}")
    print(f"\n{len(rows)} rows in {time.perf_counter() - w0:.0f} s.  limit: at the initial state (what the build "
          f"states); old: before issue 29; min, end: linearised along the variant's own run (the smallest, at its "
          f"end).  As shipped, 1.1x is informational: the move may end where the limit is larger.")
    for b in bad:
        print("DISAGREEMENT:", b)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
