"""Issue 19, FMU API: a step never answers about a state it did not keep, a
state from another FMU is refused, a parameter keeps its physical range, and
a second fmi2FreeInstance is recognised.

One small FMU built by fmugen, ``edge``, holds three independent problems with
closed-form answers (each test switches the others off by a parameter):

* w' = -lam w: RK4 with a fixed step h multiplies w by
  R(-lam h) = 1 - z + z^2/2 - z^3/6 + z^4/24 (z = lam h) per step, stable for
  lam h <= 2.785 (the other states' eigenvalues are 0);
* x' = r, y = sqrt(1 - x): the output is NaN after t = 1 / r;
* s' = c: with c = 1e306 the state overflows at t = 179.77 s.

``edge2`` is the same model under another name (another GUID, the same
sizes).  The parameter ranges of a robot are checked on the model a one-link
arm file gives (``mass = "m1"``), and in the FMU on ``lam >= 0``.
"""
import math
import subprocess
import sys

import fmpy
import pytest
import sympy as sp
from fmpy import read_model_description
from fmpy.fmi2 import (FMU2Slave, fmi2Discard, fmi2Error, fmi2OK, fmi2LastSuccessfulTime)

from fmugen import load_robot
from fmugen.codegen.model import POSITIVE_MIN, SymbolicModel, Variable
from fmugen.fmi import build_fmu
from fmugen.fmi.model_description import model_description_xml
import fmi_log
from fmi_log import start, status_of, step

RK4, DOPRI5, RODAS3 = 3, 1, 2


def edge_model(name):
    w, x, s_, lam, r, c = (sp.Symbol(n, real=True) for n in ("w", "x", "s", "lam", "r", "c"))
    return SymbolicModel.from_equations(
        name,
        [Variable("w", w, start=1.0, output=True), Variable("x", x, start=0.0, output=True),
         Variable("s", s_, start=0.0, output=True)], [],
        [Variable("lam", lam, start=1000.0, min=0.0), Variable("r", r, start=1.0), Variable("c", c, start=0.0)],
        [-lam * w, r + 0 * x, c + 0 * s_], [Variable("y", sp.Symbol("y", real=True))], [sp.sqrt(1 - x)])


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmu_api")
    out = {"dir": d}
    for m in (edge_model("edge"), edge_model("edge2")):
        out[m.name] = build_fmu(m, d / f"{m.name}.fmu", fmi_type="cs").path
    return out


def open_fmu(fmus, name, tag):
    return fmi_log.open_fmu(fmus[name], fmus["dir"] / f"{name}_{tag}", name)


# --------------------------------------------------------------------------
# fmi2SetFMUstate: only a state of this FMU
# --------------------------------------------------------------------------
def test_a_state_from_another_fmu_with_the_same_sizes_is_refused(fmus):
    a, b = open_fmu(fmus, "edge", "sa"), open_fmu(fmus, "edge2", "sb")
    for f in (a, b):
        start(f)
    assert step(a, 0.0, 0.01) == fmi2OK
    foreign = a.getFMUstate()
    x_b = b.getReal([b.vr["w"]])[0]
    assert status_of(lambda: b.setFMUstate(foreign)) == fmi2Error
    assert "taken from another FMU" in b.log.text(fmi2Error), b.log.messages
    assert "GUID" in b.log.text(fmi2Error)
    assert b.getReal([b.vr["w"]])[0] == x_b  # nothing changed
    # serialized: the GUID in the blob
    blob = a.serializeFMUstate(foreign)
    assert status_of(lambda: b.deSerializeFMUstate(blob)) == fmi2Error
    assert "another GUID" in b.log.text(fmi2Error)
    # the same FMU, another instance: allowed, and the continuation is the same number
    a2 = open_fmu(fmus, "edge", "sa2")
    start(a2)
    a2.setFMUstate(foreign)
    assert a2.getReal([a2.vr["w"]])[0] == a.getReal([a.vr["w"]])[0]
    a.freeFMUstate(foreign)
    for f in (a, a2, b):
        f.freeInstance()


