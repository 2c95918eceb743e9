"""Opening an FMU the master did not build: one clear line when it cannot be run.

A third-party FMU may be anything: not a zip, an empty file, a FIFO, FMI 1.0,
a modelDescription.xml that is not XML (or 300 MB of it), a model
identifier without its binary, a binary for another platform only, a zip that
unzips to more than :data:`MAX_UNZIPPED_BYTES`.  fmpy
and the zip/XML libraries each raise their own exceptions for these, whose
text names neither the FMU nor what to do.  :func:`read_description` checks
what can be checked before parsing, parses under one guard, and raises
:class:`~fmugen.cosim.errors.CosimError` (a ``FmugenError``: the command
line prints one line and exits 2) that names the FMU, its file and the
problem.  :func:`load_failure` turns what loading the binary raised into the
same kind of line.

What the master then asks of the FMU is checked where it is asked
(:meth:`fmugen.cosim.master.Master.run`: FMU states for iterated schemes and
adaptive steps).
"""
from __future__ import annotations

import re
import stat
import zipfile
from pathlib import Path

from .errors import CosimError

__all__ = ["MAX_DESCRIPTION_BYTES", "MAX_UNZIPPED_BYTES", "read_description", "load_failure", "platform_binary"]

#: largest modelDescription.xml read (uncompressed): a generated PUMA arm's is
#: ~100 KB; 64 MB holds a model with some 100 000 variables, and bounds the
#: memory and time a hostile file can make the parser spend
MAX_DESCRIPTION_BYTES = 64 * 1024 * 1024
#: most the master unzips of one FMU (binaries, resources, the description; not sources/ nor
#: documentation/, which it skips) and most members: a zip bomb inside an SSP's FMU would otherwise
#: fill the disk (the SSP's own extraction is bounded, fmpy's extraction of the FMU is not).  The
#: sizes are the ones the zip declares: Python's zipfile stops a member at its declared size.
MAX_UNZIPPED_BYTES = 2 << 30
MAX_MEMBERS = 65536


def _label(name: str, path: Path) -> str:
    return f"FMU {name!r} ({path})"


#: the FMI versions the master runs (fmugen/cosim/units.py: FMI 2.0, units3.py: FMI 3.0)
VERSIONS = ("2.0", "3.0")
RUNS = "the master runs FMI 2.0 FMUs and FMI 3.0 FMUs"


def platform_binary(model_identifier: str, fmi_version: str = "2.0") -> str:
    """``binaries/<platform>/<model identifier><extension>`` of this machine: FMI 2.0's platform names
    (``linux64``, sec. 2.3), FMI 3.0's platform tuples (``x86_64-linux``, sec. 2.5.1)."""
    from fmpy import platform, platform_tuple, sharedLibraryExtension

    folder = platform_tuple if fmi_version.startswith("3") else platform
    return f"binaries/{folder}/{model_identifier}{sharedLibraryExtension}"


def read_description(name: str, path, interface: str):
    """The fmpy model description of the FMU at ``path`` (unit ``name``), checked to be a
    readable FMI 2.0 or 3.0 FMU with the ``interface`` ("cs" or "me") and its binary for this platform;
    else :class:`CosimError` naming the FMU and the problem."""
    path = Path(path)
    where = _label(name, path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise CosimError(f"{where}: the file does not exist") from None
    except OSError as e:
        raise CosimError(f"{where}: cannot open the file: {e.strerror or e}") from None
    if not stat.S_ISREG(st.st_mode):
        raise CosimError(f"{where}: not a regular file (a directory, FIFO or device); an FMU is a zip file")
    if st.st_size == 0:
        raise CosimError(f"{where}: the file is empty; an FMU is a zip file")
    try:
        with zipfile.ZipFile(path) as z:
            infos = z.infolist()
            names = {i.filename for i in infos}
            if len(infos) > MAX_MEMBERS:
                raise CosimError(f"{where}: {len(infos)} members in the zip, more than the {MAX_MEMBERS} this "
                                 f"master unzips")
            unzipped = sum(i.file_size for i in infos if not i.filename.startswith(("sources/", "documentation/")))
            if unzipped > MAX_UNZIPPED_BYTES:
                raise CosimError(f"{where}: unzips to {unzipped / 2**20:.0f} MB, more than the "
                                 f"{MAX_UNZIPPED_BYTES // 2**20} MB this master extracts")
            try:
                info = z.getinfo("modelDescription.xml")
            except KeyError:
                raise CosimError(f"{where}: the zip holds no modelDescription.xml: not an FMU") from None
            if info.file_size > MAX_DESCRIPTION_BYTES:
                raise CosimError(f"{where}: modelDescription.xml is {info.file_size / 2**20:.0f} MB, more than "
                                 f"the {MAX_DESCRIPTION_BYTES // 2**20} MB this master reads")
            with z.open(info) as f:
                head = f.read(65536).decode("utf-8", "replace")
    except CosimError:
        raise
    except zipfile.BadZipFile:
        raise CosimError(f"{where}: not a zip file, so not an FMU") from None
    except OSError as e:
        raise CosimError(f"{where}: cannot read the file: {e.strerror or e}") from None
    # the FMI version before the schema check: an FMI 1.0 description fails the 2.0 schema, and the
    # schema's complaint would hide that it is simply another version
    m = re.search(r"<fmiModelDescription\b[^>]*?\bfmiVersion\s*=\s*[\"']([^\"']{0,20})[\"']", head)
    if m and m.group(1) not in VERSIONS:
        raise CosimError(f"{where}: FMI {m.group(1)}; {RUNS}")
    from fmpy import read_model_description

    try:
        md = read_model_description(str(path))
    except CosimError:
        raise
    except Exception as e:  # lxml, fmpy's own checks, zip: whatever the parser met
        text = " ".join(str(e).split()) or type(e).__name__
        raise CosimError(f"{where}: modelDescription.xml cannot be read ({type(e).__name__}: {text[:300]})") from None
    version = str(getattr(md, "fmiVersion", "") or "?")
    if version not in VERSIONS:
        raise CosimError(f"{where}: FMI {version}; {RUNS}")
    part = md.coSimulation if interface == "cs" else md.modelExchange
    if part is None:
        kind = "Co-Simulation" if interface == "cs" else "Model-Exchange"
        raise CosimError(f"{where} has no {kind} interface (fmi_type = {interface!r})")
    ident = str(part.modelIdentifier or "")
    binary = platform_binary(ident, version)
    if binary not in names:
        have = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2
                       and n.split("/")[1]})
        others = [n for n in names if n.startswith(binary.rsplit("/", 1)[0] + "/") and n != binary]
        if others:
            why = (f"no {binary} for its model identifier {ident!r} (the platform folder holds "
                   f"{', '.join(sorted(o.rsplit('/', 1)[1] for o in others)[:4])})")
        else:
            why = (f"no binary for this platform ({binary}; it has {', '.join(have) if have else 'no binaries'})"
                   + ("; its sources/ can be compiled with `fmpy compile`" if any(n.startswith("sources/")
                                                                                for n in names) else ""))
        raise CosimError(f"{where}: {why}")
    return md


def load_failure(name: str, path, call: str, exc: BaseException, messages=()) -> CosimError:
    """One line for an exception raised while loading or instantiating the FMU's binary."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    tail = f"; its last message: {messages[-1]}" if messages else ""
    return CosimError(f"{_label(name, Path(path))}: {call} failed ({type(exc).__name__}: {text[:300]}){tail}")
