"""Looped dynamics of kinematic trees (issue 20): c_runtime/chain_dynamics.c against Pinocchio.

A random tree is built with Pinocchio directly (``pin.Model.addJoint``: placements with
arbitrary rotations, revolute and prismatic joints about unaligned axes, several branches,
bodies numbered depth first as a URDF parser numbers them) and handed to the runtime's loops
as the general joint model (:func:`fmugen.codegen.chain.tree_constants`); forward dynamics,
end-effector position, and the exact Jacobian are compared with ``aba``,
``computeABADerivatives`` and the frame Jacobian.  External wrenches, which Pinocchio's
derivatives take as fixed in the body frame (fmugen's are fixed in the base frame), are checked
against ``aba`` with the same forces and against central differences.  DH chains (the special
case) are covered by tests/test_large_models.py.
"""
import numpy as np
import pytest

from fmugen.codegen.chain import NC, evaluate_chain, tree_constants

pin = pytest.importorskip("pinocchio")

RTOL = 1e-10


def rel(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(b))


def random_tree(n, seed):
    """(pinocchio model, revolute flags, parents, body constants as dicts)."""
    rng = np.random.default_rng(seed)
    model = pin.Model()
    revolute, parents, bodies = [], [], []
    path = []  # the bodies from the root to the last one: a depth-first numbering
    for i in range(n):
        par = -1 if i == 0 else path[int(rng.integers(0, len(path)))]
        if par >= 0:
            del path[path.index(par) + 1:]
        path.append(i)
        R = pin.utils.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        p = rng.uniform(-0.5, 0.5, 3)
        axis = np.array([0.0, 0.0, 1.0]) if i % 4 == 0 else rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        rev = i % 3 != 2
        joint = pin.JointModelRevoluteUnaligned(axis) if rev else pin.JointModelPrismaticUnaligned(axis)
        jid = model.addJoint(par + 1, joint, pin.SE3(R, p), f"j{i}")
        mass, com = rng.uniform(0.5, 3.0), rng.uniform(-0.2, 0.2, 3)
        A = rng.normal(size=(3, 3))
        inertia = A @ A.T * 0.05 + np.eye(3) * 0.01
        model.appendBodyToJoint(jid, pin.Inertia(mass, com, inertia), pin.SE3.Identity())
        revolute.append(rev)
        parents.append(par)
        bodies.append(dict(R=R, p=p, axis=axis, mass=mass, com=com, inertia=inertia,
                           rotor_inertia=rng.uniform(0.0, 0.1), damping=rng.uniform(0.0, 0.5)))
    model.armature = np.array([b["rotor_inertia"] for b in bodies])
    return model, revolute, parents, bodies


def test_random_tree_equals_pinocchio_aba_and_its_derivatives():
    n, ee = 14, 11
    model, revolute, parents, bodies = random_tree(n, seed=3)
    assert len(set(parents)) > 3 and sum(not r for r in revolute) >= 4  # branches, prismatic joints
    g, ee_pos = np.array([0.3, -0.2, -9.81]), np.array([0.1, -0.2, 0.3])
    model.gravity.linear = g
    data = model.createData()
    lc = np.array([float(x) for x in tree_constants(bodies, g, ee_pos)], float)
    b = np.array([body["damping"] for body in bodies])
    rng = np.random.default_rng(7)
    for _ in range(3):
        q, qd, tau = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-10, 10, n)
        args = np.r_[q, qd, tau, lc]
        fd = evaluate_chain("fd", revolute, args, parent=parents, ee_body=ee)
        ref = pin.aba(model, data, q, qd, tau - b * qd)  # Pinocchio has no joint damping: b qd moved to tau
        assert rel(fd[:n], ref) < RTOL
        pin.forwardKinematics(model, data, q)
        assert np.max(np.abs(fd[n:] - data.oMi[ee + 1].act(ee_pos))) < 1e-12
        jac = evaluate_chain("jacobian", revolute, args, parent=parents, ee_body=ee)
        D = jac[n:n + 3 * n * n].reshape(n, 3 * n)
        pin.computeABADerivatives(model, data, q, qd, tau - b * qd)
        minv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
        assert rel(jac[:n], ref) < RTOL
        assert rel(D[:, :n], data.ddq_dq) < RTOL
        assert rel(D[:, n:2 * n], data.ddq_dv - minv * b[None, :]) < RTOL
        assert rel(D[:, 2 * n:], minv) < RTOL
        pin.computeJointJacobians(model, data, q)
        J = pin.getFrameJacobian(model, data, ee + 1, pin.SE3(np.eye(3), ee_pos), pin.LOCAL_WORLD_ALIGNED)
        assert np.max(np.abs(jac[n + 3 * n * n:].reshape(3, n) - J[:3])) < 1e-12


