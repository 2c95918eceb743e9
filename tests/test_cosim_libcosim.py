"""An independent master: Jacobi with held inputs equals libcosim's fixed-step execution
(libcosimpy, the Open Simulation Platform's C++ master) on the same FMUs to round-off."""
import numpy as np
import pytest

from cosim_rigs import INTERNAL, THETA_STEP, split_system
from fmugen.cosim import run

libcosimpy = pytest.importorskip("libcosimpy")


def _libcosim(system, H, n):
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_step_size(step_size=int(round(H * 1e9)))  # nanoseconds
    keep, idx, vr = [], {}, {}
    for u in system.units:
        sl = CosimLocalSlave(fmu_path=str(u.path), instance_name=u.name)
        keep.append(sl)
        idx[u.name] = ex.add_local_slave(sl)
        vr[u.name] = {v.name.decode(): v.reference for v in ex.slave_variables(idx[u.name])
                      if v.type == CosimVariableType.REAL.value}
    for u in system.units:
        for name, value in u.start_values.items():
            if name == "solver.method":
                ex.integer_initial_value(idx[u.name], 0, int(value))
            else:
                ex.real_initial_value(idx[u.name], vr[u.name][name], float(value))
    for c in system.couplings:
        (su, sv), (tu, tv) = c.source, c.target
        ex.connect_real_variables(idx[su], vr[su][sv], idx[tu], vr[tu][tv])
    obs = CosimObserver.create_time_series(buffer_size=n + 10)
    ex.add_observer(obs)
    for r in system.recorded:
        obs.start_time_series(idx[r.unit], vr[r.unit][r.variable], CosimVariableType.REAL)
    assert ex.step(n)
    out = {}
    for r in system.recorded:
        times, steps, values = obs.time_series_real_samples(idx[r.unit], vr[r.unit][r.variable], 0, n + 1)
        out[r.column] = (np.asarray(times) * 1e-9, np.asarray(values))
    return out


@pytest.mark.parametrize("ps,H", [("default", 1e-3), ("stiff", 5e-4)])
def test_jacobi_hold_equals_libcosim(ps, H):
    n = 400
    system = split_system(ps, "step", stop=n * H)
    assert system.units[0].start_values["amp.theta_ref"] == THETA_STEP
    assert all(system.units[1].start_values[k] == v for k, v in INTERNAL.items())
    ours = run(system, "jacobi", "hold", step=H)
    theirs = _libcosim(system, H, n)
    for col in ours.columns:
        t, v = theirs[col]
        m = len(t)  # libcosim's series holds t_0 .. t_{n-1}
        assert m >= n
        assert np.allclose(t, ours.time[:m], rtol=0, atol=1e-12)
        scale = np.max(np.abs(ours[col][:m]))
        assert scale > 0
        # identical FMU calls in the same order: equal to round-off
        assert np.max(np.abs(v - ours[col][:m])) <= 1e-13 * scale, col
