"""FMU building: modelDescription.xml, validation, simulation against scipy.

FMUs of two small models (a pendulum; a 3-dof mass-matrix model with a
Cholesky solve) are built once per module, validated with
fmpy.validation.validate_fmu, simulated as Model Exchange (fmpy's CVode) and
Co-Simulation (the runtime's solvers), and compared with scipy's solve_ivp
at rtol 1e-11 on the closed-form equations.
"""
import ctypes
import os
import re
import zipfile

import numpy as np
import pytest
import sympy as sp
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from fmugen.codegen.model import SymbolicModel, Variable
from fmugen.fmi import BuildError, base_units, build_fmu, model_description_xml, variable_layout
from fmugen.fmi.build import runtime_dir
from fmugen.fmi.model_description import runtime_parameters
from fmugen.fmi.units import UnitError

from test_codegen_c import pendulum, spd_model

pytestmark = pytest.mark.skipif(not any(runtime_dir().glob("fmi2*.c")),
                                reason="the FMI runtime (c_runtime/fmi2*.c) is not there yet")


@pytest.fixture(scope="module")
def pend_fmu(tmp_path_factory):
    model, parts = pendulum()
    res = build_fmu(model, tmp_path_factory.mktemp("pend") / "Pendulum.fmu", fmi_type="both")
    return model, parts, res


@pytest.fixture(scope="module")
def spd_fmu(tmp_path_factory):
    model, parts = spd_model()
    res = build_fmu(model, tmp_path_factory.mktemp("spd"), fmi_type="both")
    return model, parts, res


# --------------------------------------------------------------------------
# references
# --------------------------------------------------------------------------
def pendulum_reference(parts, params, x0, tau, t_eval):
    states, inputs, pvars, f, g = parts
    syms = [v.symbol for v in states + inputs + pvars]
    fn = sp.lambdify(syms, f, "numpy")
    gn = sp.lambdify(syms, g, "numpy")
    sol = solve_ivp(lambda t, x: fn(*x, tau, *params), (t_eval[0], t_eval[-1]), x0, t_eval=t_eval,
                    method="DOP853", rtol=1e-11, atol=1e-12)
    assert sol.success
    y = np.array([gn(*sol.y[:, k], tau, *params) for k in range(len(t_eval))])
    return sol.y.T, y


def spd_reference(parts, params, x0, tau, t_eval):
    q, qd, taus, ps, M, rhs, pos = parts
    syms = list(q) + list(qd) + list(taus) + list(ps)
    Mf, rf = sp.lambdify(syms, M, "numpy"), sp.lambdify(syms, rhs, "numpy")

    def f(t, x):
        a = (*x, *tau, *params)
        return np.concatenate([x[3:], np.linalg.solve(np.asarray(Mf(*a), float),
                                                      np.asarray(rf(*a), float).ravel())])

    sol = solve_ivp(f, (t_eval[0], t_eval[-1]), x0, t_eval=t_eval, method="DOP853", rtol=1e-11, atol=1e-12)
    assert sol.success
    return sol.y.T


# --------------------------------------------------------------------------
# validation and model description
# --------------------------------------------------------------------------
def test_fmus_validate_clean(pend_fmu, spd_fmu):
    for _, _, res in (pend_fmu, spd_fmu):
        assert validate_fmu(str(res.path)) == []


def test_fmu_contents_and_sources(pend_fmu, tmp_path):
    model, _, res = pend_fmu
    with zipfile.ZipFile(res.path) as zf:
        names = set(zf.namelist())
        assert f"binaries/linux64/{res.model_identifier}.so" in names
        for h in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h", "fmugen_model.h",
                  "model.c", "README.txt"):
            assert f"sources/{h}" in names
        for c in runtime_dir().glob("*.c"):
            assert f"sources/{c.name}" in names
        assert res.guid in zf.read("sources/model.c").decode()
        zf.extractall(tmp_path)
    md = read_model_description(str(res.path))
    assert md.guid == res.guid
    # the listed SourceFiles compile on their own, with the command of the README
    listed = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    assert sorted(listed) == sorted([c.name for c in runtime_dir().glob("*.c")] + ["model.c"])
    cmd = (tmp_path / "sources" / "README.txt").read_text().split("\n\n")[1].strip()
    assert os.system(f"cd {tmp_path / 'sources'} && {cmd} 2>/dev/null") == 0


