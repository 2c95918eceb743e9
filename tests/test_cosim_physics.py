"""Physics versus coupling: a scene whose drive has its sign reversed (the actuator's torque enters the joint
negated, so the position loop feeds back positively) is unstable at rest.  The build says so, naming the
unstable mode's dominant states (from the monolithic linearisation at the state of rest), and a
co-simulation that runs away is reported as the system's divergence, without advice to shrink the step.
The same scene with the right sign is stable at rest and says nothing."""
from pathlib import Path

import fmugen
from fmugen.cosim import run

SPLIT = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "single_joint_split.toml"


def _scene(tmp_path, sign):
    text = SPLIT.read_text().replace('initial = "given"', 'initial = "equilibrium"')
    text = text.replace('["actuator.tau", "joint.tau"],', '{ from = "actuator.tau", to = "joint.tau", factor = %s },'
                        % sign)
    assert "factor" in text
    p = tmp_path / f"split_{'reversed' if sign < 0 else 'right'}.toml"
    p.write_text(text)
    return fmugen.load_scene(p)


def test_a_reversed_drive_is_unstable_at_rest_and_its_divergence_is_the_systems(tmp_path):
    right = _scene(tmp_path, 1.0)
    assert right.initial.unstable == [] and "unstable" not in right.initial.report()
    wrong = _scene(tmp_path, -1.0)
    # the position loop with positive feedback: a real eigenvalue > 0 whose mode is the joint's motion
    assert len(wrong.initial.unstable) >= 1
    assert "warning: the state of rest is unstable" in wrong.initial.report()
    assert "joint." in wrong.initial.unstable[0].split("dominant states")[1]
    built = wrong.build(tmp_path / "fmus")
    assert "unstable" in built.summary()
    assert built.system.rest_unstable == tuple(wrong.initial.unstable)
    for scheme, ext, H in [("gauss-seidel", "hold", 2e-3), ("newton", "cubic", 1e-2)]:
        r = run(built.system, scheme, ext, step=H, stop=1.0)
        assert "unstable at rest" in str(r.summary) and "joint." in r.summary.physics
        f = r.summary.failure
        if f is not None:  # a runaway the divergence check stopped: the system's, no step advice
            assert f.cause == "diverged", r.summary
            assert "physically unstable" in f.message and "the system diverges" in f.message
            assert "smaller step" not in f.message and "newton" not in f.message
    # the joint ran away by itself (positive position feedback): a coupling error could not do that at 1 ms
    r = run(built.system, "newton", "cubic", step=1e-3, stop=1.0)
    assert abs(r["joint.theta"][-1]) > 1e3 * abs(r["joint.theta"][0]) + 0.1 or r.summary.failure is not None
