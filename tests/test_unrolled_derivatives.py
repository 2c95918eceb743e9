"""The per-robot unrolled Jacobians of the forward and inverse dynamics (fmugen.codegen.unrolled_derivatives)
against Pinocchio's ``computeABADerivatives`` and ``computeRNEADerivatives`` -- a chain (UR5), prismatic
joints (Panda's fingers), a tree (HyQ) -- against the looped runtime where Pinocchio has no model (rotor
inertia, damping, smooth Coulomb friction), the folding evaluation against the compiled code, and the
statuses of a mass matrix that is not positive definite."""
from __future__ import annotations

import numpy as np
import pytest

from erd_robots import rel, robot
from fmugen.codegen import unrolled_derivatives
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
    gen = from_kernels(kernels, "fd")
    assert "FMUGEN_UNROLLED_BLOCK_V4 fmugen_unrolled_fd_jacobian_b" in gen.source  # x86-64-v4, -v3 and baseline
    fd = CompiledUnrolledJacobian(gen)
    idj = CompiledUnrolledJacobian(from_kernels(kernels, "id"))
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


def _hyq_with_drives(seed: int, first: int):
    """HyQ's Kernels, its body constants with random rotor inertia and damping and Coulomb friction on every
    other joint from ``first``, and the random generator."""
    _, _, kernels, _, _ = robot("hyq")
    n = kernels.n
    lc = np.array(kernels.constants, float).reshape(n, -1)
    rng = np.random.default_rng(seed)
    lc[:, 25] = rng.uniform(0.0, 0.3, n)  # rotor inertia
    lc[:, 26] = rng.uniform(0.0, 2.0, n)  # damping
    lc[first::2, 27] = 1.5  # Coulomb level
    lc[:, 28] = 0.05
    return kernels, lc, rng


def test_rotor_damping_friction_equal_the_runtime():
    """Rotor inertia, viscous damping and smooth Coulomb friction, which Pinocchio has not, against the
    looped runtime's fmugen_chain_fd_jacobian and fmugen_chain_id_jacobian on the same numbers (HyQ: a tree)."""
    from fmugen.batch import Kernels

    kernels, lc, rng = _hyq_with_drives(5, 0)
    n = kernels.n
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


def test_product_loop_on_interleaved_branches_equals_the_sums_and_the_original_numbering():
    """The loop that forms M^-1 (-∂ID) (the default) against the straight-line sums and against the robot
    numbered the usual way: HyQ's four legs renumbered depth by depth, so that every root branch is broken
    by the others (the loop then runs over spans holding the other branches' zeros), with rotor inertia,
    damping and friction on."""
    kernels, lc, rng = _hyq_with_drives(8, 1)
    n = kernels.n
    depth = [0] * n
    for i, par in enumerate(kernels.parents):
        depth[i] = depth[par] + 1 if par >= 0 else 0
    order = sorted(range(n), key=lambda i: (depth[i], i))  # old index of each new body, parents first
    new = {old: k for k, old in enumerate(order)}
    parents = [new[kernels.parents[o]] if kernels.parents[o] >= 0 else -1 for o in order]
    root = []
    for par in parents:
        root.append(root[par] if par >= 0 else len(root))
    assert root != sorted(root)  # each branch broken by the others
    revolute = [kernels.revolute[o] for o in order]
    g = kernels.globals[:3]
    gens = [unrolled_jacobian(revolute, parents, lc[order], g, dense_product=d) for d in (True, False)]
    gens.append(unrolled_jacobian(kernels.revolute, kernels.parents, lc, g))  # the usual numbering
    with pytest.MonkeyPatch.context() as mp:  # M^-1 = X X^T as the loop as well, over the broken spans
        mp.setattr(unrolled_derivatives, "MINV_LOOP_MIN", 0)
        gens.append(unrolled_jacobian(revolute, parents, lc[order], g))
    assert "Xc[xdst[t]]" in gens[3].source and "Xc[xdst[t]]" not in gens[0].source
    assert "fmugen_unrolled_fd_jacobian_product(" in gens[0].source and "_product(" not in gens[1].source
    made = [CompiledUnrolledJacobian(gen) for gen in gens]
    try:
        q, qd, x = rng.uniform(-1, 1, (3, n)), rng.uniform(-1, 1, (3, n)), rng.uniform(-3, 3, (3, n))
        loop, sums = (m.derivatives(q[:, order], qd[:, order], x[:, order]) for m in made[:2])
        ref = made[2].derivatives(q, qd, x)
        minv_loop = made[3].derivatives(q[:, order], qd[:, order], x[:, order])
        ix = np.ix_(order, order)
        for a, b, r, c in zip(loop, sums, ref, minv_loop):
            assert rel(a, b) < 1e-12 and rel(c, b) < 1e-12
            assert rel(a, r[:, order] if r.ndim == 2 else r[:, ix[0], ix[1]]) < 1e-12
    finally:
        for m in made:
            m.close()
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


