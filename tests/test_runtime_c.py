"""Tests of the hand-written FMI 2.0 runtime in c_runtime/.

The runtime is compiled with two hand-written models (tests/c_models/): a
forced Van der Pol oscillator with a mass (``vdp``) and a stiff linear chain
with eigenvalues -1 and -1e5 (``stiff``).  Results are checked against
scipy's ``solve_ivp`` at rtol 1e-12, finite differences and closed forms;
misuse through the FMI API is checked for fmi2Error plus a logged message.
"""
import ctypes
import os
import shutil
import subprocess
import threading
import zipfile
from ctypes import byref, c_double, c_int, c_size_t, c_uint, POINTER
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fmpy
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Model, FMU2Slave, fmi2CallbackFunctions, fmi2Discard, fmi2Error, fmi2EventInfo,
                       fmi2LastSuccessfulTime, fmi2Terminated, fmi2DoStepStatus)
from fmpy.validation import validate_fmu

from fmi_log import Log

ROOT = Path(__file__).resolve().parents[1]
RUNTIME = ROOT / "c_runtime"
MODELS = Path(__file__).resolve().parent / "c_models"
FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"
CFLAGS = ["-O2", "-fPIC", "-Wall", "-Wextra", "-Werror", f"-I{RUNTIME}", f"-I{FMI_HEADERS}"]

# value references (fmugen_model.h layout)
VDP = dict(x=0, v=1, der_x=2, der_v=3, F=4, E=5, z=6, mu=7, m=8, k=9, rtol=10, atol=11, max_step=12,
           fixed_step=13)
STIFF = dict(y_slow=0, y_fast=1, der_slow=2, der_fast=3, w=4, s=5, a=6, L=7, rtol=8, atol=9, max_step=10,
             fixed_step=11)
INT_SOLVER, INT_N_STEPS, INT_N_REJECTED, INT_N_RHS, INT_N_JAC = range(5)
DOPRI5, IMPLICIT, RK4 = 1, 2, 3


def _build(out_dir, objects, name, defines=()):
    """Compile tests/c_models/<name>/model.c, link it with the runtime objects
    and zip an FMU; returns its path."""
    work = out_dir / f"{name}{'_'.join(d for d in defines)}"
    binaries = work / "fmu" / "binaries" / "linux64"
    binaries.mkdir(parents=True)
    shutil.copy(MODELS / name / "modelDescription.xml", work / "fmu" / "modelDescription.xml")
    model_o = work / "model.o"
    subprocess.run(["gcc", *CFLAGS, *[f"-D{d}" for d in defines], "-c", str(MODELS / name / "model.c"),
                    "-o", str(model_o)], check=True, capture_output=True, text=True)
    subprocess.run(["gcc", "-shared", "-o", str(binaries / f"{name}.so"), str(model_o), *map(str, objects), "-lm"],
                   check=True, capture_output=True, text=True)
    fmu = out_dir / f"{work.name}.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        for f in (work / "fmu").rglob("*"):
            z.write(f, f.relative_to(work / "fmu"))
    return fmu


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("runtime")
    objects = []
    for src in sorted(RUNTIME.glob("*.c")):
        o = out / (src.stem + ".o")
        r = subprocess.run(["gcc", *CFLAGS, "-c", str(src), "-o", str(o)], capture_output=True, text=True)
        assert r.returncode == 0, f"{src.name} does not compile warning-free:\n{r.stderr}"
        objects.append(o)
    return dict(vdp=_build(out, objects, "vdp"), stiff=_build(out, objects, "stiff"),
                vdp_nojac=_build(out, objects, "vdp", ["FMUGEN_TEST_NO_JACOBIAN"]),
                stiff_nojac=_build(out, objects, "stiff", ["FMUGEN_TEST_NO_JACOBIAN"]), out=out, objects=objects)


def open_fmu(path, cls, tmp, name="inst", log=None):
    md = read_model_description(str(path))
    unzip = fmpy.extract(str(path), unzipdir=str(tmp / f"{path.stem}_{name}_{cls.__name__}"))
    mi = md.coSimulation.modelIdentifier if cls is FMU2Slave else md.modelExchange.modelIdentifier
    fmu = cls(guid=md.guid, unzipDirectory=unzip, modelIdentifier=mi, instanceName=name)
    log = log or Log()
    fmu.instantiate(callbacks=log.callbacks)
    fmu.log = log
    return fmu


