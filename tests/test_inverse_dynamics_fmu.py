"""The inverse dynamics as its own FMU (computed-torque control): tau(q, qd, qdd)."""
import fmpy
import numpy as np
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

import fmugen
from fmugen.fmi.build import build_fmu


def test_inverse_dynamics_fmu_equals_python_model(tmp_path):
    arm = fmugen.load_robot("robots/stanford_arm.toml")
    model = arm.inverse_dynamics_model()
    path = build_fmu(model, tmp_path / "sid.fmu", fmi_type="cs").path
    assert validate_fmu(str(path)) == []
    unzip = tmp_path / "u"
    fmpy.extract(str(path), str(unzip))
    md = fmpy.read_model_description(str(unzip))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s = FMU2Slave(guid=md.guid, unzipDirectory=str(unzip), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="id")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    rng = np.random.default_rng(8)
    n = arm.n
    names = [f"{stem}[{i + 1}]" for stem in ("q", "qd", "qdd") for i in range(n)]
    tau_vrs = [vr[f"tau[{i + 1}]"] for i in range(n)]
    for _ in range(5):
        q, qd, qdd = rng.normal(size=(3, n))
        s.setReal([vr[nm] for nm in names], list(np.r_[q, qd, qdd]))
        tau = np.array(s.getReal(tau_vrs))
        ref = arm.inverse_dynamics(q, qd, qdd)
        assert np.abs(tau - ref).max() <= 1e-12 * np.abs(ref).max()
        # d tau / d qdd = M(q): exact directional derivatives, column by column
        M = arm.mass_matrix(q)
        for j in range(n):
            seed = [0.0] * n
            seed[j] = 1.0
            col = s.getDirectionalDerivative(tau_vrs, [vr[f"qdd[{i + 1}]"] for i in range(n)], seed)
            assert np.allclose(col, M[:, j], rtol=1e-12, atol=1e-12 * np.abs(M).max())
    s.terminate()
    s.freeInstance()
