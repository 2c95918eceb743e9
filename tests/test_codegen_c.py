"""Generated model.c against independent numpy/sympy evaluation.

Each model is compiled (with c_runtime/linalg.c) into a shared library and its
evaluate/jacobian compared with the closed forms lambdified by sympy, with
numpy's LU solve standing in for the generated Cholesky solve.
"""
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import sympy as sp

from fmugen.codegen.c_code import (
    OpCount,
    c_identifier,
    cholesky_solve_ops,
    count_c_expression,
    count_operations,
    generate_c,
)
from fmugen.codegen.c_harness import CompiledModel
from fmugen.codegen.model import SymbolicModel, Variable
from fmugen.codegen.program import Program

RTOL = 1e-12


def assert_close(actual, expected, rtol=RTOL):
    actual, expected = np.asarray(actual, float), np.asarray(expected, float)
    scale = max(1.0, float(np.max(np.abs(expected)))) if expected.size else 1.0
    np.testing.assert_allclose(actual, expected, rtol=rtol, atol=rtol * scale)


# --------------------------------------------------------------------------
# models
# --------------------------------------------------------------------------
def pendulum():
    """Damped pendulum with a torque input; tip position as outputs."""
    phi, w, tau = sp.symbols("phi w tau", real=True)
    g, L, m, d = sp.symbols("g L m d", real=True)
    xt, yt, e = sp.symbols("x_tip y_tip E", real=True)
    states = [Variable("phi", phi, "rad", start=0.3, output=True), Variable("w", w, "rad/s", start=0.0)]
    inputs = [Variable("tau", tau, "N.m", start=0.0)]
    params = [Variable("g", g, "m/s2", start=9.81), Variable("L", L, "m", start=0.7),
              Variable("m", m, "kg", start=1.3), Variable("d", d, "N.m.s/rad", start=0.05)]
    f = [w, -g / L * sp.sin(phi) + (tau - d * w) / (m * L**2)]
    outs = [Variable("x_tip", xt, "m"), Variable("y_tip", yt, "m"), Variable("E", e, "J")]
    gexp = [L * sp.sin(phi), -L * sp.cos(phi),
            m * L**2 * w**2 / 2 - m * g * L * sp.cos(phi)]
    model = SymbolicModel.from_equations("Pendulum", states, inputs, params, f, outs, gexp,
                                         description="pendulum", provenance="closed form")
    return model, (states, inputs, params, f, gexp)


