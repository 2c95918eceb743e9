"""Main job: the thesis PUMA as FMUs, simulated against a high-accuracy reference.

1. Reads ``robots/puma_thesis.toml`` (the McGalliard thesis's PUMA, read
   literally) and builds a Model-Exchange and a Co-Simulation FMU.
2. Drives the arm with stepped joint torques, as the thesis did (torques held
   between trajectory knots): the inverse dynamics of a smooth move, sampled
   at the middle of each 50 ms knot, applied open loop.
3. Reference: the same equations as one ODE solved knot by knot with scipy's
   Radau at rtol = atol = 1e-12, confirmed by DOP853 at 1e-12.
4. Error against run time: the CS FMU with each internal solver over a
   tolerance sweep, the ME FMU under fmpy's CVode and under scipy's Radau
   (calling the FMU's fmi2GetDerivatives), and the thesis's own
   constant-acceleration scheme (which diverged in 1984).  Errors are on the
   joint angles at every output point (CS: one per 50 ms knot; ME: 2 ms); run time is the median of 5 runs after a
   warm-up.  Writes ``OUT/puma_error_vs_time.csv`` and ``.png``.

    python examples/puma_fmu_vs_reference.py --out out
"""
from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import fmugen  # noqa: E402
from fmugen.fmi.build import build_fmu  # noqa: E402

KNOT = 0.05  # s between torque knots
STOP = 2.0  # s
STEP = 0.002  # s, ME output interval (1000 points)
CS_STEP = KNOT  # s, CS communication step: one per torque knot, so the tolerance sets the error


def desired_path(q0, t):
    """A smooth point-to-point move (cosine blend) of every joint over STOP seconds."""
    move = np.array([0.8, 0.5, -0.6, 1.0, -0.4, 1.2])[: len(q0)]
    s = (1 - np.cos(np.pi * t / STOP)) / 2
    ds = np.pi / (2 * STOP) * np.sin(np.pi * t / STOP)
    dds = (np.pi / STOP) ** 2 / 2 * np.cos(np.pi * t / STOP)
    return q0 + move * s, move * ds, move * dds


def torque_knots(arm, q0):
    """Stepped torques, as the thesis fed them: the inverse dynamics of a smooth
    move evaluated at each knot's midpoint and held over the knot (open loop)."""
    taus = []
    for k in range(int(round(STOP / KNOT))):
        q, qd, qdd = desired_path(q0, (k + 0.5) * KNOT)
        taus.append(arm.inverse_dynamics(q, qd, qdd))
    return np.array(taus)  # row k acts on [k KNOT, (k+1) KNOT)


def reference(arm, q0, taus, method="Radau", rtol=1e-12):
    """Dense reference q(t), solving knot by knot (the torque is discontinuous at knots)."""
    n = arm.n
    x = np.r_[q0, np.zeros(n)]
    pieces = []
    for k, tau in enumerate(taus):
        t0, t1 = k * KNOT, (k + 1) * KNOT

        def rhs(t, y):
            return np.r_[y[n:], arm.forward_dynamics(y[:n], y[n:], tau)]

        sol = solve_ivp(rhs, (t0, t1), x, method=method, rtol=rtol, atol=rtol, dense_output=True)
        if not sol.success:
            raise RuntimeError(f"reference solve failed on knot {k}: {sol.message}")
        pieces.append(sol.sol)
        x = sol.y[:, -1]

    def q_at(t):
        t = np.atleast_1d(t)
        k = np.clip((t / KNOT).astype(int), 0, len(pieces) - 1)
        return np.array([pieces[kk](tt)[:n] for kk, tt in zip(k, t)])

    return q_at


def thesis_scheme(arm, q0, taus, steps_per_knot):
    """McGalliard's simulator: acceleration held over a step, no iteration (section III.C)."""
    n = arm.n
    h = KNOT / steps_per_knot
    q, v = q0.copy(), np.zeros(n)
    times, qs = [0.0], [q.copy()]
    for k, tau in enumerate(taus):
        for s in range(steps_per_knot):
            a = arm.forward_dynamics(q, v, tau)
            q = q + h * v + 0.5 * h * h * a
            v = v + h * a
            times.append(k * KNOT + (s + 1) * h)
            qs.append(q.copy())
            if not np.all(np.isfinite(q)) or np.abs(q).max() > 1e3:
                return np.array(times), np.array(qs), False
    return np.array(times), np.array(qs), True