def _tree_robot(n, seed, friction_parameter=True, wrench_on=()):
    """A random tree (general joint axes, prismatic joints, joint offsets, an end-effector frame) as a
    fmugen Robot, with one symbolic parameter (a Coulomb level) when asked."""
    import sympy as sp

    from fmugen.robot.description import JOINTS, PRISMATIC, REVOLUTE, Body, Frame, Parameter, Robot
    from test_tree_dynamics import random_tree

    _, revolute, parents, bodies = random_tree(n, seed=seed)
    rng = np.random.default_rng(seed)
    F = lambda v: tuple(sp.Float(float(x)) for x in v)  # noqa: E731
    FM = lambda M: tuple(F(row) for row in np.asarray(M))  # noqa: E731
    fc = sp.Symbol("fc", real=True) if friction_parameter else sp.Float(0.4)
    rb = tuple(Body(name=f"b{i}", joint=REVOLUTE if revolute[i] else PRISMATIC, parent=parents[i],
                    rotation=FM(b["R"]), translation=F(b["p"]), axis=F(b["axis"]), mass=sp.Float(b["mass"]),
                    com=F(b["com"]), inertia_com=FM(b["inertia"]), rotor_inertia=sp.Float(b["rotor_inertia"]),
                    damping=sp.Float(b["damping"]), offset=sp.Float(rng.uniform(-0.5, 0.5)),
                    friction=fc if i % 2 else 0, friction_velocity=sp.Float(0.1), external_wrench=i in wrench_on)
               for i, b in enumerate(bodies))
    return Robot(name="tree", convention=JOINTS, links=(), gravity=F([0, 0, -9.81]), bodies=rb,
                 frames=(Frame("tool", n - 3, FM(np.eye(3)), F([0.05, 0.1, -0.2])),), end_frame="tool",
                 parameters=(Parameter("fc", fc, 0.7),) if friction_parameter else ())


@pytest.mark.parametrize("n", [8, 14])
def test_folded_models_get_unrolled_code_equal_to_the_loops(n):
    """A model whose robot numbers are all known (parameters folded) gets code of its own instead of the
    runtime's loops -- forward dynamics with the end-effector position, its Jacobian with dp_ee/dq (up to
    UNROLLED_JACOBIAN_MAX bodies; beyond, the loops' Jacobian beside the unrolled forward dynamics), the
    inverse dynamics and its Jacobian -- and evaluates what the loops evaluate with the parameter set."""
    from fmugen.codegen.c_code import generate_c
    from fmugen.codegen.c_harness import CompiledModel
    from fmugen.codegen.chain import UNROLLED_JACOBIAN_MAX
    from fmugen.dynamics.manipulator import Manipulator

    arm = Manipulator(_tree_robot(n, seed=11))
    rng = np.random.default_rng(6)
    for kind, m in (("fd", arm.state_space_model(outputs=("p_ee", "qdd"), strategy="loops")),
                    ("id", arm.inverse_dynamics_model(strategy="loops"))):
        looped, folded = generate_c(m).source, generate_c(m.with_parameters_folded()).source
        assert "fmugen_unrolled_" not in looped and "fmugen_chain_" in looped
        assert f"fmugen_unrolled_{kind}_" in folded
        assert (f"fmugen_unrolled_{'jacobian' if kind == 'fd' else 'id_jacobian'}_" in folded) == \
            (n <= UNROLLED_JACOBIAN_MAX)
        assert ("fmugen_chain_" in folded) == (n > UNROLLED_JACOBIAN_MAX)
        # the forward dynamics' functions carry the x86-64-v3 clone, the Jacobians' the -v3 and -v4 ones, the
        # inverse dynamics' none
        v3 = "FMUGEN_UNROLLED_BLOCK_V3 fmugen_unrolled_"
        jac = "FMUGEN_UNROLLED_BLOCK_V4 fmugen_unrolled_" + ("jacobian_" if kind == "fd" else "id_jacobian_")
        assert (jac in folded) == (n <= UNROLLED_JACOBIAN_MAX)
        assert (v3 + "fd_" in folded) == (kind == "fd")
        assert ("FMUGEN_UNROLLED_BLOCK fmugen_unrolled_id_" in folded) == (kind == "id")
        assert "FMUGEN_UNROLLED_BLOCK fmugen_unrolled_fd_" not in folded
        p = np.array([v.start for v in m.parameters], float)
        with CompiledModel.build(looped) as cl, CompiledModel.build(folded) as cf:
            for _ in range(3):
                if kind == "fd":
                    x, u = np.r_[rng.uniform(-3, 3, n), rng.uniform(-2, 2, n)], rng.uniform(-10, 10, n)
                else:
                    x, u = [], np.r_[rng.uniform(-3, 3, n), rng.uniform(-2, 2, n), rng.uniform(-3, 3, n)]
                for a, b in zip(cl.evaluate(p, 0.0, x, u), cf.evaluate([], 0.0, x, u)):
                    if a.size:
                        assert rel(b, a) < 1e-12
                for a, b in zip(cl.jacobian(p, 0.0, x, u), cf.jacobian([], 0.0, x, u)):
                    if a.size:
                        assert rel(b, a) < 1e-11


