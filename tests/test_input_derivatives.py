"""Co-Simulation inputs between communication points: u(t) = u_c + du s + ddu s^2 / 2 + dddu s^3 / 6.

An integrator x' = u makes the effect exact: x(t) is the integral of that polynomial,
which every CS solver integrates to its tolerance (1e-12 here).
"""
import numpy as np
import pytest
import sympy as sp
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

import fmugen
from fmugen.codegen.model import SymbolicModel, Variable


@pytest.fixture(scope="module")
def integrator(tmp_path_factory):
    x, u = sp.Symbol("x", real=True), sp.Symbol("u", real=True)
    m = SymbolicModel.from_equations("integrator", [Variable("x", x, start=0.0, output=True)],
                                     [Variable("u", u, start=0.0)], [], [u])
    path = fmugen.build_fmu(m, tmp_path_factory.mktemp("integ") / "integrator.fmu", fmi_type="cs").path
    return path


@pytest.mark.parametrize("solver", [1, 2, 3])
def test_input_derivatives_to_third_order_are_integrated_and_carried_on(integrator, tmp_path, solver):
    md = read_model_description(str(integrator))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(integrator), str(tmp_path / "u")),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="i")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.setInteger([vr["solver.method"]], [solver])
    fmu.setReal([vr["solver.rtol"], vr["solver.atol"]], [1e-12, 1e-12])
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    u0, du, ddu, dddu, H = 0.3, -1.5, 4.0, -9.0, 0.2
    fmu.setReal([vr["u"]], [u0])
    fmu.setRealInputDerivatives([vr["u"]], [1], [du])
    fmu.setRealInputDerivatives([vr["u"]], [2], [ddu])
    fmu.setRealInputDerivatives([vr["u"]], [3], [dddu])
    exact = lambda t: u0 * t + du * t**2 / 2 + ddu * t**3 / 6 + dddu * t**4 / 24  # noqa: E731
    for k in (1, 2):  # the second step goes on along the same polynomial
        fmu.doStep(currentCommunicationPoint=(k - 1) * H, communicationStepSize=H)
        x, u = fmu.getReal([vr["x"], vr["u"]])
        s = k * H
        assert x == pytest.approx(exact(s), rel=1e-9, abs=1e-12)
        assert u == pytest.approx(u0 + du * s + ddu * s**2 / 2 + dddu * s**3 / 6, rel=1e-12)
    # switched off again: held from here
    fmu.setRealInputDerivatives([vr["u"]] * 3, [1, 2, 3], [0.0, 0.0, 0.0])
    x2, u2 = fmu.getReal([vr["x"], vr["u"]])
    fmu.doStep(currentCommunicationPoint=2 * H, communicationStepSize=H)
    assert fmu.getReal([vr["x"]])[0] == pytest.approx(x2 + u2 * H, rel=1e-9)
    fmu.terminate()
    fmu.freeInstance()
