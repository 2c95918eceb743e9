"""Sizing of per-joint hydraulic parameter sets for the thesis PUMA.

Data: McGalliard (1984) section III.E.7.a (robots/puma_thesis.toml): standard
DH, masses m = [33.5, 77.3, 36.3, 8.95, 2.39, 1.00] kg, a2 = 0.432 m,
d3 = 0.125 m, a3 = 0.019 m, d4 = 0.432 m, centres of mass in the link frames.

Rule (written into every generated file's header):

1. tau_g[j] -- worst static gravity torque about joint j: the largest
   |(sum_{k>=j} m_k (c_k - o_{j-1}) x g) . z_{j-1}| over a pose grid of
   q2..q5 (9 values each over a full turn, 45 deg apart; q1, q6 do not change it).
2. J[j] -- worst inertia about axis j: sum_{k>=j} m_k (d_k^2 + rho^2) over
   the same grid, d_k the distance of c_k from the axis, rho = 0.1 m an
   allowance for each link's own extent (at least 0.01 kg.m2).
3. Stall torque T = max(2 tau_g, J alpha_ref), alpha_ref = 100 rad/s^2 (the
   default set's 210 N.m / 2 kg.m2); D_m = T/P_s rounded up to 2 digits.
4. With f = D_m/D_m(default): Q_N, V_t, K_c0, C_tm, C_im scale with f (same
   no-load speed, the same K_a gives K_v = 10 1/s, same leakage per
   displacement); B_m scales with J/J(default) (same B_m/J).  Everything
   else is the default set.
"""
from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np

from .parameters import DATA_DIR, load_parameter_set

MASS = np.array([33.5, 77.3, 36.3, 8.95, 2.39, 1.00])
COM = np.array([[0, 0, 0.08], [-0.216, 0, 0.2175], [0, 0, 0.216], [0, 0.02, 0], [0, 0, 0], [0, 0, 0.01]])
DH_A = np.array([0, 0.432, 0.019, 0, 0, 0])
DH_D = np.array([0, 0, 0.125, 0.432, 0, 0])
DH_ALPHA = np.radians([-90, 0, 90, -90, 90, 0])
G = 9.81
ALPHA_REF = 100.0  # rad/s^2
RHO = 0.1  # m


def _frames(q):
    """Origins o_i and z axes z_i (i = 0..6) of the standard-DH frames."""
    T = np.eye(4)
    o, z, Ts = [T[:3, 3].copy()], [T[:3, 2].copy()], []
    for i in range(6):
        ct, st, ca, sa = math.cos(q[i]), math.sin(q[i]), math.cos(DH_ALPHA[i]), math.sin(DH_ALPHA[i])
        A = np.array([[ct, -st * ca, st * sa, DH_A[i] * ct], [st, ct * ca, -ct * sa, DH_A[i] * st],
                      [0, sa, ca, DH_D[i]], [0, 0, 0, 1]])
        T = T @ A
        Ts.append(T)
        o.append(T[:3, 3].copy())
        z.append(T[:3, 2].copy())
    coms = [Ts[k][:3, :3] @ COM[k] + Ts[k][:3, 3] for k in range(6)]
    return o, z, coms


def worst_case(n_grid: int = 9):
    """(tau_g[6], J[6]) maxima over the pose grid (see module docstring)."""
    grid = np.linspace(-math.pi, math.pi, n_grid)
    tau = np.zeros(6)
    J = np.zeros(6)
    g = np.array([0, 0, -G])
    for q2, q3, q4, q5 in itertools.product(grid, grid, grid, grid):
        o, z, c = _frames([0, q2, q3, q4, q5, 0])
        for j in range(6):
            t, jj = 0.0, 0.0
            for k in range(j, 6):
                r = c[k] - o[j]
                t += np.dot(np.cross(r, MASS[k] * g), z[j])
                d2 = np.dot(r, r) - np.dot(r, z[j]) ** 2
                jj += MASS[k] * (d2 + RHO**2)
            tau[j] = max(tau[j], abs(t))
            J[j] = max(J[j], jj)
    return tau, np.maximum(J, 0.01)


def _round_up(x, digits=2):
    e = math.floor(math.log10(x)) - digits + 1
    return math.ceil(x / 10**e) * 10**e