def test_random_tree_with_external_wrenches():
    n = 9
    model, revolute, parents, bodies = random_tree(n, seed=5)
    g = np.array([0.0, 0.0, -9.81])
    data = model.createData()
    lc = np.array([float(x) for x in tree_constants(bodies, g)], float)
    b = np.array([body["damping"] for body in bodies])
    rng = np.random.default_rng(2)
    q, qd, tau = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-10, 10, n)
    ext_bodies = [n - 1, 2, 4]
    ext = rng.uniform(-5, 5, (len(ext_bodies), 6))  # force at the COM, torque; base coordinates

    def fd(q_, qd_, tau_, ext_):
        return evaluate_chain("fd", revolute, np.r_[q_, qd_, tau_, lc, ext_.ravel()], ext_bodies,
                              parent=parents)[:n]

    pin.forwardKinematics(model, data, q)
    fext = [pin.Force.Zero() for _ in range(n + 1)]
    for k, e in zip(ext_bodies, ext):  # the same wrench in Pinocchio's joint frame
        oMi = data.oMi[k + 1]
        Rk, pk = oMi.rotation, oMi.translation
        c = pk + Rk @ model.inertias[k + 1].lever
        fext[k + 1] = pin.Force(Rk.T @ e[:3], Rk.T @ (e[3:] + np.cross(c - pk, e[:3])))
    assert rel(fd(q, qd, tau, ext), pin.aba(model, data, q, qd, tau - b * qd, fext)) < RTOL
    jac = evaluate_chain("jacobian", revolute, np.r_[q, qd, tau, lc, ext.ravel()], ext_bodies, parent=parents)
    ne = len(ext_bodies)
    D = jac[n:n + n * (3 * n + 6 * ne)].reshape(n, 3 * n + 6 * ne)
    h = 1e-6
    cols = []
    for which in range(4):  # central differences by q, qd, tau, ext
        base = [q, qd, tau, ext.ravel()]
        for j in range(base[which].size):
            up = [x.copy() for x in base]
            dn = [x.copy() for x in base]
            up[which][j] += h
            dn[which][j] -= h
            cols.append((fd(up[0], up[1], up[2], up[3]) - fd(dn[0], dn[1], dn[2], dn[3])) / (2 * h))
    assert rel(D, np.array(cols).T) < 1e-6


def test_parents_must_come_first():
    from fmugen.codegen.chain import ChainDynamics
    import sympy as sp

    with pytest.raises(ValueError, match="after its parent"):
        ChainDynamics(sp.zeros(0, 1), sp.zeros(0, 0), sp.zeros(0, 1), revolute=(True, True), parent=(1, -1))
    assert NC == 29