def vdp_rhs(mu=1.0, m=1.0, F=lambda t: 0.0):
    return lambda t, y: [y[1], (mu * (1 - y[0] ** 2) * y[1] - y[0] + F(t)) / m]


def reference(rhs, y0, t, method="DOP853"):
    sol = solve_ivp(rhs, (t[0], t[-1]), y0, method=method, t_eval=t, rtol=1e-12, atol=1e-12)
    assert sol.success
    return sol.y.T


def me_get(getter, n=2):
    """Call an fmpy FMU2Model getter that fills a caller-provided array."""
    buf = (c_double * n)()
    getter(buf, n)
    return list(buf)


def start_cs(fmu, solver=DOPRI5, reals=None, t0=0.0):
    fmu.setupExperiment(startTime=t0)
    fmu.setInteger([INT_SOLVER], [solver])
    if reals:
        fmu.setReal(list(reals.keys()), list(reals.values()))
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()


def run_cs(fmu, times, vrs):
    out = [fmu.getReal(vrs)]
    for t0, t1 in zip(times[:-1], times[1:]):
        fmu.doStep(t0, t1 - t0)
        out.append(fmu.getReal(vrs))
    return np.array(out)


# ---------------------------------------------------------------------------
# model description, ME and CS against scipy
# ---------------------------------------------------------------------------

def test_runtime_compiles_and_fmus_validate(fmus):
    for key in ("vdp", "stiff"):
        assert validate_fmu(str(fmus[key])) == [], key


def test_model_exchange_matches_scipy(fmus):
    res = simulate_fmu(str(fmus["vdp"]), fmi_type="ModelExchange", stop_time=5.0, output_interval=0.05,
                       relative_tolerance=1e-10, start_values={"mu": 1.5, "F": 0.3}, output=["x", "v", "z"])
    ref = reference(vdp_rhs(1.5, F=lambda t: 0.3), [2.0, 0.0], res["time"])
    err = np.max(np.abs(np.column_stack([res["x"], res["v"]]) - ref))
    assert err < 1e-6, err  # CVode at rtol 1e-10: global error well below 1e-6
    np.testing.assert_allclose(res["z"], ref[:, 1] + 0.5 * 0.3, atol=1e-6)


@pytest.mark.parametrize("solver,rtol,tol", [(DOPRI5, 1e-6, 1e-5), (DOPRI5, 1e-9, 1e-8), (IMPLICIT, 1e-6, 1e-5),
                                             (IMPLICIT, 1e-8, 1e-7)])
def test_co_simulation_matches_scipy(fmus, solver, rtol, tol):
    """Each adaptive solver within 10x its requested tolerance (rtol = atol)."""
    res = simulate_fmu(str(fmus["vdp"]), fmi_type="CoSimulation", stop_time=5.0, output_interval=0.05,
                       start_values={"mu": 1.5, "F": 0.3, "solver": solver, "rtol": rtol, "atol": rtol},
                       output=["x", "v", "n_steps", "n_rejected"])
    ref = reference(vdp_rhs(1.5, F=lambda t: 0.3), [2.0, 0.0], res["time"])
    err = np.max(np.abs(np.column_stack([res["x"], res["v"]]) - ref))
    assert err < tol, (solver, err)
    assert res["n_steps"][-1] > 0


def test_rk4_fixed_step_error_is_fourth_order(fmus, tmp_path):
    """RK4 with fixed_step h: global error ~ C h^4 (halving h divides it by ~16)."""
    errs = []
    times = np.linspace(0, 2, 21)
    ref = reference(vdp_rhs(), [2.0, 0.0], times)
    for h in (0.02, 0.01):
        fmu = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name=f"h{h}")
        start_cs(fmu, RK4, {VDP["fixed_step"]: h})
        out = run_cs(fmu, times, [VDP["x"], VDP["v"]])
        n_steps, = fmu.getInteger([INT_N_STEPS])
        assert n_steps == round(2 / h)
        errs.append(np.max(np.abs(out - ref)))
        fmu.terminate()
        fmu.freeInstance()
    ratio = errs[0] / errs[1]
    assert 12 < ratio < 20, errs


