"""The errors fmugen raises for bad input.

Every problem with what a user gives -- a file, a field in it, an override, an
API argument -- is a :class:`FmugenError`.  It subclasses :class:`ValueError`
so that code written against the earlier ``ValueError`` keeps working.  The
command line prints the message on one line and exits with status 2.

* :class:`FmugenError`     -- any user error (bad value, bad name, bad option);
* :class:`InputFileError`  -- a problem in a file; the message starts with the
  file and, where there is one, the entry and field:
  ``"robots/arm.toml: link 2 (upper_arm): mass: non-finite value inf"``.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

__all__ = ["FmugenError", "InputFileError", "read_text_file", "toml_problem", "check_finite", "check_identifier",
           "MAX_IDENTIFIER_LENGTH", "IDENTIFIER_PATTERN"]

#: names that become C identifiers, FMU model identifiers and file names: ASCII
#: only (a C compiler and every file system accept them), bounded so that
#: ``<identifier>.so`` and the temporary build directory stay far below the
#: 255-byte file-name limit of common file systems.
IDENTIFIER_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
MAX_IDENTIFIER_LENGTH = 64
#: largest input text file read (robot, scene, parameter set, assembly): the biggest shipped file is
#: a few kB; a larger one is refused with its size before it is read into memory
MAX_INPUT_BYTES = 16 * 2**20


class FmugenError(ValueError):
    """Bad input given to fmugen (the message says what and where)."""


class InputFileError(FmugenError):
    """A file (or an entry or field of it) that fmugen cannot accept."""


def read_text_file(path, what: str = "file") -> str:
    """The UTF-8 text of ``path``; a missing, unreadable or binary file is an
    :class:`InputFileError` naming the file (never a bare ``UnicodeDecodeError``)."""
    import stat

    p = Path(path)
    try:
        st = p.stat()
        if stat.S_ISDIR(st.st_mode):
            raise IsADirectoryError
        if not stat.S_ISREG(st.st_mode):  # /dev/zero, a FIFO, a socket: reading could never end
            raise InputFileError(f"{p}: not a regular file (a device, FIFO or socket); a {what} must be a file")
        if st.st_size > MAX_INPUT_BYTES:
            raise InputFileError(f"{p}: {st.st_size / 2**20:.0f} MiB; a {what} is text of at most "
                                 f"{MAX_INPUT_BYTES // 2**20} MiB")
        with open(p, "rb") as fh:
            data = fh.read(MAX_INPUT_BYTES + 1)
        if len(data) > MAX_INPUT_BYTES:  # it grew while being read
            raise InputFileError(f"{p}: more than {MAX_INPUT_BYTES // 2**20} MiB; a {what} is text of at most "
                                 f"{MAX_INPUT_BYTES // 2**20} MiB")
    except FileNotFoundError:
        raise InputFileError(f"{p}: no such {what}") from None
    except IsADirectoryError:
        raise InputFileError(f"{p}: is a directory, not a {what}") from None
    except OSError as exc:
        raise InputFileError(f"{p}: cannot read the {what}: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{p}: not a UTF-8 text file (byte 0x{data[exc.start]:02x} at offset "
                             f"{exc.start}); a {what} must be UTF-8 TOML") from None
    if "\x00" in text:
        raise InputFileError(f"{p}: contains a NUL byte; a {what} must be a text file")
    return text


def toml_problem(exc: BaseException) -> str:
    """The phrase for a file tomllib could not read: its syntax error, or nesting deeper than
    Python's recursion allows (``a = [[[[...]]]]`` thousands deep) -- never a bare RecursionError."""
    if isinstance(exc, RecursionError):
        return "not usable TOML: values nested too deeply (arrays or tables inside each other hundreds of levels deep)"
    return f"not valid TOML: {exc}"


def check_finite(value: float, where: str) -> float:
    """``value`` as a float, or an :class:`InputFileError` at ``where`` if NaN or infinite."""
    try:
        v = float(value)
    except OverflowError:
        raise InputFileError(f"{where}: an integer beyond the double-precision range") from None
    except (TypeError, ValueError):
        raise InputFileError(f"{where}: {value!r} is not a number") from None
    if not math.isfinite(v):
        raise InputFileError(f"{where}: non-finite value {v!r}")
    return v


def check_identifier(name, where: str) -> str:
    """``name`` if it is an ASCII identifier of at most :data:`MAX_IDENTIFIER_LENGTH`
    characters, else an :class:`InputFileError` ``"<where> must be a C identifier ..."``."""
    rule = (f"must be a C identifier (ASCII letters, digits and '_', starting with a letter; at most "
            f"{MAX_IDENTIFIER_LENGTH} characters, as it also becomes a file name)")
    if not isinstance(name, str):
        raise InputFileError(f"{where} {rule}, got {name!r}")
    if len(name) > MAX_IDENTIFIER_LENGTH:
        raise InputFileError(f"{where} {rule}, got {len(name)} characters ({name[:20]!r}...)")
    if not IDENTIFIER_PATTERN.match(name):
        bad = sorted({c for c in name if not (c.isascii() and (c.isalnum() or c == "_"))})
        why = f"the characters {''.join(bad)!r} are not allowed" if bad else "it does not start with a letter"
        raise InputFileError(f"{where} {rule}, got {name!r}: {why}")
    return name
