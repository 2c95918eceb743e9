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
"""
import math
import os

import pytest

from fmugen.cosim import run
from fmugen.cosim.errors import CosimError
from fmugen.cosim.system import Coupling, CosimSystem, Recorded, Unit
from fmugen.errors import FmugenError

from third_party_fmu import broken_fmus, build_lag

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
