"""Runs that compare the restructured master with the single-module master it replaced.

``tests/legacy/master_59795fa.py`` is ``fmugen/cosim/master.py`` as it was at commit 59795fa, before it was
split into modules, unchanged; :func:`legacy_master` loads it inside ``fmugen.cosim`` (so it uses today's
FMU wrappers and ME block) and :func:`run_case` runs a case with either master on the same FMUs.
``fingerprint(result)`` hashes what must agree bit for bit: the recorded arrays (their bytes), every summary
counter, and where a run failed, the failure's time, cause, FMU and coupling.  ``CASES`` cover each scheme x
extrapolation, adaptive runs with rollbacks, divergence reports, an FMU failure, a non-converged iteration,
Model-Exchange units, an algebraic FMU (exact Newton columns), FMUs without input interpolation and threads.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import replace

import numpy as np

from cosim_rigs import amp_split_system, split_system


def fingerprint(r) -> str:
    s = r.summary
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(r.time, dtype=float).tobytes())
    h.update(np.ascontiguousarray(r.values, dtype=float).tobytes())
    f = s.failure
    counters = [s.status == "failed", s.macro_steps, s.rollbacks, s.iterations, s.jacobians, s.do_steps,
                s.fmu_calls, repr(s.step_min), repr(s.step_max), s.threads,
                [repr(f.time), f.cause, f.unit, f.coupling] if f else None]
    h.update(json.dumps(counters).encode())
    return h.hexdigest()[:24]


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


def legacy_master():
    """The master of commit 59795fa as module ``fmugen.cosim._master_59795fa``."""
    import importlib.util
    import sys
    from pathlib import Path

    name = "fmugen.cosim._master_59795fa"
    if name not in sys.modules:
        path = Path(__file__).parent / "legacy" / "master_59795fa.py"
        spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def run_case(name, legacy=False):
    from fmugen.cosim import Master

    system, scheme, ext, opts = CASES[name]()
    if legacy:
        Master = legacy_master().Master
    else:
        opts.setdefault("estimate", False)  # its shadow steps add FMU calls (the trajectory: test_cosim_estimate)
        if scheme in ("iterative", "newton"):
            opts.setdefault("coupling_tol", 1e-8)  # the old master's default (now derived from the FMUs' rtol)
    workers = opts.pop("workers", 1)
    with Master(system, scheme, ext, workers=workers) as m:
        if name.startswith("no-interp"):
            chain = next(u for u in m.units if u.name == "chain")
            chain.can_interpolate = False
            m.no_interp[chain.in_sl] = True
        return m.run(**opts)
