"""Sweeps on a Dask local cluster with 2 worker processes (examples/scenes/single_joint_split.toml).

Every point equals the same run done serially with the same FMUs, bit for bit, and equals the scene built
with that point's values; failed points are recorded with their reason; a restarted sweep skips the points
done; the state of rest is solved again per point (P_L = tau_load / D_m); folded parameters are refused.

``OPTS`` (passed to the sweep and to every serial run alike) switches the master's divergence monitor off:
these tests are about the sweep, and the monitor's verdict on borderline runs is still being tuned (it
stops joint.J = 1.25 at t = 0.21 s on a bounded run).  The failing point below fails in its FMU.
"""
import csv
import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.cosim.master import run
from fmugen.sweep import SweepError, make_points, sweep
from fmugen.sweep.metrics import compute, parse_metrics
from fmugen.sweep.points import parse_samples

SPLIT = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "single_joint_split.toml"
OPTS = {"detect_divergence": False}


@pytest.fixture(scope="module")
def client():
    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=40)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture(scope="module")
def grid_sweep(client, tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep_grid")
    r = sweep(SPLIT, grid=["joint.J=1,3", "path.q_begin=0,0.02"], out=out, client=client, options=OPTS,
              save_runs=True, progress=False)
    return r, out


def _serial(system, values):
    """The same run in this process: the sweep's FMUs, the point's start values set by hand."""
    units = []
    for u in system.units:
        sv = dict(u.start_values)
        if u.name == "joint":
            sv["J"] = values["joint.J"]
        else:
            sv["path.q_begin"] = values["path.q_begin"]
        units.append(dataclasses.replace(u, start_values=sv))
    return run(dataclasses.replace(system, units=tuple(units)), **OPTS)


def test_every_point_equals_the_serial_run_bit_for_bit(grid_sweep):
    r, out = grid_sweep
    assert [row["status"] for row in r.rows] == ["ok"] * 4
    assert len({row["worker"] for row in r.rows}) == 2  # both workers ran points
    scene = fmugen.load_scene(SPLIT).keeping(["joint.J", "path.q_begin"])
    system = scene.cosim_system({g: out / "fmus" / f"{g}.fmu" for g in scene.groups})
    wanted = parse_metrics(None, [c.column for c in system.recorded])
    for row in r.rows:
        res = _serial(system, row)
        with np.load(out / "runs" / f"{row['key']}.npz") as z:
            assert np.array_equal(z["time"], res.time) and np.array_equal(z["values"], res.values)
        serial = compute(res.time, res.values, res.columns, wanted)
        assert all(row[k] == v for k, v in serial.items()), row["key"]
    # the table on disk holds the same numbers (written with repr: they read back exactly)
    with open(out / "results.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [float(t["joint.theta:final"]) for t in table] == list(r.column("joint.theta:final"))
    assert (out / "metrics.png").stat().st_size > 10_000
    # the point moved the motion: q_begin = 0.02 starts the path above the joint
    assert r.rows[1]["joint.theta:peak"] != r.rows[0]["joint.theta:peak"]


def test_a_point_equals_the_scene_built_at_that_point(grid_sweep, tmp_path):
    r, out = grid_sweep
    row = r.rows[3]
    assert (row["joint.J"], row["path.q_begin"]) == (3.0, 0.02)
    built = fmugen.load_scene(SPLIT, set={"joint.J": 3.0, "path.q_begin": 0.02}).build(tmp_path)
    res = run(built.system, **OPTS)
    with np.load(out / "runs" / f"{row['key']}.npz") as z:
        assert np.array_equal(z["values"], res.values)


def test_restart_skips_the_points_done(grid_sweep, client):
    r0, out = grid_sweep
    r1 = sweep(SPLIT, grid=["joint.J=1,3", "path.q_begin=0,0.02"], out=out, client=client, options=OPTS,
               save_runs=True, progress=False)
    assert (r1.ran, r1.skipped) == (0, 4)
    assert r1.rows == r0.rows
    # an interrupted sweep: the last two rows lost, the last one cut in the middle of writing
    journal = out / "points.csv"
    lines = journal.read_text().splitlines(keepends=True)
    journal.write_text("".join(lines[:-2]) + lines[-2][: len(lines[-2]) // 2])
    r2 = sweep(SPLIT, grid=["joint.J=1,3", "path.q_begin=0,0.02"], out=out, client=client, options=OPTS,
               save_runs=True, progress=False)
    assert (r2.ran, r2.skipped) == (2, 2)
    strip = [{k: v for k, v in row.items() if k not in ("wall_time", "worker")} for row in r2.rows]
    assert strip == [{k: v for k, v in row.items() if k not in ("wall_time", "worker")} for row in r0.rows]
    # a bigger grid in the same folder runs only the new points
    r3 = sweep(SPLIT, grid=["joint.J=1,3,5", "path.q_begin=0,0.02"], out=out, client=client, options=OPTS,
               save_runs=True, progress=False)
    assert (r3.ran, r3.skipped, len(r3.rows)) == (2, 4, 6)
    with pytest.raises(SweepError, match="holds another sweep"):
        sweep(SPLIT, grid=["joint.J=1,3"], out=out, client=client, options=OPTS, metrics=["final"],
              progress=False)


def test_failed_points_are_recorded_with_their_reason(client, tmp_path):
    r = sweep(SPLIT, grid=["joint.J=0,1e-3,2", "actuator.beta_e=7e8,1e12"], out=tmp_path, client=client,
              options=OPTS, metrics=["joint.theta:final"], progress=False)
    status = {(row["joint.J"], row["actuator.beta_e"]): row for row in r.rows}
    for beta in (7e8, 1e12):  # J = 0: fails the check a file value gets (J > 0), refused and never run
        assert status[(0.0, beta)]["status"] == "refused"
        assert "joint.J = 0.0 is not > 0" in status[(0.0, beta)]["failure"]
        assert status[(0.0, beta)]["worker"] == "client"
        assert np.isnan(status[(0.0, beta)]["joint.theta:final"])
    bad = status[(1e-3, 1e12)]  # the coupling of a light joint and a stiff fluid explodes
    assert bad["status"] == "failed" and "co-simulation stopped at t = " in bad["failure"]
    assert "chain" in bad["failure"]
    for key in ((1e-3, 7e8), (2.0, 7e8), (2.0, 1e12)):
        assert status[key]["status"] == "ok" and abs(status[key]["joint.theta:final"] - 0.1) < 2e-3
    with open(tmp_path / "results.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert sorted(t["status"] for t in table) == ["failed", "ok", "ok", "ok", "refused", "refused"]


def test_monte_carlo_points_are_the_seeded_samples(client, tmp_path):
    r = sweep(SPLIT, sample=["actuator.beta_e=normal(7e8,5e7)"], n=3, seed=11, out=tmp_path, client=client,
              options=OPTS, metrics=["actuator.P_L:peak"], progress=False)
    expect = make_points(samples=parse_samples(["actuator.beta_e=normal(7e8,5e7)"]), n=3, seed=11)
    assert [row["actuator.beta_e"] for row in r.rows] == [p["actuator.beta_e"] for p in expect]
    assert all(row["status"] == "ok" for row in r.rows)
    assert len(set(r.column("actuator.P_L:peak"))) == 3  # each sample reached the FMU
    # the last sample, run here by hand with the sweep's FMUs
    scene = fmugen.load_scene(SPLIT).keeping(["actuator.beta_e"])
    system = scene.cosim_system({g: tmp_path / "fmus" / f"{g}.fmu" for g in scene.groups})
    chain = system.unit("chain")
    chain = dataclasses.replace(chain, start_values={**chain.start_values,
                                                     "actuator.beta_e": expect[-1]["actuator.beta_e"]})
    res = run(dataclasses.replace(system, units=(chain, system.unit("joint"))), **OPTS)
    P_L = res["actuator.P_L"]
    assert r.rows[-1]["actuator.P_L:peak"] == P_L[np.argmax(np.abs(P_L))]


def test_the_state_of_rest_is_solved_again_per_point(client, tmp_path):
    # held against a load torque: at rest tau = D_m P_L = tau_load, so P_L = tau_load / D_m
    sets = {"scene.initial": "equilibrium", "joint.tau_load": 50.0, "path.q_end": 0.0}
    r = sweep(SPLIT, grid=["actuator.D_m=1.5e-5,3e-5,3e-6"], sets=sets, out=tmp_path, client=client, options=OPTS,
              metrics=["actuator.P_L:final", "joint.w:peak"], progress=False)
    # D_m = 3e-6: the stall torque P_s D_m = 42 N.m is below the load: no state of rest, never submitted
    stalled = r.rows.pop()
    assert stalled["status"] == "error" and stalled["worker"] == "client"
    assert "no state of rest" in stalled["failure"] or "stall torque" in stalled["failure"]
    for row in r.rows:
        assert row["status"] == "ok"
        assert abs(row["actuator.P_L:final"] - 50.0 / row["actuator.D_m"]) < 1e-6 * 50.0 / row["actuator.D_m"]
        assert abs(row["joint.w:peak"]) < 1e-9  # it stays at rest


def test_a_sweep_keeps_zero_valued_parameters_settable():
    scene = fmugen.load_scene(SPLIT)
    assert scene.keeping(["joint.J"]) is scene  # only zeros are folded: the scene's own FMUs serve
    kept = scene.keeping(["path.q_begin", "joint.J"])
    assert kept.spec.instances["path"].keep == ("q_begin",)
    names = lambda s: {v.name for v in s.group_model("chain")[0].parameters}
    assert "path.q_begin" in names(kept) and "path.q_begin" not in names(scene)


def test_folded_and_unknown_parameters_are_refused(tmp_path):
    scene = tmp_path / "fixed.toml"
    scene.write_text(SPLIT.read_text().replace('joint = { type = "joint_inertia" }',
                                               'joint = { type = "joint_inertia", fixed = ["B_m"] }'))
    with pytest.raises(SweepError, match=r"fixed: B_m is folded into a constant.*remove it from 'fixed'"):
        sweep(scene, grid=["joint.B_m=1,2"], out=tmp_path / "a", progress=False)
    with pytest.raises(SweepError, match="joint has no parameter or state 'Jx'"):
        sweep(SPLIT, grid=["joint.Jx=1,2"], out=tmp_path / "b", progress=False)
    with pytest.raises(SweepError, match="no instance 'jiont'"):
        sweep(SPLIT, grid=["jiont.J=1,2"], out=tmp_path / "c", progress=False)


def test_the_command_line_on_a_scheduler_address(client, tmp_path, capsys):
    from fmugen.cli import main

    addr = client.scheduler.address
    rc = main(["sweep", str(SPLIT), "--grid", "amp.K_a=12,20", "--metrics", "joint.theta:settling", "--out",
               str(tmp_path), "--scheduler", addr, "--no-divergence-check"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert "2 points" in out.out and "2 ok, 0 failed" in out.out and "results.csv" in out.out
    assert f"at {addr}" in out.err and "done" in out.err
    with open(tmp_path / "results.csv", newline="") as fh:
        t = {float(row["amp.K_a"]): float(row["joint.theta:settling"]) for row in csv.DictReader(fh)}
    assert t[20.0] < t[12.0]  # a stiffer position loop settles sooner
    rc = main(["sweep", str(SPLIT), "--sample", "joint.J=__import__('os').system('true')", "-n", "2", "--seed",
               "1", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert rc == 2 and "not a distribution" in err and err.count("\n") == 1


def test_the_error_metric_is_against_the_reference_of_the_scene_at_that_point(client, tmp_path):
    from fmugen.cosim.reference import solve_reference

    opts = dict(OPTS, stop=0.2)
    r = sweep(SPLIT, grid=["joint.J=3"], out=tmp_path, client=client, options=opts,
              metrics=["joint.theta:error", "joint.theta:final"], save_runs=True, progress=False)
    row = r.rows[0]
    assert row["status"] == "ok"
    with np.load(tmp_path / "runs" / f"{row['key']}.npz") as z:
        t, theta = z["time"], z["values"][:, 0]
    # the reference of the scene written with J = 3 (not the sweep's parameter plumbing), solved here
    problem = dataclasses.replace(fmugen.load_scene(SPLIT, set={"joint.J": 3.0}).reference_problem(), stop_time=0.2)
    ref = solve_reference(problem, times=t, cache=False)
    assert row["joint.theta:error"] == pytest.approx(np.max(np.abs(theta - ref["joint.theta"])), rel=1e-6)
    # a coupling error well above the reference's own, within 1 % of the 0.1 rad move
    assert 100 * ref.error_of("joint.theta") < row["joint.theta:error"] < 1e-3


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_a_monolithic_scene_runs_its_one_fmu_and_matches_fmpy(client, tmp_path, fmi_version):
    import fmpy

    sets = {"scene.monolithic": True, "scene.fmi_version": fmi_version}
    r = sweep(SPLIT, grid=["joint.J=1,3"], sets=sets, out=tmp_path, client=client, metrics=["final"],
              save_runs=True, progress=False)
    assert [row["status"] for row in r.rows] == ["ok", "ok"]
    scene = fmugen.load_scene(SPLIT, set=sets)
    (group,) = scene.groups
    unit = scene.cosim_system({group: tmp_path / "fmus" / f"{group}.fmu"}).unit(group)
    row = r.rows[1]
    # fmpy's own simulation loop over the same FMU, J = 3 given as a start value
    res = fmpy.simulate_fmu(str(unit.path), validate=False, fmi_type="CoSimulation", output_interval=1e-3,
                            start_values={**unit.start_values, "joint.J": 3.0},
                            output=["joint.theta", "actuator.P_L"])
    with np.load(tmp_path / "runs" / f"{row['key']}.npz") as z:
        cols = list(z["columns"])
        assert np.allclose(z["time"], res["time"], rtol=0, atol=1e-12)
        for c in ("joint.theta", "actuator.P_L"):
            ref = res[c]
            assert np.max(np.abs(z["values"][:, cols.index(c)] - ref)) <= 1e-9 * np.max(np.abs(ref))


def test_threads_in_one_process_give_the_same_runs(tmp_path):
    # a local cluster of its own: one process, two threads (FMU instances are independent per thread)
    r = sweep(SPLIT, grid=["joint.J=1,3"], out=tmp_path, workers=2, processes=False, options=OPTS,
              metrics=["final"], save_runs=True, progress=False)
    scene = fmugen.load_scene(SPLIT)
    system = scene.cosim_system({g: tmp_path / "fmus" / f"{g}.fmu" for g in scene.groups})
    for row in r.rows:
        joint = system.unit("joint")
        joint = dataclasses.replace(joint, start_values={**joint.start_values, "J": row["joint.J"]})
        res = run(dataclasses.replace(system, units=(system.unit("chain"), joint)), **OPTS)
        with np.load(tmp_path / "runs" / f"{row['key']}.npz") as z:
            assert np.array_equal(z["values"], res.values)


def _lose_J3(bundle, task):
    """A task the cluster loses (as when a worker process dies): raised, not returned."""
    from fmugen.sweep.worker import run_point

    if task.values["joint.J"] == 3.0:
        raise RuntimeError("worker tcp://10.0.0.7:40111 died")
    return run_point(bundle, task)


def test_a_task_the_cluster_loses_is_recorded_with_the_reason(tmp_path, monkeypatch):
    import fmugen.sweep.execute as execute

    monkeypatch.setattr(execute, "run_point", _lose_J3)
    r = sweep(SPLIT, grid=["joint.J=1,3"], out=tmp_path, workers=2, processes=False, options=OPTS,
              metrics=["joint.theta:final"], progress=False)
    lost = r.rows[1]
    assert (r.rows[0]["status"], lost["status"]) == ("ok", "error")
    assert "RuntimeError: worker tcp://10.0.0.7:40111 died" in lost["failure"]
    assert np.isnan(lost["joint.theta:final"])
    # recorded as done, like a failed run: a restart skips it
    r2 = sweep(SPLIT, grid=["joint.J=1,3"], out=tmp_path, workers=2, processes=False, options=OPTS,
               metrics=["joint.theta:final"], progress=False)
    assert (r2.ran, r2.skipped, r2.rows[1]["status"]) == (0, 2, "error")


def test_a_swept_start_value_equals_the_scene_started_there(client, tmp_path):
    r = sweep(SPLIT, grid=["joint.theta=0.05"], out=tmp_path, client=client, options=OPTS,
              metrics=["joint.theta:final"], save_runs=True, progress=False)
    row = r.rows[0]
    built = fmugen.load_scene(SPLIT, set={"joint.theta": 0.05}).build(tmp_path / "at")
    res = run(built.system, **OPTS)
    with np.load(tmp_path / "runs" / f"{row['key']}.npz") as z:
        assert z["values"][0, 0] == 0.05  # joint.theta at t = 0
        assert np.array_equal(z["values"], res.values)
