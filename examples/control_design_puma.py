"""Control design on the PUMA hydraulic scene with python-control: trim, linearise, LQR, check nonlinear.

What a control engineer does with fmugen, end to end:

1. the plant: the scene ``examples/scenes/puma_hydraulic.toml`` without its
   path sources and P amplifiers (``fmugen.control.scene.scene_model``), so
   the six current drivers' voltages ``drv1.u`` ... ``drv6.u`` [V] are the
   inputs: arm (12 states) + six chains (driver current, spool stroke and
   speed, load pressure: 24 states);
2. the operating point: the arm held at the pose q0, at rest -- ``fmugen.trim``
   solves for the voltages (and every chain state) that hold it;
3. the linear model: ``fmugen.linearize`` -> ``control.StateSpace`` (A, B, C, D
   from the exact Jacobians), outputs ``arm.q``;
4. the gains: LQR (``control.lqr``) with Bryson's weights -- joint error
   0.01 rad, joint speed 0.2 rad/s, each chain state ten times its nominal
   value, voltage 10 V -- on the state scaled by its nominal values, and a
   static prefilter N = -(C (A - B K)^-1 B)^-1 for unit static gain:

       u = u0 - K (x - x0) + N (r - q0);

5. the linear closed loop: Bode plot of joint ``--joint`` and step responses
   of all joints (PNG, Agg backend);
6. the same gains on the **nonlinear** monolithic model (scipy's Radau with
   the exact Jacobian A(x, u) - B(x, u) K) for a reference step of
   ``--step`` rad on joint ``--joint``, overlaid on the linear prediction; the
   largest difference is printed.  It shrinks like step^2 while no servo
   spool crosses its null (PUMA, joint 2: steps up to ~5e-4 rad).  Beyond,
   the orifice law's kink at null -- the flow gain is proportional to
   sqrt(P_s - P_L) on one side and sqrt(P_s + P_L) on the other -- leaves a
   part proportional to the step: ~0.3 % of it on the PUMA at its holding
   pressures, a property of the valve, not of the linearisation.

``--scene examples/scenes/single_joint_split.toml --positions joint.theta
--at joint.tau_load=50 --pose 0.2`` runs the same on the one-joint rig.

Run:  python examples/control_design_puma.py --out out/control_puma [--step 0.02] [--joint 2]
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
Q0 = [0.3, -0.5, 0.8, 0.2, -0.4, 0.6]


def design(scene_path, positions="arm.q", pose=Q0, at=None, remove=("path*", "amp*"),
           q_err=0.01, qd_err=0.2, u_max=10.0):
    """Plant, operating point, linear model and LQR gains (see module doc). Returns a dict."""
    import control

    import fmugen
    from fmugen.codegen.evaluate import ModelEvaluator
    from fmugen.control.names import lookup
    from fmugen.control.scene import scene_model

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the thesis PUMA's own remarks on its link data
        scene = fmugen.load_scene(scene_path)
        plant = scene_model(scene, without=remove)
    given = dict(at or {})
    controls = [v.name for v in plant.inputs if v.name not in given]
    pos = [s.name for s in lookup(plant, positions, ("state",))]
    vel = [n.replace(".q[", ".qd[") if ".q[" in n else n.replace("theta", "w") for n in pos]
    given.update(dict(zip(pos, np.atleast_1d(pose).astype(float))))
    given.update({n: 0.0 for n in vel})
    op = fmugen.trim(plant, at=given, free=controls)
    sys_ol = fmugen.linearize(plant, op, outputs=pos, inputs=controls)
    # Bryson's rule on the state scaled by its nominal value
    nominal = np.array([abs(v.nominal) if v.nominal else 1.0 for v in plant.states])
    xmax = 10.0 * nominal
    for n in pos:
        xmax[[v.name for v in plant.states].index(n)] = q_err
    for n in vel:
        xmax[[v.name for v in plant.states].index(n)] = qd_err
    Q = np.diag(1.0 / xmax**2)
    R = np.eye(len(controls)) / u_max**2
    K, _, cl_poles = control.lqr(sys_ol, Q, R)
    A, B, C = sys_ol.A, sys_ol.B, sys_ol.C
    Acl = A - B @ K
    N = -np.linalg.inv(C @ np.linalg.solve(Acl, B))
    sys_cl = control.ss(Acl, B @ N, C, 0, inputs=[f"r_{control_name(n)}" for n in pos],
                        outputs=sys_ol.output_labels, states=sys_ol.state_labels, name="closed_loop")
    ci = [v.name for v in plant.inputs]
    return dict(plant=plant, op=op, sys_ol=sys_ol, sys_cl=sys_cl, K=K, N=N, poles=cl_poles, positions=pos,
                controls=controls, control_index=[ci.index(n) for n in controls],
                pos_index=[[v.name for v in plant.states].index(n) for n in pos],
                evaluator=ModelEvaluator(plant, op.parameter_values))


def control_name(fmi_name):
    from fmugen.control.names import signal_name

    return signal_name(fmi_name)


def simulate_nonlinear(d, r_step, t_end, t_eval, rtol=1e-8):
    """q(t) of the nonlinear plant under u = u0 - K (x - x0) + N r_step (scipy Radau, exact Jacobian)."""
    from scipy.integrate import solve_ivp

    ev, op, K, N = d["evaluator"], d["op"], d["K"], d["N"]
    ic = d["control_index"]
    x0, u0 = op.x, op.u
    v = N @ r_step

    def inputs(x):
        u = u0.copy()
        u[ic] = u0[ic] - K @ (x - x0) + v
        return u

    def f(t, x):
        return ev.f(t, x, inputs(x))

    def jac(t, x):
        A, B, _, _ = ev.jacobians(t, x, inputs(x))
        return A - B[:, ic] @ K

    sol = solve_ivp(f, (0.0, t_end), x0, method="Radau", jac=jac, t_eval=t_eval, rtol=rtol,
                    atol=1e-2 * rtol * np.maximum(np.abs(x0), 1.0))
    if not sol.success:
        raise RuntimeError(f"nonlinear simulation failed: {sol.message}")
    return sol.y[d["pos_index"]].T


def compare(d, joint, step, t_end=1.0, n=501, rtol=1e-8):
    """Linear prediction and nonlinear response for a step of ``step`` on position ``joint`` (1-based)."""
    import control

    t = np.linspace(0.0, t_end, n)
    r = np.zeros(len(d["positions"]))
    r[joint - 1] = step
    lin = control.forced_response(d["sys_cl"], t, np.outer(r, np.ones_like(t)), squeeze=False).outputs.T
    q0 = d["op"].x[d["pos_index"]]
    nl = simulate_nonlinear(d, r, t_end, t, rtol) - q0
    return t, lin, nl


def plots(d, t, lin, nl, joint, out: Path):
    import control
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    sys_j = d["sys_cl"][joint - 1, joint - 1]
    omega = np.logspace(-1, 4, 400)
    plt.figure()
    control.bode_plot(sys_j, omega, dB=True)
    plt.suptitle(f"closed loop, {d['positions'][joint - 1]} from its reference")
    plt.savefig(out / "bode.png", dpi=120)
    plt.close("all")
    ts = np.linspace(0, 1.0, 501)
    resp = control.step_response(d["sys_cl"], ts, squeeze=False)
    fig, ax = plt.subplots()
    for j, name in enumerate(d["positions"]):
        ax.plot(resp.time, resp.outputs[j, j], label=name)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("joint response to its unit reference step [rad/rad]")
    ax.legend()
    ax.grid(True)
    fig.savefig(out / "step.png", dpi=120)
    plt.close(fig)
    fig, ax = plt.subplots()
    for j, name in enumerate(d["positions"]):
        line, = ax.plot(t, nl[:, j], label=f"{name} nonlinear")
        ax.plot(t, lin[:, j], "--", color=line.get_color(), label=f"{name} linear")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("q - q0 [rad]")
    ax.legend(fontsize=6, ncol=2)
    ax.grid(True)
    ax.set_title(f"reference step on {d['positions'][joint - 1]}: nonlinear plant vs linear prediction")
    fig.savefig(out / "nonlinear_vs_linear.png", dpi=120)
    plt.close(fig)
    with open(out / "nonlinear_vs_linear.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t"] + [f"{n} linear" for n in d["positions"]] + [f"{n} nonlinear" for n in d["positions"]])
        for k in range(t.size):
            w.writerow([f"{t[k]:.6g}"] + [f"{v:.12g}" for v in lin[k]] + [f"{v:.12g}" for v in nl[k]])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    p.add_argument("--scene", default=str(ROOT / "examples" / "scenes" / "puma_hydraulic.toml"))
    p.add_argument("--positions", default="arm.q", help="the position states the loop controls")
    p.add_argument("--pose", default=",".join(map(str, Q0)), help="their values at the operating point")
    p.add_argument("--at", action="append", default=[], metavar="NAME=VALUE",
                   help="inputs held (not used by the controller), e.g. joint.tau_load=50")
    p.add_argument("--joint", type=int, default=2, help="which position gets the reference step (1-based)")
    p.add_argument("--step", type=float, default=0.02, help="reference step [rad]")
    p.add_argument("--duration", type=float, default=1.0, help="simulated time [s]")
    p.add_argument("--out", default="out/control_puma", help="directory for the plots and the CSV")
    a = p.parse_args(argv)
    at = {k: float(v) for k, v in (s.split("=", 1) for s in a.at)}
    t0 = time.perf_counter()
    d = design(a.scene, a.positions, [float(v) for v in a.pose.split(",")], at)
    print(d["op"].report())
    print(f"open loop: {d['sys_ol'].nstates} states, inputs {', '.join(d['controls'])}")
    poles = np.sort_complex(d["poles"])
    print(f"LQR closed-loop poles: slowest {poles[np.argmin(np.abs(poles))]:.4g}, fastest "
          f"{poles[np.argmax(np.abs(poles))]:.4g}, max real part {poles.real.max():.4g} 1/s")
    print(f"LQR gains K: {d['K'].shape[0]}x{d['K'].shape[1]}, largest |K| {np.abs(d['K']).max():.4g}")
    t, lin, nl = compare(d, a.joint, a.step, a.duration)
    err = np.abs(nl - lin).max()
    print(f"step {a.step:g} rad on {d['positions'][a.joint - 1]}: largest |nonlinear - linear| = {err:.3e} rad "
          f"({err / abs(a.step):.3%} of the step); final value {nl[-1, a.joint - 1]:.6g} rad")
    plots(d, t, lin, nl, a.joint, Path(a.out))
    print(f"wrote {a.out}/bode.png, step.png, nonlinear_vs_linear.png, .csv  ({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
