"""The largest macro step at which held-input Jacobi is stable, from the FMUs' own linearisations.

Held-input Jacobi -- every FMU steps from the values at t_n, its inputs held
over the step -- is the loop of most FMI importers (libcosim's fixed-step
algorithm, FMPy's ``simulate_ssp``) and fmugen's ``jacobi``/``hold``: at step n
every FMU k is given v^n, steps [t_n, t_n + H] with it held, and its outputs
are read at t_n + H *with the inputs still at v^n*; those are v^{n+1}.

What is modelled.  Every instance is linearised on its own at the scene's
initial state (its states there, its inputs at their values at rest,
:attr:`Scene.rest_inputs`): x_i' = A_i x_i + B_i u_i, s_i = C_i x_i + D_i u_i,
where the signals s_i are the instance's states and outputs (a connection
reads either).  Connections inside an FMU group are instantaneous, as in the
group's assembled model (solved once: the scene has no algebraic loop), which
gives each FMU k as x_k' = A_k x_k + B_k v, s_k = C_k x_k + D_k v with v the
coupled values (one per connection between groups, v = W s, W the
connections' factors).  Writing Cv = W C, Dv = W D, one macro step is exactly

    x^{n+1} = Phi x^n + Gam B v^n,                   Phi_k = exp(A_k H), Gam_k = int_0^H exp(A_k s) ds
    v^{n+1} = Cv x^{n+1} + Dv v^n                    (outputs read after the step, inputs still v^n)

on the augmented state (x, v).  D -- direct feedthrough, e.g. a motor's
gear-spring torque c (phi_m/ratio - q) read by the arm depends on the arm's q
given to the motor FMU as an input -- is delayed by one macro step here, as
Jacobi delays it.  The earlier analysis (diagonal blocks of the monolithic
model's Jacobian, issue 29) took it as exact: 15.6 ms for the split
puma_electric, whose limit is 1.6 us (the wrist's gear spring), and no limit
at all for the split ur5_electric (69 us) and puma_geared_drive (1.3 ms);
where no output feeds through (the hydraulic scenes) both agree.  The exact flow of the same linearisation is
x' = (A + B (I - Dv)^-1 Cv) x (the monolithic model's Jacobian).  The scheme
is stable while the spectral radius of the step map is no larger than the
exact flow's, exp(A_exact H) (modes at rest -- a free joint angle -- stay at 1
in both); :func:`jacobi_hold_limit` scans H upwards by factors of 2 for the
first unstable step and bisects it to 1 %.  Model-Exchange groups are
integrated together by the master (their mutual couplings exact): they form
one block.

What it does not see: the linearisation holds near the initial state only.
The PUMA's inertia changes with its pose (puma_wrist_locked: 1.9 ms at rest,
2.3 ms at the end of its move), and a regularised kink is linear only far
inside its width: a smoothed Coulomb friction at zero speed is a large
damping that any motion leaves (puma_geared_drive: 1.33 ms at rest, 0.74 ms
along its move, and a 1 % move diverges at 0.9x the limit at rest); a
component with events is linearised in its initial mode.  The FMUs'
internal solvers are taken as exact; components of
an SSP beside the scene (``[external]``) have no model and are left out.  It
is a limit, not a promise of accuracy: stable steps can still be far off (see
``fmugen report``); ``examples/check_jacobi_limits.py`` runs every shipped
split scene just below and above its limit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import scipy.linalg as sl

#: relative margin on the spectral radius: round-off in expm, marginal modes at exactly 1
_MARGIN = 1e-7


@dataclass
class JacobiLinearisation:
    """The scene's FMUs linearised at its initial state, coupled by held-input Jacobi.

    ``states``: "inst.var" per row of ``A``; ``blocks``: state indices of each
    block (an FMU group, or all Model-Exchange groups together), named by
    ``block_names``; ``couplings``: "source -> target" per coupled value.
    x' = A x + B v, v = Cv x + Dv v (exact) or v^{n+1} = Cv x^{n+1} + Dv v^n (Jacobi/held).
    """

    states: list
    blocks: list
    block_names: list
    couplings: list
    A: np.ndarray
    B: np.ndarray
    Cv: np.ndarray
    Dv: np.ndarray
    _growth: Optional[float] = field(default=None, repr=False)  # max Re of the exact flow's eigenvalues

    def exact_jacobian(self) -> np.ndarray:
        """The coupled system's Jacobian (every coupling instantaneous): the monolithic model's."""
        nv = len(self.Dv)
        if not nv:
            return self.A.copy()
        return self.A + self.B @ np.linalg.solve(np.eye(nv) - self.Dv, self.Cv)

    def step_matrix(self, H: float) -> np.ndarray:
        """The held-input Jacobi macro-step matrix on (x, v)."""
        nx, nv = self.A.shape[0], self.B.shape[1]
        Phi = np.zeros((nx, nx))
        GB = np.zeros((nx, nv))
        for ix in self.blocks:
            m = len(ix)
            cols = np.nonzero(np.any(self.B[ix, :] != 0.0, axis=0))[0]
            # exp([[A_k, B_k], [0, 0]] H) = [[Phi_k, Gam_k B_k], [0, I]] in one call
            M = np.zeros((m + len(cols), m + len(cols)))
            M[:m, :m] = self.A[np.ix_(ix, ix)] * H
            M[:m, m:] = self.B[np.ix_(ix, cols)] * H
            E = sl.expm(M)
            Phi[np.ix_(ix, ix)] = E[:m, :m]
            GB[np.ix_(ix, cols)] = E[:m, m:]
        Z = np.zeros((nx + nv, nx + nv))
        Z[:nx, :nx], Z[:nx, nx:] = Phi, GB
        Z[nx:, :nx], Z[nx:, nx:] = self.Cv @ Phi, self.Cv @ GB + self.Dv
        return Z

    def spectral_radii(self, H: float) -> tuple:
        """(rho of the Jacobi step map, rho of the exact flow exp(A_exact H) = exp(H max Re lambda))."""
        if self._growth is None:
            ev = np.linalg.eigvals(self.exact_jacobian()) if len(self.A) else np.zeros(1)
            self._growth = float(np.max(ev.real))
        rho_j = float(max(abs(np.linalg.eigvals(self.step_matrix(H)))))
        return rho_j, math.exp(self._growth * H)

    def stable(self, H: float) -> bool:
        rho_j, rho_x = self.spectral_radii(H)
        return math.isfinite(rho_j) and rho_j <= max(1.0, rho_x) * (1 + _MARGIN)


def _block_of(scene) -> dict:
    """instance -> block name: its FMU group, "Model-Exchange" for every ME group's members."""
    out = {}
    for g in scene.groups.values():
        for inst in g.members:
            out[inst] = "Model-Exchange" if g.fmi_type == "me" else g.name
    return out


