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

Part B (``--cosim``): the scene's own joint loops -- the P amplifiers
u_k = K_a,k (theta_ref,k - q_k) -- get gains chosen on the same linearised
plant (each K_a,k maximises the decay rate of the slowest closed-loop mode),
and the scene, with those gains and a ``--move`` of joint ``--joint`` on its
path, runs in the co-simulation master (``fmugen.cosim.run``: one FMU per
chain and one for the arm), overlaid on the prediction of the closed scene
linearised at its trimmed start (paths removed, connections applied).

Run:  python examples/control_design_puma.py --out out/control_puma [--step 0.02] [--joint 2] [--cosim]
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


# --------------------------------------------------------------------------------------------
# Part B: the scene's own joint loops (P amplifiers u_k = K_a,k (theta_ref,k - q_k)), their gains
# chosen on the linearised plant, checked in the co-simulation master against the linear prediction.
# --------------------------------------------------------------------------------------------

def loops(scene):
    """[(amplifier, path, position state, plant input)] from the scene's connections, in amplifier order."""
    src = {(ti, tv): (si, sv) for si, sv, ti, tv, _ in scene.connections}
    drives = {(si, sv): (ti, tv) for si, sv, ti, tv, _ in scene.connections}
    out = []
    for amp in sorted(i for i in scene.spec.instances if scene.spec.instances[i].source == "amplifier"):
        path = src[(amp, "theta_ref")][0]
        pos = ".".join(src[(amp, "theta")])
        out.append((amp, path, pos, ".".join(drives[(amp, "u")])))
    return out


def slowest_decay(A):
    """min over the modes of -Re(lambda) [1/s]: the decay rate of the slowest mode."""
    return float(np.min(-np.linalg.eigvals(A).real))


def amplifier_gains(scene_path, sets=None):
    """Gains K_a that make the slowest closed-loop mode decay fastest, one joint at a time.

    On the open plant (scene without paths and amplifiers) linearised at the
    paths' start positions, the ideal P amplifier closes u = K (r - q):
    A_cl = A - B K C.  Each K_a,k is chosen on a log grid (0.05 to 20 times
    the scene's value, the others held), refined by a bounded scalar search,
    to maximise the slowest decay rate -- the pole-placement reading of
    "settle fastest" for a single gain; two sweeps over the joints.
    """
    from scipy.optimize import minimize_scalar

    import fmugen
    from fmugen.codegen.evaluate import ModelEvaluator
    from fmugen.control import scene_model

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = fmugen.load_scene(scene_path, set=sets)
        lp = loops(scene)
        plant = scene_model(scene, without=[a for a, *_ in lp] + [p for _, p, *_ in lp])
    r0 = [ModelEvaluator(scene.base_models[p]).g(0.0)[0] for _, p, *_ in lp]
    pos = [q for *_, q, _ in lp]
    vel = [n.replace(".q[", ".qd[") if ".q[" in n else n.replace("theta", "w") for n in pos]
    op = fmugen.trim(plant, at={**dict(zip(pos, r0)), **{v: 0.0 for v in vel}}, free=[u for *_, u in lp])
    G = fmugen.linearize(plant, op, outputs=pos, inputs=[u for *_, u in lp])
    K0 = np.array([next(v.start for v in scene.base_models[a].parameters if v.name == "K_a") for a, *_ in lp])
    K = K0.copy()

    def rate(k, j):
        Kj = K.copy()
        Kj[j] = k
        return slowest_decay(G.A - G.B @ np.diag(Kj) @ G.C)

    for _ in range(2):
        for j in range(len(K)):
            grid = K0[j] * np.logspace(np.log10(0.05), np.log10(20), 41)
            rates = [rate(k, j) for k in grid]
            b = int(np.argmax(rates))
            lo, hi = np.log(grid[max(b - 1, 0)]), np.log(grid[min(b + 1, len(grid) - 1)])
            res = minimize_scalar(lambda lk: -rate(np.exp(lk), j), bounds=(lo, hi), method="bounded")
            K[j] = np.exp(res.x) if -res.fun >= rates[b] else grid[b]
    return dict(loops=lp, K0=K0, K=K, plant=G, rate0=slowest_decay(G.A - G.B @ np.diag(K0) @ G.C),
                rate=slowest_decay(G.A - G.B @ np.diag(K) @ G.C), r0=np.array(r0))