def test_variable_communication_steps_and_input_ramp(fmus, tmp_path):
    """Random communication step sizes; the input F changes between steps and
    is extrapolated within a step from fmi2SetRealInputDerivatives."""
    rng = np.random.default_rng(1)
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.01, 0.3, 25))])
    F = lambda t: 0.2 + 0.5 * t  # applied as value + first derivative at each communication point
    ref = reference(vdp_rhs(F=F), [2.0, 0.0], times)
    for solver in (DOPRI5, IMPLICIT):
        fmu = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name=f"var{solver}")
        start_cs(fmu, solver, {VDP["rtol"]: 1e-8, VDP["atol"]: 1e-8})
        out = [fmu.getReal([VDP["x"], VDP["v"]])]
        for t0, t1 in zip(times[:-1], times[1:]):
            fmu.setReal([VDP["F"]], [F(t0)])
            fmu.setRealInputDerivatives([VDP["F"]], [1], [0.5])
            fmu.doStep(t0, t1 - t0)
            out.append(fmu.getReal([VDP["x"], VDP["v"]]))
        err = np.max(np.abs(np.array(out) - ref))
        assert err < 1e-7, (solver, err)
        # after the step the input holds its extrapolated value
        assert fmu.getReal([VDP["F"]])[0] == pytest.approx(F(times[-1]), rel=1e-14)
        fmu.freeInstance()


# ---------------------------------------------------------------------------
# stiffness: RK4 above its stability limit fails loudly, RODAS3 does not
# ---------------------------------------------------------------------------

def stiff_reference(times, L=1e5):
    return reference(lambda t, y: [-y[0] + y[1], -L * (y[1] - 1.0)], [0.0, 0.0], times, method="Radau")


def test_rk4_unstable_on_stiff_model_returns_discard(fmus, tmp_path):
    # h L = 10 > 2.785: |R(-10)| = 291, the state would overflow within ~130 steps; RK4's own
    # estimate of its limit (2.785e-5 s) refuses the first step (issue 19: never OK beyond it)
    fmu = open_fmu(fmus["stiff"], FMU2Slave, tmp_path, name="rk4bad")
    start_cs(fmu, RK4)
    x0 = fmu.getReal([0, 1])
    with pytest.raises(FMICallException) as info:
        for k in range(2000):
            fmu.doStep(k * 1e-4, 1e-4)
    assert info.value.status == fmi2Discard
    assert "exceeds the RK4 stability limit ~ 27.9 us" in fmu.log.last() and "not taken" in fmu.log.last()
    t_ok = fmu.getRealStatus(fmi2LastSuccessfulTime)
    assert t_ok == 0.0 and fmu.getReal([0, 1]) == x0
    assert fmu.getStatus(fmi2DoStepStatus) == fmi2Discard
    assert fmu.getBooleanStatus(fmi2Terminated) == 0
    assert np.all(np.isfinite(fmu.getReal([0, 1])))  # state kept at the last good point
    with pytest.raises(FMICallException):  # stepFailed: no further doStep
        fmu.doStep(t_ok, 1e-4)
    fmu.terminate()
    fmu.freeInstance()
    # below the limit (h L = 2) the same method is stable and accurate
    fmu = open_fmu(fmus["stiff"], FMU2Slave, tmp_path, name="rk4good")
    start_cs(fmu, RK4, {STIFF["fixed_step"]: 2e-5})
    times = np.linspace(0, 0.05, 6)
    out = run_cs(fmu, times, [0, 1])
    assert np.max(np.abs(out - stiff_reference(times))) < 1e-6
    fmu.freeInstance()


@pytest.mark.parametrize("key", ["stiff", "stiff_nojac"])
def test_implicit_solver_with_macro_steps_far_beyond_stability_limit(fmus, tmp_path, key):
    """Communication steps of 1e-2 s (360x the RK4 limit 2.785e-5 s) with
    RODAS3: within 10x the tolerance of a Radau rtol 1e-12 reference, in a
    few hundred internal steps (an explicit method needs > 2 / 2.8e-5)."""
    fmu = open_fmu(fmus[key], FMU2Slave, tmp_path, name="impl")
    start_cs(fmu, IMPLICIT, {STIFF["rtol"]: 1e-6, STIFF["atol"]: 1e-6})
    times = np.linspace(0, 2, 201)
    out = run_cs(fmu, times, [0, 1])
    err = np.max(np.abs(out - stiff_reference(times)))
    assert err < 1e-5, err
    n_steps, n_rej, n_rhs, n_jac = fmu.getInteger([INT_N_STEPS, INT_N_REJECTED, INT_N_RHS, INT_N_JAC])
    assert n_steps < 2000 and n_jac >= n_steps
    if key == "stiff_nojac":  # finite-difference Jacobian costs nx f-evaluations each
        assert n_rhs >= 2 * n_jac
    fmu.freeInstance()