def test_value_references_follow_the_c_contract(spd_fmu):
    """fmpy reads the layout fmugen_model.h documents: x, der(x), u, y, p, runtime."""
    model, _, res = spd_fmu
    md = read_model_description(str(res.path))
    nx, nu, ny, np_ = model.nx, model.nu, model.ny, model.np
    real = {v.name: v.valueReference for v in md.modelVariables if v.type == "Real"}
    for i, v in enumerate(model.states):
        assert real[v.name] == i and real[f"der({v.name})"] == nx + i
    for i, v in enumerate(model.inputs):
        assert real[v.name] == 2 * nx + i
    for i, v in enumerate(model.outputs):
        assert real[v.name] == 2 * nx + nu + i
    for i, v in enumerate(model.parameters):
        assert real[v.name] == 2 * nx + nu + ny + i
    header = (runtime_dir() / "fmugen_model.h").read_text()
    off = int(re.search(r"#define FMUGEN_RT_ATOL (\d+)", header).group(1))
    assert real["solver.atol"] == 2 * nx + nu + ny + np_ + off
    layout = variable_layout(model)
    assert layout.real == real
    assert layout.integer == {v.name: v.valueReference for v in md.modelVariables if v.type == "Integer"}


def test_runtime_parameter_starts_are_the_runtime_defaults():
    """The XML start values must be what fmugen_set_defaults really sets."""
    text = (runtime_dir() / "runtime_support.c").read_text()
    body = text[text.index("void fmugen_set_defaults"):]
    for r in runtime_parameters():
        if r.type == "Real":
            key = "FMUGEN_RT_" + r.name.split(".")[1].upper()
            m = re.search(rf"rt\[{key}\]\s*=\s*([0-9.eE+-]+)\s*;", body)
            assert m, key
            assert float(m.group(1)) == r.start
    m = re.search(r"s\.solver\s*=\s*(FMUGEN_SOLVER_\w+)\s*;", body)
    header = (runtime_dir() / "fmugen_model.h").read_text()
    val = int(re.search(rf"#define {m.group(1)} (\d+)", header).group(1))
    assert [r.start for r in runtime_parameters() if r.name == "solver.method"] == [val]


def test_model_structure_is_exact(pend_fmu):
    """Dependencies against the free symbols of the closed forms (not the program)."""
    model, (states, inputs, params, f, g), res = pend_fmu
    md = read_model_description(str(res.path))
    index = {v.name: k + 1 for k, v in enumerate(md.modelVariables)}
    by_sym = {v.symbol: v.name for v in states + inputs + params}

    def names(unknown):
        return {v.name for v in unknown.dependencies}

    def expected(expr, with_params=False):
        allowed = states + inputs + (params if with_params else [])
        return {by_sym[s] for s in sp.sympify(expr).free_symbols if s in {v.symbol for v in allowed}}

    ders = {u.variable.name: u for u in md.derivatives}
    assert names(ders["der(phi)"]) == {"w"} and ders["der(phi)"].dependenciesKind == ["constant"]
    assert names(ders["der(w)"]) == expected(f[1]) == {"phi", "w", "tau"}
    outs = {u.variable.name: u for u in md.outputs}
    assert set(outs) == {"phi", "x_tip", "y_tip", "E"}
    assert names(outs["phi"]) == {"phi"}
    for i, v in enumerate(model.outputs):
        assert names(outs[v.name]) == expected(g[i])
    init = {u.variable.name: u for u in md.initialUnknowns}
    assert set(init) == {"der(phi)", "der(w)", "x_tip", "y_tip", "E"}
    assert names(init["der(w)"]) == expected(f[1], True) == {"phi", "w", "tau", "g", "L", "m", "d"}
    assert names(init["E"]) == {"phi", "w", "g", "L", "m"}
    assert [u.variable.name for u in md.initialUnknowns] == sorted(init, key=index.get)


