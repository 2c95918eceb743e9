"""The parallel executor: the FMUs of one sweep stepped side by side on threads.

Under Jacobi and the iterated schemes every FMU of a sweep steps from values fixed before it, so they are
independent tasks (fmpy's ctypes calls release the GIL; each FMU is its own instance, touched by one thread).
The first sweeps run sequentially and are timed per FMU; if a sweep costs enough to pay the hand-over, the
FMUs are split into ``workers`` groups of nearly equal cost (longest processing time first) and all but one
group go to threads.  Results are bit for bit those of one thread, failures included.
"""
from __future__ import annotations

import time as _time

# threads step the FMUs only when one sequential sweep of them took at least this long [s]: handing a group
# to a thread and collecting it costs ~0.1 ms (measured on the PUMA: Jacobi at 0.625 ms, 47 us of FMU work
# per step, ran 3x slower on two threads; Newton/cubic at 40 ms, ~0.8 ms per sweep, 1.37x faster)
PARALLEL_MIN_COST = 5e-4
# the sweeps are timed sequentially until they have cost TIMED_BUDGET [s] or TIMED_SWEEPS sweeps have run;
# the mean decides, the per-FMU sums balance the groups (the first sweeps, from rest, are the cheapest)
TIMED_BUDGET, TIMED_SWEEPS = 0.01, 64


def balanced_groups(units, cost, n):
    """Longest processing time first: ``units`` into at most ``n`` groups of nearly equal summed cost."""
    groups = [[] for _ in range(min(n, len(units)))]
    load = [0.0] * len(groups)
    for u in sorted(units, key=lambda u: -cost.get(u.name, 0.0)):
        k = load.index(min(load))
        groups[k].append(u)
        load[k] += cost.get(u.name, 0.0)
    return [g for g in groups if g]


class SweepExecutor:
    """Steps the Co-Simulation FMUs of a sweep with ``do(u, t, H, no_prior)`` (returns its FMU calls): on one
    thread, or -- ``workers`` > 1 and sweeps costly enough -- on ``workers`` threads."""

    def __init__(self, units, do, workers: int):
        self.units = [u for u in units if u.kind != "me"]
        self.do = do
        self.workers = workers
        self.pool = None
        self.groups = None  # the FMUs each thread steps, balanced by their measured cost
        self.cost, self.timed = {}, 0
        if workers > 1 and len(self.units) > 1:
            from concurrent.futures import ThreadPoolExecutor

            self.pool = ThreadPoolExecutor(min(workers, len(self.units)) - 1, thread_name_prefix="fmugen-cosim")

    @property
    def threads(self) -> int:
        return len(self.groups) if self.pool is not None and self.groups else 1

    def sweep(self, t, H, no_prior) -> int:
        do = self.do
        calls = 0
        if self.pool is None:
            for u in self.units:
                calls += do(u, t, H, no_prior)
        elif self.groups is not None:
            calls += self._parallel(t, H, no_prior)
        else:  # the first sweeps: sequential, each FMU timed; then the groups
            cost = self.cost
            for u in self.units:
                c0 = _time.perf_counter()
                calls += do(u, t, H, no_prior)
                cost[u.name] = cost.get(u.name, 0.0) + _time.perf_counter() - c0
            self.timed += 1
            total = sum(cost.values())
            if total >= TIMED_BUDGET or self.timed >= TIMED_SWEEPS:
                if total < self.timed * PARALLEL_MIN_COST:  # a hand-over would cost more than it saves
                    self.shutdown()
                else:
                    self.groups = balanced_groups(self.units, cost, self.workers)
        return calls

    def _parallel(self, t, H, no_prior) -> int:
        """The sweep with the groups on threads.  Waits for every group before a failure is raised, so no
        FMU is still stepping when the master restores or reports."""
        futs = [self.pool.submit(self._group, g, t, H, no_prior) for g in self.groups[1:]]
        calls, failure = 0, None
        try:
            calls += self._group(self.groups[0], t, H, no_prior)
        except Exception as e:  # a UnitFailure: raised once every thread is done
            failure = e
        for f in futs:
            try:
                calls += f.result()
            except Exception as e:
                failure = failure or e
        if failure is not None:
            raise failure
        return calls

    def _group(self, group, t, H, no_prior) -> int:
        calls = 0
        for u in group:
            calls += self.do(u, t, H, no_prior)
        return calls

    def shutdown(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True)
            self.pool = None