def test_implicit_solver_is_l_stable(fmus, tmp_path):
    """L = 1e12, one communication step of 1 s: an L-stable method damps the
    fast mode completely (y_fast = w) and the slow mode follows the closed
    form y_slow = 1 - exp(-t) (within the tolerance)."""
    fmu = open_fmu(fmus["stiff"], FMU2Slave, tmp_path, name="lstab")
    start_cs(fmu, IMPLICIT, {STIFF["L"]: 1e12})
    fmu.doStep(0.0, 1.0)
    y_slow, y_fast = fmu.getReal([0, 1])
    assert abs(y_fast - 1.0) < 1e-9
    assert abs(y_slow - (1 - np.exp(-1.0))) < 1e-5
    fmu.freeInstance()


def test_dopri5_on_stiff_model_stays_accurate(fmus, tmp_path):
    """The explicit adaptive method stays stable (its step control keeps h L
    near its stability limit ~3.3) and accurate, at many steps."""
    fmu = open_fmu(fmus["stiff"], FMU2Slave, tmp_path, name="dp")
    start_cs(fmu, DOPRI5)
    times = np.linspace(0, 0.2, 11)
    out = run_cs(fmu, times, [0, 1])
    assert np.max(np.abs(out - stiff_reference(times))) < 1e-5
    n_steps, = fmu.getInteger([INT_N_STEPS])
    assert n_steps > 0.2 * 1e5 / 3.4 * 0.8  # bounded by stability, not accuracy
    fmu.freeInstance()


# ---------------------------------------------------------------------------
# misuse through the API
# ---------------------------------------------------------------------------

def expect_error(fmu, call, *words, status=fmi2Error):
    n = len(fmu.log.messages)
    with pytest.raises(FMICallException) as info:
        call()
    assert info.value.status == status
    assert len(fmu.log.messages) > n, "no message logged"
    msg = fmu.log.last()
    for w in words:
        assert w in msg, (w, msg)


def test_wrong_state_calls(fmus, tmp_path):
    cs = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name="ws")
    expect_error(cs, lambda: cs.doStep(0.0, 0.1), "fmi2DoStep", "instantiated")
    expect_error(cs, lambda: cs.getReal([0]), "fmi2GetReal", "instantiated")
    expect_error(cs, lambda: cs.exitInitializationMode(), "fmi2ExitInitializationMode")
    expect_error(cs, lambda: cs.terminate(), "fmi2Terminate")
    start_cs(cs)
    expect_error(cs, lambda: cs.setupExperiment(startTime=0.0), "fmi2SetupExperiment", "stepComplete")
    expect_error(cs, lambda: cs.enterInitializationMode(), "fmi2EnterInitializationMode")
    expect_error(cs, lambda: cs.setReal([VDP["mu"]], [2.0]), "mu", "value reference 7", "parameter")
    expect_error(cs, lambda: cs.setReal([VDP["x"]], [1.0]), "state")
    expect_error(cs, lambda: cs.setInteger([INT_SOLVER], [2]), "solver")
    expect_error(cs, lambda: cs.fmi2CancelStep(cs.component), "fmi2CancelStep")
    # an ME function on a CS instance
    lib = cs.dll
    lib.fmi2EnterEventMode.restype = c_int
    assert lib.fmi2EnterEventMode(ctypes.c_void_p(cs.component)) == fmi2Error
    assert "Model Exchange function" in cs.log.last()
    cs.doStep(0.0, 0.1)  # the refused calls changed nothing
    cs.terminate()
    expect_error(cs, lambda: cs.doStep(0.1, 0.1), "terminated")
    cs.reset()
    start_cs(cs, IMPLICIT, {VDP["mu"]: 2.0})  # usable again after reset
    assert cs.getReal([VDP["mu"], VDP["x"]]) == [2.0, 2.0]
    cs.freeInstance()

    me = open_fmu(fmus["vdp"], FMU2Model, tmp_path, name="wsme")
    me.setupExperiment(startTime=0.0)
    expect_error(me, lambda: me_get(me.getDerivatives), "fmi2GetDerivatives", "instantiated")
    me.enterInitializationMode()
    me.exitInitializationMode()
    expect_error(me, lambda: me.setContinuousStates((c_double * 2)(1, 2), 2), "fmi2SetContinuousStates",
                 "eventMode")
    expect_error(me, lambda: me.completedIntegratorStep(), "fmi2CompletedIntegratorStep")
    do_step = me.dll.fmi2DoStep
    do_step.argtypes, do_step.restype = [ctypes.c_void_p, c_double, c_double, c_int], c_int
    assert do_step(me.component, 0.0, 0.1, 1) == fmi2Error and "Co-Simulation function" in me.log.last()
    me.enterContinuousTimeMode()
    expect_error(me, lambda: me.newDiscreteStates(), "fmi2NewDiscreteStates", "continuousTimeMode")
    expect_error(me, lambda: me.setContinuousStates((c_double * 3)(1, 2, 3), 3), "nx = 3", "has 2")
    fn = me.dll.fmi2GetEventIndicators
    fn.argtypes, fn.restype = [ctypes.c_void_p, POINTER(c_double), c_size_t], c_int
    assert fn(me.component, (c_double * 1)(), 1) == fmi2Error and "ni = 1" in me.log.last()
    assert fn(me.component, None, 0) == 0
    me.freeInstance()