def linearise_split(scene, values: Optional[dict] = None, t: Optional[float] = None) -> JacobiLinearisation:
    """The scene's FMU groups linearised separately (see the module's docstring): at its initial state, or
    at the states ``values`` ("inst.var" -> value, e.g. a point of a run) and time ``t``, the connected
    inputs there taken from their sources."""
    from ..codegen.evaluate import ModelEvaluator

    t0 = scene.spec.start if t is None else float(t)
    if values is None:
        x0, rest = scene.initial.values, scene.rest_inputs
    else:
        x0 = dict(values)
        rest = scene.input_values(x0, t0)
    block = _block_of(scene)
    insts = list(scene.spec.instances)
    xo, uo, so = {}, {}, {}  # offsets of each instance's states, inputs, signals
    sig = {}  # (inst, var) -> signal index
    states = []
    parts = []
    nx = nu = ns = 0
    for inst in insts:
        m = scene.base_models[inst]
        x = np.array([x0.get(f"{inst}.{v.name}", v.start if v.start is not None else 0.0) for v in m.states],
                     dtype=float)
        u = np.array([rest.get(f"{inst}.{v.name}", v.start if v.start is not None else 0.0) for v in m.inputs],
                     dtype=float)
        if m.nx or m.ny:
            A, B, C, D = (np.asarray(M, dtype=float) for M in ModelEvaluator(m).jacobians(t0, x, u))
        else:
            A = B = C = D = None
        parts.append((m, A, B, C, D))
        xo[inst], uo[inst], so[inst] = nx, nu, ns
        for k, v in enumerate(m.states):
            sig[(inst, v.name)] = ns + k
            states.append(f"{inst}.{v.name}")
        for k, v in enumerate(m.outputs):
            sig[(inst, v.name)] = ns + m.nx + k
        nx, nu, ns = nx + m.nx, nu + m.nu, ns + m.nx + m.ny
    A, B = np.zeros((nx, nx)), np.zeros((nx, nu))
    C, D = np.zeros((ns, nx)), np.zeros((ns, nu))  # signals: every instance's states, then its outputs
    for inst, (m, Ai, Bi, Ci, Di) in zip(insts, parts):
        i, j, s = xo[inst], uo[inst], so[inst]
        C[s:s + m.nx, i:i + m.nx] = np.eye(m.nx)
        if Ai is None:
            continue
        A[i:i + m.nx, i:i + m.nx] = Ai
        B[i:i + m.nx, j:j + m.nu] = Bi
        C[s + m.nx:s + m.nx + m.ny, i:i + m.nx] = Ci
        D[s + m.nx:s + m.nx + m.ny, j:j + m.nu] = Di
    inputs = {(inst, v.name): uo[inst] + k for inst in insts for k, v in enumerate(scene.base_models[inst].inputs)}
    L_in = np.zeros((nu, ns))  # connections inside a block: instantaneous
    E_rows, W_rows, labels = [], [], []  # connections between blocks: the coupled values v
    for si, sv, ti, tv, f in scene.connections:
        factor = 1.0 if f is None else float(f)
        if block[si] == block[ti]:
            L_in[inputs[(ti, tv)], sig[(si, sv)]] = factor
        else:
            E_rows.append(inputs[(ti, tv)])
            W_rows.append((sig[(si, sv)], factor))
            labels.append(f"{si}.{sv} -> {ti}.{tv}")
    nv = len(labels)
    E = np.zeros((nu, nv))
    W = np.zeros((nv, ns))
    for k, (r, (c, factor)) in enumerate(zip(E_rows, W_rows)):
        E[r, k] = 1.0
        W[k, c] = factor
    # inside a block: u = L_in (C x + D u) + E v  ->  u = Mi (L_in C x + E v)  (L_in D nilpotent: no loop)
    Mi = np.linalg.inv(np.eye(nu) - L_in @ D) if nu else np.zeros((0, 0))
    Ku_x, Ku_v = Mi @ L_in @ C, Mi @ E
    Ag = A + B @ Ku_x
    Bg = B @ Ku_v
    Cv = W @ (C + D @ Ku_x)
    Dv = W @ (D @ Ku_v)
    names = list(dict.fromkeys(block[i] for i in insts))
    blocks = []
    for name in names:
        ix = [xo[inst] + k for inst in insts if block[inst] == name for k in range(scene.base_models[inst].nx)]
        blocks.append(np.array(ix, dtype=int))
    keep = [k for k, ix in enumerate(blocks) if len(ix)]
    # the blocks do not touch but through v (a coupling inside Ag between blocks would be a bug here)
    mask = np.zeros((nx, nx), dtype=bool)
    for ix in blocks:
        mask[np.ix_(ix, ix)] = True
    if nx and np.any(Ag[~mask] != 0.0):
        raise ValueError("held-input Jacobi analysis: FMU blocks coupled other than through their inputs")
    return JacobiLinearisation(states, [blocks[k] for k in keep], [names[k] for k in keep], labels,
                               Ag, Bg, Cv, Dv)