def test_external_wrenches_keep_the_loops():
    """External wrenches are the loops' alone (the unrolled code has none): a folded model with them keeps
    the runtime call."""
    from fmugen.codegen.c_code import generate_c
    from fmugen.dynamics.manipulator import Manipulator

    arm = Manipulator(_tree_robot(8, seed=12, friction_parameter=False, wrench_on=(5,)))
    src = generate_c(arm.state_space_model(outputs=("p_ee",), strategy="loops")).source
    assert "fmugen_chain_fd(" in src and "fmugen_unrolled_" not in src


def test_folded_urdf_fmu_equals_the_looped_fmu(tmp_path):
    """`fmugen build panda.urdf --fold all` (9 joints, two of them prismatic; the file's damping folded)
    gives an FMU with the unrolled dynamics and Jacobian that validates and runs, ME and CS, as the
    FMU with the loops and the damping as a parameter does."""
    import importlib.metadata
    from pathlib import Path

    from fmpy import simulate_fmu
    from fmpy.validation import validate_fmu

    from fmugen.cli import main

    try:
        root = Path(importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"))
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (pip install -e '.[test]')")
    urdf = root / "panda_description/urdf/panda.urdf"
    fmus = {}
    for fold in ("none", "all"):
        fmus[fold] = tmp_path / f"panda_{fold}.fmu"
        assert main(["build", str(urdf), "-o", str(fmus[fold]), "--fmi-type", "both", "--fold", fold]) == 0
        assert validate_fmu(str(fmus[fold])) == []
    import zipfile

    with zipfile.ZipFile(fmus["all"]) as z:
        model_c = z.read("sources/model.c").decode()
    assert "fmugen_unrolled_jacobian_" in model_c and "fmugen_chain_" not in model_c
    start = {"tau[1]": 3.0, "tau[4]": -2.0, "q[2]": 0.3, "qd[6]": 0.5}
    outs = ["q[1]", "q[4]", "q[9]", "p_ee[3]"]
    for fmi_type in ("ModelExchange", "CoSimulation"):
        tol = {"relative_tolerance": 1e-10} if fmi_type == "ModelExchange" else {}  # CVode: steps chosen alike
        r = [simulate_fmu(str(fmus[f]), fmi_type=fmi_type, stop_time=0.2, output_interval=0.02, start_values=start,
                          output=outs, **tol) for f in ("none", "all")]
        a, b = (np.column_stack([x[o] for o in outs]) for x in r)
        assert np.abs(a - a[0]).max() > 1e-3 and rel(b, a) < 1e-8, fmi_type


def test_a_massless_leaf_keeps_the_loops_and_their_run_time_status():
    """Numbers that make the mass matrix singular at every state (a massless, inertia-free leaf: its pivot
    folds to 0) give no unrolled code: the folded model keeps the loops' call, which reports the state as
    the model with its parameters free does (status FMUGEN_NOT_POSITIVE_DEFINITE), instead of a build that
    fails or code that divides by zero."""
    from dataclasses import replace

    import sympy as sp

    from fmugen.codegen.c_code import generate_c
    from fmugen.codegen.c_harness import CompiledModel
    from fmugen.dynamics.manipulator import Manipulator
    from fmugen.robot.description import Body

    robot = _tree_robot(8, seed=13, friction_parameter=False)
    leaf = [i for i in range(8) if all(b.parent != i for b in robot.bodies)][0]
    zero3 = (sp.Float(0),) * 3
    bodies = list(robot.bodies)
    b = bodies[leaf]
    bodies[leaf] = Body(name=b.name, joint=b.joint, parent=b.parent, rotation=b.rotation, translation=b.translation,
                        axis=b.axis, mass=sp.Float(0), com=zero3, inertia_com=(zero3,) * 3, rotor_inertia=sp.Float(0),
                        damping=b.damping, offset=b.offset)
    m = Manipulator(replace(robot, bodies=tuple(bodies))).state_space_model(outputs=("p_ee",), strategy="loops")
    src = generate_c(m.with_parameters_folded()).source
    assert "fmugen_chain_fd(" in src and "fmugen_unrolled_" not in src
    with CompiledModel.build(src) as cm, pytest.raises(RuntimeError, match="status 1"):  # NOT_POSITIVE_DEFINITE
        cm.evaluate([], 0.0, np.zeros(16), np.zeros(8))


def test_source_independent_of_hash_seed(tmp_path):
    """The work array's slots follow the statements' order, not Python's string hashes (PYTHONHASHSEED):
    the same robot gives the same C text in every process, as an FMU build must."""
    import os
    import subprocess
    import sys
    import textwrap

    script = tmp_path / "gen.py"
    script.write_text(textwrap.dedent(f"""
        import hashlib, sys
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        from test_unrolled_derivatives import _tree_robot
        from fmugen.batch import Kernels
        from fmugen.codegen.unrolled_aba import unrolled_fd
        from fmugen.codegen.unrolled_derivatives import unrolled_jacobian
        k = Kernels.from_robot(_tree_robot(9, 5, friction_parameter=False))
        g = k.globals[:3]
        texts = [unrolled_fd(k.revolute, k.parents, k.constants, g).source]
        texts += [unrolled_jacobian(k.revolute, k.parents, k.constants, g, kind).source for kind in ("fd", "id")]
        print(hashlib.sha256("".join(texts).encode()).hexdigest())
    """))
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    path = os.pathsep.join([root] + ([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else []))
    digests = set()
    for seed in ("1", "2", "3"):
        r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                           env=dict(os.environ, PYTHONHASHSEED=seed, PYTHONPATH=path))
        assert r.returncode == 0, r.stderr
        digests.add(r.stdout.strip())
    assert len(digests) == 1 and len(next(iter(digests))) == 64


def test_loops_of_every_shape_and_their_plain_c_equal_the_sums():
    """The loops' variants on one branch of nine joints (Panda, with rotor inertia, damping and friction):
    M^-1 from the statements or as the loop X X^T, the product's sums of both kinds in one pass or one
    kind a pass in chunks of rows (ROWS 8: a pass of eight rows and one of a single row), each of those
    in the plain C of a compiler without vector types, and where M^-1 is a loop the AVX-512 variant (eight
    rows a register; run where the CPU has it) beside the AVX one (FMUGEN_UNROLLED_NARROW), against the
    straight-line sums."""
    import dataclasses

    _, _, kernels, _, _ = robot("panda")
    n = kernels.n
    lc = np.array(kernels.constants, float).reshape(n, -1)
    rng = np.random.default_rng(12)
    lc[:, 25], lc[:, 26], lc[::2, 27], lc[:, 28] = rng.uniform(0, 0.3, n), rng.uniform(0, 2, n), 1.5, 0.05
    args = (kernels.revolute, kernels.parents, lc, kernels.globals[:3])
    gens = [unrolled_jacobian(*args, dense_product=False), unrolled_jacobian(*args)]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(unrolled_derivatives, "MINV_LOOP_MIN", 0)
        gens.append(unrolled_jacobian(*args))
        mp.setattr(unrolled_derivatives._DenseProduct, "ROWS", 8)
        mp.setattr(unrolled_derivatives._DenseProduct, "ROWS_WIDE", 8)
        gens.append(unrolled_jacobian(*args))
    assert "Xc[xdst[t]]" in gens[2].source and "FMUGEN_SHUFFLE(a0, a1" in gens[1].source
    assert "_product_wide" in gens[2].source and "_product_wide" not in gens[1].source
    assert "fmugen_v8 x0" in gens[2].source
    # 2 kinds x 2 chunks, in the vector and the plain branch, in the AVX and the AVX-512 function
    assert gens[3].source.count("for (int t = first[c]; t < first[c + 1]; t++)") == 2 * 2 * 2 * 2
    gens += [dataclasses.replace(g, source=g.source.replace("#ifdef FMUGEN_UNROLLED_V4", "#if 0")) for g in gens[1:]]
    made = [CompiledUnrolledJacobian(g) for g in gens]
    made += [CompiledUnrolledJacobian(g, flags=("-O2", "-DFMUGEN_UNROLLED_NARROW")) for g in gens[2:4]]
    try:
        q, qd, x = rng.uniform(-1, 1, (3, n)), rng.uniform(-1, 1, (3, n)), rng.uniform(-3, 3, (3, n))
        ref = made[0].derivatives(q, qd, x)
        for m in made[1:]:
            for a, b in zip(m.derivatives(q, qd, x), ref):
                assert rel(a, b) < 1e-12
    finally:
        for m in made:
            m.close()
        kernels.close()