def input_table(names, taus):
    """fmpy input signal with exact steps at the knots (repeated time points)."""
    dtype = [("time", np.float64)] + [(nm, np.float64) for nm in names]
    rows = []
    for k, tau in enumerate(taus):
        rows.append((k * KNOT, *tau))
        rows.append(((k + 1) * KNOT, *tau))
    return np.array(rows, dtype=dtype)


def me_with_scipy(unzip, md, q0, taus, method="Radau", rtol=1e-10):
    """The ME FMU's own derivatives (fmi2GetDerivatives) integrated by scipy, knot by knot."""
    from fmpy.fmi2 import FMU2Model

    vr = {v.name: v.valueReference for v in md.modelVariables}
    n = len(q0)
    fmu = FMU2Model(guid=md.guid, unzipDirectory=str(unzip), modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="puma")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.setReal([vr[f"q[{i + 1}]"] for i in range(n)], list(q0))
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.enterContinuousTimeMode()
    from ctypes import POINTER, c_double

    buf, der = np.zeros(2 * n), np.zeros(2 * n)
    pbuf, pder = buf.ctypes.data_as(POINTER(c_double)), der.ctypes.data_as(POINTER(c_double))
    fmu.getContinuousStates(pbuf, 2 * n)
    x = buf.copy()
    tau_vrs = [vr[f"tau[{i + 1}]"] for i in range(n)]
    ts, qs = [0.0], [x[:n].copy()]

    def rhs(t, y):
        fmu.setTime(t)
        buf[:] = y
        fmu.setContinuousStates(pbuf, 2 * n)
        fmu.getDerivatives(pder, 2 * n)
        return der.copy()

    for k, tau in enumerate(taus):
        fmu.setReal(tau_vrs, list(tau))
        n_out = int(round(KNOT / STEP))
        grid = k * KNOT + STEP * np.arange(1, n_out + 1)
        grid[-1] = (k + 1) * KNOT  # exactly the span's end
        sol = solve_ivp(rhs, (k * KNOT, (k + 1) * KNOT), x, method=method, rtol=rtol, atol=rtol, t_eval=grid)
        x = sol.y[:, -1]
        ts.extend(sol.t)
        qs.extend(sol.y[:n].T)
    fmu.terminate()
    fmu.freeInstance()
    return np.array(ts), np.array(qs)


def errors(t, q, q_ref):
    """max, final-time and RMS angle error [rad] at the simulator's own output times,
    and correct digits -log10 max |err| / (atol + |q_ref|) with atol = 1e-6 rad."""
    ref = q_ref(t)
    e = np.abs(q - ref)
    digits = -np.log10(np.max(e / (1e-6 + np.abs(ref))) + 1e-300)
    return e.max(), e[-1].max(), float(np.sqrt(np.mean(e**2))), digits


