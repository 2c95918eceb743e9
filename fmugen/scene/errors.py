"""The error a scene raises for anything wrong in what the user wrote."""
from __future__ import annotations

import difflib

from ..errors import FmugenError


class SceneError(FmugenError):
    """A scene file, a ``--set`` or a scene request is wrong; the message names file, key and reason."""


def did_you_mean(name: str, known) -> str:
    """`` (did you mean 'x'?)`` when a known name is close, else ``""``."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""
