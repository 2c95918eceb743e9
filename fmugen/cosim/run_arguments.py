"""The arguments of the run commands (``fmugen cosim``, ``reference``, ``report``), for a scene or an SSP.

:func:`check_args` checks every argument before anything is built or written; :func:`run_flags` gives
the run settings the command line set.  A module of its own so that :mod:`fmugen.cosim.commands` and
:mod:`fmugen.ssp.report` (``fmugen report x.ssp``) both use it without importing each other.
"""
from __future__ import annotations

__all__ = ["check_args", "run_flags"]


def check_args(args, scene) -> None:
    """Every argument of cosim/reference/report, checked before anything is built or written
    (:mod:`fmugen.arguments`: each refusal names the argument)."""
    from .. import arguments as a
    from ..scene.file import check_time_grid

    a.output_folder(args.out, "--out", inputs=[args.scene])
    start, stop, step = scene.spec.start, scene.spec.stop, scene.spec.step
    if args.stop is not None:
        stop = a.number(args.stop, "--stop")
        if not stop > start:
            raise a.FmugenError(f"--stop {args.stop!r}: must be after the scene's start time {start!r}")
    cosim = dict(getattr(scene.spec, "cosim", None) or {})
    if getattr(args, "step", None) is not None:
        step = a.positive(args.step, "--step", "a positive macro step [s]")
    elif cosim.get("step") is not None:  # the file's [cosim] step (or --set cosim.step): bounded the same way
        step = a.positive(cosim["step"], "[cosim] step", "a positive macro step [s]")
    if getattr(args, "tol", None) is not None:
        a.tolerance(args.tol, "--tol")
    given = [o for o, v in (("--stop", args.stop), ("--step", getattr(args, "step", None))) if v is not None]
    check_time_grid(start, stop, min(step, stop - start),
                    f"{'/'.join(given)}:" if given else f"{args.scene}: [scene]/[cosim] stop and step:")
    if getattr(args, "points", None) is not None:
        args.points = a.count(args.points, "--points", 1, a.MAX_POINTS)
    if getattr(args, "steps", None) is not None:
        for h in a.number_list(args.steps, "--steps", lambda v, w: a.positive(v, w, "a positive macro step")):
            check_time_grid(start, stop, min(h, stop - start), f"--steps {args.steps}:")
    if getattr(args, "target", None) is not None:
        a.positive(args.target, "--target", "a positive error target")
    if getattr(args, "repeats", None) is not None:
        args.repeats = a.count(args.repeats, "--repeats", 1, 1000)


def run_flags(args) -> dict:
    """The run settings given on the command line (None: not given)."""
    return {"scheme": getattr(args, "scheme", None), "extrapolation": getattr(args, "extrapolation", None),
            "step": getattr(args, "step", None), "stop": args.stop, "adaptive": getattr(args, "adaptive", None),
            "tol": getattr(args, "tol", None), "workers": args.workers, "coupling_tol": args.coupling_tol,
            "iterations": args.iterations, "detect_divergence": args.detect_divergence}
