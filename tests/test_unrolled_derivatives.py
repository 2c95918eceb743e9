"""The per-robot unrolled Jacobians of the forward and inverse dynamics (fmugen.codegen.unrolled_derivatives)
against Pinocchio's ``computeABADerivatives`` and ``computeRNEADerivatives`` -- a chain (UR5), prismatic
joints (Panda's fingers), a tree (HyQ) -- against the looped runtime where Pinocchio has no model (rotor
inertia, damping, smooth Coulomb friction), the folding evaluation against the compiled code, and the
statuses of a mass matrix that is not positive definite."""
from __future__ import annotations

import numpy as np
import pytest

from erd_robots import rel, robot
from fmugen.codegen.unrolled_derivatives import (CompiledUnrolledJacobian, evaluate_numeric, from_kernels,
                                                 unrolled_jacobian)


def _sym(upper):
    return np.triu(upper) + np.triu(upper, 1).T


@pytest.mark.parametrize("name", ["ur5", "panda", "hyq"])
def test_equals_pinocchio(name):
    from fmugen.codegen.benchmarks import to_pinocchio

    pin, _, kernels, model, mp = robot(name)
    data = model.createData()
    iv = [m[1] for m in mp]
    ix = np.ix_(iv, iv)
    n = kernels.n
    fd, idj = CompiledUnrolledJacobian(from_kernels(kernels, "fd")), CompiledUnrolledJacobian(from_kernels(kernels, "id"))
    try:
        rng = np.random.default_rng(4)
        q, qd, x = rng.uniform(-1, 1, (3, n)), rng.uniform(-1, 1, (3, n)), rng.uniform(-3, 3, (3, n))
        gf, gi = fd.derivatives(q, qd, x), idj.derivatives(q, qd, x)
        for k in range(3):
            qp, vp = to_pinocchio(model, mp, q[k], qd[k])
            xp = to_pinocchio(model, mp, None, x[k])
            pin.computeABADerivatives(model, data, qp, vp, xp)
            for got, ref in zip(gf, (data.ddq[iv], data.ddq_dq[ix], data.ddq_dv[ix], _sym(data.Minv)[ix])):
                assert rel(got[k], ref) < 1e-9
            pin.computeRNEADerivatives(model, data, qp, vp, xp)
            for got, ref in zip(gi, (data.tau[iv], data.dtau_dq[ix], data.dtau_dv[ix], _sym(data.M)[ix])):
                assert rel(got[k], ref) < 1e-9
        # the same passes on numbers (no compiler) give the compiled code's result
        qdd, J = evaluate_numeric(kernels.revolute, kernels.parents, kernels.constants, kernels.globals[:3],
                                  q[0], qd[0], x[0])
        assert rel(qdd, gf[0][0]) < 1e-12 and rel(J, np.hstack([b[0] for b in gf[1:]])) < 1e-12
    finally:
        fd.close()
        idj.close()
        kernels.close()


def test_rotor_damping_friction_equal_the_runtime():
    """Rotor inertia, viscous damping and smooth Coulomb friction, which Pinocchio has not, against the
    looped runtime's fmugen_chain_fd_jacobian and fmugen_chain_id_jacobian on the same numbers (HyQ: a tree)."""
    from fmugen.batch import Kernels

    _, _, kernels, _, _ = robot("hyq")
    n = kernels.n
    lc = np.array(kernels.constants, float).reshape(n, -1)
    rng = np.random.default_rng(5)
    lc[:, 25] = rng.uniform(0.0, 0.3, n)  # rotor inertia
    lc[:, 26] = rng.uniform(0.0, 2.0, n)  # damping
    lc[::2, 27] = 1.5  # Coulomb level on every other joint
    lc[:, 28] = 0.05
    k2 = Kernels(kernels.revolute, kernels.parents, lc, kernels.globals[:3])
    compiled = {kind: CompiledUnrolledJacobian(unrolled_jacobian(k2.revolute, k2.parents, lc, kernels.globals[:3],
                                                                 kind)) for kind in ("fd", "id")}
    try:
        q, qd, x = rng.uniform(-1, 1, (4, n)), rng.uniform(-1, 1, (4, n)), rng.uniform(-3, 3, (4, n))
        for kind, ref in (("fd", k2.fd_derivatives(q, qd, x)), ("id", k2.id_derivatives(q, qd, x))):
            got = compiled[kind].derivatives(q, qd, x)
            for g, r in zip(got, ref):
                assert rel(g, r) < 1e-9, kind
    finally:
        for c in compiled.values():
            c.close()
        k2.close()
        kernels.close()


def test_not_positive_definite_and_refusals():
    """A state the dynamics cannot answer (NaN: the first positivity check fails) is reported as status 1
    (LinAlgError) with no result; a nonsense kind is refused."""
    lc = np.zeros((2, 29))
    for i in range(2):
        lc[i, [0, 4, 8]] = 1.0  # placements: identity rotations
        lc[i, 14] = 1.0  # joint axes z
        lc[i, 15] = 1.0  # 1 kg
        lc[i, 19:22] = 0.1  # inertia about the COM
    lc[1, 9] = 0.5  # the second joint 0.5 m along x
    lc[1, 16] = 0.3  # its COM off the axis
    ok = CompiledUnrolledJacobian(unrolled_jacobian([True, True], [-1, 0], lc, [0, 0, -9.81]))
    try:
        qdd, dq, dqd, minv = ok.derivatives(np.zeros(2), np.zeros(2), np.zeros(2))
        assert np.all(np.isfinite(dq)) and np.allclose(minv, minv.T)
        with pytest.raises(np.linalg.LinAlgError):  # a NaN state: the first check fails, nothing returned
            ok.derivatives(np.array([np.nan, 0.0]), np.zeros(2), np.zeros(2))
    finally:
        ok.close()
    with pytest.raises(ValueError, match="kind"):
        unrolled_jacobian([True], [-1], lc[:1], [0, 0, -9.81], kind="ddq")
