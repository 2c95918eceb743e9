"""``fmugen sweep x.ssp``: a parameter study over an SSP archive's systems.

The plan a sweep needs (:class:`fmugen.sweep.prepare.SweepPlan` for a
scene): the archive is loaded once (:func:`fmugen.ssp.load_system`), each
swept name is ``component.variable`` -- a parameter, an input's start value
or a state's start value of that component's FMU -- and each point sets
those as start values over the archive's bindings.  Nothing is built: the
FMUs are the archive's.  The ``error`` metric needs a reference solution,
which an archive has not (no symbolic model): it is refused.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Mapping, Sequence

from ..sweep.errors import SweepError
from ..sweep.prepare import PointRefused, PointTask
from .loader import load_system


class SspSweepPlan:
    """Duck-typed :class:`fmugen.sweep.prepare.SweepPlan` for an archive (same attributes and methods)."""

    def __init__(self, path, names: Sequence[str], fmu_dir, sets=None, progress=None,
                 allow_factories: bool = False):
        from ..scene import parse_sets
        from .cli import settable, with_sets

        self.scene_path = Path(path)
        # --set: the same rules as fmugen cosim x.ssp (run settings and start values)
        system = with_sets(load_system(self.scene_path), parse_sets(sets), str(self.scene_path), SweepError)
        self.names = tuple(names)
        self.targets = {}
        for name in self.names:
            comp, var, v = settable(system, name, str(self.scene_path), SweepError)
            if v.type not in ("Real", "Float64"):  # FMI 2.0's Real, FMI 3.0's Float64
                raise SweepError(f"{self.scene_path}: {name}: {comp}.{var} is {v.type}; a sweep sets Real values")
            self.targets[name] = (comp, var)
        self.system = system
        self.parameters, self.states = self.names, ()
        self.equilibrium = False
        spec = SimpleNamespace(cosim=dict(system.settings), start=system.start_time, stop=system.stop_time,
                               step=system.step, record=tuple(r.column for r in system.recorded))
        self.scene = SimpleNamespace(name=system.name, spec=spec)
        self.columns = spec.record
        self.fmu_dir = Path(fmu_dir)

    def build(self) -> "SspSweepPlan":
        self.built = None
        self.digest = hashlib.sha256(b"".join(Path(u.path).read_bytes() for u in self.system.units)).hexdigest()
        return self

    @property
    def reference_problem(self):
        raise SweepError(f"{self.scene_path}: the error metric needs a reference solution; an SSP archive has no "
                         f"symbolic model (use fmugen report {self.scene_path} for a self-convergence reference)")

    def check_point(self, index: int, values: Mapping[str, float]) -> None:
        for n, v in values.items():
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise PointRefused(f"refused: point {index}: {n} = {v!r} is not a finite number")

    def task(self, index: int, key: str, values: Mapping[str, float]) -> PointTask:
        self.check_point(index, values)
        starts = {u.name: {} for u in self.system.units}
        for n in self.names:
            comp, var = self.targets[n]
            starts[comp][var] = float(values[n])
        return PointTask(index, key, dict(values), starts, None, {})