# --------------------------------------------------------------------------
# a step that is not kept: the state is where the message says
# --------------------------------------------------------------------------
def test_dopri5_overflow_keeps_a_finite_last_good_point(fmus):
    """x' = 1e306 overflows at t = 1.7977e308 / 1e306 = 179.77 s.  A trial step that overflows is
    rejected like any failed trial (an infinite state once passed the error test, whose weights
    were infinite too, and was returned by fmi2GetReal after the discard); the state stays at the
    last good point the message names, x = c t there (exact: x' is constant), finite with OK."""
    fmu = open_fmu(fmus, "edge", "dp")
    start(fmu, ints={"solver.method": DOPRI5}, reals={"c": 1e306, "r": 0.0, "lam": 0.0})
    assert step(fmu, 0.0, 100.0) == fmi2OK
    assert step(fmu, 100.0, 100.0) == fmi2Discard
    t_ok = fmu.getRealStatus(fmi2LastSuccessfulTime)
    x = fmu.getReal([fmu.vr["s"]])[0]  # fmi2OK, and finite
    assert math.isfinite(x) and 179.0 < t_ok < 179.77
    assert x == pytest.approx(1e306 * t_ok, rel=1e-12)
    assert f"last good point t = {t_ok:.17g} " in fmu.log.text(fmi2Discard)
    fmu.freeInstance()


@pytest.mark.parametrize("solver", [DOPRI5, RODAS3, RK4])
def test_a_point_that_fails_its_end_check_goes_back_to_the_step_start(fmus, solver):
    """ramp: x' = 1, y = sqrt(1 - x) is NaN after t = 1.  The step to 1.25 is discarded, and
    fmi2GetReal (OK) gives the point the message names: x = 1, y = 0 at t = 1."""
    fmu = open_fmu(fmus, "edge", f"end{solver}")
    start(fmu, ints={"solver.method": solver}, reals={"lam": 1.0})
    for k in range(4):
        assert step(fmu, 0.25 * k, 0.25) == fmi2OK
    assert step(fmu, 1.0, 0.25) == fmi2Discard
    assert fmu.getRealStatus(fmi2LastSuccessfulTime) == 1.0
    x, y = fmu.getReal([fmu.vr["x"], fmu.vr["y"]])
    assert x == pytest.approx(1.0, abs=1e-12) and y ** 2 == pytest.approx(0.0, abs=1e-12)
    assert "kept at the last good point t = 1 " in fmu.log.text(fmi2Discard)
    fmu.freeInstance()


def _r4(z):
    return 1 - z + z ** 2 / 2 - z ** 3 / 6 + z ** 4 / 24


def test_rk4_beyond_its_stability_estimate_refuses_the_step(fmus):
    """lam h = 3 > 2.785: refused before any step (fmi2Discard, x kept at 1, the limit 2.785/lam in the
    message); lam h = 2.5 inside: OK and x = R(-2.5)^n exactly as the closed form."""
    fmu = open_fmu(fmus, "edge", "rk4bad")
    start(fmu, ints={"solver.method": RK4}, reals={"solver.fixed_step": 3e-3})
    assert step(fmu, 0.0, 0.03) == fmi2Discard
    assert fmu.getReal([fmu.vr["w"]])[0] == 1.0
    assert fmu.getRealStatus(fmi2LastSuccessfulTime) == 0.0
    msg = fmu.log.text(fmi2Discard)
    assert "h = 3 ms exceeds the RK4 stability limit ~ 2.79 ms" in msg and "was not taken" in msg, msg
    assert "last good point t = 0" in msg
    fmu.freeInstance()
    fmu = open_fmu(fmus, "edge", "rk4good")
    start(fmu, ints={"solver.method": RK4}, reals={"solver.fixed_step": 2.5e-3})
    for k in range(3):
        assert step(fmu, k * 0.01, 0.01) == fmi2OK
    assert fmu.getReal([fmu.vr["w"]])[0] == pytest.approx(_r4(2.5) ** 12, rel=1e-12)
    assert not fmu.log.text()
    fmu.freeInstance()


