"""Parameter studies: a scene run at every point of a grid or a Monte-Carlo sample, on Dask.

    import fmugen.sweep
    r = fmugen.sweep.sweep("examples/scenes/single_joint_split.toml", grid=["joint.J=1,2,4"],
                           metrics=["final,peak,settling"], out="out/sweep_J")
    r.rows                      # one dict per point: values, status, failure, metrics
    r.column("joint.theta:final")

* :mod:`.points`  -- grid and sampling (``normal(1.6e9,5e7)``: parsed, never evaluated; seeded);
* :mod:`.prepare` -- the FMUs built once, each point's start values (and state of rest);
* :mod:`.worker`  -- one point on a Dask worker, from FMUs shipped once;
* :mod:`.metrics` -- final value, peak, settling time, L-inf error against the reference;
* :mod:`.table`   -- the journal (restart), the table (CSV, Parquet), the plot;
* :mod:`.execute` -- :func:`sweep`: the local cluster or a scheduler, progress, restart;
* :mod:`.cli`     -- ``fmugen sweep``.

How to run a sweep on a real cluster: ``fmugen/sweep/README.md``.
"""
from .errors import SweepError
from .execute import SweepResult, start_client, sweep
from .points import Distribution, make_points, parse_distribution, point_key

__all__ = ["SweepError", "SweepResult", "start_client", "sweep", "Distribution", "make_points",
           "parse_distribution", "point_key"]