def test_spd_model_structure_couples_through_the_solve(spd_fmu):
    model, _, res = spd_fmu
    md = read_model_description(str(res.path))
    ders = {u.variable.name: {v.name for v in u.dependencies} for u in md.derivatives}
    q, qd, tau, ps, M, rhs, pos = spd_model()[1]
    # qdd = M^-1 rhs: each acceleration depends on everything in M and rhs
    name = {v.symbol: v.name for v in model.states + model.inputs}
    expected = {name[s] for s in (M.free_symbols | rhs.free_symbols) if s in name}
    assert expected == set(name.values())  # (this model couples everything)
    for i in range(1, 4):
        assert ders[f"der(qd[{i}])"] == expected
        assert ders[f"der(q[{i}])"] == {f"qd[{i}]"}


def test_units_are_defined_with_si_exponents(spd_fmu):
    md = read_model_description(str(spd_fmu[2].path))
    units = {u.name: u.baseUnit for u in md.unitDefinitions}
    assert (units["N.m"].kg, units["N.m"].m, units["N.m"].s) == (1, 2, -2)
    assert (units["rad/s2"].rad, units["rad/s2"].s) == (1, -2)
    var = {v.name: v for v in md.modelVariables}
    assert var["der(qd[1])"].unit == "rad/s2" and var["tau[1]"].unit == "N.m"


def test_unit_table():
    assert base_units("m3/(s.Pa)").exponents() == {"kg": -1, "m": 4, "s": 1}
    assert base_units("N.m.s/rad").exponents() == {"kg": 1, "m": 2, "s": -1, "rad": -1}
    assert base_units("A/V").exponents() == {"kg": -1, "m": -2, "s": 3, "A": 2}
    assert base_units("kg.m2").exponents() == base_units("N.m.s2").exponents()
    assert base_units("deg").factor == pytest.approx(np.pi / 180)
    with pytest.raises(UnitError, match="unknown unit 'furlong'"):
        base_units("furlong/s")
    with pytest.raises(UnitError, match="more than one '/'"):
        base_units("m/s/s")


def test_unknown_unit_names_the_variable():
    x = sp.Symbol("x")
    m = SymbolicModel.from_equations("u", [Variable("x", x, "parsec", start=1.0)], [], [], [-x])
    with pytest.raises(ValueError, match="variable x: unit 'parsec'"):
        model_description_xml(m, "{g}", "u")


def test_parameter_without_start_is_an_error(tmp_path):
    x, k = sp.symbols("x k")
    m = SymbolicModel.from_equations("nostart", [Variable("x", x, start=1.0)], [],
                                     [Variable("k", k, "1/s")], [-k * x])
    with pytest.raises(ValueError, match="parameter 'k' has no start value"):
        build_fmu(m, tmp_path / "a.fmu")


def test_compiler_error_gives_the_command(tmp_path):
    model, _ = pendulum()
    with pytest.raises(BuildError) as e:
        build_fmu(model, tmp_path / "bad.fmu", extra_cflags=("-fno-such-flag-fmugen",))
    msg = str(e.value)
    cmd = next(line for line in msg.splitlines() if "-fno-such-flag-fmugen" in line)
    assert cmd.strip().startswith("cd ") and re.search(r"\s-c \w+\.c\b", cmd)
    assert "error" in msg  # the compiler's own message
    assert not (tmp_path / "bad.fmu").exists()


def test_builds_are_reproducible(pend_fmu, tmp_path):
    model, _, res = pend_fmu
    again = build_fmu(pendulum()[0], tmp_path / "Pendulum.fmu")
    assert again.guid == res.guid
    with zipfile.ZipFile(res.path) as a, zipfile.ZipFile(again.path) as b:
        assert a.namelist() == b.namelist()
        for n in a.namelist():
            if not n.startswith("binaries/"):
                assert a.read(n) == b.read(n), n


# --------------------------------------------------------------------------
# simulation against scipy
# --------------------------------------------------------------------------
PEND_START = {"phi": 1.2, "w": -0.5, "tau": 0.4, "g": 9.81, "L": 0.7, "m": 1.3, "d": 0.05}


