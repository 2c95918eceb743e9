"""The per-robot unrolled forward dynamics (fmugen.codegen.unrolled_aba) against Pinocchio's ``aba`` and the
looped runtime: a chain (UR5), prismatic joints (Panda's fingers), trees (HyQ, Talos), locked joints (against
Pinocchio's reduced model), rotor inertia, damping and friction (against fmugen_chain_fd), the expression
folding and the inline sine and cosine."""
from __future__ import annotations

import ctypes
import subprocess

import numpy as np
import pytest

from erd_robots import ROBOTS
from erd_robots import rel as _rel
from erd_robots import robot as _robot
from fmugen.codegen.unrolled_aba import (SINCOS_C, WINDOW, CompiledUnrolledFD, Program, Var, _pressure_order,
                                         _windows, evaluate_numeric, from_kernels, unrolled_fd)


def test_folding():
    P = Program()
    x, y = Var("x"), Var("y")
    assert P.sop([(0.0, x), (2.0, 3.0)]) == 6.0  # 0 x vanishes, constants multiply
    assert P.sop([(1.0, x)]) is not None and P.sop([(1.0, x)]).name == "x"  # 1 x is x: no statement
    v = P.sop([(-1.0, x)])
    assert v.name == "x" and v.neg and not P.stmts  # -x is a sign, no statement
    a = P.sop([(x,), (-1.0, y)])
    b = P.sop([(y,), (-1.0, x)])
    assert a.name == b.name and b.neg != a.neg and len(P.stmts) == 1  # x - y and y - x: one statement
    assert P.sop([(x, 0.5), (0.5, x)]).name == "x"  # like terms merged
    assert P.call("cos", 0.0) == 1.0 and P.recip(4.0) == 0.25
    P.effect(f"out = {a.name};", [a])
    P.sop([(x, y)])  # unused
    assert [s[0] for s in P.live()] == [a.name, None]


def test_windows_reach_the_same_entries():
    """emit_c's windows: every access rewritten through a pointer reaches the entry it did, within a one-byte
    displacement, the pointer inside the entries used (C allows no pointer past an array); read-only arrays
    through const pointers; rarely used entries left alone."""
    import re

    rng = np.random.default_rng(3)
    body = [f"    const double t{i} = w[{rng.integers(0, 400)}] * q[{rng.integers(0, 9)}] + w[100 + {rng.integers(0, 60)}];"
            for i in range(300)] + [f"    J[{k}] = t{k};" for k in range(0, 200, 3)] + ["    w[5000] = t1;"]
    out = _windows(body, {"q": False, "w": True, "J": True}, count=12, min_uses=4)
    ptr = {}
    while re.match(r"    (const )?double \*fmugen_p", out[2 * len(ptr)]):  # a pointer, the macro keeping it opaque
        m = re.fullmatch(r"    (const )?double \*(fmugen_p\d+) = (\w+) \+ (\d+);", out[2 * len(ptr)])
        assert m and out[2 * len(ptr) + 1] == f"    FMUGEN_UNROLLED_WINDOW({m.group(2)});"
        assert bool(m.group(1)) == (m.group(3) == "q")
        ptr[m.group(2)] = (m.group(3), int(m.group(4)))
    assert 1 <= len(ptr) <= 12
    rest = out[2 * len(ptr):]
    assert len(rest) == len(body)
    spelled = re.compile(r"(fmugen_p\d+)\[(-?\d+)\]|\b(q|w|J)\[(\d+)(?: \+ (\d+))?\]")

    def entries(line):
        got = []
        for m in spelled.finditer(line):
            if m.group(1):
                arr, mid = ptr[m.group(1)]
                off = int(m.group(2))
                assert -WINDOW // 2 <= off < WINDOW // 2  # a one-byte displacement of 8-byte entries
                got.append((arr, mid + off))
            else:
                got.append((m.group(3), int(m.group(4)) + int(m.group(5) or 0)))
        return got

    used = {}
    for old, new in zip(body, rest):
        assert entries(new) == entries(old) and spelled.sub("", new) == spelled.sub("", old)
        for arr, k in entries(old):
            used.setdefault(arr, set()).add(k)
    for arr, mid in ptr.values():
        assert min(used[arr]) <= mid <= max(used[arr])
    assert "w[5000]" in rest[-1]  # used once: not worth a window
    assert _windows(["    x = 1.0;"], {"w": True}) == ["    x = 1.0;"]