def test_tree_robot_through_the_generated_model():
    """A tree written in the general joint model (fmugen.robot.description.Body, with joint offsets and an
    end-effector frame) becomes a looped model whose generated C equals Pinocchio on the same numbers."""
    import sympy as sp

    from fmugen.codegen.c_code import generate_c
    from fmugen.codegen.c_harness import CompiledModel
    from fmugen.dynamics.manipulator import Manipulator
    from fmugen.robot.description import JOINTS, PRISMATIC, REVOLUTE, Body, Frame, Robot

    n = 8
    model, revolute, parents, bodies = random_tree(n, seed=11)
    rng = np.random.default_rng(4)
    offsets = rng.uniform(-0.5, 0.5, n)
    F = lambda v: tuple(sp.Float(float(x)) for x in v)  # noqa: E731
    FM = lambda M: tuple(F(row) for row in np.asarray(M))  # noqa: E731
    rbodies = tuple(Body(name=f"b{i}", joint=REVOLUTE if revolute[i] else PRISMATIC, parent=parents[i],
                         rotation=FM(b["R"]), translation=F(b["p"]), axis=F(b["axis"]), mass=sp.Float(b["mass"]),
                         com=F(b["com"]), inertia_com=FM(b["inertia"]), rotor_inertia=sp.Float(b["rotor_inertia"]),
                         damping=sp.Float(b["damping"]), offset=sp.Float(offsets[i]))
                    for i, b in enumerate(bodies))
    tool = np.array([0.05, 0.1, -0.2])
    robot = Robot(name="tree", convention=JOINTS, links=(), gravity=F([0, 0, -9.81]), bodies=rbodies,
                  frames=(Frame("tool", 5, FM(np.eye(3)), F(tool)),), end_frame="tool")
    m = Manipulator(robot).state_space_model(outputs=("p_ee",), strategy="loops")
    data = model.createData()
    b = np.array([body["damping"] for body in bodies])
    with CompiledModel.build(generate_c(m).source) as cm:
        p = np.array([v.start for v in m.parameters], float)
        for _ in range(2):
            q, qd, tau = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-10, 10, n)
            dx, y = cm.evaluate(p, 0.0, np.r_[q, qd], tau)
            qp = q + offsets  # Pinocchio's joints have no offset: the motion is by q + offset
            assert rel(dx[n:], pin.aba(model, data, qp, qd, tau - b * qd)) < RTOL  # and no damping
            pin.forwardKinematics(model, data, qp)
            assert np.max(np.abs(y[:3] - data.oMi[6].act(tool))) < 1e-12
            dfdx, dfdu, _, _ = cm.jacobian(p, 0.0, np.r_[q, qd], tau)
            pin.computeABADerivatives(model, data, qp, qd, tau - b * qd)
            minv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
            assert rel(dfdx[n:, :n], data.ddq_dq) < RTOL and rel(dfdx[n:, n:], data.ddq_dv - minv * b[None, :]) < RTOL
    # the inverse dynamics in the loops: tau and d tau / d(q, qd, qdd) against rnea and its derivatives
    idm = Manipulator(robot).inverse_dynamics_model(strategy="loops")
    with CompiledModel.build(generate_c(idm).source) as ci:
        q, qd, qdd = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-3, 3, n)
        _, tau = ci.evaluate([], 0.0, [], np.r_[q, qd, qdd])
        qp = q + offsets
        assert rel(tau, pin.rnea(model, data, qp, qd, qdd) + b * qd) < RTOL
        _, _, _, dgdu = ci.jacobian([], 0.0, [], np.r_[q, qd, qdd])
        pin.computeRNEADerivatives(model, data, qp, qd, qdd)
        M = np.triu(data.M) + np.triu(data.M, 1).T
        assert rel(dgdu, np.c_[data.dtau_dq, data.dtau_dv + np.diag(b), M]) < RTOL