def spd_model():
    """3-dof model M(q) qdd = tau - h(q, qd) solved through a SolveSPD step.

    M = [[a + b c2, e c2 c3, e s3], [., a + c3^2, b s2 c3], [., ., 2a]] with
    a dominant diagonal (positive definite for the parameters used); the
    Jacobian program solves M [dqdd/dq | dqdd/dqd | dqdd/dtau] = ... with a
    second SolveSPD (k = 9 right-hand sides).
    """
    q = sp.symbols("q1:4", real=True)
    qd = sp.symbols("qd1:4", real=True)
    tau = sp.symbols("tau1:4", real=True)
    a, b, e, k = sp.symbols("a b e k", real=True)
    c2, s2, c3, s3 = sp.cos(q[1]), sp.sin(q[1]), sp.cos(q[2]), sp.sin(q[2])
    M = sp.Matrix([[a + b * c2, e * c2 * c3, e * s3],
                   [e * c2 * c3, a + c3**2, b * s2 * c3],
                   [e * s3, b * s2 * c3, 2 * a]])
    h = sp.Matrix([b * s2 * qd[0] * qd[1] + k * q[0],
                   e * s3 * qd[2]**2 - b * s2 * qd[0]**2 + k * sp.sin(q[1]),
                   e * c3 * qd[0] * qd[2] + k * q[2] ** 3])
    rhs = sp.Matrix(tau) - h
    states = ([Variable(f"q[{i+1}]", q[i], "rad", start=0.1 * (i + 1), output=True) for i in range(3)]
              + [Variable(f"qd[{i+1}]", qd[i], "rad/s", start=0.0, output=True) for i in range(3)])
    inputs = [Variable(f"tau[{i+1}]", tau[i], "N.m", start=0.0) for i in range(3)]
    params = [Variable("a", a, "kg.m2", start=3.0), Variable("b", b, "kg.m2", start=0.8),
              Variable("e", e, "kg.m2", start=0.5), Variable("k", k, "N.m/rad", start=2.0)]

    prog = Program("w")
    Ms = sp.Matrix(3, 3, lambda i, j: prog.let(M[i, j], "M") if i >= j else 0)
    Ms = sp.Matrix(3, 3, lambda i, j: Ms[max(i, j), min(i, j)])
    r = sp.Matrix(prog.let_vec(rhs, "r"))
    qdd = prog.solve_spd(Ms, r, "qdd")
    # outputs: a point at the end of a 2-link planar chain
    px = prog.let(sp.cos(q[0]) + sp.cos(q[0] + q[1]), "px")
    py = prog.let(sp.sin(q[0]) + sp.sin(q[0] + q[1]), "py")

    # Jacobian: M dqdd/dz = d rhs/dz - (dM/dz) qdd for z in (q, qd, tau)
    jac = Program("j")
    z = list(q) + list(qd) + list(tau)
    B = sp.Matrix(3, 9, lambda i, j: jac.let(
        sp.diff(rhs[i], z[j]) - sum(sp.diff(M[i, c], z[j]) * qdd[c] for c in range(3))))
    D = jac.solve_spd(Ms, B, "D")
    eye, zero = sp.eye(3), sp.zeros(3)
    dfdx = sp.zeros(6, 6)
    dfdx[:3, 3:] = eye
    dfdx[3:, :] = D[:, :6]
    dfdu = zero.col_join(D[:, 6:])
    pos = sp.Matrix([sp.cos(q[0]) + sp.cos(q[0] + q[1]), sp.sin(q[0]) + sp.sin(q[0] + q[1])])
    dgdx = sp.Matrix(2, 6, lambda i, j: jac.let(sp.diff(pos[i], z[j])))
    model = SymbolicModel(
        name="spd3", description="3-dof mass-matrix model", states=tuple(states),
        inputs=tuple(inputs), parameters=tuple(params),
        outputs=(Variable("p[1]", sp.Symbol("p1"), "m"), Variable("p[2]", sp.Symbol("p2"), "m")),
        program=prog, derivatives=tuple(qd) + tuple(qdd), output_exprs=(px, py),
        jacobian=jac, dfdx=dfdx, dfdu=dfdu, dgdx=dgdx, dgdu=sp.zeros(2, 3),
        provenance="test model")
    return model, (q, qd, tau, (a, b, e, k), M, rhs, pos)


# --------------------------------------------------------------------------
# fixtures: compile once per module
# --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pend():
    model, parts = pendulum()
    gen = generate_c(model)
    with CompiledModel.build(gen.source) as cm:
        yield model, parts, gen, cm


@pytest.fixture(scope="module")
def spd():
    model, parts = spd_model()
    gen = generate_c(model)
    with CompiledModel.build(gen.source) as cm:
        yield model, parts, gen, cm


def function_text(source: str, name: str) -> str:
    start = source.index(f"static int {name}(")
    return source[start:source.index("\n}\n", start)]


# --------------------------------------------------------------------------
# pendulum
# --------------------------------------------------------------------------
def test_pendulum_evaluate_matches_sympy(pend):
    model, (states, inputs, params, f, gexp), gen, cm = pend
    syms = [v.symbol for v in states + inputs + params]
    f_num = sp.lambdify(syms, f, "numpy")
    g_num = sp.lambdify(syms, gexp, "numpy")
    rng = np.random.default_rng(1)
    for _ in range(20):
        x = rng.uniform(-3, 3, 2)
        u = rng.uniform(-2, 2, 1)
        p = rng.uniform(0.5, 2.0, 4)
        dx, y = cm.evaluate(p, 0.0, x, u)
        assert_close(dx, f_num(*x, *u, *p))
        assert_close(y, g_num(*x, *u, *p))
        dx2, none = cm.evaluate(p, 0.0, x, u, want_y=False)  # y == NULL path
        assert none is None
        np.testing.assert_array_equal(dx2, dx)


def test_pendulum_jacobian_matches_sympy(pend):
    model, (states, inputs, params, f, gexp), gen, cm = pend
    xs, us = [v.symbol for v in states], [v.symbol for v in inputs]
    syms = xs + us + [v.symbol for v in params]
    F, G = sp.Matrix(f), sp.Matrix(gexp)
    refs = [sp.lambdify(syms, J, "numpy") for J in
            (F.jacobian(xs), F.jacobian(us), G.jacobian(xs), G.jacobian(us))]
    rng = np.random.default_rng(2)
    for _ in range(10):
        x, u, p = rng.uniform(-3, 3, 2), rng.uniform(-2, 2, 1), rng.uniform(0.5, 2, 4)
        for got, ref in zip(cm.jacobian(p, 0.0, x, u), refs):
            assert_close(got, np.asarray(ref(*x, *u, *p), float))


