"""The FMI Compliance Checker (``fmuCheck.linux64``, built on FMI Library) as a test oracle.

FMI Library is what OMSimulator, OpenModelica's importer, libcosim and the checker itself parse
modelDescription.xml with; it enforces rules fmpy's validation does not (one start per alias set).
``tests/tools/build_fmu_checker.sh`` builds the checker from its published sources; the tests find it as
``$FMUCHECK``, on the PATH, or in that script's default prefix, and skip (naming the script) without it.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

DEFAULT_PREFIX = Path.home() / ".cache" / "fmugen" / "fmuchecker"
BUILD_SCRIPT = "tests/tools/build_fmu_checker.sh"


def find_checker():
    """Path of fmuCheck.linux64, or None."""
    for cand in (os.environ.get("FMUCHECK"), shutil.which("fmuCheck.linux64"), DEFAULT_PREFIX / "fmuCheck.linux64"):
        if cand and Path(cand).is_file() and os.access(cand, os.X_OK):
            return Path(cand)
    return None


@dataclass
class Verdict:
    returncode: int
    fmu_reported: int  # warnings and errors the FMU logged
    warnings: int  # the checker's own
    errors: int
    fatal: int
    log: str

    @property
    def clean(self) -> bool:
        return self.returncode == 0 and self.warnings == 0 and self.errors == 0 and self.fatal == 0

    def problems(self) -> str:
        return "\n".join(ln for ln in self.log.splitlines() if ln.startswith(("[ERROR]", "[FATAL]", "[WARNING]"))
                         or "status:Error" in ln or "status:Fatal" in ln)[:4000]


def check(fmu, kind: str, tmp: Path, stop: float, step: float) -> Verdict:
    """Run the checker on ``fmu`` for ``kind`` ("me", "cs" or "xml") to ``stop`` with ``step``
    (ME: its explicit Euler step; CS: the communication step)."""
    exe = find_checker()
    log = tmp / f"{Path(fmu).stem}_{kind}.log"
    args = [str(exe), "-k", kind, "-l", "3", "-e", str(log), "-o", str(tmp / f"{Path(fmu).stem}_{kind}.csv")]
    if kind != "xml":
        args += ["-s", repr(stop), "-h", repr(step)]
    p = subprocess.run(args + [str(fmu)], capture_output=True, text=True, timeout=300)
    text = log.read_text(errors="replace") if log.is_file() else p.stdout + p.stderr

    def count(pattern):
        m = re.search(pattern, text)
        return int(m.group(1)) if m else 0

    summary = "FMU check summary" in text
    return Verdict(p.returncode, count(r"FMU reported:\s*(\d+)"), count(r"Checker reported:\s*(\d+) Warning"),
                   count(r"Checker reported:\s*\d+ Warning\(s\)\s*(\d+) Error") if summary else 1,
                   count(r"(\d+) Fatal error"), text)
