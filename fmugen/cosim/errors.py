"""Errors of the co-simulation package.

:class:`CosimError` is bad input to the master (unknown scheme, a coupling to
a variable that does not exist, a non-finite step): a ``ValueError`` (the
project's :class:`fmugen.errors.FmugenError` where that exists), raised before
anything runs.  A run that fails *while running* does not raise: it returns
its results up to the failure with a :class:`~fmugen.cosim.master.FailureReport`.
"""
from __future__ import annotations

try:  # the project's user-error class, when present
    from ..errors import FmugenError as _Base
except ImportError:  # pragma: no cover - older trees
    _Base = ValueError


class CosimError(_Base):
    """A co-simulation set-up or option the master refuses (a ValueError), always one line: a name taken
    from a system or an FMU may hold a newline or another control character, which is shown escaped."""

    def __init__(self, message="", *args):
        text = str(message)
        if not text.isprintable():
            text = "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in text)
        super().__init__(text, *args)
