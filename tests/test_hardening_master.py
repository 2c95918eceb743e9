"""Issue 19, the master with FMUs it did not build: one clear line, never a raw exception.

The third-party FMU (``tests/third_party_fmu.py``, C written by the test, not
fmugen's runtime) is a first-order lag that declares
``canGetAndSetFMUstate="false"``.  Two of them in a chain, A driven by its
held input u = 1 and B by A's output:

* Gauss-Seidel at a fixed step runs; each FMU steps its lag exactly with the
  input held, so B's output is the closed form of that recursion;
* Newton, fixed-point iteration and adaptive steps need FMU states: refused
  before anything runs, with one line naming the FMU and the capability
  (it was an UnboundLocalError);
* broken FMUs (empty, not a zip, bad XML, FMI 1.0, no binary for this
  platform, a wrong model identifier, a binary that does not load, a wrong
  GUID, a 300 MB description) each give one CosimError (a FmugenError: the
  command line prints it and exits 2) that names the FMU's file.

Issue 27, every capability a scheme relies on is checked or its fallback stated:

* canGetAndSetFMUstate="false": the run at a fixed step says in its summary that it has no error estimate
  (the estimate reruns windows from saved states), instead of a silent NaN;
* canHandleVariableCommunicationStepSize="false" (FMI 2.0's default): adaptive steps are refused, and so is
  a fixed step that does not divide the run's span (its last step would be shorter); a dividing step runs
  with constant steps and no estimate (whose windows step H/2), said;
* a Model-Exchange FMU with providesDirectionalDerivative="false": the ME block never calls
  fmi2GetDirectionalDerivative (it would fail here), takes Radau's Jacobian by differences, and says so;
* dense output from an FMU with maxOutputDerivativeOrder = 0 is linear, said;
* Hermite inputs (newton/quadratic) name the FMU without output derivatives or without
  canInterpolateInputs, and newton/linear runs it.
"""
import math
import os

import numpy as np
import pytest

from fmugen.cosim import run
from fmugen.cosim.errors import CosimError
from fmugen.cosim.system import Coupling, CosimSystem, Recorded, Unit
from fmugen.errors import FmugenError

from third_party_fmu import broken_fmus, build_gain, build_lag

TA, TB, H, STOP = 0.1, 0.05, 0.01, 0.2


@pytest.fixture(scope="module")
def lag(tmp_path_factory):
    return build_lag(tmp_path_factory.mktemp("lag"))


def chain(path_a, path_b=None):
    return CosimSystem(
        name="lags",
        units=(Unit("A", path_a, "cs", {"u": 1.0, "T": TA}), Unit("B", path_b or path_a, "cs", {"T": TB})),
        couplings=(Coupling(("A", "y"), ("B", "u")),),
        recorded=(Recorded("A.y", "A", "y"), Recorded("B.y", "B", "y")),
        start_time=0.0, stop_time=STOP, step=H, order=("A", "B"))


def test_gauss_seidel_runs_a_fmu_without_states_exactly(lag):
    r = run(chain(lag), scheme="gauss-seidel")
    assert r.ok, r.summary
    a, b = math.exp(-H / TA), math.exp(-H / TB)
    ya = yb = held = 0.0
    for _ in range(round(STOP / H)):
        new = 1 + (ya - 1) * a
        # Gauss-Seidel/linear: B, which cannot interpolate, holds the midpoint of the line to A's new output
        u = 0.5 * (ya + new)
        yb = u + (yb - u) * b
        held = new + (held - new) * b  # A's new output held over the step (first order)
        ya = new
    assert r["A.y"][-1] == pytest.approx(1 - math.exp(-STOP / TA), rel=1e-12)
    assert r["B.y"][-1] == pytest.approx(yb, rel=1e-12)
    exact = 1 - (TA * math.exp(-STOP / TA) - TB * math.exp(-STOP / TB)) / (TA - TB)  # T_B y' = y_A(t) - y
    assert abs(yb - exact) < 0.1 * abs(held - exact)  # 5.9e-4 against 1.1e-2


@pytest.mark.parametrize("scheme, adaptive", [("newton", False), ("iterative", False), ("gauss-seidel", True),
                                              ("newton", True)])
