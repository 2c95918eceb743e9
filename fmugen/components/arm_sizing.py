"""Actuator parameter sets for any arm: the PUMA sets' rule (sizing.py), generalised.

What each joint needs (:func:`requirements`), from the arm's own dynamics:

* ``tau_g`` -- the worst static gravity torque |h(q, 0)_j| over a set of
  poses (a grid over a full turn of every revolute joint and the stated range
  of every prismatic one, the joints' limits where the robot file gives them,
  or poses you pass);
* ``J`` -- the worst inertia about the joint, max M(q)_jj over the same poses
  (exact; the PUMA rule's sum m (d^2 + rho^2) was an estimate);
* with a trajectory (times, q): the worst inverse-dynamics torque
  |M qdd + h| and the worst speed |qd| along it (qd, qdd by finite
  differences of the samples).

Proposals, one parameter set per joint (the families of ``data/default.toml``),
margins stated in each file's header:

* hydraulic (:func:`hydraulic_sets`): stall torque P_s D_m >= max(margin
  tau_g, margin tau_peak, J alpha_ref); D_m rounded up to 2 digits; the
  default set's Q_N, V_t, K_c0, C_tm, C_im scaled by f = D_m/D_m(default)
  (same no-load speed K_q0/D_m, same leakage per displacement), Q_N raised
  further when that speed is below 1.25x the required joint speed; B_m with
  J (a prismatic joint: the same numbers as the linear cylinder's A_p and the
  moving mass M, B_p).  The hydraulic natural frequency, damping and the P
  loop's velocity gain are reported.
* electric (:func:`electric_sets`, RobotR3-style ``dc_motor``): the default
  motor (k_t, J_m) with a current limit i_max and a top speed w_m_max (both
  stated assumptions); gear ratio |n| >= margin max(tau_g, tau_peak, J alpha_ref)
  / (k_t i_max), rounded up (a prismatic joint: n in rad/m, a screw);
  refused (named in the notes) when n w_peak exceeds w_m_max -- no gear
  serves both torque and speed with that motor.

``fmugen size ROBOT.toml [--trajectory q.csv] [--kind hydraulic|electric] --out DIR``
writes the sets; ``parameter_set = "DIR/joint2.toml"`` uses one in a scene.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from ..errors import FmugenError
from .parameters import load_parameter_set
from .sizing import _round_up

PRISMATIC_RANGE = (-0.5, 0.5)  # m, a prismatic joint's range when the file states none


@dataclass
class JointNeed:
    joint: int
    revolute: bool
    tau_g: float  # worst static gravity torque/force
    J: float  # worst inertia (mass) about/along the joint
    tau_peak: Optional[float] = None  # worst torque along the trajectory
    w_peak: Optional[float] = None  # worst speed along the trajectory (or the joint's velocity limit)
    effort: Optional[float] = None  # the robot file's effort limit (URDF), reported against the proposal


def _arm(robot):
    import fmugen

    return fmugen.load_robot(robot) if isinstance(robot, (str, Path)) else robot


def pose_grid(arm, n_grid: int = 5, max_poses: int = 4096, seed: int = 0, params=None) -> np.ndarray:
    """Poses: a grid of ``n_grid`` values per joint (the first joint left at 0 when it changes no gravity
    torque -- a vertical base axis, or any prismatic one: gravity is uniform -- which is checked on
    random poses, not assumed), sampled at random down to ``max_poses`` when the grid is larger."""
    ranges = []
    for k, link in enumerate(arm.robot.bodies):
        lim = getattr(link, "limits", None)
        rev = str(link.joint).lower().startswith("r")
        lo, hi = (-math.pi, math.pi) if rev else PRISMATIC_RANGE
        if lim is not None:
            lo = lim.lower if lim.lower is not None else lo
            hi = lim.upper if lim.upper is not None else hi
        ranges.append(np.linspace(lo, hi, n_grid))
    rng = np.random.default_rng(seed)
    if not _first_joint_moves_gravity(arm, ranges, rng, params=params):
        ranges[0] = np.array([0.0])
    n = int(np.prod([len(r) for r in ranges]))
    if n <= max_poses:
        return np.array(list(itertools.product(*ranges)))
    return np.array([[rng.choice(r) for r in ranges] for _ in range(max_poses)])


def _first_joint_moves_gravity(arm, ranges, rng, poses: int = 4, params=None) -> bool:
    """Whether turning (or sliding) the first joint changes the gravity torques h(q, 0) of some pose."""
    zero, params = np.zeros(arm.n), dict(params or {})
    for _ in range(poses):
        q = np.array([rng.uniform(r[0], r[-1]) for r in ranges])
        q[0] = 0.0
        ref = np.asarray(arm.bias(q, zero, **params), dtype=float)
        scale = max(float(np.max(np.abs(ref))), 1e-300)
        for a in (ranges[0][0], 0.5 * (ranges[0][0] + ranges[0][-1]) + 0.3, ranges[0][-1]):
            q[0] = a
            if np.max(np.abs(np.asarray(arm.bias(q, zero, **params), dtype=float) - ref)) > 1e-9 * scale:
                return True
    return False


def _checked_params(arm, params) -> dict:
    """``params`` (name -> value) as finite floats for parameters the robot file has, the file's own checks
    applied to the new values; a symbolic parameter without a value is named with the flag that gives one."""
    from ..scene.errors import did_you_mean
    from ..robot.value_checks import robot_value_problem
    from ..values import as_number

    names = {p.name: p for p in arm.robot.parameters}
    out = {}
    for k, v in dict(params or {}).items():
        if k not in names:
            raise FmugenError(f"{arm.robot.name}: --set {k}: the robot file has no parameter {k!r}"
                              f"{did_you_mean(k, names)}; parameters: {', '.join(names) or '-'}")
        out[k] = as_number(v, f"{arm.robot.name}: --set {k}")
    missing = [k for k, p in names.items() if p.value is None and k not in out]
    if missing:
        raise FmugenError(f"{arm.robot.name}: symbolic parameter(s) {', '.join(missing)} need a value: "
                          f"--set {missing[0]}=VALUE")
    problem = robot_value_problem(arm.robot, out) if out else None
    if problem:
        raise FmugenError(f"{arm.robot.name}: --set: {problem}")
    return out


def requirements(robot, poses: Optional[np.ndarray] = None, trajectory: Optional[tuple] = None,
                 n_grid: int = 5, speed: float = 1.0, params=None) -> list:
    """[JointNeed] per joint (module doc).  ``trajectory``: (times, q[n_samples, n]);
    ``speed``: the required joint speed [rad/s or m/s] when there is no trajectory and no velocity limit;
    ``params``: values of the robot file's parameters (its symbolic ones need one), checked as the file's."""
    arm = _arm(robot)
    params = _checked_params(arm, params)
    n = arm.n
    P = pose_grid(arm, n_grid, params=params) if poses is None else np.atleast_2d(np.asarray(poses, dtype=float))
    if P.shape[1] != n:
        raise FmugenError(f"sizing: poses have {P.shape[1]} joints, the arm {n}")
    zero = np.zeros(n)
    tau_g, J = np.zeros(n), np.zeros(n)
    for q in P:
        tau_g = np.maximum(tau_g, np.abs(np.asarray(arm.bias(q, zero, **params), dtype=float)))
        J = np.maximum(J, np.diag(np.asarray(arm.mass_matrix(q, **params), dtype=float)))
    tau_peak = w_peak = None
    if trajectory is not None:
        t, Q = np.asarray(trajectory[0], dtype=float), np.atleast_2d(np.asarray(trajectory[1], dtype=float))
        if Q.shape != (len(t), n) or len(t) < 3 or not np.all(np.diff(t) > 0):
            raise FmugenError(f"sizing: the trajectory needs increasing times and q of shape (samples, {n})")
        Qd = np.gradient(Q, t, axis=0, edge_order=2)
        Qdd = np.gradient(Qd, t, axis=0, edge_order=2)
        tau_peak = np.max(np.abs([np.asarray(arm.inverse_dynamics(q, qd, qdd, **params), dtype=float)
                                  for q, qd, qdd in zip(Q, Qd, Qdd)]), axis=0)
        w_peak = np.max(np.abs(Qd), axis=0)
    out = []
    for j, link in enumerate(arm.robot.bodies):
        lim = getattr(link, "limits", None)
        w = (w_peak[j] if w_peak is not None else
             lim.velocity if lim is not None and lim.velocity is not None else speed)
        out.append(JointNeed(j + 1, str(link.joint).lower().startswith("r"), float(tau_g[j]),
                             max(float(J[j]), 1e-2), None if tau_peak is None else float(tau_peak[j]), float(w),
                             None if lim is None else lim.effort))
    return out


def hydraulic_sets(needs: Sequence[JointNeed], base="default", margin: float = 2.0,
                   alpha_ref: float = 100.0) -> list:
    """[(set {family: {name: value}}, notes)] per joint (module doc)."""
    b = load_parameter_set(base).sections
    P_s = b["servo_valve"]["P_s"]
    out = []
    for nd in needs:
        T = max(margin * nd.tau_g, margin * (nd.tau_peak or 0.0), nd.J * alpha_ref)
        D_m = _round_up(T / P_s)
        f = D_m / b["hydraulic_actuator"]["D_m"]
        s = {fam: dict(v) for fam, v in b.items()}
        sv, ha = s["servo_valve"], s["hydraulic_actuator"]
        sv["Q_N"] *= f
        sv["K_c0"] *= f
        for k in ("V_t", "C_tm", "C_im"):
            ha[k] *= f
        ha["D_m"] = D_m
        J = round(nd.J, 4)
        s["joint_inertia"]["J"] = J
        s["joint_inertia"]["B_m"] = b["joint_inertia"]["B_m"] * J / b["joint_inertia"]["J"]
        if not nd.revolute:  # a prismatic joint: the linear cylinder (kind="linear") and a moving mass, the
            # same numbers in their own names (force/pressure is an area; the mass along the joint)
            ha["A_p"] = D_m
            s["joint_inertia"]["M"] = J
            s["joint_inertia"]["B_p"] = b["joint_inertia"]["B_p"] * J / b["joint_inertia"]["M"]
        w_nl = sv["Q_N"] * math.sqrt(P_s / sv["dp_N"]) / D_m  # no-load speed, valve fully open
        if w_nl < 1.25 * nd.w_peak:
            sv["Q_N"] *= 1.25 * nd.w_peak / w_nl
            w_nl = 1.25 * nd.w_peak
        w_h = math.sqrt(4 * ha["beta_e"] * D_m**2 / (ha["V_t"] * J))
        K_q0 = sv["Q_N"] * math.sqrt(P_s / sv["dp_N"])
        z_h = (sv["K_c0"] + ha["C_tm"]) / D_m * math.sqrt(ha["beta_e"] * J / ha["V_t"]) \
            + s["joint_inertia"]["B_m"] / (4 * D_m) * math.sqrt(ha["V_t"] / (ha["beta_e"] * J))
        K_v = s["amplifier"]["K_a"] * s["current_driver"]["G_i"] * K_q0 / sv["i_rated"] / D_m
        notes = dict(joint=nd.joint, kind="hydraulic", revolute=nd.revolute, effort=nd.effort, tau_g=nd.tau_g, tau_peak=nd.tau_peak, J=J,
                     w_peak=nd.w_peak, stall=P_s * D_m, D_m=D_m, f=f, no_load_speed=w_nl, omega_h=w_h,
                     zeta_h=z_h, K_v=K_v, margin=_margin(P_s * D_m, nd))
        out.append((s, notes))
    return out


def electric_sets(needs: Sequence[JointNeed], base="default", margin: float = 1.5, i_max: float = 10.0,
                  w_m_max: float = 420.0, alpha_ref: float = 100.0) -> list:
    """[(set, notes)] per joint: the default dc_motor with the gear ratio chosen (module doc)."""
    b = load_parameter_set(base).sections
    k_t, sign = b["dc_motor"]["k_t"], math.copysign(1.0, b["dc_motor"]["ratio"])
    out = []
    for nd in needs:
        T = max(nd.tau_g, nd.tau_peak or 0.0, nd.J * alpha_ref)
        n = max(1, math.ceil(margin * T / (k_t * i_max)))
        s = {fam: dict(v) for fam, v in b.items()}
        s["dc_motor"]["ratio"] = sign * n
        speed = n * nd.w_peak
        notes = dict(joint=nd.joint, kind="electric", effort=nd.effort, tau_g=nd.tau_g, tau_peak=nd.tau_peak, J=nd.J,
                     w_peak=nd.w_peak, ratio=n, max_torque=n * k_t * i_max, motor_speed=speed,
                     margin=_margin(n * k_t * i_max, nd), feasible=speed <= w_m_max,
                     i_max=i_max, w_m_max=w_m_max)
        out.append((s, notes))
    return out


def _margin(capacity: float, nd: JointNeed):
    """capacity / the worst load (gravity or trajectory), or None when there is none (sized by inertia)."""
    load = max(nd.tau_g, nd.tau_peak or 0.0)
    return capacity / load if load > 1e-9 * max(capacity, 1.0) else None


def _margin_text(m) -> str:
    return "no gravity or trajectory load: sized by J alpha_ref" if m is None else f"margin {m:.2f}x the worst load"


def write_sets(sets: list, directory, robot_name: str = "arm") -> list:
    """One TOML parameter set per joint (``joint<k>.toml``), the rule and the margins in its header."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for s, n in sets:
        head = [f"# Parameter set for joint {n['joint']} of {robot_name} ({n['kind']}), proposed by "
                f"fmugen.components.arm_sizing (rule: its module docstring).",
                f"#   worst gravity torque {n['tau_g']:.4g}, worst trajectory torque "
                f"{'-' if n['tau_peak'] is None else format(n['tau_peak'], '.4g')}, inertia {n['J']:.4g}, "
                f"required speed {n['w_peak']:.4g}"]
        if n["kind"] == "hydraulic":
            if n.get("revolute", True):
                head.append(f"#   stall torque P_s D_m = {n['stall']:.4g} ({_margin_text(n['margin'])}), "
                            f"D_m = {n['D_m']:.3g} m3/rad, no-load speed {n['no_load_speed']:.3g}")
            else:
                head.append(f"#   prismatic: a linear cylinder (hydraulic_actuator kind = \"linear\", joint_inertia kind = "
                            f"\"prismatic\"); stall force P_s A_p = {n['stall']:.4g} ({_margin_text(n['margin'])}), "
                            f"A_p = {n['D_m']:.3g} m2, moving mass M = {n['J']:.4g} kg, no-load speed "
                            f"{n['no_load_speed']:.3g} m/s")
            head.append(f"#   omega_h = {n['omega_h']:.4g} rad/s, zeta_h = {n['zeta_h']:.3f}, K_v = {n['K_v']:.4g} 1/s "
                        f"(a P loop needs K_v < 2 zeta_h omega_h = {2 * n['zeta_h'] * n['omega_h']:.4g})")
        else:
            head.append(f"#   gear ratio {n['ratio']}, torque at i_max = {n['i_max']} A: {n['max_torque']:.4g} "
                        f"({_margin_text(n['margin'])}), motor speed at the required speed {n['motor_speed']:.4g} "
                        f"rad/s of at most {n['w_m_max']} -- {'ok' if n['feasible'] else 'TOO FAST: a bigger motor'}")
        if n.get("effort") is not None:
            cap = n["stall"] if n["kind"] == "hydraulic" else n["max_torque"]
            head.append(f"#   the robot file's effort limit {n['effort']:.4g}: the proposal gives {cap / n['effort']:.2f}x it"
                        + (" (lower alpha_ref or the margin to stay within it)" if cap > n["effort"] else ""))
        lines = head + ["# Units: as in default.toml (SI).", ""]
        for fam, vals in s.items():
            lines.append(f"[{fam}]")
            lines += [f"{k} = {float(v)!r}" for k, v in vals.items()]
            lines.append("")
        p = directory / f"joint{n['joint']}.toml"
        p.write_text("\n".join(lines))
        paths.append(p)
    return paths