def puma_sets(n_grid: int = 9) -> list:
    """The six per-joint sets as dicts {family: {name: value}} plus a notes dict."""
    base = load_parameter_set("default").sections
    tau, J = worst_case(n_grid)
    P_s = base["servo_valve"]["P_s"]
    out = []
    for j in range(6):
        T = max(2 * tau[j], J[j] * ALPHA_REF)
        D_m = _round_up(T / P_s)
        f = D_m / base["hydraulic_actuator"]["D_m"]
        Jr = round(float(J[j]), 4)
        s = {fam: dict(vals) for fam, vals in base.items()}
        s["servo_valve"]["Q_N"] *= f
        s["servo_valve"]["K_c0"] *= f
        for k in ("V_t", "C_tm", "C_im"):
            s["hydraulic_actuator"][k] *= f
        s["hydraulic_actuator"]["D_m"] = D_m
        s["joint_inertia"]["J"] = Jr
        s["joint_inertia"]["B_m"] = base["joint_inertia"]["B_m"] * Jr / base["joint_inertia"]["J"]
        ha, sv = s["hydraulic_actuator"], s["servo_valve"]
        w_h = math.sqrt(4 * ha["beta_e"] * D_m**2 / (ha["V_t"] * Jr))
        K_ce = sv["K_c0"] + ha["C_tm"]
        z_h = K_ce / D_m * math.sqrt(ha["beta_e"] * Jr / ha["V_t"]) \
            + s["joint_inertia"]["B_m"] / (4 * D_m) * math.sqrt(ha["V_t"] / (ha["beta_e"] * Jr))
        K_q0 = sv["Q_N"] * math.sqrt(P_s / sv["dp_N"])
        K_v = s["amplifier"]["K_a"] * s["current_driver"]["G_i"] * K_q0 / sv["i_rated"] / D_m
        notes = dict(joint=j + 1, tau_g=float(tau[j]), J=Jr, stall=P_s * D_m, D_m=D_m, f=f,
                     omega_h=w_h, zeta_h=z_h, K_v=K_v, margin=P_s * D_m / tau[j] if tau[j] > 1e-9 else math.inf)
        out.append((s, notes))
    return out


def write_puma_sets(directory: Path = DATA_DIR, n_grid: int = 9) -> list:
    """Write puma_joint1.toml ... puma_joint6.toml; returns the paths."""
    paths = []
    for s, n in puma_sets(n_grid):
        lines = [
            f"# Parameter set \"puma_joint{n['joint']}\": hydraulic actuator for joint {n['joint']} of the thesis PUMA.",
            "# Generated by fmugen.components.sizing.write_puma_sets() -- edit the rule there, not this file.",
            "#",
            "# Sizing rule (McGalliard 1984 masses/COMs/DH, robots/puma_thesis.toml):",
            "#   tau_g = worst static gravity torque about this joint over a 9^4 grid of q2..q5 (45 deg apart),",
            "#   J     = worst sum m_k (d_k^2 + (0.1 m)^2) over the same grid (>= 0.01 kg.m2),",
            "#   stall torque P_s D_m >= max(2 tau_g, J * 100 rad/s^2), D_m rounded up to 2 digits,",
            "#   Q_N, V_t, K_c0, C_tm, C_im scaled by f = D_m/D_m(default); B_m by J/J(default).",
            f"#   tau_g = {n['tau_g']:.1f} N.m, J = {n['J']:.4f} kg.m2, stall torque = {n['stall']:.1f} N.m"
            f" (margin {n['margin']:.2f}x gravity), f = {n['f']:.4g}",
            f"#   omega_h = {n['omega_h']:.1f} rad/s, zeta_h = {n['zeta_h']:.3f}, K_v = {n['K_v']:.3f} 1/s"
            f" (P loop needs K_v < 2 zeta_h omega_h = {2 * n['zeta_h'] * n['omega_h']:.2f})",
            "# Units: as in default.toml (SI).",
            "",
        ]
        for fam, vals in s.items():
            lines.append(f"[{fam}]")
            for k, v in vals.items():
                lines.append(f"{k} = {v!r}")
            lines.append("")
        p = Path(directory) / f"puma_joint{n['joint']}.toml"
        p.write_text("\n".join(lines))
        paths.append(p)
    return paths


if __name__ == "__main__":
    for s, n in puma_sets():
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in n.items()})