def test_schemes_that_need_fmu_states_refuse_such_an_fmu(lag, scheme, adaptive):
    with pytest.raises(CosimError) as info:
        run(chain(lag), scheme=scheme, extrapolation="linear" if scheme != "gauss-seidel" else "hold",
            adaptive=adaptive)
    msg = str(info.value)
    assert "FMU 'A'" in msg and str(lag) in msg and 'canGetAndSetFMUstate="false"' in msg, msg
    assert "jacobi or gauss-seidel at a fixed step" in msg and "\n" not in msg


EXPECTED = {
    "empty": "the file is empty",
    "not a zip": "not a zip file",
    "bad XML": "modelDescription.xml cannot be read",
    "FMI 1.0": "FMI 1.0; the master runs FMI 2.0 FMUs",
    "no binary": "no binary for this platform",
    "wrong identifier": "for its model identifier 'other'",
    "not a library": "loading its binary failed",
    "wrong GUID": "fmi2Instantiate failed",
    "300 MB description": "modelDescription.xml is 300 MB, more than the 64 MB this master reads",
}


def test_broken_fmus_give_one_line_naming_the_fmu(lag, tmp_path):
    fmus = broken_fmus(tmp_path, lag)
    assert set(fmus) == set(EXPECTED)
    cwd = os.getcwd()
    for kind, path in fmus.items():
        with pytest.raises(FmugenError) as info:
            run(chain(lag, path), scheme="gauss-seidel")
        msg = str(info.value)
        assert isinstance(info.value, CosimError) and "\n" not in msg, (kind, msg)
        assert f"FMU 'B' ({path})" in msg and EXPECTED[kind] in msg, (kind, msg)
        # the host's working folder is its own (fmpy changes into the binary's folder and, when the load
        # fails, did not change back: every relative path of the process broke after it)
        assert os.getcwd() == cwd, kind
    # a folder, a FIFO (reading it would block) and a file that does not exist
    fifo = tmp_path / "pipe.fmu"
    os.mkfifo(fifo)
    for path, said in ((tmp_path, "not a regular file"), (fifo, "not a regular file"),
                       (tmp_path / "none.fmu", "the file does not exist")):
        with pytest.raises(CosimError, match=said):
            run(chain(lag, path), scheme="jacobi")


def test_an_fmu_that_unzips_beyond_the_bound_is_refused_before_unzipping(lag, tmp_path, monkeypatch):
    """The master extracts an FMU (fmpy.extract, no size bound of its own): an FMU declaring more than
    MAX_UNZIPPED_BYTES (sources/ aside) is refused, naming the FMU, before a byte is written."""
    import zipfile

    import fmugen.cosim.loading as loading

    declared = sum(i.file_size for i in zipfile.ZipFile(lag).infolist()
                   if not i.filename.startswith(("sources/", "documentation/")))
    monkeypatch.setattr(loading, "MAX_UNZIPPED_BYTES", declared - 1)
    with pytest.raises(CosimError, match=r"^FMU 'A' \(.*lag.fmu\): unzips to 0 MB, more than the 0 MB"):
        run(chain(lag), scheme="jacobi")
    monkeypatch.setattr(loading, "MAX_UNZIPPED_BYTES", declared)
    assert run(chain(lag, _copy(lag, tmp_path / "fits.fmu")), scheme="jacobi").ok


def _copy(src, dst):
    import shutil

    shutil.copy(src, dst)
    return dst


def test_a_run_without_fmu_states_says_it_has_no_estimate(lag):
    r = run(chain(lag), scheme="gauss-seidel")
    assert r.ok and math.isnan(r.summary.error_estimate) and r.summary.estimate_samples == 0
    (w,) = r.summary.warnings
    assert w.startswith("no coupling error estimate: FMU 'A' declares canGetAndSetFMUstate=\"false\""), w
    assert f"warning: {w}" in str(r.summary) and r.summary.as_dict()["warnings"] == [w]
    assert run(chain(lag), scheme="gauss-seidel", estimate=False).summary.warnings == []


@pytest.fixture(scope="module")
def fixed_step_lag(tmp_path_factory):
    return build_gain(tmp_path_factory.mktemp("fixed"), "fixed", dependencies="", lag=True,
                      capabilities={"canHandleVariableCommunicationStepSize": "false"})