def test_pendulum_sin_cos_computed_once(pend):
    _, _, gen, _ = pend
    ev = function_text(gen.source, "evaluate")
    # sin(phi) appears in f and in x_tip; cos(phi) in y_tip and E
    assert ev.count("sin(") == 1
    assert ev.count("cos(") == 1
    assert gen.op_counts["evaluate"].expressions.calls == (("cos", 1), ("sin", 1))


def test_generated_source_is_documented(pend):
    model, _, gen, _ = pend
    head = gen.source[: gen.source.index("*/")]
    for v in model.states + model.inputs + model.outputs + model.parameters:
        assert v.name in head and v.unit in head
    assert f"evaluate: {gen.op_counts['evaluate'].expressions}" in head
    assert "closed form" in head  # provenance


# --------------------------------------------------------------------------
# model with a linear solve
# --------------------------------------------------------------------------
def spd_reference(parts, x, u, p):
    q, qd, tau, ps, M, rhs, pos = parts
    syms = list(q) + list(qd) + list(tau) + list(ps)
    Mn = np.asarray(sp.lambdify(syms, M, "numpy")(*x, *u, *p), float)
    rn = np.asarray(sp.lambdify(syms, rhs, "numpy")(*x, *u, *p), float).ravel()
    return Mn, rn


def test_spd_model_evaluate_matches_numpy_solve(spd):
    model, parts, gen, cm = spd
    rng = np.random.default_rng(3)
    p = np.array([3.0, 0.8, 0.5, 2.0])
    q, qd, tau, ps, M, rhs, pos = parts
    pos_num = sp.lambdify(list(q), pos, "numpy")
    for _ in range(20):
        x, u = rng.uniform(-2, 2, 6), rng.uniform(-5, 5, 3)
        Mn, rn = spd_reference(parts, x, u, p)
        dx, y = cm.evaluate(p, 0.0, x, u)
        assert_close(dx[:3], x[3:])
        assert_close(dx[3:], np.linalg.solve(Mn, rn))
        assert_close(y, np.asarray(pos_num(*x[:3]), float).ravel())


def test_spd_model_jacobian_matches_numpy(spd):
    """dqdd/dz = M^-1 (drhs/dz - dM/dz qdd), evaluated with numpy."""
    model, parts, gen, cm = spd
    q, qd, tau, ps, M, rhs, pos = parts
    z = list(q) + list(qd) + list(tau)
    syms = z + list(ps)
    dM = [sp.lambdify(syms, M.diff(zj), "numpy") for zj in z]
    drhs = sp.lambdify(syms, rhs.jacobian(z), "numpy")
    dpos = sp.lambdify(syms, pos.jacobian(z[:6]), "numpy")
    rng = np.random.default_rng(4)
    p = np.array([3.0, 0.8, 0.5, 2.0])
    for _ in range(10):
        x, u = rng.uniform(-2, 2, 6), rng.uniform(-5, 5, 3)
        Mn, rn = spd_reference(parts, x, u, p)
        qdd = np.linalg.solve(Mn, rn)
        args = (*x, *u, *p)
        Bn = np.asarray(drhs(*args), float) - np.column_stack(
            [np.asarray(d(*args), float) @ qdd for d in dM])
        D = np.linalg.solve(Mn, Bn)
        dfdx, dfdu, dgdx, dgdu = cm.jacobian(p, 0.0, x, u)
        ref_dfdx = np.zeros((6, 6))
        ref_dfdx[:3, 3:] = np.eye(3)
        ref_dfdx[3:] = D[:, :6]
        assert_close(dfdx, ref_dfdx)
        assert_close(dfdu, np.vstack([np.zeros((3, 3)), D[:, 6:]]))
        assert_close(dgdx, np.asarray(dpos(*args), float))
        np.testing.assert_array_equal(dgdu, np.zeros((2, 3)))


def test_spd_model_jacobian_against_finite_differences(spd):
    """Second, formulation-free check of dfdx: central differences of evaluate."""
    model, parts, gen, cm = spd
    p = np.array([3.0, 0.8, 0.5, 2.0])
    x, u = np.array([0.3, -0.7, 1.1, 0.5, -0.2, 0.9]), np.array([1.0, -2.0, 0.5])
    dfdx = cm.jacobian(p, 0.0, x, u)[0]
    h = 1e-6
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        fd = (cm.evaluate(p, 0.0, x + e, u)[0] - cm.evaluate(p, 0.0, x - e, u)[0]) / (2 * h)
        np.testing.assert_allclose(dfdx[:, j], fd, rtol=1e-6, atol=1e-7)