def _most_live(stmts) -> int:
    """The most values of the function live at once: defined, and used by a statement still to come."""
    last = {}
    for i, (_, _, deps, _) in enumerate(stmts):
        for d in deps:
            last[d] = i
    live, most = set(), 0
    for i, (name, _, deps, _) in enumerate(stmts):
        live -= {d for d in deps if last.get(d) == i}
        if name is not None and name in last:
            live.add(name)
        most = max(most, len(live))
    return most


def test_pressure_order():
    """emit_c's statement order: a permutation in which every statement follows what it reads and the effects
    keep their order, holding fewer values live than the order of emission (a body's vectors one after the
    other, each summed at the end)."""
    stmts = []
    for v in range(4):  # four vectors of 6 products each, then their sums, an effect per sum
        stmts += [(f"a{v}_{k}", "", (f"in{k}",), 0) for k in range(6)]
    for v in range(4):
        stmts.append((f"s{v}", "", tuple(f"a{v}_{k}" for k in range(6)), 0))
        stmts.append((None, "", (f"s{v}",), 0))
    stmts.append((None, "", ("s0", "s3"), 0))
    out = _pressure_order(stmts)
    assert sorted(map(repr, out)) == sorted(map(repr, stmts))
    pos = {st[0]: i for i, st in enumerate(out) if st[0] is not None}
    for i, st in enumerate(out):
        assert all(pos.get(d, -1) < i for d in st[2])
    assert [st for st in out if st[0] is None] == [st for st in stmts if st[0] is None]
    assert _most_live(stmts) == 24 and _most_live(out) <= 8


def test_inline_sincos(tmp_path):
    (tmp_path / "s.c").write_text("#include <math.h>\n" + SINCOS_C + "\nvoid many(int n, const double *x, double *s, "
                                  "double *c) { for (int i = 0; i < n; i++) fmugen_unrolled_sincos(x[i], s + i, c + i); }\n")
    subprocess.run(["cc", "-std=c99", "-O2", "-fPIC", "-shared", "-o", str(tmp_path / "s.so"), str(tmp_path / "s.c"),
                    "-lm"], check=True)
    lib = ctypes.CDLL(str(tmp_path / "s.so"))
    rng = np.random.default_rng(0)
    quarter = np.arange(-400, 401) * np.pi / 4
    x = np.concatenate([rng.uniform(-7, 7, 200000), rng.uniform(-1e5, 1e5, 100000), quarter, quarter + 1e-13,
                        quarter - 1e-13, [0.0, -0.0, 1e-300, 99999.99, 1e5, -3e5, 1e300]])
    s, c = np.zeros_like(x), np.zeros_like(x)
    lib.many(ctypes.c_int(x.size), ctypes.c_void_p(x.ctypes.data), ctypes.c_void_p(s.ctypes.data),
             ctypes.c_void_p(c.ctypes.data))
    assert np.max(np.abs(s - np.sin(x))) < 3e-16 and np.max(np.abs(c - np.cos(x))) < 3e-16
    bad = np.array([np.inf, -np.inf, np.nan])
    s, c = np.zeros(3), np.zeros(3)
    lib.many(ctypes.c_int(3), ctypes.c_void_p(bad.ctypes.data), ctypes.c_void_p(s.ctypes.data),
             ctypes.c_void_p(c.ctypes.data))
    assert np.all(np.isnan(s)) and np.all(np.isnan(c))


@pytest.mark.parametrize("name", list(ROBOTS))
def test_equals_pinocchio(name):
    from fmugen.codegen.benchmarks import to_pinocchio

    pin, robot, kernels, model, mp = _robot(name)
    data = model.createData()
    iv = [m[1] for m in mp]
    n = kernels.n
    gen = from_kernels(kernels)
    cm = CompiledUnrolledFD(gen)
    try:
        rng = np.random.default_rng(1)
        q, qd, x = rng.uniform(-1, 1, (3, n)), rng.uniform(-1, 1, (3, n)), rng.uniform(-3, 3, (3, n))
        got = cm.fd(q, qd, x)
        for k in range(3):
            qp, vp = to_pinocchio(model, mp, q[k], qd[k])
            xp = to_pinocchio(model, mp, None, x[k])
            assert _rel(got[k], pin.aba(model, data, qp, vp, xp)[iv]) < 1e-9
        assert _rel(got, kernels.fd(q, qd, x)) < 1e-9
        assert _rel(evaluate_numeric(kernels.revolute, kernels.parents, kernels.constants, kernels.globals[:3],
                                     q[0], qd[0], x[0]), got[0]) < 1e-12
    finally:
        cm.close()
        kernels.close()