def timed(fn, repeat):
    fn()  # warm-up
    times = []
    result = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="out")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--robot", default=str(ROOT / "robots" / "puma_thesis.toml"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    import fmpy
    from fmpy.validation import validate_fmu

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        arm = fmugen.load_robot(args.robot)
    for w in caught:
        print(f"note: {w.message}")
    n = arm.n
    q0 = np.array([0.0, -0.6, 0.3, 0.0, 0.5, 0.0])[:n]
    taus = torque_knots(arm, q0)

    t0 = time.perf_counter()
    model = arm.state_space_model(outputs=("p_ee",))
    fmu_path = out / f"{model.name}.fmu"
    result = build_fmu(model, fmu_path, fmi_type="both")
    print(f"built {fmu_path} (ME + CS) in {time.perf_counter() - t0:.1f} s")
    for name, ops in result.op_counts.items():
        print(f"  {name}: {ops}")
    problems = validate_fmu(str(fmu_path))
    if problems:
        raise SystemExit(f"FMU does not validate: {problems}")
    unzip = Path(tempfile.mkdtemp(prefix="fmugen_puma_"))
    fmpy.extract(str(fmu_path), str(unzip))

    print("reference: Radau rtol=atol=1e-12, knot by knot ...")
    q_ref = reference(arm, q0, taus, "Radau")
    q_chk = reference(arm, q0, taus, "DOP853")
    grid = np.arange(0.0, STOP + STEP / 2, STEP)
    confirm = np.abs(q_chk(grid) - q_ref(grid)).max()
    print(f"  Radau vs DOP853 (both 1e-12): max |dq| = {confirm:.2e} rad")

    start = {f"q[{i + 1}]": float(q0[i]) for i in range(n)}
    inputs = input_table([f"tau[{i + 1}]" for i in range(n)], taus)
    outputs = [f"q[{i + 1}]" for i in range(n)]

    rows = []

    def record(label, tol, seconds, t, q, extra=""):
        emax, efin, erms, digits = errors(t, q, q_ref)
        rows.append((label, tol, seconds, emax, efin, erms, digits, extra))
        print(f"  {label:<22} tol={tol:<8.0e} time={seconds * 1e3:9.2f} ms  max|err|={emax:9.2e} rad  "
              f"final={efin:9.2e}  rms={erms:9.2e}  digits={digits:5.1f} {extra}")

    print(f"Co-Simulation FMU (communication step {CS_STEP * 1e3:g} ms = one torque knot):")
    for solver, label in ((1, "CS dopri5"), (2, "CS rodas3 (implicit)")):
        for tol in (1e-4, 1e-6, 1e-8, 1e-10):
            params = {"solver.method": solver, "solver.rtol": tol, "solver.atol": tol}

            def run():
                return fmpy.simulate_fmu(str(unzip), fmi_type="CoSimulation", stop_time=STOP, output_interval=CS_STEP,
                                         start_values={**start, **params}, input=inputs, output=outputs)

            seconds, res = timed(run, args.repeat)
            q = np.column_stack([res[o] for o in outputs])
            record(label, tol, seconds, res["time"], q)

    print("Model-Exchange FMU under fmpy's CVode (2 ms output):")
    for tol in (1e-4, 1e-6, 1e-8):

        def run_me():
            return fmpy.simulate_fmu(str(unzip), fmi_type="ModelExchange", stop_time=STOP, output_interval=STEP,
                                     relative_tolerance=tol, start_values=start, input=inputs, output=outputs)

        seconds, res = timed(run_me, args.repeat)
        q = np.column_stack([res[o] for o in outputs])
        record("ME + CVode", tol, seconds, res["time"], q)

    print("Model-Exchange FMU, its fmi2GetDerivatives integrated by scipy (knot by knot):")
    md = fmpy.read_model_description(str(unzip))
    for tol in (1e-6, 1e-8, 1e-9):
        seconds, (t, q) = timed(lambda: me_with_scipy(unzip, md, q0, taus, "Radau", tol), max(1, args.repeat // 2))
        record("ME + scipy Radau", tol, seconds, t, q)

    print("The thesis's constant-acceleration scheme (no iteration), for comparison:")
    for spk in (5, 25, 125):
        seconds, (t, q, ok) = timed(lambda: thesis_scheme(arm, q0, taus, spk), 1)
        if ok:
            record("thesis scheme", KNOT / spk, seconds, t, q, "(tol = its step h)")
        else:
            print(f"  thesis scheme          h={KNOT / spk:.0e}: diverged before t = {t[-1]:.2f} s")
            rows.append(("thesis scheme", KNOT / spk, seconds, np.inf, np.inf, np.inf, 0.0, "diverged"))

    csv = out / "puma_error_vs_time.csv"
    with open(csv, "w") as fh:
        fh.write("method,tolerance,median_seconds,max_err_rad,final_err_rad,rms_err_rad,correct_digits,note\n")
        for r in rows:
            fh.write(",".join(str(x) for x in r) + "\n")
    print(f"wrote {csv}")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 5))
        for label in dict.fromkeys(r[0] for r in rows):
            pts = [(r[2], r[3]) for r in rows if r[0] == label and np.isfinite(r[3])]
            if pts:
                ax.loglog(*zip(*pts), "o-", label=label)
        ax.axhline(confirm, color="grey", ls=":", label="reference check (Radau vs DOP853)")
        ax.set_xlabel("median wall time per 2 s simulation [s]")
        ax.set_ylabel("max joint-angle error [rad]")
        ax.set_title(f"{model.name}: error against run time")
        ax.legend(fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / "puma_error_vs_time.png", dpi=110)
        print(f"wrote {out / 'puma_error_vs_time.png'}")
    except ImportError:
        pass
    shutil.rmtree(unzip, ignore_errors=True)
    # the reference must be far below the errors we report
    smallest = min(r[3] for r in rows if np.isfinite(r[3]) and r[3] > 0)
    if confirm * 100 > smallest:
        print(f"warning: reference check {confirm:.1e} is not 100x below the smallest error {smallest:.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
