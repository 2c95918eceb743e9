"""Every shipped scene exported as an SSP archive and run unchanged by other tools.

    python examples/ssp_other_tools.py [--scenes single_joint_split,puma_hydraulic] [--stop T] [--out out/ssp]

For each scene: ``fmugen ssp`` writes ``out/ssp/<scene>.ssp``; libcosim
(``CosimExecution.from_ssp_file``, its fixed step from the archive) and FMPy's
``simulate_ssp`` (at the archive's step) run it; fmugen's master runs the same
archive with held-input Jacobi at that step (what both tools do) and with the
scene's own scheme.  Printed per scene and recorded column: the largest
difference of libcosim and of FMPy to fmugen's Jacobi/held (relative to the
column's magnitude), and of fmugen's Jacobi/held to fmugen's scene scheme
(how far the importers' loop is from fmugen's run).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import fmugen
from fmugen.cosim import run
from fmugen.ssp import export_ssp

ROOT = Path(__file__).resolve().parents[1]


def libcosim(path, system, n):
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_ssp_file(str(path))
    idx = {s.name.decode(): s.index for s in ex.slave_infos()}
    vr = {k: {v.name.decode(): v.reference for v in ex.slave_variables(i) if v.type == CosimVariableType.REAL.value}
          for k, i in idx.items()}
    obs = CosimObserver.create_time_series(buffer_size=n + 10)
    ex.add_observer(obs)
    for c in system.recorded:
        obs.start_time_series(idx[c.unit], vr[c.unit][c.variable], CosimVariableType.REAL)
    t0 = time.perf_counter()
    ok = ex.step(n)
    wall = time.perf_counter() - t0
    out = {}
    for c in system.recorded:
        t, _, v = obs.time_series_real_samples(idx[c.unit], vr[c.unit][c.variable], 0, n + 1)
        out[c.column] = np.asarray(v)
    return ok, wall, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="single_joint_split,single_joint_split_stiff,puma_hydraulic,puma_electric")
    ap.add_argument("--stop", type=float, default=None, help="stop time [s] (default: each scene's)")
    ap.add_argument("--out", default="out/ssp")
    ap.add_argument("--no-fmpy", action="store_true", help="skip FMPy's simulate_ssp (slow: Python per call)")
    ap.add_argument("--reference", action="store_true",
                    help="also the largest error of Jacobi/held at the archive's step (what libcosim computes) "
                         "against the scene's reference solution (Radau at 1e-12), in the columns' units")
    args = ap.parse_args(argv)
    out = Path(args.out)
    for name in args.scenes.split(","):
        scene = fmugen.load_scene(ROOT / "examples" / "scenes" / f"{name}.toml")
        r = export_ssp(scene, out / f"{name}.ssp", fmus_dir=out / name)
        system = fmugen.load_system(r["path"])
        H = r["libcosim_step"]
        stop = args.stop or system.stop_time
        n = int(round((stop - system.start_time) / H))
        lim = r["jacobi_limit"]
        print(f"\n{name}: {len(system.units)} FMUs; held-input Jacobi limit "
              f"{'none found' if lim == float('inf') else f'{lim:.3g} s'} (linearised at rest); archive step "
              f"{H:g} s; {n} steps to t = {stop:g} s")
        t0 = time.perf_counter()
        jh = run(system, "jacobi", "hold", step=H, stop=system.start_time + n * H, detect_divergence=False)
        t_jh = time.perf_counter() - t0
        own = run(system, step=None, stop=system.start_time + n * H, scheme=r["scheme"],
                  extrapolation=r["extrapolation"])
        print(f"  fmugen jacobi/hold {t_jh:.1f} s ({jh.summary.status}); fmugen {r['scheme']}/{r['extrapolation']} "
              f"at {system.step:g} s ({own.summary.status})")
        ok, wall, lc = libcosim(r["path"], system, n)
        print(f"  libcosim: {'ok' if ok else 'FAILED'} in {wall:.1f} s")
        fm = None
        if not args.no_fmpy:
            from fmpy.ssp.simulation import simulate_ssp

            t0 = time.perf_counter()
            res = simulate_ssp(str(r["path"]), start_time=system.start_time, stop_time=system.start_time + n * H,
                               step_size=H)
            print(f"  fmpy simulate_ssp: {time.perf_counter() - t0:.1f} s")
            fm = res
        print(f"  {'column':<18} {'max |fmugenJH|':>14} {'libcosim-fmugenJH':>18} {'fmpy-fmugenJH':>14} "
              f"{'fmugenJH-own':>13}   (differences relative to max |fmugenJH|)")
        for c in system.recorded:
            ref = jh[c.column]
            scale = max(np.max(np.abs(ref)), 1e-300)
            m = min(len(lc[c.column]), len(ref))
            d_lc = np.max(np.abs(lc[c.column][:m] - ref[:m])) / scale
            d_fm = float("nan")
            if fm is not None:
                col = f"{c.unit}.{c.variable}"
                if col in fm.dtype.names:
                    v = fm[col]  # FMPy's row k holds the values after the step from t_k
                    k = min(len(v), len(ref) - 1)
                    d_fm = np.max(np.abs(v[:k] - ref[1:k + 1])) / scale
            ot = np.interp(jh.time, own.time, own[c.column])
            d_own = np.max(np.abs(ref - ot)) / scale
            print(f"  {c.column:<18} {scale:14.3g} {d_lc:18.2e} {d_fm:14.2e} {d_own:13.2e}")
        if args.reference:
            from fmugen.cosim.reference import solve_reference
            from fmugen.cosim.system import ReferenceProblem

            p = scene.reference_problem()
            p = ReferenceProblem(p.model, p.x0, p.u, p.columns, p.start_time, float(jh.time[-1]), p.nominals)
            ref = solve_reference(p, times=jh.time)
            print(f"  Jacobi/held at {H:g} s (libcosim's result, to the figures above) against the reference "
                  f"(its own error estimate in brackets):")
            for c in system.recorded:
                if c.column in ref.columns:
                    k = list(ref.columns).index(c.column)
                    print(f"    {c.column:<18} {np.max(np.abs(jh[c.column] - ref[c.column])):10.3g} "
                          f"{c.physical_unit}  [{ref.error[k]:.1e}]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
