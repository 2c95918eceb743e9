"""CPU time per call, the one way the benchmarks time code (a helper of bench_large_models.py,
bench_tree_dynamics.py and urdf_table.py; run alone it prints Pinocchio's Python call overhead).

* ``per_call(fn, args, k)``: CPU seconds per call of ``fn(*args)`` over ``k`` calls from Python;
* ``pinocchio_per_call(fn, args, k)``: the same for a Pinocchio algorithm (``aba``, ``rnea``,
  ``computeABADerivatives``: model, data and three vectors) less the same call on an empty model, i.e.
  the algorithm without Python's call overhead;
* ``c_loop(cm, p, x, u, which, k)``: CPU seconds per call of a generated function called ``k`` times by
  a C loop (``CompiledModel.time_per_call``, whose own figure is wall time).

CPU time of the calling thread (``time.thread_time``), not wall time: 2 cores shared with other work,
and not the process's CPU time either, which counts the BLAS threads that numpy's OpenBLAS leaves
spinning after a call (they inflated both sides of a ratio, unequally: iiwa's unrolled ∇FD 2.65 against
2.24 µs with ``OPENBLAS_NUM_THREADS=1``, Pinocchio's 7.6 against 5.7).
"""
from __future__ import annotations

import argparse
import functools
import time
from pathlib import Path

import numpy as np


def robots_dir() -> Path:
    """example-robot-data's robots/ folder (the package installs files, no Python module)."""
    from importlib.metadata import PackageNotFoundError, distribution

    try:
        d = Path(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots"))
    except PackageNotFoundError as e:
        raise ImportError("example-robot-data is not installed") from e
    if not d.is_dir():
        raise ImportError(f"example-robot-data's robots folder not found at {d}")
    return d


def per_call(fn, args, k: int) -> float:
    t = time.thread_time()
    for _ in range(k):
        fn(*args)
    return (time.thread_time() - t) / k


@functools.lru_cache(maxsize=None)
def _empty_pinocchio():
    import pinocchio as pin

    empty = pin.Model()
    z = np.zeros(0)
    return empty, empty.createData(), z


def pinocchio_per_call(fn, args, k: int) -> float:
    empty, ed, z = _empty_pinocchio()
    return per_call(fn, args, k) - per_call(fn, (empty, ed, z, z, z), k)


def c_loop(cm, p, x, u, which: str, k: int) -> float:
    t = time.thread_time()
    cm.time_per_call(p, x, u, which, n=k)
    return (time.thread_time() - t) / k


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--calls", type=int, default=20000, help="calls timed")
    args = ap.parse_args(argv)
    import pinocchio as pin

    empty, ed, z = _empty_pinocchio()
    print(f"pinocchio.aba on an empty model (the call overhead subtracted): "
          f"{per_call(pin.aba, (empty, ed, z, z, z), args.calls) * 1e6:.2f} us CPU per call")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