def _pend_case(parts):
    params = [PEND_START[n] for n in ("g", "L", "m", "d")]
    t = np.linspace(0.0, 2.0, 41)
    return pendulum_reference(parts, params, [PEND_START["phi"], PEND_START["w"]], PEND_START["tau"], t)


@pytest.mark.parametrize("fmi_type", ["ModelExchange", "CoSimulation"])
def test_pendulum_simulation_matches_scipy(pend_fmu, fmi_type):
    model, parts, res = pend_fmu
    start = dict(PEND_START, g=3.7)  # a parameter changed through the FMI interface
    params = [start[n] for n in ("g", "L", "m", "d")]
    t = np.linspace(0.0, 2.0, 41)
    x_ref, y_ref = pendulum_reference(parts, params, [start["phi"], start["w"]], start["tau"], t)
    if fmi_type == "CoSimulation":
        start.update({"solver.rtol": 1e-9, "solver.atol": 1e-11})
        kw = {}
    else:
        kw = {"relative_tolerance": 1e-10}
    r = simulate_fmu(str(res.path), fmi_type=fmi_type, start_values=start, stop_time=2.0,
                     output_interval=0.05, output=["phi", "x_tip", "y_tip", "E"], **kw)
    assert np.allclose(r["time"], t)
    tol = 1e-6
    np.testing.assert_allclose(r["phi"], x_ref[:, 0], atol=tol)
    np.testing.assert_allclose(r["x_tip"], y_ref[:, 0], atol=tol)
    np.testing.assert_allclose(r["y_tip"], y_ref[:, 1], atol=tol)
    np.testing.assert_allclose(r["E"], y_ref[:, 2], atol=10 * tol)


@pytest.mark.parametrize("method", [0, 1, 2])
def test_spd_model_simulation_matches_scipy(spd_fmu, method):
    """ME (fmpy's CVode, method 0) and both CS solvers (1 Dormand-Prince; 2 the implicit
    one, which uses the generated Jacobian)."""
    model, parts, res = spd_fmu
    x0 = [0.4, -0.3, 0.8, 0.2, 0.0, -0.5]
    tau = [1.0, -0.5, 0.3]
    start = {v.name: x for v, x in zip(model.states, x0)}
    start.update({f"tau[{i + 1}]": v for i, v in enumerate(tau)})
    rtol = 1e-8
    if method:
        start.update({"solver.method": method, "solver.rtol": rtol, "solver.atol": rtol})
        kw = {"fmi_type": "CoSimulation"}
    else:
        kw = {"fmi_type": "ModelExchange", "relative_tolerance": rtol}
    t = np.linspace(0.0, 2.0, 21)
    x_ref = spd_reference(parts, [3.0, 0.8, 0.5, 2.0], x0, tau, t)
    r = simulate_fmu(str(res.path), start_values=start, stop_time=2.0,
                     output_interval=0.1, output=[v.name for v in model.states], **kw)
    got = np.column_stack([r[v.name] for v in model.states])
    err = np.max(np.abs(got - x_ref) / np.maximum(1.0, np.abs(x_ref)))
    print(f"solver {method}: max scaled error {err:.2e} at rtol = atol = {rtol}")
    assert err < 10 * rtol


def test_folded_fmu_simulates_like_the_parameterised_one(pend_fmu, tmp_path):
    model, parts, res = pend_fmu
    folded = build_fmu(pendulum()[0], tmp_path / "PendulumFolded.fmu", fmi_type="me", fold_parameters="all")
    assert validate_fmu(str(folded.path)) == []
    md = read_model_description(str(folded.path))
    assert not [v for v in md.modelVariables if v.causality == "parameter" and not v.name.startswith("solver.")]
    assert md.coSimulation is None
    assert folded.op_counts["evaluate"].mul < res.op_counts["evaluate"].mul
    start = {"phi": 1.2, "w": -0.5, "tau": 0.4}
    kw = dict(stop_time=1.0, output_interval=0.05, relative_tolerance=1e-10, output=["phi", "w"])
    a = simulate_fmu(str(folded.path), start_values=start, **kw)
    b = simulate_fmu(str(res.path), fmi_type="ModelExchange", start_values=start, **kw)
    np.testing.assert_allclose(a["phi"], b["phi"], atol=1e-8)
    x_ref, _ = pendulum_reference(parts, [9.81, 0.7, 1.3, 0.05], [1.2, -0.5], 0.4, np.linspace(0, 1, 21))
    np.testing.assert_allclose(a["w"], x_ref[:, 1], atol=1e-6)


