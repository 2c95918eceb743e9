"""Benchmark: component files with long chains of intermediates build in time linear in their length.

The chain of the issue: ``a0 = sin(phi)``, ``a_k = sin(a_{k-1})*cos(a_{k-1}) + a_{k-1}*a_{k-1}``, each link
reading the previous one three times (expanded, 3**n terms).  Two forms of the state equation:

* ``used``: ``der(w) = -k*phi - c*a_n`` -- the whole chain is in f and in its Jacobian;
* ``unused``: ``der(w) = -k*phi + 0*a_n`` (the issue's file) -- pruned away.

For n = 10, 100, 1000 links: the derivation (``load_component``: parse, unit check, program, chain-rule
Jacobians), the generated operation count (``SymbolicModel.operation_count`` of the pruned model:
program + Jacobian program, before the CSE of the C writer), and the wall time of
``fmugen build comp.toml`` in a fresh process (derivation, C generation with its one CSE, compiling
ME and CS, zipping).  f and df/dx of the 1000-link file are checked against the chain evaluated in plain
Python and against central finite differences.  Growth: the slope of log(time) against log(n).

    python examples/bench_component_swell.py                # n = 10, 100, 1000
    python examples/bench_component_swell.py --sizes 10,100 --no-build
"""
from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def chain_file(path: Path, n: int, used: bool = True) -> Path:
    last = f"- c*a{n}" if used else f"+ 0*a{n}"
    eqs = ['"der(phi) = w"', f'"der(w) = -k*phi {last}"', '"a0 = sin(phi)"']
    eqs += [f'"a{k} = sin(a{k - 1})*cos(a{k - 1}) + a{k - 1}*a{k - 1}"' for k in range(1, n + 1)]
    inter = "\n".join(f'a{k} = {{ unit = "1" }}' for k in range(n + 1))
    path.write_text(f"""[component]
name = "chain{n}"
equations = [{", ".join(eqs)}]
[parameters]
k = {{ value = 4.0, unit = "1/s2" }}
c = {{ value = 0.5, unit = "1/s2" }}
[states]
phi = {{ unit = "1", start = -0.5 }}
w = {{ unit = "1/s" }}
[intermediates]
{inter}
""")
    return path


def chain_value(phi: float, n: int) -> float:
    a = math.sin(phi)
    for _ in range(n):
        a = math.sin(a) * math.cos(a) + a * a
    return a


def derive(path: Path) -> tuple:
    from fmugen.components.equations import read_component_file
    from fmugen.components.equations.file import component_model

    t0 = time.perf_counter()
    model = component_model(read_component_file(path))
    return model, time.perf_counter() - t0


def build(path: Path, out: Path) -> float:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-W", "ignore", "-m", "fmugen.cli", "build", str(path), "-o", str(out),
                        "--no-cache"], cwd=ROOT, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"fmugen build {path} failed:\n{r.stdout}\n{r.stderr}")
    return time.perf_counter() - t0


def check(model, n: int) -> tuple:
    """(|f - plain Python|, max |df/dx - central differences| / scale) at phi = -0.5, w = 0.3."""
    from fmugen.components import NumericModel

    ev = NumericModel(model)
    p = {v.name: v.start for v in model.parameters}
    x = np.array([-0.5, 0.3])
    f = np.asarray(ev.f(0.0, x, []), float)
    f_ref = np.array([x[1], -p["k"] * x[0] - p["c"] * chain_value(x[0], n)])
    A = np.asarray(ev.dfdx(0.0, x, []), float)
    h = 1e-6
    fd = np.array([(np.asarray(ev.f(0.0, x + h * e, []), float) - np.asarray(ev.f(0.0, x - h * e, []), float))
                   / (2 * h) for e in np.eye(2)]).T
    return float(np.max(np.abs(f - f_ref))), float(np.max(np.abs(A - fd)) / max(1.0, np.max(np.abs(A))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="10,100,1000")
    ap.add_argument("--no-build", action="store_true", help="derivation only (no C, no compiler)")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for n in sizes:
            for used in (True, False):
                path = chain_file(tmp / f"chain{n}{'u' if used else ''}.toml", n, used)
                model, t_derive = derive(path)
                ops = model.pruned().operation_count()
                t_build = math.nan if args.no_build else build(path, tmp / f"chain{n}{'u' if used else ''}.fmu")
                err = check(model, n) if used else (math.nan, math.nan)
                rows.append((n, "used" if used else "0*a_n", t_derive, ops, t_build, *err))
    print(f"{'n':>6} {'form':>6} {'derive s':>9} {'ops':>7} {'build s':>8} {'|f-ref|':>9} {'|J-FD|':>9}")
    for n, form, td, ops, tb, ef, ej in rows:
        print(f"{n:6d} {form:>6} {td:9.2f} {ops:7d} {tb:8.2f} {ef:9.1e} {ej:9.1e}")
    used = [r for r in rows if r[1] == "used"]
    if len(used) >= 2:
        (n0, _, d0, o0, b0, *_), (n1, _, d1, o1, b1, *_) = used[-2], used[-1]
        k = math.log(n1 / n0)
        print(f"growth n = {n0} -> {n1} (used): derive ~ n^{math.log(d1 / d0) / k:.2f}, ops ~ n^"
              f"{math.log(o1 / o0) / k:.2f}" + ("" if args.no_build else f", build ~ n^{math.log(b1 / b0) / k:.2f}"))


if __name__ == "__main__":
    main()