def test_bad_value_references_null_arrays_and_nan(fmus, tmp_path):
    cs = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name="bad")
    cs.setupExperiment(startTime=0.0)
    expect_error(cs, lambda: cs.setReal([VDP["der_x"]], [1.0]), "der(x)", "value reference 2")
    expect_error(cs, lambda: cs.setReal([VDP["E"]], [1.0]), "E", "value reference 5", "output")
    expect_error(cs, lambda: cs.setReal([99], [1.0]), "value reference 99", "unknown")
    expect_error(cs, lambda: cs.setInteger([INT_N_STEPS], [3]), "n_steps")
    expect_error(cs, lambda: cs.setInteger([INT_SOLVER], [7]), "solver = 7")
    expect_error(cs, lambda: cs.setReal([VDP["rtol"]], [-1e-6]), "rtol")
    expect_error(cs, lambda: cs.setReal([VDP["atol"]], [0.0]), "atol")
    expect_error(cs, lambda: cs.setBoolean([0], [True]), "value reference 0")
    for name, vr in (("F", VDP["F"]), ("mu", VDP["mu"]), ("x", VDP["x"])):
        for bad in (float("nan"), float("inf")):
            expect_error(cs, lambda: cs.setReal([vr], [bad]), name, "not finite")
    # a refused multi-variable call changes nothing, not even the good part
    expect_error(cs, lambda: cs.setReal([VDP["mu"], VDP["F"]], [3.0, float("nan")]), "F")
    # NULL arrays with nvr > 0
    fn = cs.dll.fmi2SetReal
    fn.argtypes, fn.restype = [ctypes.c_void_p, POINTER(c_uint), c_size_t, POINTER(c_double)], c_int
    assert fn(cs.component, None, 2, None) == fmi2Error and "NULL" in cs.log.last()
    fn = cs.dll.fmi2GetReal
    fn.argtypes, fn.restype = [ctypes.c_void_p, POINTER(c_uint), c_size_t, POINTER(c_double)], c_int
    cs.enterInitializationMode()
    assert fn(cs.component, (c_uint * 1)(0), 1, None) == fmi2Error and "value[]" in cs.log.last()
    assert fn(cs.component, None, 0, None) == 0  # nvr = 0 is a no-op
    cs.exitInitializationMode()
    assert cs.getReal([VDP["mu"]]) == [1.0]
    expect_error(cs, lambda: cs.getReal([1000]), "unknown value reference 1000")
    expect_error(cs, lambda: cs.doStep(0.5, 0.1), "currentCommunicationPoint")
    expect_error(cs, lambda: cs.doStep(0.0, -0.1), "step size")
    expect_error(cs, lambda: cs.setRealInputDerivatives([VDP["x"]], [1], [1.0]), "not an input")
    expect_error(cs, lambda: cs.setRealInputDerivatives([VDP["F"]], [1], [float("nan")]), "not finite")
    n = len(cs.log.messages)
    cs.setRealInputDerivatives([VDP["F"]] * 2, [2, 3], [1.0, 1.0])  # second and third derivatives are used: no message
    assert len(cs.log.messages) == n
    cs.setRealInputDerivatives([VDP["F"]], [4], [1.0])  # fmi2Warning: fourth derivatives are ignored
    assert len(cs.log.messages) == n + 1 and cs.log.messages[-1][0] == 1 and "ignored" in cs.log.last()
    cs.freeInstance()


