"""Fuzzing the FMI runtime (issue 9): random FMI call sequences and mutated
serialized FMU states, under AddressSanitizer and UndefinedBehaviorSanitizer.

``fuzz_driver.c`` (this folder) is compiled with every ``c_runtime/*.c`` file
and one model:

* ``vdp``   -- the hand-written Van der Pol model of tests/c_models (inputs,
  outputs, exact Jacobian);
* ``rig``   -- generated model.c of the one-joint hydraulic rig (stiff set):
  validity ranges on pressures and the spool, 7 states;
* ``chain`` -- generated model.c of a 2-link spatial arm: a Cholesky solve of
  the mass matrix in every evaluation (parameters set to zero make it fail).

Each driver runs for a bounded wall-clock time (FUZZ_SECONDS, default 8 s each)
with a fixed seed, so a finding is reproduced by rerunning the same command.
Any sanitizer report aborts the driver (``-fno-sanitize-recover=all``), and
the driver itself checks the runtime's contract after every call (valid
status codes; finite states and outputs after fmi2OK/fmi2Warning from
fmi2DoStep; finite derivatives after fmi2OK from fmi2GetDerivatives).  The
test fails on any finding and prints the numbers of sequences and calls.
"""
import os
import re
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import fmpy
import pytest

from fmugen.codegen.c_code import generate_c

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
RUNTIME = ROOT / "c_runtime"
SECONDS = float(os.environ.get("FUZZ_SECONDS", "8"))
SEED = int(os.environ.get("FUZZ_SEED", "20261201"))
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]


def _sanitizers_work(tmp_path) -> bool:
    src = tmp_path / "probe.c"
    src.write_text("int main(void) { return 0; }\n")
    r = subprocess.run(["cc", *SANITIZE, str(src), "-o", str(tmp_path / "probe")], capture_output=True)
    return r.returncode == 0 and subprocess.run([str(tmp_path / "probe")]).returncode == 0


def _model_sources(tmp_path):
    from fmugen.components.assembly import load_assembly
    from fmugen.dynamics.manipulator import Manipulator
    from fmugen.robot.chain import n_link_chain

    rig = load_assembly(ROOT / "examples" / "single_joint_stiff.toml")
    chain = Manipulator(n_link_chain(2, symbolic=True)).state_space_model(outputs=("p_ee",))
    out = {"vdp": ROOT / "tests" / "c_models" / "vdp" / "model.c"}
    for key, model in (("rig", rig), ("chain", chain)):
        p = tmp_path / f"{key}_model.c"
        p.write_text(generate_c(model, guid="{fuzz-" + key + "}").source)
        out[key] = p
    return out


def _cc(args):
    r = subprocess.run(["cc", *args], capture_output=True, text=True)
    assert r.returncode == 0, f"cc {' '.join(args)}\n{r.stderr}"


@pytest.fixture(scope="module")
def drivers(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    if shutil.which("cc") is None or not _sanitizers_work(d):
        pytest.skip("no C compiler with AddressSanitizer/UndefinedBehaviorSanitizer")
    headers = Path(fmpy.__file__).parent / "c-code"
    flags = ["-std=c99", "-g", "-O1", *SANITIZE, "-Wall", "-Wextra", "-Werror", f"-I{RUNTIME}", f"-I{headers}"]
    # the driver and the runtime once, each model on its own; two compilers at a time
    sources = {f"rt_{c.stem}": c for c in sorted(RUNTIME.glob("*.c"))}
    sources["driver"] = HERE / "fuzz_driver.c"
    sources.update({f"model_{k}": c for k, c in _model_sources(d).items()})
    with ThreadPoolExecutor(2) as pool:
        list(pool.map(lambda kv: _cc([*flags, "-c", str(kv[1]), "-o", str(d / f"{kv[0]}.o")]), sources.items()))
    common = [str(d / f"{k}.o") for k in sources if not k.startswith("model_")]
    exes = {}
    for key in ("vdp", "rig", "chain"):
        exes[key] = d / f"fuzz_{key}"
        _cc([*SANITIZE, *common, str(d / f"model_{key}.o"), "-o", str(exes[key]), "-lm"])
    return exes


@pytest.mark.parametrize("model", ["vdp", "rig", "chain"])
def test_fuzz_runtime_finds_nothing(drivers, model):
    env = dict(os.environ, ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:halt_on_error=1",
               UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1")
    r = subprocess.run([str(drivers[model]), str(SEED), str(SECONDS)], capture_output=True, text=True, env=env,
                       timeout=SECONDS * 10 + 60)
    summary = [ln for ln in r.stdout.splitlines() if ln.startswith("fuzz: seed")]
    print(f"{model}: {summary[-1] if summary else r.stdout[-2000:]}")
    assert r.returncode == 0, f"findings or a sanitizer report (rerun: {drivers[model]} {SEED} {SECONDS}):\n" \
                              f"{r.stdout[-4000:]}\n{r.stderr[-6000:]}"
    m = re.search(r"sequences (\d+) calls (\d+) \(steps completed (\d+).*restored from blobs (\d+).*"
                  r"re-sealed (\d+)\) findings 0", summary[-1])
    assert m, summary
    sequences, calls, steps, restored, mutated = map(int, m.groups())
    # the driver reached deep into the runtime, not only refusals at the door
    assert sequences > 500 and calls > 20_000 and steps > 200 and restored > 200 and mutated > 50