def cosim_against_linear(scene_path, gains, joint, move, stop, sets=None):
    """The scene with the designed gains and a small move of ``joint``: co-simulation vs linear prediction.

    The linear prediction is the *closed* scene (paths removed, amplifiers kept)
    trimmed at the paths' start values and linearised from the references
    theta_ref to the positions, driven by the paths' q_ref(t) - q_ref(0).
    """
    import control

    import fmugen
    import fmugen.cosim
    from fmugen.codegen.evaluate import ModelEvaluator
    from fmugen.control import scene_model

    lp = gains["loops"]
    amp, path, pos, _ = lp[joint - 1]
    sets = dict(sets or {})
    sets.update({f"{a}.K_a": float(k) for (a, *_), k in zip(lp, gains["K"])})
    # every path holds its start value, but the one that moves
    sets.update({f"{p}.q_end": float(r) for (_, p, *_), r in zip(lp, gains["r0"])})
    sets[f"{path}.q_end"] = float(gains["r0"][joint - 1] + move)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = fmugen.load_scene(scene_path, set=sets)
        closed = scene_model(scene, without=[p for _, p, *_ in lp])
    refs = [f"{a}.theta_ref" for a, *_ in lp]
    op = fmugen.trim(closed, at=dict(zip(refs, gains["r0"])))
    G = fmugen.linearize(closed, op, outputs=[q for *_, q, _ in lp], inputs=refs)
    # detect_divergence off: from rest, the coupled signals grow from zero by more than the master's
    # 100x-in-8-steps rule at the path's start, which it would report as a diverging coupling
    result = fmugen.cosim.run(scene, stop=stop, detect_divergence=False)
    if not result.ok:
        raise RuntimeError(f"co-simulation failed: {result.summary}")
    t = result.time
    r = np.array([[ModelEvaluator(scene.base_models[p]).g(tk)[0] for tk in t] for _, p, *_ in lp])
    lin = control.forced_response(G, t, r - r[:, :1], squeeze=False).outputs
    y0 = np.array([op[q] for *_, q, _ in lp])
    lin = (lin + y0[:, None]).T
    cos = np.array([result[q] for *_, q, _ in lp]).T
    return t, lin, cos, pos


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
    p.add_argument("--cosim", action="store_true",
                   help="part B: choose the scene's amplifier gains, co-simulate a --move of --joint with them")
    p.add_argument("--move", type=float, default=0.01, help="part B: path move of --joint [rad]")
    p.add_argument("--stop", type=float, default=0.6, help="part B: co-simulated time [s]")
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
    if a.cosim:
        cosim_part(a)
    return 0


def cosim_part(a) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t0 = time.perf_counter()
    g = amplifier_gains(a.scene)
    for (amp, *_), k0, k in zip(g["loops"], g["K0"], g["K"]):
        print(f"{amp}.K_a: {k0:.6g} -> {k:.6g} V/rad")
    print(f"slowest closed-loop decay rate: {g['rate0']:.4g} -> {g['rate']:.4g} 1/s")
    t, lin, cos, pos = cosim_against_linear(a.scene, g, a.joint, a.move, a.stop)
    err = np.abs(cos - lin).max()
    print(f"co-simulation (fmugen.cosim.run, the scene's FMUs) of a {a.move:g} rad move of {pos}: largest "
          f"|co-simulation - linear| = {err:.3e} rad ({err / abs(a.move):.3%} of the move)  "
          f"({time.perf_counter() - t0:.1f} s)")
    out = Path(a.out)
    fig, ax = plt.subplots()
    for j, (*_, name, _) in enumerate(g["loops"]):
        line, = ax.plot(t, cos[:, j] - cos[0, j], label=f"{name} co-simulation")
        ax.plot(t, lin[:, j] - lin[0, j], "--", color=line.get_color(), label=f"{name} linear")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("q - q(0) [rad]")
    ax.legend(fontsize=6, ncol=2)
    ax.grid(True)
    ax.set_title(f"designed gains, move of {pos}: co-simulation vs linear", fontsize=10)
    fig.savefig(out / "cosim_vs_linear.png", dpi=120)
    plt.close(fig)
    print(f"wrote {out}/cosim_vs_linear.png")


if __name__ == "__main__":
    sys.exit(main())