def test_loops_equal_straight_line_code_on_a_tree_with_damping_and_friction():
    """Two derivations that share no code on what Pinocchio lacks: viscous damping and the smooth Coulomb
    friction F_c tanh(qd / v_c), on a 5-body tree; the parameters changed at run time."""
    import sympy as sp

    from fmugen.codegen.c_code import generate_c
    from fmugen.codegen.c_harness import CompiledModel
    from fmugen.dynamics.manipulator import Manipulator
    from fmugen.robot.description import JOINTS, PRISMATIC, REVOLUTE, Body, Parameter, Robot

    n = 5
    _, revolute, parents, bodies = random_tree(n, seed=21)
    fc = [sp.Symbol(f"fc{i}", real=True) for i in range(n)]
    vc = sp.Symbol("vc", real=True)
    F = lambda v: tuple(sp.Float(float(x)) for x in v)  # noqa: E731
    FM = lambda M: tuple(F(row) for row in np.asarray(M))  # noqa: E731
    rbodies = tuple(Body(name=f"b{i}", joint=REVOLUTE if revolute[i] else PRISMATIC, parent=parents[i],
                         rotation=FM(b["R"]), translation=F(b["p"]), axis=F(b["axis"]), mass=sp.Float(b["mass"]),
                         com=F(b["com"]), inertia_com=FM(b["inertia"]), rotor_inertia=sp.Float(b["rotor_inertia"]),
                         damping=sp.Float(b["damping"]), friction=fc[i], friction_velocity=vc)
                    for i, b in enumerate(bodies))
    params = tuple(Parameter(f"fc{i}", fc[i], 0.3 + 0.2 * i) for i in range(n)) + (Parameter("vc", vc, 0.5),)
    robot = Robot(name="tree", convention=JOINTS, links=(), gravity=F([0, 0, -9.81]), bodies=rbodies,
                  parameters=params, end_frame="b3")
    arm = Manipulator(robot)
    straight = arm.state_space_model(outputs=("p_ee", "qdd"), strategy="straight")
    looped = arm.state_space_model(outputs=("p_ee", "qdd"), strategy="loops")
    assert [v.name for v in looped.parameters] == [v.name for v in straight.parameters]
    rng = np.random.default_rng(8)
    with CompiledModel.build(generate_c(straight).source) as cs, CompiledModel.build(generate_c(looped).source) as cl:
        for k in range(3):
            p = np.array([v.start for v in looped.parameters]) * (rng.uniform(0.5, 1.5, len(params)) if k else 1)
            q, qd, tau = rng.uniform(-np.pi, np.pi, n), rng.uniform(-1, 1, n), rng.uniform(-10, 10, n)
            x = np.r_[q, qd]
            ref_dx, ref_y = cs.evaluate(p, 0.0, x, tau)
            dx, y = cl.evaluate(p, 0.0, x, tau)
            assert rel(dx, ref_dx) < RTOL and rel(y, ref_y) < RTOL
            for a, b in zip(cl.jacobian(p, 0.0, x, tau), cs.jacobian(p, 0.0, x, tau)):
                assert rel(a, b) < RTOL


@pytest.mark.parametrize("rel_path", ["allegro_hand_description/urdf/allegro_left_hand.urdf",
                                      "kinova_description/robots/kinova.urdf"])
def test_urdf_robots_through_the_loops_equal_pinocchio(rel_path):
    """fmugen's URDF reader -> the general joint model -> the runtime's loops (a 16-DoF hand: four fingers on
    a fixed palm; a chain with continuous joints), against Pinocchio's reading of the same file."""
    import importlib.metadata
    import warnings
    from pathlib import Path

    from fmugen.codegen.benchmarks import pinocchio_urdf_map, to_pinocchio
    from fmugen.codegen.c_code import generate_c
    from fmugen.codegen.c_harness import CompiledModel
    from fmugen.dynamics.manipulator import Manipulator
    from fmugen.robot.urdf import load_urdf

    try:
        root = Path(importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"))
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (pip install -e '.[test]')")
    path = root / rel_path
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = load_urdf(path)
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    mp = pinocchio_urdf_map(model, robot)
    iv = [m[1] for m in mp]
    n = robot.n
    m = Manipulator(robot).state_space_model(outputs=(), strategy="loops")
    zero = {v.name: 0.0 for v in m.parameters if v.name.startswith(("b_", "fc_"))}  # Pinocchio has neither
    p = np.array([zero.get(v.name, v.start) for v in m.parameters], float)
    rng = np.random.default_rng(3)
    with CompiledModel.build(generate_c(m).source) as cm:
        for _ in range(2):
            q, qd, tau = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-2, 2, n)
            qp, vp = to_pinocchio(model, mp, q, qd)
            taup = np.zeros(model.nv)
            taup[iv] = tau
            dx, _ = cm.evaluate(p, 0.0, np.r_[q, qd], tau, want_y=False)
            assert rel(dx[n:], pin.aba(model, data, qp, vp, taup)[iv]) < 1e-9
            dfdx, dfdu, _, _ = cm.jacobian(p, 0.0, np.r_[q, qd], tau)
            pin.computeABADerivatives(model, data, qp, vp, taup)
            minv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
            assert rel(dfdu[n:], minv[np.ix_(iv, iv)]) < 1e-9
            assert rel(dfdx[n:, n:], data.ddq_dv[np.ix_(iv, iv)]) < 1e-9
            assert rel(dfdx[n:, :n], data.ddq_dq[np.ix_(iv, iv)]) < 1e-9  # continuous: along the tangent
