"""The thesis PUMA with six hydraulic chains under a 1 kHz discrete controller per joint (dlqr).

    python examples/design_puma_sampled.py [--check]

1. Trim: the open-loop plant (``scene_model(scene, without=["path*", "amp*"])``, inputs drv1.u ...
   drv6.u) at the scene's initial pose q0, qd = 0, the six amplifier voltages and the 24 chain
   states free (``fmugen.trim``): the state of rest the analog P loop only reaches with a position
   error.
2. Linearise the whole plant there (``fmugen.linearize``: 36 states, exact Jacobians), cut it into
   the six per-joint blocks -- joint k's angle and speed, its chain's current, spool position and
   speed, load pressure (6 states, input drv{k}.u; the other joints are neither driven nor fed back
   in the block: their coupling stays in the full model, where the design is checked) --, discretise
   each with a zero-order hold at T = 1 ms (``fmugen.control.sampled.zoh``, what ``fmugen.control.c2d`` uses;
   equal to ``control.c2d(..., 'zoh')`` to the last bit) and augment it with the sampled
   integral of the angle error z[k+1] = z[k] + T (theta[k] - r[k]).
3. ``control.dlqr`` per joint on the 7-state augmented model, Bryson weights.
4. The law, run every 1 ms and held (zero-order hold), no computation delay::

       u[k] = u0 + N_u rd[k] - K_x (x[k] - x0 - e_theta (r[k] - q0) - N_x rd[k]) - K_z z[k]

   with r, rd the path's q_ref, qd_ref (the velocity feed-forward N_x, N_u: the chain's steady state
   per unit joint speed, from the same linear block); the constant u0 + K_x (x0 - e_theta q0) is the
   integrator's start value (z0 = -(...)/K_z), so the file is the linear system
   ``fmugen.control.discrete_controller_file`` writes: one state z, inputs r, rd, theta, w, i, x_v,
   v_v, P_L, output u.
5. Check on the *full* linearisation (36 plant states + 6 integrators, all joints coupled, ZOH at
   1 ms): the spectral radius of the closed loop with the six decentralised gains (< 1: stable).
6. Write examples/components/puma_sampled_ctrl{k}.toml and examples/scenes/puma_hydraulic_sampled.toml
   (the thesis scene with amp{k} replaced by ctrl{k}; starts "given" at the trim, the controllers'
   integrators and held outputs at their values there).

Why per joint and full chain state: the analog P amplifier leaves each hydraulic mode (35-577 rad/s,
damping 0.02-0.3) almost undamped; feeding back the load pressure and spool states damps it, and the
per-joint design keeps the controller in the joint's FMU (it reads the joint angle and speed across
the arm/joint boundary as the amplifier did, its chain's states inside its own FMU).  The coupling
between joints through M(q)^-1 and gravity is weak at the pose: the full-model check confirms it.

Measured (2-core machine, shared): the full loop's spectral radius 0.9901 (slowest mode ~10 1/s);
the whole 2 s move, Newton/cubic at 1 ms (the scene's [cosim]): tracking error <= 5.6e-4 rad (joint 3),
the pose held to 1e-12 rad before the path starts, <= 5e-9 rad off the end point at 2 s; 19 s wall
(Newton/linear 2.7 s).  Against the hybrid reference (Radau 1e-12, a piece per sample interval) over the
first 0.5 s (`fmugen report ... --stop 0.5`, 10 min, nearly all of it the reference), L-inf over the six
angles at H = 1 / 0.5 / 0.25 ms: Newton/cubic 2.2e-7 / 2.8e-8 / 3.4e-9 rad (order 3), Newton/linear
9.5e-6 / 2.8e-6 / 7.3e-7 (order 1.8-1.9), Gauss-Seidel/linear 5.7e-4 (flagged unreliable by the master's
estimate) / 4.5e-5 / 9.1e-6.  tests/test_puma_sampled.py.

    python examples/design_puma_sampled.py
    fmugen cosim examples/scenes/puma_hydraulic_sampled.toml --out out/puma_sampled
    fmugen report examples/scenes/puma_hydraulic_sampled.toml --stop 0.5 --steps 1e-3,5e-4,2.5e-4 \
        --schemes newton/cubic,newton/linear,gauss-seidel/linear --repeats 1 --no-monolithic --out out/rep
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import fmugen
from fmugen.control import discrete_controller_file, scene_model
from fmugen.control.linearize import linear_model

ROOT = Path(__file__).resolve().parent
SCENE = ROOT / "scenes" / "puma_hydraulic.toml"
OUT_SCENE = ROOT / "scenes" / "puma_hydraulic_sampled.toml"
COMPONENTS = ROOT / "components"
T = 1e-3  # sample period [s]
Q0 = [0.0, -0.4, 0.6, 0.0, 0.5, 0.0]
Q1 = [0.5, -0.1, 0.2, 0.4, 0.9, -0.5]
CHAIN = ("drv{k}.i", "valve{k}.x_v", "valve{k}.v_v", "act{k}.P_L")
INPUTS = [("r", "rad"), ("rd", "rad/s"), ("theta", "rad"), ("w", "rad/s"), ("i", "A"), ("x_v", "1"),
          ("v_v", "1/s"), ("P_L", "Pa")]
# Bryson: the largest deviation accepted of theta, w, i, x_v, v_v, P_L, z and of u
SCALE = {"theta": 2e-4, "w": 0.05, "i": 1e-2, "x_v": 1.0, "v_v": 600.0, "P_L": 1.4e7, "z": 2e-5, "u": 10.0}


def joint_states(k):
    return [f"arm.q[{k}]", f"arm.qd[{k}]"] + [s.format(k=k) for s in CHAIN]


def design(scene=None, T=T, scale=SCALE):
    """Trim, linearise, dlqr per joint; returns a dict with everything the files and the checks need."""
    import control

    scene = scene or fmugen.load_scene(str(SCENE))
    plant = scene_model(scene, without=["path*", "amp*"])
    op = fmugen.trim(plant, at={"arm.q": Q0, "arm.qd": 0}, free=[f"drv{k}.u" for k in range(1, 7)])
    lm = linear_model(plant, op, outputs=[])
    names = list(lm.states)
    x_op = dict(zip(names, np.asarray(op.x, float)))
    u_op = dict(zip(lm.inputs, np.asarray(op.u, float)))
    Qw = np.diag([1 / scale[n] ** 2 for n in ("theta", "w", "i", "x_v", "v_v", "P_L", "z")])
    Rw = np.array([[1 / scale["u"] ** 2]])
    joints = []
    for k in range(1, 7):
        idx = [names.index(s) for s in joint_states(k)]
        A, B = lm.A[np.ix_(idx, idx)], lm.B[idx][:, [list(lm.inputs).index(f"drv{k}.u")]]

        Ad, Bd = fmugen.control.sampled.zoh(A, B, T)
        Aa = np.block([[Ad, np.zeros((6, 1))], [T * np.eye(1, 6), np.eye(1)]])
        Ba = np.vstack([Bd, np.zeros((1, 1))])
        K, _, E = control.dlqr(Aa, Ba, Qw, Rw)
        K = np.asarray(K).ravel()
        # velocity feed-forward: der(qd) = 0 and der(chain) = 0 with qd = 1 (the angle deviation 0)
        rows = [1, 2, 3, 4, 5]
        M = np.hstack([A[np.ix_(rows, [2, 3, 4, 5])], B[rows]])
        sol = np.linalg.solve(M, -A[rows, 1])
        N_x = np.r_[0.0, 1.0, sol[:4]]
        N_u = sol[4]
        x0 = np.array([x_op[s] for s in joint_states(k)])
        u0 = u_op[f"drv{k}.u"]
        Kx, Kz = K[:6], K[6]
        c = u0 + Kx @ (x0 - Q0[k - 1] * np.eye(1, 6).ravel())
        z0 = -c / Kz
        # the controller as a linear discrete system: inputs (r, rd, theta, w, i, x_v, v_v, P_L), state z
        e = np.eye(1, 6).ravel()
        Dr = Kx @ e                       # from r
        Drd = N_u + Kx @ N_x              # from rd
        Dc = np.r_[Dr, Drd, -Kx]
        Bc = np.r_[-T, 0.0, T, 0.0, 0.0, 0.0, 0.0, 0.0]
        joints.append(dict(k=k, K=K, poles=np.asarray(E), A=A, B=B, Ad=Ad, Bd=Bd, x0=x0, u0=u0, z0=z0,
                           N_x=N_x, N_u=N_u, ctrl=(np.eye(1), Bc[None, :], np.array([[-Kz]]), Dc[None, :])))
    return dict(scene=scene, plant=plant, op=op, lm=lm, joints=joints, T=T)


def full_loop_radius(d):
    """Spectral radius of the full linearised plant (ZOH at T) + 6 integrators under the six gains."""
    lm, T = d["lm"], d["T"]
    names, n = list(lm.states), len(lm.states)
    Ad, Bd = fmugen.control.sampled.zoh(lm.A, lm.B, T)
    Aa = np.zeros((n + 6, n + 6))
    Aa[:n, :n] = Ad
    Ba = np.vstack([Bd, np.zeros((6, 6))])
    Kfull = np.zeros((6, n + 6))
    for j in d["joints"]:
        k = j["k"]
        qi = names.index(f"arm.q[{k}]")
        Aa[n + k - 1, n + k - 1] = 1.0
        Aa[n + k - 1, qi] = T
        col = list(lm.inputs).index(f"drv{k}.u")
        for s, g in zip(joint_states(k), j["K"][:6]):
            Kfull[col, names.index(s)] = g
        Kfull[col, n + k - 1] = j["K"][6]
    Acl = Aa - Ba @ Kfull
    ev = np.linalg.eigvals(Acl)
    return float(np.abs(ev).max()), ev


def write_files(d, components=COMPONENTS, scene_path=OUT_SCENE):
    components.mkdir(parents=True, exist_ok=True)
    for j in d["joints"]:
        k = j["k"]
        discrete_controller_file(
            components / f"puma_sampled_ctrl{k}.toml", j["ctrl"], inputs=INPUTS, outputs=[("u", "V")],
            name=f"puma_sampled_ctrl{k}", state_unit="rad.s", sample_period=d["T"],
            description=f"joint {k}: dlqr state feedback (angle, speed, current, spool, load pressure) + "
                        f"integral of the angle error, velocity feed-forward, T_s = {d['T']:g} s, ZOH")
    js = d["joints"]
    # the trim's round-off zeros (1e-30 and below, joints 1, 4, 6 carry no gravity load) written as 0.0
    fmt = lambda vals: "[" + ", ".join(repr(float(v) if abs(v) > 1e-25 else 0.0) for v in vals) + "]"  # noqa: E731
    text = f'''# GENERATED by examples/design_puma_sampled.py -- do not edit; run the script again.
# The thesis system (puma_hydraulic.toml: PUMA + six hydraulic chains, one FMU per chain) with each analog
# P amplifier replaced by a 1 kHz discrete controller (examples/components/puma_sampled_ctrl{{k}}.toml):
#   u[k] = u0 + N_u rd - K_x (x - x_ref(r, rd)) - K_z z,  z[k+1] = z[k] + T_s (theta - r),  held (ZOH)
# x = (theta, w, i, x_v, v_v, P_L) of joint k: K from control.dlqr on the trimmed linearisation (the joint's
# block of the monolithic one), ZOH-discretised at T_s = 1 ms, augmented by the integrator.
# Starts "given": the trim at the initial pose (arm held, chains at the holding pressure), the integrators
# at the value that holds it (z0), the held outputs at the trim voltages (u0).
# The macro step must divide 1 ms. Reference: the hybrid one (a Radau piece per sample interval).

[scene]
name = "puma_hydraulic_sampled"
description = "thesis PUMA, six hydraulic chains, a 1 kHz dlqr controller per joint"
stop = 2.0
step = 1e-3
tolerance = 1e-8
initial = "given"
record = ["arm.q[1]", "arm.q[2]", "arm.q[3]", "arm.q[4]", "arm.q[5]", "arm.q[6]",
          "ctrl1.u", "ctrl2.u", "ctrl3.u", "ctrl4.u", "ctrl5.u", "ctrl6.u",
          "act1.tau", "act2.tau", "act3.tau", "act4.tau", "act5.tau", "act6.tau"]

[instances.arm]
robot = "../../robots/puma_thesis_com.toml"
formulation = "newton_euler"
start = {{ "q[1]" = {Q0[0]!r}, "q[2]" = {Q0[1]!r}, "q[3]" = {Q0[2]!r}, "q[4]" = {Q0[3]!r}, "q[5]" = {Q0[4]!r}, "q[6]" = {Q0[5]!r} }}

[fmus.arm]
members = ["arm"]

[repeat.joint]
values = {{ k = [1, 2, 3, 4, 5, 6], q0 = {fmt(Q0)}, q1 = {fmt(Q1)}, i0 = {fmt(j["x0"][2] for j in js)}, xv0 = {fmt(j["x0"][3] for j in js)}, vv0 = {fmt(j["x0"][4] for j in js)}, pl0 = {fmt(j["x0"][5] for j in js)}, z0 = {fmt(j["z0"] for j in js)}, u0 = {fmt(j["u0"] for j in js)} }}
connect = [["path{{k}}.q_ref", "ctrl{{k}}.r"], ["path{{k}}.qd_ref", "ctrl{{k}}.rd"],
           ["arm.q[{{k}}]", "ctrl{{k}}.theta"], ["arm.qd[{{k}}]", "ctrl{{k}}.w"],
           ["drv{{k}}.i", "ctrl{{k}}.i"], ["valve{{k}}.x_v", "ctrl{{k}}.x_v"], ["valve{{k}}.v_v", "ctrl{{k}}.v_v"],
           ["act{{k}}.P_L", "ctrl{{k}}.P_L"],
           ["ctrl{{k}}.u", "drv{{k}}.u"], ["drv{{k}}.i", "valve{{k}}.i"], ["valve{{k}}.port", "act{{k}}.port"],
           ["act{{k}}.flange", "arm.joint[{{k}}]"]]
fmus = {{ "joint{{k}}" = {{ members = ["path{{k}}", "ctrl{{k}}", "drv{{k}}", "valve{{k}}", "act{{k}}"] }} }}

[repeat.joint.instances]
"path{{k}}" = {{ type = "ptp_trajectory", parameters = {{ q_begin = "{{q0}}", q_end = "{{q1}}", qd_max = 1.0, qdd_max = 4.0, t_start = 0.2 }} }}
"ctrl{{k}}" = {{ type = "file:../components/puma_sampled_ctrl{{k}}.toml", start = {{ x_1 = "{{z0}}", u_k = "{{u0}}" }} }}
"drv{{k}}" = {{ type = "current_driver", kind = "lag", parameter_set = "puma_joint{{k}}", start = {{ i = "{{i0}}" }} }}
"valve{{k}}" = {{ type = "servo_valve", order = 2, parameter_set = "puma_joint{{k}}", start = {{ x_v = "{{xv0}}", v_v = "{{vv0}}" }} }}
"act{{k}}" = {{ type = "hydraulic_actuator", form = "load_pressure", parameter_set = "puma_joint{{k}}", start = {{ P_L = "{{pl0}}" }} }}

[cosim]                        # every sample instant a communication point: the step divides 1 ms
scheme = "newton"              # Newton/cubic at 1 ms: 2e-7 rad against the hybrid reference over 0.25 s;
extrapolation = "cubic"        # Newton/linear 9e-6 rad (second order), Gauss-Seidel 2e-4 rad (the sampler
step = 1e-3                    # reads the arm's outputs of the step's start: one macro step of delay)
'''
    scene_path.write_text(text)
    return scene_path


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--check", action="store_true", help="design and check only, write nothing")
    a = ap.parse_args()
    d = design()
    print(f"trim residual {np.abs(d['op'].residual).max():.1e}; u0 = {np.round(d['op'].u, 6)}")
    for j in d["joints"]:
        p = j["poles"]
        print(f"joint {j['k']}: K = {np.array2string(j['K'], precision=4)}; |poles| max {np.abs(p).max():.4f}; "
              f"slowest s = {np.log(p[np.argmax(np.abs(p))]) / d['T']:.1f} 1/s; z0 = {j['z0']:.4g}")
    rho, ev = full_loop_radius(d)
    s = np.log(ev.astype(complex)) / d["T"]
    print(f"full linearised closed loop (42 states, all joints coupled): spectral radius {rho:.6f} "
          f"({'stable' if rho < 1 else 'UNSTABLE'}); slowest continuous-equivalent rate {(-s.real).min():.2f} 1/s")
    if not a.check:
        print("wrote", write_files(d))


if __name__ == "__main__":
    main()