def test_spd_model_not_positive_definite_returns_status(spd):
    model, parts, gen, cm = spd
    # a = -3 makes M indefinite: the Cholesky reports it, evaluate returns 1
    with pytest.raises(RuntimeError, match="status 1"):
        cm.evaluate([-3.0, 0.8, 0.5, 2.0], 0.0, np.zeros(6), np.zeros(3))


def test_spd_model_op_counts_include_linear_solve(spd):
    _, _, gen, _ = spd
    ev, jac = gen.op_counts["evaluate"], gen.op_counts["jacobian"]
    assert ev.linear_solve == cholesky_solve_ops(3, 1)
    assert jac.linear_solve == cholesky_solve_ops(3, 1) + cholesky_solve_ops(3, 9)
    src = gen.source
    assert "fmugen_spd_solve(3, 1, " in src and "fmugen_spd_solve(3, 9, " in src


def test_folded_parameters_match_unfolded_pendulum(pend):
    model, parts, gen, cm = pend
    folded = model.with_parameters_folded()
    gen2 = generate_c(folded)
    assert gen2.op_counts["evaluate"].expressions.mul < gen.op_counts["evaluate"].expressions.mul
    p = [v.start for v in model.parameters]
    x, u = np.array([0.4, -1.1]), np.array([0.3])
    with CompiledModel.build(gen2.source) as cm2:
        assert cm2.np == 0
        for a, b in zip(cm2.evaluate([], 0.0, x, u), cm.evaluate(p, 0.0, x, u)):
            assert_close(a, b)
        for a, b in zip(cm2.jacobian([], 0.0, x, u), cm.jacobian(p, 0.0, x, u)):
            assert_close(a, b)


def test_folded_parameters_match_unfolded(spd):
    model, parts, gen, cm = spd
    folded = model.with_parameters_folded()
    gen2 = generate_c(folded)
    assert gen2.op_counts["evaluate"].expressions.mul <= gen.op_counts["evaluate"].expressions.mul
    p = [v.start for v in model.parameters]
    x, u = np.array([0.3, -0.7, 1.1, 0.5, -0.2, 0.9]), np.array([1.0, -2.0, 0.5])
    with CompiledModel.build(gen2.source) as cm2:
        assert cm2.np == 0
        assert_close(cm2.evaluate([], 0.0, x, u)[0], cm.evaluate(p, 0.0, x, u)[0])
        for a, b in zip(cm2.jacobian([], 0.0, x, u), cm.jacobian(p, 0.0, x, u)):
            assert_close(a, b)


# --------------------------------------------------------------------------
# smaller properties
# --------------------------------------------------------------------------
def test_time_dependent_model_and_powers():
    """t as a symbol; sin(x)**2 must not call sin twice; odd powers and roots."""
    x, t, c = sp.symbols("x t c", real=True)
    f = [sp.sin(x) ** 2 * sp.cos(t) + x ** 3 / (1 + x ** 2) ** 2 + sp.sqrt(c + x ** 2) - c * x ** sp.Rational(5, 2)]
    m = SymbolicModel.from_equations("timed", [Variable("x", x, start=0.5)], [],
                                     [Variable("c", c, start=2.0)], f)
    gen = generate_c(m)
    ev = function_text(gen.source, "evaluate")
    assert ev.count("sin(") == 1
    ref = sp.lambdify([x, t, c], f[0])
    dref = sp.lambdify([x, t, c], sp.diff(f[0], x))
    with CompiledModel.build(gen.source) as cm:
        for xv, tv in [(0.5, 0.0), (1.3, 2.0), (0.01, -7.0)]:
            assert_close(cm.evaluate([2.0], tv, [xv], [])[0], [ref(xv, tv, 2.0)])
            assert_close(cm.jacobian([2.0], tv, [xv], [])[0], [[dref(xv, tv, 2.0)]])


def test_op_count_of_tiny_expression_hand_counted():
    a, b, c, d = sp.symbols("a b c d")
    # a*b*c: 2 mul; sin(a)*d: 1 mul, 1 call; a/b: 1 div; two binary +/-
    ops = count_operations([a * b * c + sp.sin(a) * d - a / b]).expressions
    assert (ops.mul, ops.add, ops.div, ops.calls) == (3, 2, 1, (("sin", 1),))
    # shared sin(a) and a*b across two outputs: sin once, a*b once
    ops = count_operations([sp.sin(a) * a * b, sp.sin(a) + a * b * c]).expressions
    assert (ops.mul, ops.add, ops.div, ops.calls) == (3, 1, 0, (("sin", 1),))
    # unary minus is free, x**2 is one multiplication, 1/x**3 two and a division
    ops = count_operations([-a * b, a ** 2, 1 / a ** 3]).expressions
    assert (ops.mul, ops.add, ops.div) == (1 + 1 + 2, 0, 1)