def jacobi_map(lin: JacobiLinearisation, H: float) -> np.ndarray:
    """The held-input Jacobi macro-step matrix of ``lin`` on (states, coupled values)."""
    return lin.step_matrix(H)


def jacobi_hold_limit(scene, h_max: Optional[float] = None, rel: float = 0.01,
                      lin: Optional[JacobiLinearisation] = None) -> float:
    """First unstable macro step of held-input Jacobi on ``scene`` [s] (``math.inf``: stable up to
    ``h_max``, default the run's length; one group: ``inf``; unstable from 2^-20 x the scene's step
    on: 0.0).  Upwards from there by factors of 2, then bisected to ``rel``."""
    if len(scene.groups) < 2:
        return math.inf
    lin = linearise_split(scene) if lin is None else lin
    if not lin.states or not lin.couplings:  # (an FMU without states still delays what feeds through it)
        return math.inf
    h_max = float(h_max or (scene.spec.stop - scene.spec.start))
    H = min(scene.spec.step, h_max) * 2.0 ** -20
    if not lin.stable(H):
        return 0.0
    lo = H
    while True:
        H = 2 * lo
        if H > h_max:
            return math.inf
        if not lin.stable(H):
            hi = H
            break
        lo = H
    while hi - lo > rel * lo:
        mid = 0.5 * (lo + hi)
        if lin.stable(mid):
            lo = mid
        else:
            hi = mid
    return hi


def stable_step(limit: float, step: float, safety: float = 0.5) -> float:
    """``step`` if it is below ``safety`` x ``limit``, else the largest 1-2-5 x 10^k step below that
    (so that an importer's integer clock -- libcosim counts nanoseconds -- holds it exactly)."""
    if not math.isfinite(limit) or not limit > 0 or step <= safety * limit:  # 0: no stable step at all
        return step
    target = safety * limit
    e = math.floor(math.log10(target))
    for mant in (5, 2, 1):
        h = mant * 10.0 ** e
        if h <= target:
            return float(f"{h:.1e}")
    return float(f"{10.0 ** (e - 1) * 5:.1e}")
