"""Stability limits of the non-iterative schemes on the split rigs, and divergence detection.

Two independent sources for the first unstable macro step H*: the shared
note's figures (LIMITS) and the spectral radius of the exact macro-step map of
the linearised split (each part advanced by its matrix exponential with held
or linearly extrapolated inputs; built here from the models' exact Jacobians,
not from the master).  The master must be stable at 0.8 H* and at 1.25 H* end
with a divergence report naming the coupling, before any value overflows.
"""
import numpy as np
import pytest
import scipy.linalg as sl

from cosim_rigs import LIMITS, _components, split_system
from fmugen.components import assemble, joint_inertia
from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.cosim import run

CASES = [(ps, sch, ex) for ps in ("default", "stiff") for (sch, ex) in LIMITS[ps]]


def _linear_parts(ps):
    comps, links = _components(ps, "step", False)
    chain = assemble("chain", comps, links, outputs=["actuator.tau"])
    Ac, Bc, Cc, _ = ModelEvaluator(chain).jacobians(0.0)
    ins = [v.name for v in chain.inputs]
    Bc = Bc[:, [ins.index("amp.theta"), ins.index("actuator.w")]]
    Aj, Bj, _, _ = ModelEvaluator(joint_inertia(parameter_set=ps, name="joint")).jacobians(0.0)
    return Ac, Bc, Cc, Aj, Bj[:, :1]  # joint states (theta, w) are its outputs


def _discrete(A, B, H):
    """x+ = Phi x + G0 u_n + G1 (u_n - u_{n-1}) for u(t_n + sH) = u_n + s (u_n - u_{n-1})."""
    n, m = B.shape
    M = np.zeros((n + 2 * m, n + 2 * m))
    M[:n, :n], M[:n, n:n + m], M[n:n + m, n + m:] = A * H, B * H, np.eye(m)
    E = sl.expm(M)
    return E[:n, :n], E[:n, n:n + m], E[:n, n + m:]


def spectral_radius(ps, scheme, extrapolation, H):
    Ac, Bc, Cc, Aj, Bj = _linear_parts(ps)
    nc, nj = len(Ac), len(Aj)
    Pc, G0c, G1c = _discrete(Ac, Bc, H)
    Pj, G0j, G1j = _discrete(Aj, Bj, H)
    if (scheme, extrapolation) == ("jacobi", "hold"):
        Z = np.block([[Pc, G0c], [G0j @ Cc, Pj]])
    elif (scheme, extrapolation) == ("jacobi", "linear"):
        n = nc + nj
        Z = np.zeros((2 * n, 2 * n))
        Z[:nc, :nc], Z[:nc, nc:n], Z[:nc, n + nc:] = Pc, G0c + G1c, -G1c
        Z[nc:n, nc:n], Z[nc:n, :nc], Z[nc:n, n:n + nc] = Pj, (G0j + G1j) @ Cc, -G1j @ Cc
        Z[n:, :n] = np.eye(n)
    else:  # Gauss-Seidel, joint first with tau_n held, then the chain with theta, w at t_{n+1} held
        Zj = np.hstack([G0j @ Cc, Pj])
        Z = np.vstack([np.hstack([Pc, np.zeros((nc, nj))]) + G0c @ Zj, Zj])
    return max(abs(np.linalg.eigvals(Z)))


@pytest.mark.parametrize("ps,scheme,ext", CASES)
def test_linear_analysis_brackets_the_notes_limit(ps, scheme, ext):
    H = LIMITS[ps][(scheme, ext)]
    assert spectral_radius(ps, scheme, ext, 0.8 * H) < 1.0
    assert spectral_radius(ps, scheme, ext, 1.25 * H) > 1.0
    # the note's figure is the crossing to within 4 %
    assert spectral_radius(ps, scheme, ext, 0.96 * H) < 1.0 < spectral_radius(ps, scheme, ext, 1.04 * H)


@pytest.mark.parametrize("ps,scheme,ext", CASES)
def test_stable_below_and_divergence_reported_above(ps, scheme, ext):
    H = LIMITS[ps][(scheme, ext)]
    stable = run(split_system(ps, stop=5.0), scheme, ext, step=0.8 * H)
    assert stable.ok, stable.summary
    theta = stable["joint.theta"]
    # the position loop settled on the 0.1 rad step (the reference value)
    assert abs(theta[-1] - 0.1) < 1e-3
    assert np.max(np.abs(theta[-len(theta) // 5:] - 0.1)) < 1e-3

    unstable = run(split_system(ps, stop=5.0), scheme, ext, step=1.25 * H)
    s = unstable.summary
    assert s.status == "failed" and s.failure.cause == "diverged", s
    assert s.failure.coupling in ("chain.actuator.tau -> joint.tau", "joint.theta -> chain.amp.theta",
                                  "joint.w -> chain.actuator.w")
    assert "stability limit" in s.failure.message
    # stopped before overflow, results up to the failure returned and finite
    assert s.failure.time < 5.0
    assert len(unstable.time) == s.macro_steps + 1 and np.all(np.isfinite(unstable.values))
    assert np.max(np.abs(unstable["joint.theta"])) < 10.0
