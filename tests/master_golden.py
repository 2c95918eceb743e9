"""The cases that compare the restructured master with the single-module master it replaced.

The old master (``fmugen/cosim/master.py`` of commit 59795fa, before it was split into modules) ran each of
``CASES`` once on today's FMU wrappers and ME block and on the rigs' FMUs; what it gave is stored in
``tests/data/master_59795fa.npz`` (how: tests/data/README.md): the recorded arrays, the summary counters of
:func:`counters` and, where a run failed, the failure's time, cause, FMU and coupling.  ``CASES`` cover each
scheme x extrapolation, adaptive runs with rollbacks, divergence reports, an FMU failure, a non-converged
iteration, Model-Exchange units, an algebraic FMU (exact Newton columns), FMUs without input interpolation and
threads.  :func:`fmu_sources_key` names the FMUs' code the results belong to (C sources and XML of each FMU).
"""
from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from cosim_rigs import amp_split_system, split_system


STORED = Path(__file__).parent / "data" / "master_59795fa.npz"


def counters(r) -> dict:
    """Every summary counter that must agree exactly, and where a run failed, the failure's time, cause, FMU
    and coupling (floats as they are: JSON writes and reads them back bit for bit)."""
    s, f = r.summary, r.summary.failure
    return {"failed": s.status == "failed", "macro_steps": s.macro_steps, "rollbacks": s.rollbacks,
            "iterations": s.iterations, "jacobians": s.jacobians, "do_steps": s.do_steps, "fmu_calls": s.fmu_calls,
            "step_min": s.step_min, "step_max": s.step_max, "threads": s.threads,
            "failure": [f.time, f.cause, f.unit, f.coupling] if f else None}


def fmu_sources_key(system) -> str:
    """Hash of every FMU's sources/ and modelDescription.xml: the code the results depend on besides the
    master's (the compiler aside)."""
    h = hashlib.sha256()
    for u in sorted(system.units, key=lambda u: u.name):
        with zipfile.ZipFile(u.path) as z:
            for n in sorted(n for n in z.namelist() if n.startswith("sources/") or n == "modelDescription.xml"):
                h.update(f"{u.name}/{n}\0".encode() + z.read(n) + b"\1")
    return h.hexdigest()[:16]


def stored_results() -> dict:
    """case -> {"time", "values", "columns", "counters", "fmu_sources"} of the old master."""
    with np.load(STORED) as z:
        meta = json.loads(str(z["meta"]))
        return {m["case"]: dict(m, time=z[f"time_{i}"], values=z[f"values_{i}"]) for i, m in enumerate(meta)}


def _me(unit):
    return replace(unit, fmi_type="me", start_values={k: v for k, v in unit.start_values.items()
                                                      if not k.startswith("solver.")})


def _mixed():
    s = split_system("stiff", "smooth", stop=0.2)
    return replace(s, units=(s.units[0], _me(s.units[1])))


CASES = {}
for _s, _e in [("jacobi", "hold"), ("jacobi", "linear"), ("jacobi", "quadratic"), ("gauss-seidel", "hold"),
               ("gauss-seidel", "linear"), ("gauss-seidel", "quadratic"), ("iterative", "linear"),
               ("iterative", "quadratic"), ("iterative", "cubic"), ("newton", "linear"), ("newton", "quadratic"),
               ("newton", "cubic")]:
    CASES[f"{_s}/{_e}"] = (lambda s=_s, e=_e: (split_system("default", "smooth", stop=0.3), s, e,
                                                dict(step=2e-3)))
CASES["stiff newton/cubic 20ms"] = lambda: (split_system("stiff", "smooth", stop=0.4), "newton", "cubic",
                                             dict(step=0.02))
CASES["adaptive jacobi/linear"] = lambda: (split_system(stop=0.3), "jacobi", "linear",
                                           dict(step=2e-3, adaptive=True, tol=1e-2))
CASES["adaptive newton/quadratic"] = lambda: (split_system(stop=0.3), "newton", "quadratic",
                                              dict(step=2e-3, adaptive=True, tol=1e-2))
CASES["adaptive gauss-seidel/hold"] = lambda: (split_system("stiff", stop=0.2), "gauss-seidel", "hold",
                                               dict(step=5e-3, adaptive=True, tol=1e-3))
CASES["diverged jacobi/hold"] = lambda: (split_system(stop=1.0), "jacobi", "hold", dict(step=5e-3))
CASES["diverged gauss-seidel/hold"] = lambda: (split_system("stiff", stop=1.0), "gauss-seidel", "hold",
                                               dict(step=7e-3))
CASES["fmu-failure"] = lambda: (split_system("stiff", "step", stop=1.0), "jacobi", "hold",
                                dict(step=0.02, detect_divergence=False))
CASES["not-converged"] = lambda: (split_system("stiff", stop=0.2), "iterative", "linear",
                                  dict(step=0.02, max_iterations=5))
CASES["amp newton/linear"] = lambda: (amp_split_system(stop=0.3), "newton", "linear", dict(step=5e-3))
CASES["amp gauss-seidel/linear"] = lambda: (amp_split_system(stop=0.3), "gauss-seidel", "linear",
                                            dict(step=1e-3))
CASES["mixed me jacobi/linear"] = lambda: (_mixed(), "jacobi", "linear", dict(step=5e-3))
CASES["mixed me newton/linear"] = lambda: (_mixed(), "newton", "linear", dict(step=5e-3))
CASES["threads newton/cubic"] = lambda: (split_system(stop=0.3), "newton", "cubic",
                                         dict(step=2e-3, workers=2))
CASES["threads adaptive jacobi/linear"] = lambda: (split_system(stop=0.3), "jacobi", "linear",
                                                   dict(step=2e-3, adaptive=True, tol=1e-2, workers=2))


# the chain FMU treated as one that cannot interpolate inputs (canInterpolateInputs = false): midpoint values.
# Not Gauss-Seidel: since the old master it gives such an FMU the midpoint of the line to its source's new value
# (second order) instead of the new value held (first order), checked by tests/test_cosim_feedthrough.py
for _s, _e in [("jacobi", "linear"), ("newton", "linear"), ("iterative", "linear")]:
    CASES[f"no-interp {_s}/{_e}"] = (lambda s=_s, e=_e: (split_system("default", "smooth", stop=0.3), s, e,
                                                          dict(step=2e-3)))


def run_case(name):
    """The case run by today's master, with the old master's defaults; returns (result, its system)."""
    from fmugen.cosim import Master

    system, scheme, ext, opts = CASES[name]()
    opts.setdefault("estimate", False)  # its shadow steps add FMU calls (the trajectory: test_cosim_estimate)
    if scheme in ("iterative", "newton"):
        opts.setdefault("coupling_tol", 1e-8)  # the old master's default (now derived from the FMUs' rtol)
    workers = opts.pop("workers", 1)
    with Master(system, scheme, ext, workers=workers) as m:
        if name.startswith("no-interp"):
            chain = next(u for u in m.units if u.name == "chain")
            chain.can_interpolate = False
            m.no_interp[chain.in_sl] = True
        return m.run(**opts), system