def test_an_fmu_with_one_step_size_refuses_what_would_change_it(fixed_step_lag, lag):
    s = chain(fixed_step_lag, lag)
    for kw, said in (({"scheme": "jacobi", "adaptive": True, "extrapolation": "hold"},
                      "but adaptive macro steps change the step; run at a fixed step"),
                     ({"scheme": "gauss-seidel", "step": 0.03},
                      "but 0.2 s is not a whole number of macro steps of 0.03 s")):
        with pytest.raises(CosimError) as info:
            run(s, **kw)
        msg = str(info.value)
        assert "\n" not in msg and f"FMU 'A' ({fixed_step_lag})" in msg and said in msg, msg
        assert 'canHandleVariableCommunicationStepSize="false"' in msg, msg
    r = run(s, scheme="gauss-seidel", step=0.02)
    assert r.ok and r.summary.step_min == r.summary.step_max == 0.02 and len(r.time) == 11
    assert r.summary.warnings[0].startswith("no coupling error estimate: FMU 'A' declares "
                                            "canHandleVariableCommunicationStepSize")
    # the lag steps exactly with its input held: A.y = 1 - exp(-t / T) at u = 1 (RK4 at 1e-5 s sub-steps)
    assert r["A.y"][-1] == pytest.approx(1 - math.exp(-STOP / TA), rel=1e-9)


def test_me_fmu_without_directional_derivatives_gets_a_jacobian_by_differences(tmp_path):
    import shutil
    import zipfile
    from dataclasses import replace

    from cosim_rigs import split_system
    from fmugen.cosim import Master

    s = split_system("stiff", "smooth", stop=0.2)
    units = []
    for u in s.units:
        path = tmp_path / u.path.name
        with zipfile.ZipFile(u.path) as zin, zipfile.ZipFile(path, "w") as zout:
            for item in zin.infolist():
                data = zin.read(item.filename)
                if item.filename == "modelDescription.xml":
                    data = data.replace(b'providesDirectionalDerivative="true"', b'providesDirectionalDerivative="false"')
                zout.writestr(item, data)
        units.append(replace(u, path=path, fmi_type="me", start_values={
            k: v for k, v in u.start_values.items() if not k.startswith("solver.")}))
    exact_units = tuple(replace(u, fmi_type="me", start_values=w.start_values) for u, w in zip(s.units, units))
    with Master(replace(s, units=tuple(units)), "jacobi", "hold") as m:
        for u in m.units:
            u._dirDer = lambda *a: 3  # fmi2Error: a call would fail the run
        r = m.run(step=0.05)
    assert r.ok, r.summary
    assert sum("providesDirectionalDerivative=\"false\": the ME block's Jacobian by finite differences" in w
               for w in r.summary.warnings) == 2, r.summary.warnings
    ref = run(replace(s, units=exact_units), "jacobi", "hold", step=0.05)
    assert ref.ok and ref.summary.warnings == []
    scale = np.max(np.abs(ref["joint.theta"]))
    assert np.max(np.abs(r["joint.theta"] - ref["joint.theta"])) < 1e-6 * scale
    shutil.rmtree(tmp_path, ignore_errors=True)


def test_dense_output_from_an_fmu_without_output_derivatives_says_it_is_linear(lag):
    r = run(chain(lag), scheme="gauss-seidel", dense=True, estimate=False)
    assert r.ok and np.all(np.isnan(r.slopes))
    assert r.summary.warnings == ["dense output: FMU 'A', 'B' gives no output derivatives (maxOutputDerivativeOrder "
                                  "= 0): its columns are linear between communication points"]


@pytest.mark.parametrize("caps, said", [
    ({"maxOutputDerivativeOrder": "0"}, "declares maxOutputDerivativeOrder = 0"),
    ({"maxOutputDerivativeOrder": "1", "canInterpolateInputs": "false"}, "cannot interpolate inputs"),
])
def test_hermite_inputs_name_the_capability_a_third_party_fmu_lacks(tmp_path, lag, caps, said):
    """Newton/quadratic sends parabolas (input derivatives of order 1-2) built from the sources' slopes."""
    gain = build_gain(tmp_path, "hermite", dependencies="", lag=True, capabilities=caps)
    s = CosimSystem("lags", (Unit("A", gain, "cs", {"u": 1.0}), Unit("B", gain, "cs")),
                    (Coupling(("A", "y"), ("B", "u")), Coupling(("B", "y"), ("A", "u"))),
                    (Recorded("A.y", "A", "y"),), 0.0, STOP, H)
    with pytest.raises(CosimError) as info:
        run(s, scheme="newton", extrapolation="quadratic")
    msg = str(info.value)
    assert "\n" not in msg and said in msg and "FMU 'A'" in msg and "use newton/linear" in msg, msg
    assert run(s, scheme="newton", extrapolation="linear", estimate=False).ok
