"""No symbolic swell through the intermediates of a component file: a chain of n intermediates, each reading
the previous one three times (3**n terms expanded), is n named program steps; the Jacobian is the chain rule
over them; build time and generated size grow linearly.  f and df/dx against plain Python and finite
differences; 1000 links built into an FMU.  The CPU bounds below catch swell (3**n terms), not speed: a
1000-link build takes ~20 s of CPU; its build time is measured by examples/bench_component_swell.py, not
here (CPU time too grows on a machine whose cores are shared: 30.2 s once under four busy processes)."""
from __future__ import annotations

import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fmugen.components import NumericModel
from fmugen.components.equations import load_component, read_component_file

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "examples"))
from bench_component_swell import chain_file, chain_value  # noqa: E402


def derived(tmp_path, n, used=True):
    path = chain_file(tmp_path / f"chain{n}{'u' if used else ''}.toml", n, used)
    t0 = time.process_time()
    m = load_component(path)
    return m, time.process_time() - t0


def check_against_plain_python_and_fd(m, n, x):
    ev = NumericModel(m)
    k, c = 4.0, 0.5
    f = np.asarray(ev.f(0.0, x, []), float)
    assert f == pytest.approx([x[1], -k * x[0] - c * chain_value(x[0], n)], rel=1e-12, abs=1e-14)
    A = np.asarray(ev.dfdx(0.0, x, []), float)
    h = 1e-6
    fd = np.array([(np.asarray(ev.f(0.0, x + h * e, []), float) - np.asarray(ev.f(0.0, x - h * e, []), float))
                   / (2 * h) for e in np.eye(2)]).T
    assert np.all(np.isfinite(A))
    assert np.allclose(A, fd, rtol=1e-7, atol=1e-8 * max(1.0, np.abs(A).max()))
    # the derivative of the chain itself, by the chain rule in plain Python
    a, da = math.sin(x[0]), math.cos(x[0])
    for _ in range(n):
        a, da = math.sin(a) * math.cos(a) + a * a, (math.cos(2 * a) + 2 * a) * da
    assert A[1, 0] == pytest.approx(-k - c * da, rel=1e-10)


def test_the_issue_chain_of_12_unused_links_is_instant(tmp_path):
    # was > 120 s (the intermediates expanded before differentiation, 3**12 terms)
    m, cpu = derived(tmp_path, 12, used=False)
    assert cpu < 2.0
    assert m.pruned().operation_count() <= 4  # the chain is not needed: pruned away


@pytest.mark.parametrize("n", [6, 12, 40])
def test_f_and_jacobian_of_a_used_chain(tmp_path, n):
    m, _ = derived(tmp_path, n)
    for phi in (-0.5, -0.2, -0.35):
        check_against_plain_python_and_fd(m, n, np.array([phi, 0.3]))


def test_every_intermediate_is_one_program_step_and_the_size_grows_linearly(tmp_path):
    m100, _ = derived(tmp_path, 100)
    m200, _ = derived(tmp_path, 200)
    ops100, ops200 = m100.pruned().operation_count(), m200.pruned().operation_count()
    assert 1.9 < ops200 / ops100 < 2.1  # linear (expanded: 3**100 more)
    names = [str(st.symbol) for st in m100.program.steps]
    assert sum(n.startswith("_wa") for n in names) == 101  # a0 ... a100, each a named step
    assert max(len(str(st.expr)) for st in m100.program.steps) < 80
    assert max(len(str(st.expr)) for st in m100.jacobian.steps) < 120


#: CPU seconds that only swell exceeds (the derivation ~10 s, the build ~20 s of a 1000-link chain)
SWELL_CPU = 120.0


def test_1000_links_derive_and_check(tmp_path):
    m, cpu = derived(tmp_path, 1000)
    assert cpu < SWELL_CPU
    check_against_plain_python_and_fd(m, 1000, np.array([-0.5, 0.3]))


def test_1000_links_build_an_fmu(tmp_path):
    path = chain_file(tmp_path / "chain1000.toml", 1000, True)
    env = dict(os.environ, PYTHONPATH=str(ROOT))  # the runtime objects of the usual cache, as any build after the first
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-W", "ignore", "-m", "fmugen.cli", "build", str(path), "-o",
                        str(tmp_path / "chain1000.fmu"), "--fmi-type", "me", "--no-cache"], cwd=ROOT, env=env,
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert r.returncode == 0, r.stdout + r.stderr
    cpu = (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)
    assert cpu < SWELL_CPU, (cpu, wall)
    assert (tmp_path / "chain1000.fmu").is_file()


def test_intermediates_limit_is_named(tmp_path):
    from fmugen.components.equations.file import MAX_INTERMEDIATES

    assert MAX_INTERMEDIATES >= 1000
    read_component_file(chain_file(tmp_path / "c.toml", 1000, True))
