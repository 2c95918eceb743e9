"""The macro-step size controller of adaptive runs (``adaptive=True``).

The local error indicator is the **interface defect** d = U_{n+1} - P(t_{n+1}): what an FMU was told its
input would be at t_{n+1} (the extrapolant, or the iterated scheme's predictor) against what it was,
relative to ``tol`` times each signal's magnitude; it is O(H^p) with p = the predictor's order.  A step with
err = max|d| / (tol * scale) > 1 is rolled back and retried smaller; an accepted step sets the next H by a
PI controller (Gustafsson 1991) with a dead band, growth at most 2x, no growth right after a rejection and
growth only when the last ``GROW_AFTER`` accepted steps all asked for it (no chattering on lightly damped
modes).  An FMU that discards, or an iteration that does not converge, is retried at a quarter of the step.
"""
from __future__ import annotations

from collections import deque

# Gustafsson PI: safety factor, largest growth, no change inside the dead band, growth votes needed
SAFETY, FAC_MAX, DEAD_BAND, GROW_AFTER = 0.8, 2.0, (0.9, 1.3), 4


class StepSizeController:
    def __init__(self, p, Hmin, Hmax):
        self.p = p  # order of the defect in H
        self.Hmin, self.Hmax = Hmin, Hmax
        self.err_prev = 1.0
        self.rejected_last = False
        self.votes = deque(maxlen=GROW_AFTER)  # step-size factors the last accepted steps proposed

    def at_minimum(self, H) -> bool:
        return H <= self.Hmin * (1 + 1e-12)

    def reject(self, H, err) -> float:
        """The defect was err x tol: the step to retry with."""
        self.votes.clear()
        self.rejected_last = True
        return max(self.Hmin, H * max(0.2, SAFETY * err ** (-1.0 / self.p)))

    def retry(self, H) -> float:
        """An FMU discarded or the iteration did not converge: a quarter of the step."""
        self.rejected_last = True
        return max(self.Hmin, H / 4)

    def accept(self, H, err) -> float:
        """The step after an accepted one whose defect was err x tol."""
        p, votes = self.p, self.votes
        err = max(err, 1e-10)
        fac = SAFETY * err ** (-0.7 / p) * self.err_prev ** (0.4 / p)
        fac = min(FAC_MAX, max(0.2, fac))
        if self.rejected_last:
            fac = min(fac, 1.0)
        votes.append(fac)
        if fac > DEAD_BAND[1]:
            # grow only when the last GROW_AFTER accepted steps all asked for it, by the least they asked: a
            # lightly damped mode makes the defect oscillate step to step
            fac = min(votes) if len(votes) == GROW_AFTER else 1.0
            if fac <= DEAD_BAND[1]:
                fac = 1.0
        elif fac >= DEAD_BAND[0]:
            fac = 1.0  # dead band: an accepted step is kept unless the change is worth it
        if fac != 1.0:
            votes.clear()
        self.err_prev = err
        self.rejected_last = False
        return min(self.Hmax, max(self.Hmin, H * fac))
