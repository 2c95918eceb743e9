"""Benchmark: the CS solvers on the stiff one-joint chain, and the fidelity table.

Part 1 -- examples/single_joint_stiff.toml built as a Co-Simulation FMU, a
0.1 rad theta_ref step simulated for 0.5 s with communication step 10 ms by
each internal solver (solver.method 1 Dormand-Prince 5(4), 2 implicit stiff,
3 RK4 at fixed steps just inside and 2x inside the eigenvalue-predicted
limit) over a tolerance sweep.  Reported: accepted steps, derivative and
Jacobian evaluations, wall time (median of 5 after a warm-up), and the
final/max error of joint.theta against scipy Radau at rtol 1e-12.

Part 2 -- the fidelity table of the default chain: states, operations in the
generated evaluate(), stable explicit (RK4) step from the eigenvalues, and
the change of the theta step response against the full chain.

Part 3 -- the FMU's implicit solver (RODAS3, C) against scipy's Radau
(Python, same model, exact Jacobian) at equal error on the stiff sets: error
of joint.theta on the 10 ms grid against Radau at rtol 1e-12, f and Jacobian
evaluations, wall time (FMU: inside fmi2DoStep, median of the repeats).
Radau's counts are interpolated (log-log) at RODAS3's errors.

Run:  python examples/bench_stiff_solvers.py [--quick] [--repeat N] [--parts 1 2 3]
"""
import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from fmpy import extract, simulate_fmu
from scipy.integrate import solve_ivp

from fmugen.codegen.c_code import generate_c
from fmugen.components import NumericModel, linearise, load_assembly, single_joint, stable_step
from fmugen.fmi.build import build_fmu

HERE = Path(__file__).resolve().parent
T_END, H_COMM = 0.5, 0.01


def reference(model, ts, T=T_END):
    ev = NumericModel(model)
    u = np.array([0.1, 0.0])
    scale = np.array([v.nominal or 1.0 for v in model.states])
    sol = solve_ivp(lambda t, x: ev.f(t, x, u), (0, T), ev.x0, method="Radau", rtol=1e-12, atol=1e-14 * scale,
                    t_eval=ts, jac=lambda t, x: ev.dfdx(t, x, u))
    return sol.y[[v.name for v in model.states].index("joint.theta")]


def run(unzipdir, start, repeats):
    common = dict(fmi_type="CoSimulation", stop_time=T_END, output_interval=H_COMM,
                  start_values=dict(start, **{"amp.theta_ref": 0.1}),
                  output=["joint.theta", "solver.n_steps", "solver.n_rhs", "solver.n_jac"])
    r = simulate_fmu(unzipdir, **common)  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        simulate_fmu(unzipdir, **common)
        times.append(time.perf_counter() - t0)
    return r, statistics.median(times)


def solver_table(repeats=5, tolerances=(1e-4, 1e-6, 1e-8, 1e-10)):
    model = load_assembly(HERE / "single_joint_stiff.toml")
    h_rk4 = stable_step(np.linalg.eigvals(linearise(model).A), "rk4")
    with tempfile.TemporaryDirectory() as tmp:
        fmu = build_fmu(model, Path(tmp) / "single_joint_stiff.fmu", fmi_type="cs").path
        unz = extract(str(fmu), str(Path(tmp) / "unz"))
        rows = []
        cases = [("DOPRI5", {"solver.method": 1, "solver.rtol": tol, "solver.atol": tol}, tol) for tol in tolerances]
        cases += [("implicit", {"solver.method": 2, "solver.rtol": tol, "solver.atol": tol}, tol) for tol in tolerances]
        cases += [("RK4", {"solver.method": 3, "solver.fixed_step": f * h_rk4}, f) for f in (0.95, 0.5)]
        ref = None
        for name, start, knob in cases:
            r, wall = run(unz, start, repeats)
            if ref is None:
                ref = reference(model, r["time"])
            err = np.abs(r["joint.theta"] - ref)
            rows.append((name, knob, int(r["solver.n_steps"][-1]), int(r["solver.n_rhs"][-1]),
                         int(r["solver.n_jac"][-1]), wall * 1e3, err[-1], err.max()))
    print(f"\nStiff one-joint chain (CS FMU), theta_ref step 0.1 rad, {T_END} s, H = {H_COMM * 1e3:.0f} ms; "
          f"RK4 stability limit from the eigenvalues: {h_rk4 * 1e6:.1f} us")
    print(f"{'solver':9} {'tol / h/h_max':>13} {'steps':>7} {'f evals':>8} {'jac':>5} {'wall ms':>8} "
          f"{'err(T)':>9} {'max err':>9}")
    for name, knob, st, nf, nj, wall, e1, e2 in rows:
        print(f"{name:9} {knob:13.3g} {st:7d} {nf:8d} {nj:5d} {wall:8.2f} {e1:9.1e} {e2:9.1e}")
    return rows


