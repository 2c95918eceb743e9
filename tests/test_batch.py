"""fmugen.batch: many states per call equal a loop of Pinocchio calls; threads change nothing; bad input named.

The robots are read twice from the same URDF of example-robot-data -- by fmugen's reader into the
batched kernels and by Pinocchio -- so the comparison checks the reader, the general joint model and
the runtime's loops together.  Joint damping and friction of the files are set to 0 (Pinocchio's
algorithms have neither).
"""
import importlib.metadata
import warnings
from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

from fmugen.batch import Kernels, StateError  # noqa: E402
from fmugen.codegen.benchmarks import pinocchio_urdf_map, to_pinocchio  # noqa: E402
from fmugen.robot.urdf import load_urdf  # noqa: E402

RTOL = 1e-9
ROBOTS = {"ur5": "ur_description/urdf/ur5_robot.urdf",  # a chain, 6 DoF
          "allegro": "allegro_hand_description/urdf/allegro_left_hand.urdf"}  # a tree: four fingers, 16 DoF


def rel(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(np.max(np.abs(b)), 1e-300)


def sym(upper):
    return np.triu(upper) + np.triu(upper, 1).T


@pytest.fixture(scope="module", params=sorted(ROBOTS))
def robot(request):
    try:
        root = Path(importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"))
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (pip install -e '.[test]')")
    path = root / ROBOTS[request.param]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = load_urdf(path)
    zero = {p.name: 0.0 for p in r.parameters if p.name.startswith(("b_", "fc_"))}
    kernels = Kernels.from_robot(r, values=zero)
    model = pin.buildModelFromUrdf(str(path))
    mp = pinocchio_urdf_map(model, r)
    yield kernels, model, mp
    kernels.close()


def states(n, count, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, (count, n)), rng.uniform(-1, 1, (count, n)), rng.uniform(-3, 3, (count, n))


def test_batched_results_equal_a_loop_of_pinocchio_calls(robot):
    kernels, model, mp = robot
    data = model.createData()
    n = kernels.n
    iv = [m[1] for m in mp]
    ix = np.ix_(iv, iv)
    q, qd, x = states(n, 6)
    qdd = kernels.fd(q, qd, x)
    fd = kernels.fd_derivatives(q, qd, x)
    tau = kernels.id(q, qd, x)
    idd = kernels.id_derivatives(q, qd, x)
    M = kernels.mass_matrix(q)
    M_columns = kernels.mass_matrix(q, method="columns")
    M_jacobian = kernels.mass_matrix(q, method="jacobian")
    Minv = kernels.mass_matrix_inverse(q)
    Minv_columns = kernels.mass_matrix_inverse(q, method="columns")
    Minv_jacobian = kernels.mass_matrix_inverse(q, method="jacobian")
    assert qdd.shape == (6, n) and all(b.shape == (6, n, n) for b in fd[1:] + idd[1:]) and M.shape == (6, n, n)
    for k in range(6):
        qp, vp = to_pinocchio(model, mp, q[k], qd[k])
        xp = to_pinocchio(model, mp, None, x[k])
        assert rel(qdd[k], pin.aba(model, data, qp, vp, xp)[iv]) < RTOL
        pin.computeABADerivatives(model, data, qp, vp, xp)
        assert rel(fd[0][k], qdd[k]) < RTOL  # the Jacobian's own qdd
        assert rel(fd[1][k], data.ddq_dq[ix]) < RTOL  # continuous joints: along the tangent
        assert rel(fd[2][k], data.ddq_dv[ix]) < RTOL
        assert rel(fd[3][k], sym(data.Minv)[ix]) < RTOL
        for Mi in (Minv, Minv_columns, Minv_jacobian):  # tree factorisation, n ABA columns, Jacobian block
            assert rel(Mi[k], sym(data.Minv)[ix]) < RTOL
        assert rel(tau[k], pin.rnea(model, data, qp, vp, xp)[iv]) < RTOL
        pin.computeRNEADerivatives(model, data, qp, vp, xp)
        assert rel(idd[0][k], tau[k]) < RTOL
        assert rel(idd[1][k], data.dtau_dq[ix]) < RTOL
        assert rel(idd[2][k], data.dtau_dv[ix]) < RTOL
        assert rel(idd[3][k], sym(data.M)[ix]) < RTOL
        ref = sym(pin.crba(model, data, qp))[ix]
        for Mk in (M, M_columns, M_jacobian):  # composite rigid bodies, n RNEA columns, Jacobian block
            assert rel(Mk[k], ref) < RTOL


def test_two_threads_equal_one_bit_for_bit(robot):
    kernels, _, _ = robot
    q, qd, x = states(kernels.n, 37, seed=1)  # odd: the two ranges differ in length
    one = [kernels.fd(q, qd, x), *kernels.fd_derivatives(q, qd, x), kernels.id(q, qd, x),
           *kernels.id_derivatives(q, qd, x), kernels.mass_matrix(q)]
    kernels.threads = 2
    try:
        two = [kernels.fd(q, qd, x), *kernels.fd_derivatives(q, qd, x), kernels.id(q, qd, x),
               *kernels.id_derivatives(q, qd, x), kernels.mass_matrix(q)]
    finally:
        kernels.threads = 1
    for a, b in zip(one, two):
        assert np.array_equal(a, b)
    # and a batch is the states one by one
    for k in (0, 20, 36):
        assert np.array_equal(kernels.fd(q[k:k + 1], qd[k:k + 1], x[k:k + 1])[0], one[0][k])


def test_bad_shapes_and_dtypes_are_refused_naming_the_argument(robot):
    kernels, _, _ = robot
    n = kernels.n
    q, qd, x = states(n, 4)
    with pytest.raises(ValueError, match=rf"fd: q must be a float64 array of shape \(N, {n}\), got float64 \({n},\)"):
        kernels.fd(q[0], qd, x)
    with pytest.raises(ValueError, match=rf"qd must be a float64 array of shape \(4, {n}\), got float64 \(3, {n}\)"):
        kernels.fd(q, qd[:3], x)
    with pytest.raises(ValueError, match=rf"tau must be a float64 array of shape \(4, {n}\), got float32"):
        kernels.fd_derivatives(q, qd, x.astype(np.float32))
    with pytest.raises(ValueError, match=rf"qdd must be a float64 array .* got int64 \(4, {n}\)"):
        kernels.id(q, qd, np.zeros((4, n), dtype=np.int64))
    with pytest.raises(ValueError, match=rf"mass_matrix: q must be .* \(N, {n}\), got float64 \(4, {n + 1}\)"):
        kernels.mass_matrix(np.zeros((4, n + 1)))
    with pytest.raises(ValueError, match="method must be one of"):
        kernels.mass_matrix(q, method="crba")
    with pytest.raises(ValueError, match="mass_matrix_inverse: method must be one of"):
        kernels.mass_matrix_inverse(q, method="aba")
    with pytest.raises(ValueError, match="threads"):
        kernels.threads = 0
    # a non-contiguous view is copied, not refused
    wide = np.zeros((4, 2 * n))
    wide[:, ::2] = q
    assert np.array_equal(kernels.mass_matrix(wide[:, ::2]), kernels.mass_matrix(q))
    # a read-only array is read (its address taken the slow way)
    frozen = q.copy()
    frozen.setflags(write=False)
    assert np.array_equal(kernels.mass_matrix(frozen), kernels.mass_matrix(q))
    # no states: empty results
    assert kernels.fd(q[:0], qd[:0], x[:0]).shape == (0, n)


def test_the_first_bad_state_is_named(robot):
    kernels, _, _ = robot
    q, qd, x = states(kernels.n, 40, seed=2)
    x[25, 0] = np.nan
    x[31, 1] = np.inf
    for threads in (1, 2):  # the second range starts at state 20: its first bad state is the batch's
        kernels.threads = threads
        try:
            with pytest.raises(StateError, match="fd: state 25: an input is NaN or infinite") as e:
                kernels.fd(q, qd, x)
            assert e.value.index == 25
            with pytest.raises(StateError, match="state 25"):
                kernels.id_derivatives(q, qd, x)
        finally:
            kernels.threads = 1


def test_a_mass_matrix_that_is_not_positive_definite_is_named():
    """A chain of two massless bodies: M = 0 and the articulated-body algorithm has nothing to divide by."""
    nc = 29
    lc = np.zeros((2, nc))
    lc[:, 0] = lc[:, 4] = lc[:, 8] = 1.0  # R = I
    lc[:, 14] = 1.0  # axis z
    lc[0, 15], lc[0, 18:22] = 1.0, (0.0, 0.1, 0.1, 0.1)  # body 0 has a mass and an inertia
    k = Kernels([True, True], [-1, 0], lc, [0, 0, -9.81], name="massless tip")
    q = np.zeros((3, 2))
    with pytest.raises(StateError, match="massless tip: fd: state 0: the mass matrix is not positive definite"):
        k.fd(q, q, q)
    with pytest.raises(StateError, match="fd_derivatives: state 0: the mass matrix is not positive definite"):
        k.fd_derivatives(q, q, q)
    for method in ("direct", "jacobian", "columns"):
        with pytest.raises(StateError, match="mass_matrix_inverse: state 0: the mass matrix is not positive"):
            k.mass_matrix_inverse(q, method=method)
    assert np.array_equal(k.id(q, q, q), np.zeros((3, 2)))  # the inverse dynamics need no solve


def test_a_dh_robot_from_its_file_equals_pinocchio_and_values_override():
    """A Denavit-Hartenberg robot (the Stanford arm: revolute and prismatic joints) through from_robot, against
    fmugen's own Pinocchio model of it; a parameter value given by name moves the result; unknown names refused."""
    from fmugen.codegen.benchmarks import pinocchio_model
    from fmugen.robot.loader import load_robot_description

    robot = load_robot_description(Path(__file__).resolve().parents[1] / "robots" / "stanford_arm.toml")
    zero = {p.name: 0.0 for p in robot.parameters if p.name.startswith(("b_", "fc_"))}
    kernels = Kernels.from_robot(robot, values=zero)
    model = pinocchio_model(robot, values=zero)
    data = model.createData()
    q, qd, x = states(kernels.n, 3, seed=4)
    qdd = kernels.fd(q, qd, x)
    M = kernels.mass_matrix(q)
    for k in range(3):
        assert rel(qdd[k], pin.aba(model, data, q[k], qd[k], x[k])) < RTOL
        assert rel(M[k], sym(pin.crba(model, data, q[k]))) < RTOL
    mass = next(p for p in robot.parameters if p.name.startswith("m"))
    heavier = Kernels.from_robot(robot, values={**zero, mass.name: 2 * mass.value + 1})
    assert not np.allclose(heavier.mass_matrix(q), M)
    with pytest.raises(KeyError, match="unknown parameter"):
        Kernels.from_robot(robot, values={"no_such_parameter": 1.0})


def test_unrolled_kernels_equal_pinocchio_and_the_loops(robot, tmp_path, monkeypatch):
    """Kernels.unrolled(): the robot's generated code gives Pinocchio's results and the looped kernels' (to
    rounding); two threads change nothing to the bit; bad input is named as by the loops; a second build
    of the same robot loads the cached library without compiling."""
    from fmugen.batch import unrolled

    monkeypatch.setenv("FMUGEN_CACHE", str(tmp_path))
    kernels, model, mp = robot
    data = model.createData()
    n = kernels.n
    iv = [m[1] for m in mp]
    ix = np.ix_(iv, iv)
    u = kernels.unrolled()
    q, qd, x = states(n, 40, seed=3)
    fd, idd = u.fd_derivatives(q, qd, x), u.id_derivatives(q, qd, x)
    for k in range(0, 40, 13):
        qp, vp = to_pinocchio(model, mp, q[k], qd[k])
        xp = to_pinocchio(model, mp, None, x[k])
        assert rel(u.fd(q, qd, x)[k], pin.aba(model, data, qp, vp, xp)[iv]) < RTOL
        pin.computeABADerivatives(model, data, qp, vp, xp)
        for got, ref in zip(fd, (data.ddq[iv], data.ddq_dq[ix], data.ddq_dv[ix], sym(data.Minv)[ix])):
            assert rel(got[k], ref) < RTOL
        pin.computeRNEADerivatives(model, data, qp, vp, xp)
        for got, ref in zip(idd, (data.tau[iv], data.dtau_dq[ix], data.dtau_dv[ix], sym(data.M)[ix])):
            assert rel(got[k], ref) < RTOL
    for got, ref in zip(fd + idd, kernels.fd_derivatives(q, qd, x) + kernels.id_derivatives(q, qd, x)):
        assert got.shape == ref.shape and rel(got, ref) < 1e-12
    u.threads = 2
    for a, b in zip(u.fd_derivatives(q, qd, x), fd):
        assert np.array_equal(a, b)
    qd[29, 1] = np.inf
    with pytest.raises(StateError) as e:
        u.fd_derivatives(q, qd, x)
    assert e.value.index == 29 and "input" in e.value.reason
    with pytest.raises(ValueError, match="qdd must be a float64 array"):
        u.id_derivatives(q, qd, x[:, :-1])
    u.close()

    def no_compile(*a):
        raise AssertionError("compiled again")

    monkeypatch.setattr(unrolled, "_compile", no_compile)
    again = kernels.unrolled()
    assert rel(again.fd(q[:3], qd[:3], x[:3]), u.fd(q[:3], qd[:3], x[:3])) == 0.0
    again.close()
    # without the cache: a library in a temporary folder, which a change of threads keeps
    monkeypatch.undo()
    monkeypatch.setenv("FMUGEN_OBJECT_CACHE", "0")
    temp = kernels.unrolled(threads=1)
    temp.threads = 2
    assert np.array_equal(temp.fd(q[:5], qd[:5], x[:5]), u.fd(q[:5], qd[:5], x[:5]))
    folder = temp._tmp
    temp.close()
    assert folder is not None and not folder.exists()


def test_unrolled_kernels_refuse_a_robot_singular_at_every_state(robot, tmp_path, monkeypatch):
    """A massless, inertia-free leaf makes M singular whatever the state (its pivot folds to 0): the unrolled
    kernels say so, naming the robot, instead of compiling code that divides by zero; the loops report
    the states (StateError)."""
    from fmugen.batch import unrolled

    monkeypatch.setenv("FMUGEN_CACHE", str(tmp_path))
    kernels, _, _ = robot
    n = kernels.n
    lc = kernels.constants
    leaf = [i for i in range(n) if i not in kernels.parents][0]
    lc[leaf, 15:26] = 0.0  # mass, centre of mass, inertia, rotor inertia
    bad = Kernels(kernels.revolute, kernels.parents, lc, kernels.globals[:3], name="massless")
    with pytest.raises(ValueError, match=r"massless: body \d+: .*not positive"):
        bad.unrolled()
    with pytest.raises(StateError):
        bad.fd(*states(n, 2))
    monkeypatch.setattr(unrolled, "_CC", "no-such-cc")
    monkeypatch.setenv("FMUGEN_OBJECT_CACHE", "0")
    with pytest.raises(RuntimeError, match="no C compiler 'no-such-cc'"):
        kernels.unrolled()
    bad.close()