def test_fold_parameters_by_name(tmp_path):
    model, _ = pendulum()
    res = build_fmu(model, tmp_path / "p.fmu", fmi_type="cs", fold_parameters=["g", "d"])
    md = read_model_description(str(res.path))
    params = [v.name for v in md.modelVariables if v.causality == "parameter"]
    assert params[:2] == ["L", "m"]
    with pytest.raises(ValueError, match="not parameters of 'Pendulum'"):
        build_fmu(model, tmp_path / "q.fmu", fold_parameters=["gee"])


def test_directional_derivatives_are_the_generated_jacobian(spd_fmu, tmp_path):
    """fmi2GetDirectionalDerivative (value references from the XML) against central
    differences of fmi2GetDerivatives, through fmpy's ME API."""
    from fmpy import extract
    from fmpy.fmi2 import FMU2Model

    model, _, res = spd_fmu
    md = read_model_description(str(res.path))
    assert md.modelExchange.providesDirectionalDerivative
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extract(str(res.path), str(tmp_path / "x")),
                    modelIdentifier=md.modelExchange.modelIdentifier, instanceName="dd")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.enterContinuousTimeMode()
    x0 = np.array([0.4, -0.3, 0.8, 0.2, 0.1, -0.5])
    u0 = np.array([1.0, -0.5, 0.3])
    tau_vr = [vr[v.name] for v in model.inputs]
    fmu.setReal(tau_vr, list(u0))
    ders = [vr[f"der({v.name})"] for v in model.states]
    outs = [vr[v.name] for v in model.outputs]

    def f(x, u):
        x = np.ascontiguousarray(x, float)
        fmu.setContinuousStates(x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), len(x))
        fmu.setReal(tau_vr, list(u))
        dx = np.zeros(len(x))
        fmu.getDerivatives(dx.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), len(x))
        return dx, np.array(fmu.getReal(outs))

    h = 1e-6
    knowns = [(v.name, k) for k, v in enumerate(model.states)] + [(v.name, 6 + k) for k, v in
                                                                  enumerate(model.inputs)]
    for name, k in knowns:
        z = np.concatenate([x0, u0])
        zp, zm = z.copy(), z.copy()
        zp[k] += h
        zm[k] -= h
        fp, yp = f(zp[:6], zp[6:])
        fm, ym = f(zm[:6], zm[6:])
        f(x0, u0)
        dd = fmu.getDirectionalDerivative(ders + outs, [vr[name]], [1.0])
        np.testing.assert_allclose(dd[:6], (fp - fm) / (2 * h), rtol=1e-6, atol=1e-7, err_msg=name)
        np.testing.assert_allclose(dd[6:], (yp - ym) / (2 * h), rtol=1e-6, atol=1e-7, err_msg=name)
    fmu.terminate()
    fmu.freeInstance()


def test_model_without_jacobian(tmp_path):
    """No jacobian program: has_jacobian 0, no directional derivatives declared."""
    from dataclasses import replace

    model, parts = pendulum()
    nojac = replace(model, jacobian=None, dfdx=None, dfdu=None, dgdx=None, dgdu=None, name="PendulumNoJac")
    res = build_fmu(nojac, tmp_path, fmi_type="both")
    assert "jacobian" not in res.op_counts
    assert validate_fmu(str(res.path)) == []
    md = read_model_description(str(res.path))
    assert not md.modelExchange.providesDirectionalDerivative
    assert not md.coSimulation.providesDirectionalDerivative
    x_ref, _ = _pend_case(parts)
    r = simulate_fmu(str(res.path), fmi_type="CoSimulation", stop_time=2.0, output_interval=0.05,
                     start_values={k: v for k, v in PEND_START.items()} | {"solver.rtol": 1e-9,
                                                                             "solver.atol": 1e-11})
    np.testing.assert_allclose(r["phi"], x_ref[:, 0], atol=1e-6)