# --------------------------------------------------------------------------
# fmi2SetReal of a parameter outside its physical range
# --------------------------------------------------------------------------
def test_robot_parameters_get_the_range_of_the_quantity_they_are(tmp_path):
    robot = tmp_path / "one_link.toml"
    robot.write_text("\n".join([
        "[robot]", 'name = "one_link"', "gravity = [0, 0, -9.81]", "",
        "[parameters]", 'm1 = { value = 2.0, unit = "kg" }', 'b1 = { value = 0.1, unit = "N.m.s/rad" }',
        'a1 = { value = 0.3, unit = "m" }', "",
        "[[links]]", 'joint = "revolute"', 'a = "a1"', "alpha = 0", "d = 0", "theta = 0", 'mass = "m1"',
        "com = [-0.15, 0, 0]", "inertia = [0.01, 0.01, 0.01]", 'damping = "b1"', ""]))
    model = load_robot(robot).state_space_model(outputs=())
    lows = {v.name: v.min for v in model.parameters}
    assert lows["m1"] == POSITIVE_MIN and lows["b1"] == 0.0 and lows["a1"] is None
    xml = model_description_xml(model, "{guid}", "one_link", ("cs",))
    assert 'name="m1"' in xml and f'min="{POSITIVE_MIN!r}"' in xml


def test_fmi2_set_real_refuses_a_parameter_outside_its_range(fmus):
    md = read_model_description(str(fmus["edge"]), validate=True)
    assert {v.name: v for v in md.modelVariables}["lam"].min == "0.0"
    fmu = open_fmu(fmus, "edge", "range")
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    lam, r = fmu.vr["lam"], fmu.vr["r"]
    for bad in ([lam], [-0.1]), ([lam], [-1e-300]), ([r, lam], [0.5, -3.0]):
        fmu.log.messages.clear()
        assert status_of(lambda: fmu.setReal(*bad)) == fmi2Error
        msg = fmu.log.text(fmi2Error)
        assert "parameter lam" in msg and "outside its physical range [0, inf]" in msg, msg
        assert fmu.getReal([lam, r]) == [1000.0, 1.0]  # a refused call changes nothing
    fmu.setReal([lam, r], [0.0, -2.0])  # the bound itself, and an open range
    assert fmu.getReal([lam, r]) == [0.0, -2.0]
    fmu.exitInitializationMode()
    fmu.freeInstance()


def test_a_start_value_outside_the_range_is_refused_at_build(tmp_path):
    from fmugen.errors import FmugenError

    from dataclasses import replace

    with pytest.raises(FmugenError, match=r"parameter lam = -1.0 is "):  # the API's own check (its wording is part A's)
        edge_model("neg").with_starts({"lam": -1.0})
    m = edge_model("neg")  # past it (a model assembled by hand): the generator is the last line
    m = replace(m, parameters=(replace(m.parameters[0], start=-1.0),) + m.parameters[1:])
    with pytest.raises(FmugenError, match=r"parameter 'lam' = -1.0 is outside its physical range \[0.0, inf\]"):
        build_fmu(m, tmp_path / "neg.fmu", fmi_type="cs")
    assert not (tmp_path / "neg.fmu").exists()


# --------------------------------------------------------------------------
# fmi2FreeInstance twice
# --------------------------------------------------------------------------
FREE_TWICE = r"""
import sys, fmpy
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
path, unzip = sys.argv[1], sys.argv[2]
md = read_model_description(path)
fmu = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(path, unzipdir=unzip),
                modelIdentifier=md.coSimulation.modelIdentifier, instanceName="twice")
fmu.instantiate()
c = fmu.component
fmu.fmi2FreeInstance(c)
fmu.fmi2FreeInstance(c)
print("freed twice without abort", flush=True)
"""


def test_free_instance_twice_does_not_abort(fmus, tmp_path):
    """glibc aborts a double free ("free(): double free detected"); the instance's tag, cleared by the
    first fmi2FreeInstance, makes the second one a no-op."""
    r = subprocess.run([sys.executable, "-c", FREE_TWICE, str(fmus["edge"]), str(tmp_path / "u")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "freed twice without abort" in r.stdout, r.stderr