# -- command line: fmugen size ------------------------------------------------------------------
def add_parser(sub) -> None:
    p = sub.add_parser("size", help="propose an actuator parameter set per joint of an arm (hydraulic or electric)")
    p.add_argument("robot", help="robot file (TOML or URDF)")
    p.add_argument("--kind", default="hydraulic", choices=("hydraulic", "electric"))
    p.add_argument("--trajectory", help="CSV with a header: time, q[1], ..., q[n] (the motion to serve)")
    p.add_argument("--grid", type=int, default=5, help="poses per joint for the worst gravity torque (default 5)")
    p.add_argument("--speed", type=float, default=1.0, help="required joint speed without a trajectory [rad/s]")
    p.add_argument("--margin", type=float, default=None, help="torque margin (default 2 hydraulic, 1.5 electric)")
    p.add_argument("--alpha", type=float, default=100.0,
                   help="joint acceleration the actuator must give the worst inertia [rad/s^2] (default 100)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="a value of a parameter of the robot file (repeatable; its symbolic ones need one), e.g. m=1.5")
    p.add_argument("--out", required=True, help="folder for joint<k>.toml")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..arguments import output_folder

    output_folder(args.out, "--out", inputs=[args.robot, args.trajectory])  # before any work
    traj = None
    if args.trajectory:
        data = np.genfromtxt(args.trajectory, delimiter=",", names=True)
        if data.dtype.names is None or len(data.dtype.names) < 2:
            raise FmugenError(f"{args.trajectory}: expected a CSV with a header time, q[1], ..., q[n]")
        cols = data.dtype.names
        traj = (np.asarray(data[cols[0]], dtype=float), np.column_stack([data[c] for c in cols[1:]]))
        if not (np.all(np.isfinite(traj[0])) and np.all(np.isfinite(traj[1]))):  # genfromtxt reads junk as nan
            raise FmugenError(f"{args.trajectory}: every cell must be a finite number (a cell is empty or not a "
                              f"number)")
    # --margin 0 is refused, not replaced by the default (``args.margin or 2.0`` did that silently)
    margin = args.margin if args.margin is not None else (2.0 if args.kind == "hydraulic" else 1.5)
    if not 1 <= args.grid <= 50 or not all(math.isfinite(x) and x > 0 for x in (args.speed, args.alpha, margin)):
        raise FmugenError("size: --grid must be 1..50; --speed, --alpha and --margin positive numbers")
    from ..scene import parse_sets

    needs = requirements(args.robot, trajectory=traj, n_grid=args.grid, speed=args.speed,
                         params=parse_sets(args.set))
    if args.kind == "hydraulic":
        sets = hydraulic_sets(needs, margin=margin, alpha_ref=args.alpha)
    else:
        sets = electric_sets(needs, margin=margin, alpha_ref=args.alpha)
    paths = write_sets(sets, args.out, Path(args.robot).stem)
    for p in paths:
        print("\n".join(line for line in p.read_text().splitlines() if line.startswith("#   ")))
    print(f"wrote {', '.join(str(p) for p in paths)}")
    return 0