def test_count_c_expression_rules():
    assert count_c_expression("-a*b - c*(d + -e)/f") == OpCount(2, 2, 1, ())
    assert count_c_expression("1.5e-3*x - pow(y, 2.5) + sqrt(z)/2.0") == OpCount(
        1, 2, 1, (("pow", 1), ("sqrt", 1)))


def _count_cholesky_loops(n, k):
    """Operations of c_runtime/linalg.c, counted by walking its loops."""
    mul = add = div = sq = 0
    for j in range(n):
        mul += j; add += j; sq += 1  # noqa: E702
        for i in range(j + 1, n):
            mul += j; add += j; div += 1  # noqa: E702
    for _ in range(k):
        for i in range(n):
            mul += i; add += i; div += 1  # noqa: E702
        for i in range(n - 1, -1, -1):
            mul += n - 1 - i; add += n - 1 - i; div += 1  # noqa: E702
    return OpCount(mul, add, div, (("sqrt", sq),) if sq else ())


@pytest.mark.parametrize("n,k", [(1, 1), (3, 1), (6, 1), (6, 12), (7, 3)])
def test_cholesky_counts_match_loops(n, k):
    assert cholesky_solve_ops(n, k) == _count_cholesky_loops(n, k)


def test_guid_is_deterministic_and_content_dependent():
    m1, _ = pendulum()
    g1, g2 = generate_c(m1), generate_c(pendulum()[0])
    assert g1.guid == g2.guid and g1.source == g2.source
    p = list(m1.parameters)
    p[0] = Variable(p[0].name, p[0].symbol, p[0].unit, start=9.80665)
    from dataclasses import replace
    assert generate_c(replace(m1, parameters=tuple(p))).guid != g1.guid


def test_source_independent_of_hash_seed(tmp_path):
    """sympy's hashes follow PYTHONHASHSEED; the generated text must not."""
    script = tmp_path / "gen.py"
    script.write_text(textwrap.dedent(f"""
        import hashlib, sys
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        from test_codegen_c import spd_model
        from fmugen.codegen.c_code import generate_c
        print(hashlib.sha256(generate_c(spd_model()[0]).source.encode()).hexdigest())
    """))
    digests = set()
    for seed in ("1", "2"):
        env = dict(os.environ, PYTHONHASHSEED=seed)
        r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env)
        assert r.returncode == 0, r.stderr
        digests.add(r.stdout.strip())
    assert len(digests) == 1


def test_unknown_symbol_is_a_clear_error():
    x, k = sp.symbols("x k")
    m = SymbolicModel.from_equations("bad", [Variable("x", x, start=1.0)], [], [], [-k * x])
    with pytest.raises(ValueError, match="symbols k are neither"):
        generate_c(m)


def test_state_without_start_is_an_error():
    x = sp.Symbol("x")
    m = SymbolicModel.from_equations("nostart", [Variable("x", x)], [], [], [-x])
    with pytest.raises(ValueError, match="state 'x' has no start value"):
        generate_c(m)


def test_symbol_names_clashing_with_c_are_renamed():
    # states named like C keywords and the function's own arguments
    # and "_s"/"s", which lose their leading underscore in C
    xs = [sp.Symbol(n, real=True) for n in ("int", "x", "dx", "sin", "_s", "s")]
    m = SymbolicModel.from_equations(
        "clash", [Variable(f"s[{i+1}]", s, start=0.1 * (i + 1)) for i, s in enumerate(xs)], [], [],
        [xs[1] * xs[2], -xs[0], xs[3] + xs[0] ** 2, sp.sin(xs[3]), xs[5], 2 * xs[4]])
    with CompiledModel.build(generate_c(m).source) as cm:
        x = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
        assert_close(cm.evaluate([], 0, x, [])[0], [0.2 * 0.3, -0.1, 0.4 + 0.01, np.sin(0.4), 0.6, 1.0])


def test_c_identifier():
    assert c_identifier("PUMA 560") == "PUMA_560"
    assert c_identifier("3dof-arm") == "m_3dof_arm"
    assert c_identifier("double") == "double_"