def test_instantiate_refuses_bad_arguments(fmus, tmp_path):
    md = read_model_description(str(fmus["vdp"]))
    unzip = fmpy.extract(str(fmus["vdp"]), unzipdir=str(tmp_path / "inst"))
    lib = ctypes.CDLL(str(Path(unzip) / "binaries" / "linux64" / "vdp.so"))
    lib.fmi2Instantiate.restype = ctypes.c_void_p
    lib.fmi2Instantiate.argtypes = [ctypes.c_char_p, c_int, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_void_p,
                                    c_int, c_int]
    log = Log()
    cb = ctypes.cast(byref(log.callbacks), ctypes.c_void_p)
    assert lib.fmi2Instantiate(b"a", 1, b"{wrong}", b"", cb, 0, 0) is None
    assert "GUID" in log.last()
    assert lib.fmi2Instantiate(b"a", 7, md.guid.encode(), b"", cb, 0, 0) is None
    assert "fmuType" in log.last()
    assert lib.fmi2Instantiate(b"", 1, md.guid.encode(), b"", cb, 0, 0) is None
    assert lib.fmi2Instantiate(b"a", 1, md.guid.encode(), b"", None, 0, 0) is None
    null_logger = fmi2CallbackFunctions()
    assert lib.fmi2Instantiate(b"a", 1, md.guid.encode(), b"", ctypes.cast(byref(null_logger), ctypes.c_void_p),
                               0, 0) is None


def test_model_failure_is_reported_not_nan(fmus, tmp_path):
    """m <= 0: the 1x1 'mass matrix' is not positive definite."""
    cs = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name="npd")
    cs.setupExperiment(startTime=0.0)
    cs.setReal([VDP["m"]], [-1.0])
    cs.enterInitializationMode()
    expect_error(cs, lambda: cs.exitInitializationMode(), "not positive definite")
    expect_error(cs, lambda: cs.getReal([VDP["der_v"]]), "not positive definite")
    cs.freeInstance()
    me = open_fmu(fmus["vdp"], FMU2Model, tmp_path, name="npdme")
    me.setupExperiment(startTime=0.0)
    me.enterInitializationMode()
    me.exitInitializationMode()
    me.enterContinuousTimeMode()
    assert np.all(np.isfinite(me_get(me.getDerivatives)))
    me.freeInstance()


def test_debug_logging_categories(fmus, tmp_path):
    cs = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name="dbg")
    start_cs(cs)
    n = len(cs.log.messages)
    cs.doStep(0.0, 0.1)
    assert len(cs.log.messages) == n  # logging off: OK messages suppressed
    cs.setDebugLogging(True, ["logAll"])
    cs.doStep(0.1, 0.1)
    assert cs.log.messages[-1][1] == "logAll" and "steps" in cs.log.last()
    expect_error(cs, lambda: cs.setDebugLogging(True, ["logNothing"]), "logNothing")
    cs.freeInstance()


# ---------------------------------------------------------------------------
# FMU state, serialisation, independence
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("solver", [DOPRI5, IMPLICIT, RK4])
def test_fmu_state_restores_continuation_bit_for_bit(fmus, tmp_path, solver):
    fmu = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name=f"st{solver}")
    start_cs(fmu, solver, {VDP["fixed_step"]: 0.01})
    vrs = [VDP["x"], VDP["v"], VDP["E"], VDP["z"]]
    run_cs(fmu, np.linspace(0, 1, 7), vrs)
    fmu.setReal([VDP["F"]], [0.7])
    fmu.setRealInputDerivatives([VDP["F"]], [1], [-0.3])
    state = fmu.getFMUstate()
    times = np.linspace(1, 3, 9)
    first = run_cs(fmu, times, vrs)
    ints = fmu.getInteger([1, 2, 3, 4])
    blob = fmu.serializeFMUstate(state)
    fmu.setFMUstate(state)
    again = run_cs(fmu, times, vrs)
    assert np.array_equal(first, again)
    assert fmu.getInteger([1, 2, 3, 4]) == ints
    # through a serialised blob into a fresh instance
    other = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name=f"st{solver}b")
    start_cs(other)
    restored = other.deSerializeFMUstate(blob)
    other.setFMUstate(restored)
    assert np.array_equal(run_cs(other, times, vrs), first)
    assert other.getInteger([INT_SOLVER]) == [solver]
    assert other.serializeFMUstate(restored) == blob
    other.freeFMUstate(restored)
    fmu.freeFMUstate(state)
    fmu.freeInstance()
    other.freeInstance()


