"""Robots of example-robot-data read twice -- by fmugen's URDF reader (into the body constants of the looped
runtime, fmugen.batch.Kernels) and by Pinocchio -- for the tests that hold fmugen's dynamics against
Pinocchio's (the unrolled code generators).  The files' damping and Coulomb friction are set to 0:
Pinocchio models neither."""
from __future__ import annotations

import importlib.metadata
import warnings
from pathlib import Path

import numpy as np
import pytest

ROBOTS = {"ur5": "ur_description/urdf/ur5_robot.urdf", "panda": "panda_description/urdf/panda.urdf",
          "hyq": "hyq_description/robots/hyq_no_sensors.urdf", "talos": "talos_data/robots/talos_full_v2.urdf"}


def robot(name):
    """(pinocchio module, fmugen Robot, Kernels, Pinocchio model, fmugen -> Pinocchio index map)."""
    pin = pytest.importorskip("pinocchio")
    from fmugen.batch import Kernels
    from fmugen.codegen.benchmarks import pinocchio_urdf_map
    from fmugen.robot.urdf import load_urdf

    try:
        root = Path(importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"))
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (pip install -e '.[test]')")
    path = root / ROBOTS[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # mimic joints read as independent joints, as Pinocchio does
        rob = load_urdf(path)
    zero = {p.name: 0.0 for p in rob.parameters if p.name.startswith(("b_", "fc_"))}  # Pinocchio has none
    kernels = Kernels.from_robot(rob, values=zero)
    model = pin.buildModelFromUrdf(str(path))
    return pin, rob, kernels, model, pinocchio_urdf_map(model, rob)


def rel(a, b) -> float:
    """max |a - b| / max |b|."""
    return float(np.max(np.abs(np.asarray(a) - b)) / max(np.max(np.abs(b)), 1e-300))
