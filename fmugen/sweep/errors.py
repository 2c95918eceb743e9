"""The error a sweep raises for bad input: a ValueError naming the option or file and the reason."""
from __future__ import annotations

from ..errors import FmugenError


class SweepError(FmugenError):
    """A sweep specification the sweep refuses (bad ``--grid``/``--sample``, a folded parameter, ...)."""


class PointRefused(SweepError):
    """A point whose values fail the physical checks a file value gets: recorded as refused, never run."""