def test_bad_serialized_states_are_refused(fmus, tmp_path):
    fmu = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name="blob")
    start_cs(fmu)
    state = fmu.getFMUstate()
    blob = bytearray(fmu.serializeFMUstate(state))
    flipped = bytearray(blob)
    flipped[len(blob) // 2] ^= 0x40
    cases = [(bytes(blob[:-9]), "bytes"), (bytes(flipped), "checksum"), (b"XXXXXXXX" + bytes(blob[8:]), "magic"),
             (b"short", "short")]
    for bad, word in cases:
        expect_error(fmu, lambda: fmu.deSerializeFMUstate(bad), word)
    # a state of another FMU (other GUID)
    stiff = open_fmu(fmus["stiff"], FMU2Slave, tmp_path, name="blob2")
    start_cs(stiff)
    expect_error(stiff, lambda: stiff.deSerializeFMUstate(bytes(blob)), "GUID")
    # an ME instance of the same FMU refuses a CS state
    me = open_fmu(fmus["vdp"], FMU2Model, tmp_path, name="blob3")
    expect_error(me, lambda: me.deSerializeFMUstate(bytes(blob)), "type")
    for f in (fmu, stiff, me):
        f.freeInstance()


def test_model_exchange_state_and_cache(fmus, tmp_path):
    me = open_fmu(fmus["vdp"], FMU2Model, tmp_path, name="mest")
    me.setupExperiment(startTime=0.0)
    me.enterInitializationMode()
    me.exitInitializationMode()
    info = fmi2EventInfo()
    me.fmi2NewDiscreteStates(me.component, byref(info))
    assert not info.newDiscreteStatesNeeded and not info.nextEventTimeDefined
    me.enterContinuousTimeMode()
    x = np.array([0.3, -1.2])
    me.setTime(0.5)
    me.setContinuousStates((c_double * 2)(*x), 2)
    state = me.getFMUstate()
    d0 = np.array(me_get(me.getDerivatives))
    np.testing.assert_allclose(d0, vdp_rhs()(0.5, x), rtol=1e-15)
    # one evaluation serves derivatives and outputs at the same point
    np.testing.assert_allclose(me.getReal([VDP["E"], VDP["z"]]), [0.5 * (x[1] ** 2 + x[0] ** 2), x[1]], rtol=1e-15)
    me.setContinuousStates((c_double * 2)(5.0, 5.0), 2)
    assert not np.array_equal(me_get(me.getDerivatives), d0)
    me.setFMUstate(state)
    assert np.array_equal(me_get(me.getDerivatives), d0)
    assert list(me_get(me.getContinuousStates)) == list(x)
    assert list(me_get(me.getNominalsOfContinuousStates)) == [1.0, 1.0]
    me.freeFMUstate(state)
    me.freeInstance()


def _trajectory(path, tmp, name, mu, solver, log=None):
    fmu = open_fmu(path, FMU2Slave, tmp, name=name, log=log)
    start_cs(fmu, solver, {VDP["mu"]: mu})
    out = run_cs(fmu, np.linspace(0, 4, 41), [VDP["x"], VDP["v"]])
    fmu.freeInstance()
    return out


def test_two_instances_and_two_threads_are_independent(fmus, tmp_path):
    alone = {mu: _trajectory(fmus["vdp"], tmp_path, f"alone{mu}", mu, IMPLICIT) for mu in (0.5, 3.0)}
    assert not np.array_equal(alone[0.5], alone[3.0])
    # interleaved in one process
    a = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name="A")
    b = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name="B")
    start_cs(a, IMPLICIT, {VDP["mu"]: 0.5})
    start_cs(b, IMPLICIT, {VDP["mu"]: 3.0})
    times = np.linspace(0, 4, 41)
    out_a, out_b = [a.getReal([0, 1])], [b.getReal([0, 1])]
    for t0, t1 in zip(times[:-1], times[1:]):
        a.doStep(t0, t1 - t0)
        b.doStep(t0, t1 - t0)
        out_a.append(a.getReal([0, 1]))
        out_b.append(b.getReal([0, 1]))
    assert np.array_equal(np.array(out_a), alone[0.5]) and np.array_equal(np.array(out_b), alone[3.0])
    a.freeInstance()
    b.freeInstance()
    # in parallel threads (ctypes releases the GIL during each call)
    results = {}

    def worker(mu):
        for _ in range(5):
            results.setdefault(mu, []).append(_trajectory(fmus["vdp"], tmp_path, f"T{mu}_{_}", mu, IMPLICIT))

    threads = [threading.Thread(target=worker, args=(mu,)) for mu in (0.5, 3.0)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for mu in (0.5, 3.0):
        for r in results[mu]:
            assert np.array_equal(r, alone[mu])


# ---------------------------------------------------------------------------
# directional and output derivatives
# ---------------------------------------------------------------------------

def test_directional_derivatives_match_finite_differences(fmus, tmp_path):
    me = open_fmu(fmus["vdp"], FMU2Model, tmp_path, name="dd")
    me.setupExperiment(startTime=0.0)
    me.setReal([VDP["mu"], VDP["m"], VDP["k"]], [1.7, 2.3, 0.8])
    me.enterInitializationMode()
    me.exitInitializationMode()
    me.enterContinuousTimeMode()
    rng = np.random.default_rng(7)
    unknowns = [VDP["der_x"], VDP["der_v"], VDP["E"], VDP["z"], VDP["x"]]
    knowns = [VDP["x"], VDP["v"], VDP["F"]]

    def g(p):
        me.setContinuousStates((c_double * 2)(*p[:2]), 2)
        me.setReal([VDP["F"]], [p[2]])
        return np.array(me.getReal(unknowns))

    for _ in range(5):
        p0 = rng.uniform(-2, 2, 3)
        g(p0)
        seed = rng.normal(size=3)
        dd = np.array(me.getDirectionalDerivative(unknowns, knowns, list(seed)))
        eps = 1e-6
        fd = (g(p0 + eps * seed) - g(p0 - eps * seed)) / (2 * eps)
        np.testing.assert_allclose(dd, fd, rtol=1e-7, atol=1e-8)
    expect_error(me, lambda: me.getDirectionalDerivative([VDP["mu"]], knowns, [1, 0, 0]), "mu", "not an unknown")
    expect_error(me, lambda: me.getDirectionalDerivative(unknowns, [VDP["E"]], [1.0]), "E", "not a known")
    me.freeInstance()
    nojac = open_fmu(fmus["vdp_nojac"], FMU2Model, tmp_path, name="ddnj")
    nojac.setupExperiment(startTime=0.0)
    nojac.enterInitializationMode()
    expect_error(nojac, lambda: nojac.getDirectionalDerivative(unknowns, knowns, [1, 0, 0]), "Jacobian")
    nojac.freeInstance()


def test_output_derivatives_from_the_chain_rule(fmus, tmp_path):
    """dE/dt = x x' + m v v' and dz/dt = v' + k dF/dt, with x', v' from the model."""
    cs = open_fmu(fmus["vdp"], FMU2Slave, tmp_path, name="od")
    start_cs(cs, DOPRI5, {VDP["m"]: 1.5})
    cs.setRealInputDerivatives([VDP["F"]], [1], [0.4])
    cs.doStep(0.0, 0.7)
    x, v, dx, dv = cs.getReal([VDP["x"], VDP["v"], VDP["der_x"], VDP["der_v"]])
    d = cs.getRealOutputDerivatives([VDP["E"], VDP["z"], VDP["x"]], [1, 1, 1])
    np.testing.assert_allclose(d, [x * dx + 1.5 * v * dv, dv + 0.5 * 0.4, dx], rtol=1e-12)
    expect_error(cs, lambda: cs.getRealOutputDerivatives([VDP["E"]], [2]), "order 2")
    cs.freeInstance()


# ---------------------------------------------------------------------------
# memory checking: a C driver under valgrind
# ---------------------------------------------------------------------------

@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind not installed")
def test_c_driver_is_clean_under_valgrind(fmus):
    out = fmus["out"]
    exe = out / "driver"
    subprocess.run(["gcc", "-g", *CFLAGS, "-o", str(exe), str(MODELS / "driver.c"), str(MODELS / "vdp" / "model.c"),
                    *map(str, fmus["objects"]), "-lm"], check=True, capture_output=True, text=True)
    r = subprocess.run(["valgrind", "--error-exitcode=1", "--leak-check=full", "--errors-for-leak-kinds=definite",
                        "-q", str(exe)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "driver: all checks passed" in r.stdout
