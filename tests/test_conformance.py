"""Every kind of FMU fmugen writes, through tools built on FMI Library: the FMI Compliance Checker passes
each with 0 warnings and 0 errors (ME and CS), and libcosim loads and steps each (and a split scene's SSP).

FMI Library enforces FMI 2.0 rules that fmpy's validation does not: a URDF arm whose joint-name aliases of
its inputs both carried a start value lost both variables there, which stopped the checker ("Model structure
is not valid") and crashed libcosim's add_local_slave.  The kinds: a DH robot file (forward and inverse
dynamics), URDF chains and a tree (straight-line and looped code), component files (smooth, with state
events, with modes, sampled by a clock), a shipped assembly and the FMUs of three split scenes (the one-joint rig; the UR5 with
electric axes, a URDF arm inside a scene; the PUMA shoulder on a stick-slip drive with backlash; the one-joint rig under a 1 kHz discrete PI).
"""
import subprocess
import sys
import textwrap
import zipfile
from functools import lru_cache
from pathlib import Path

import pytest

from fmu_checker import BUILD_SCRIPT, check, find_checker

ROOT = Path(__file__).resolve().parents[1]


def _erd(rel):
    import importlib.metadata

    try:
        base = importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    return str(Path(base) / rel)


#: kind -> (the file: in the checkout, a shipped lib:NAME, or example-robot-data's; build options; the
#: output is a folder of FMUs)
KINDS = {
    "dh_robot": ("robots/puma_thesis_com.toml", [], False),
    "dh_inverse_dynamics": ("robots/stanford_arm.toml", ["--model", "inverse_dynamics"], False),
    "urdf_chain": ("robots/ur5.urdf", [], False),
    "urdf_chain_loops": ("robots/ur5.urdf", ["--strategy", "loops"], False),
    "urdf_panda": ("erd:panda_description/urdf/panda.urdf", [], False),
    "urdf_tree": ("erd:allegro_hand_description/urdf/allegro_right_hand.urdf", [], False),
    "component_file": ("lib:stribeck", [], False),
    "component_events": ("examples/components/bouncing_ball.toml", [], False),
    "component_modes": ("lib:stick_slip", [], False),
    "component_clocked": ("lib:discrete_pid", [], False),
    "assembly": ("examples/single_joint_default.toml", [], False),
    "scene_split": ("examples/scenes/single_joint_split.toml", [], True),
    "scene_urdf_electric": ("examples/scenes/ur5_electric.toml", ["--set", "scene.monolithic=false"], True),
    "scene_hybrid": ("examples/scenes/puma_geared_drive_hybrid.toml", [], True),
    "scene_sampled": ("examples/scenes/single_joint_sampled.toml", [], True),
}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    base = tmp_path_factory.mktemp("conformance")

    @lru_cache(maxsize=None)
    def fmus(kind):
        from fmugen.cli import main

        file, options, folder = KINDS[kind]
        file = _erd(file[4:]) if file.startswith("erd:") else file if file.startswith("lib:") else str(ROOT / file)
        out = base / kind if folder else base / f"{kind}.fmu"
        assert main(["build", file, *options, "-o", str(out)]) == 0
        return sorted(out.glob("*.fmu")) if folder else [out]

    return base, fmus


def _interfaces(fmu):
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    return [k for k, present in (("me", md.modelExchange), ("cs", md.coSimulation)) if present]


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_the_compliance_checker_passes_every_kind_of_fmu(built, kind):
    if find_checker() is None:
        pytest.skip(f"no FMI Compliance Checker: build it with {BUILD_SCRIPT} (or set FMUCHECK)")
    base, fmus = built
    checked = 0
    for fmu in fmus(kind):
        for k in _interfaces(fmu):
            # ME: the checker's own explicit Euler at 10 us (the Allegro hand's light fingers are stiff);
            # CS: the FMU's solver at 1 ms steps
            v = check(fmu, k, base, stop=0.01 if k == "me" else 0.1, step=1e-5 if k == "me" else 1e-3)
            assert v.clean, f"{fmu.name} ({k}): {v.returncode=}, {v.warnings} warnings, {v.errors} errors\n" \
                            f"{v.problems()}"
            checked += 1
    assert checked >= 1


def test_the_checker_refuses_two_starts_in_an_alias_set(built, tmp_path):
    """The oracle can fail: the UR5's FMU with a start put back on an input's joint-name alias (as fmugen
    wrote them before) is refused by FMI Library's parser."""
    if find_checker() is None:
        pytest.skip(f"no FMI Compliance Checker: build it with {BUILD_SCRIPT} (or set FMUCHECK)")
    base, fmus = built
    src = fmus("urdf_chain")[0]
    bad = tmp_path / "ur5_two_starts.fmu"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(bad, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "modelDescription.xml":
                text = data.decode()
                head, sep, tail = text.partition('name="shoulder_pan_joint.tau"')
                assert sep, "the UR5's FMU names its first joint's torque shoulder_pan_joint.tau"
                end = tail.index("/>")
                tail = tail[:end].replace('causality="local"', 'causality="input"').replace(
                    ' initial="calculated"', '') + ' start="0.0"' + tail[end:]
                data = (head + sep + tail).encode()
            zout.writestr(info, data)
    v = check(bad, "cs", tmp_path, stop=0.01, step=1e-3)
    assert not v.clean and "alias" in v.log.lower(), v.log[-2000:]


_LIBCOSIM_RUN = textwrap.dedent("""
    import sys
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_step_size(step_size=1_000_000)  # 1 ms in nanoseconds
    keep = []
    for i, path in enumerate(sys.argv[1:]):
        sl = CosimLocalSlave(fmu_path=path, instance_name=f"u{i}")
        keep.append(sl)
        assert ex.add_local_slave(sl) >= 0, path
    assert ex.step(100)
    print("stepped", len(keep))
""")


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_libcosim_loads_and_steps_every_kind_of_fmu(built, kind):
    """In a child process: a crash of libcosim's loader must fail this test, not end the suite."""
    pytest.importorskip("libcosimpy")
    base, fmus = built
    paths = [str(f) for f in fmus(kind) if "cs" in _interfaces(f)]
    p = subprocess.run([sys.executable, "-c", _LIBCOSIM_RUN, *paths], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and f"stepped {len(paths)}" in p.stdout, (p.returncode, p.stdout[-1500:], p.stderr[-1500:])


def test_libcosim_runs_the_split_urdf_scene_archive(tmp_path):
    """The split ur5_electric scene (a URDF arm and six electric axes) as an SSP archive: libcosim's
    from_ssp_file loads it and runs its own default experiment's first 20 ms."""
    pytest.importorskip("libcosimpy")
    from fmugen.cli import main

    out = tmp_path / "ur5_electric.ssp"
    assert main(["ssp", str(ROOT / "examples/scenes/ur5_electric.toml"), "--set", "scene.monolithic=false",
                 "-o", str(out), "--fmus", str(tmp_path / "fmus")]) == 0
    code = textwrap.dedent("""
        import sys
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

        log_output_level(CosimLogLevel.ERROR)
        ex = CosimExecution.from_ssp_file(ssp_path=sys.argv[1])
        assert ex.num_slaves() == 7, ex.num_slaves()
        assert ex.simulate_until(target_time=20_000_000)
        print("ran", ex.status().current_time)
    """)
    p = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0 and "ran 20000000" in p.stdout, (p.returncode, p.stdout[-1500:], p.stderr[-1500:])
