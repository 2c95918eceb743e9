"""Model-Exchange units: the master integrates them together (one Radau solve over all ME states, couplings
between ME units exact at every evaluation) and mixes them with Co-Simulation units."""
from dataclasses import replace

import numpy as np
import pytest

from cosim_rigs import reference_problem, split_system
from fmugen.cosim import Master, run, solve_reference


pytestmark = pytest.mark.usefixtures("private_reference_cache")


def _me(unit):
    return replace(unit, fmi_type="me", start_values={k: v for k, v in unit.start_values.items()
                                                      if not k.startswith("solver.")})


@pytest.fixture(scope="module")
def ref():
    return solve_reference(reference_problem("stiff", "smooth", 1.0), times=np.linspace(0.0, 1.0, 1001))


def _err(r, ref):
    idx = np.rint(r.time / 1e-3).astype(int)
    on = np.abs(r.time - idx * 1e-3) < 1e-9
    return float(np.max(np.abs(r["joint.theta"][on] - ref["joint.theta"][idx[on]])))


def test_all_me_system_is_the_monolithic_solution_at_any_macro_step(ref):
    s = split_system("stiff", "smooth", stop=1.0)
    allme = replace(s, units=tuple(_me(u) for u in s.units))
    # 50 ms is 9x the Gauss-Seidel/held limit of the CS split; inside one ME block the coupling is exact
    for scheme in ("jacobi", "gauss-seidel"):
        r = run(allme, scheme, "hold", step=0.05)
        assert r.ok, r.summary
        assert _err(r, ref) < 1e-8


def test_block_jacobian_from_directional_derivatives_equals_finite_differences():
    s = split_system("stiff", "smooth", stop=1.0)
    allme = replace(s, units=tuple(_me(u) for u in s.units))
    with Master(allme, "jacobi", "hold") as m:
        r = m.run(step=0.01, stop=0.3)  # mid-motion
        assert r.ok
        blk = m.me_block
        x = blk._current_x()
        t = float(r.time[-1])
        J = blk.jac(t, x)
        f0 = blk.rhs(t, x)
        Jfd = np.empty_like(J)
        for i in range(len(x)):
            h = 1e-7 * max(abs(x[i]), blk.nominal[i])
            xp = x.copy()
            xp[i] += h
            xm = x.copy()
            xm[i] -= h
            Jfd[:, i] = (blk.rhs(t, xp) - blk.rhs(t, xm)) / (2 * h)
        assert np.all(np.isfinite(f0))
        # both FMUs' blocks and the cross terms joint <-> chain through the couplings
        scale = np.maximum(np.abs(Jfd), np.abs(J)).max(axis=1, keepdims=True) + 1e-300
        assert np.max(np.abs(J - Jfd) / scale) < 1e-5
        assert np.count_nonzero(J) > 0 and J.shape == (6, 6)


def test_mixed_cs_and_me(ref):
    s = split_system("stiff", "smooth", stop=1.0)
    mixed = replace(s, units=(s.units[0], _me(s.units[1])))  # chain CS, joint ME
    gs = run(mixed, "gauss-seidel", "linear", step=1e-3)
    assert gs.ok and _err(gs, ref) < 1e-6
    nw = run(mixed, "newton", "linear", step=1e-2)
    assert nw.ok and nw.summary.jacobians >= 1
    assert _err(nw, ref) < 5e-5