def fidelity_table():
    ladder = [("full: PI, real op-amp, lag, valve 2", dict(control="PI", opamp="real")),
              ("ideal op-amp", dict(control="PI")),
              ("+ static driver", dict(control="PI", driver="static")),
              ("+ static valve", dict(control="PI", driver="static", valve_order=0))]
    ts = np.linspace(0, 0.6, 601)
    full = None
    print("\nFidelity of the default chain (theta_ref step 0.1 rad, 0.6 s)")
    print(f"{'model':38} {'states':>6} {'ops eval':>9} {'ops jac':>8} {'RK4 h_max':>10} {'max|dtheta|':>12}")
    rows = []
    for name, opts in ladder:
        m = single_joint("default", **opts)
        gen = generate_c(m).op_counts
        ops = {k: v.total.mul + v.total.add + v.total.div + v.total.n_calls for k, v in gen.items()}
        h = stable_step(np.linalg.eigvals(linearise(m).A), "rk4")
        th = reference(m, ts, T=0.6)
        full = th if full is None else full
        d = np.max(np.abs(th - full))
        rows.append((name, m.nx, ops["evaluate"], ops.get("jacobian", 0), h, d))
        print(f"{name:38} {m.nx:6d} {ops['evaluate']:9d} {ops.get('jacobian', 0):8d} {h * 1e3:8.3f} ms {d:12.2e}")
    return rows


def radau_comparison(repeats=5, tolerances=(1e-4, 1e-5, 1e-6, 1e-7, 1e-8), cases=("stiff_P", "stiff_PI_opamp")):
    """RODAS3 in the FMU against scipy Radau at equal error (Part 3)."""
    from fmugen.suite.cases import Method, get_case
    from fmugen.suite.fmu_run import Unpacked, run as run_fmu
    from fmugen.suite.reference import reference, setup, work_precision_radau

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in cases:
            case = get_case(name)
            model = case.make_model()
            s = setup(model, case.start)
            t = np.arange(int(round(case.stop / case.H)) + 1) * case.H
            ref = reference(s, t, stiff=True)
            col = s.column("joint.theta")
            fmu = Unpacked(build_fmu(model, Path(tmp) / f"{name}.fmu", fmi_type="cs").path, Path(tmp) / name)
            radau = work_precision_radau(s, t, col, ref, rtols=tolerances)
            ours = []
            for tol in tolerances:
                runs = [run_fmu(fmu, Method(2, tol), case.start, case.stop, case.H, ["joint.theta"])
                        for _ in range(repeats + 1)]
                r = runs[-1]
                err = float(np.max(np.abs(r.values[:, 0] - ref.values[:, col])))
                ours.append((tol, err, r.f_evals, r.jac_evals, statistics.median(x.wall for x in runs[1:])))
            print(f"\n{name}: {case.title}, {case.stop} s, H = {case.H * 1e3:g} ms; error of joint.theta [rad]")
            print(f"{'solver':22} {'tol':>7} {'error':>9} {'f evals':>8} {'jac':>6} {'wall ms':>9}")
            for label, data in (("RODAS3 (FMU, C)", ours), ("scipy Radau (Python)", radau)):
                for tol, err, nf, nj, wall in data:
                    print(f"{label:22} {tol:7.0e} {err:9.2e} {nf:8d} {nj:6d} {wall * 1e3:9.2f}")
            le = np.log([e for _, e, *_ in radau])
            order = np.argsort(le)
            print(f"{'at equal error':22} {'error':>9} {'f RODAS3/Radau':>15} {'f+jac ratio':>12} "
                  f"{'Radau/RODAS3 time':>18}")
            for tol, err, nf, nj, wall in ours:
                if not (min(le) <= np.log(err) <= max(le)):
                    continue
                at = lambda k: float(np.exp(np.interp(np.log(err), le[order], np.log([r[k] for r in radau])[order])))
                rf, rj, rw = at(2), at(3), at(4)
                print(f"{'':22} {err:9.2e} {nf / rf:15.2f} {(nf + nj) / (rf + rj):12.2f} {rw / wall:18.1f}")
                rows.append((name, tol, err, nf, nj, wall, rf, rj, rw))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one tolerance, one repeat (a smoke test)")
    ap.add_argument("--repeat", type=int, default=5, help="timed runs per setting after a warm-up (default 5)")
    ap.add_argument("--parts", type=int, nargs="+", default=[1, 2, 3], choices=[1, 2, 3],
                    help="1 solver table, 2 fidelity table, 3 RODAS3 against scipy Radau (default: all)")
    args = ap.parse_args(argv)
    repeats = 1 if args.quick else args.repeat
    if 1 in args.parts:
        solver_table(repeats=repeats, tolerances=(1e-6,) if args.quick else (1e-4, 1e-6, 1e-8, 1e-10))
    if 2 in args.parts:
        fidelity_table()
    if 3 in args.parts:
        radau_comparison(repeats=repeats, tolerances=(1e-4, 1e-6) if args.quick else (1e-4, 1e-5, 1e-6, 1e-7, 1e-8))


if __name__ == "__main__":
    main()