@pytest.mark.parametrize("name, locked", [("panda", {1: 0.4, 7: 0.01}), ("talos", {0: 0.1, 5: -0.3, 20: 0.2})])
def test_locked_joints_equal_the_reduced_model(name, locked):
    """Held joints (a revolute and a prismatic finger; a tree's root and inner joints) are welded to their
    parents: the free joints' qdd equals Pinocchio's aba on buildReducedModel at the held positions."""
    from fmugen.codegen.benchmarks import to_pinocchio

    pin, robot, kernels, model, mp = _robot(name)
    n = kernels.n
    names = [b.joint_name or b.name for b in robot.bodies]
    free = [i for i in range(n) if i not in locked]
    cm = CompiledUnrolledFD(from_kernels(kernels, locked=locked))
    try:
        rng = np.random.default_rng(2)
        for _ in range(2):
            q, qd, x = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-3, 3, n)
            for i, v in locked.items():
                q[i] = v
            qp = to_pinocchio(model, mp, q, qd)[0]
            red = pin.buildReducedModel(model, [model.getJointId(names[i]) for i in locked], qp)
            joints = [red.joints[red.getJointId(names[i])] for i in free]
            mpr = [(j.idx_q, j.idx_v, j.nq) for j in joints]
            qr, vr = to_pinocchio(red, mpr, q[free], qd[free])
            ref = pin.aba(red, red.createData(), qr, vr, to_pinocchio(red, mpr, None, x[free]))[[m[1] for m in mpr]]
            qd_junk = qd.copy()
            qd_junk[list(locked)] = 7.0  # a held joint's q and qd are not read
            q_junk = q.copy()
            q_junk[list(locked)] = -5.0
            got = cm.fd(q_junk, qd_junk, x)
            assert _rel(got[free], ref) < 1e-9
            assert np.all(got[list(locked)] == 0.0)
    finally:
        cm.close()
        kernels.close()


def test_rotor_damping_friction_equal_the_runtime():
    """Rotor inertia, viscous damping and smooth Coulomb friction, which Pinocchio's aba has not, against
    the looped runtime (fmugen_chain_fd) on the same numbers."""
    from fmugen.batch import Kernels

    _, _, kernels, _, _ = _robot("panda")
    lc = np.array(kernels.constants, float).reshape(kernels.n, -1)
    rng = np.random.default_rng(3)
    lc[:, 25] = rng.uniform(0.0, 0.3, kernels.n)  # rotor inertia
    lc[:, 26] = rng.uniform(0.0, 2.0, kernels.n)  # damping
    lc[::2, 27] = 1.5  # Coulomb level on every other joint
    lc[:, 28] = 0.05
    k2 = Kernels(kernels.revolute, kernels.parents, lc, kernels.globals[:3])
    cm = CompiledUnrolledFD(unrolled_fd(k2.revolute, k2.parents, lc, kernels.globals[:3]))
    try:
        n = kernels.n
        q, qd, x = rng.uniform(-1, 1, (4, n)), rng.uniform(-1, 1, (4, n)), rng.uniform(-3, 3, (4, n))
        assert _rel(cm.fd(q, qd, x), k2.fd(q, qd, x)) < 1e-9
    finally:
        cm.close()
        k2.close()
        kernels.close()


def test_refusals():
    with pytest.raises(ValueError, match="not positive"):  # a massless leaf: D = 0 at generation time
        lc = np.zeros((1, 29))
        lc[0, [0, 4, 8]] = 1.0
        lc[0, 14] = 1.0
        unrolled_fd([True], [-1], lc, [0, 0, -9.81])
    with pytest.raises(ValueError, match="locked"):
        unrolled_fd([True], [-1], np.eye(1, 29), [0, 0, -9.81], locked={3: 0.0})
