"""SSP (System Structure and Parameterization 1.0): scenes out, systems in.

* :func:`export_ssp` (``fmugen ssp SCENE -o x.ssp``): a scene's FMUs, connections,
  parameter bindings, units and default experiment as a standard archive that
  libcosim and FMPy run (:mod:`fmugen.ssp.export`);
* :func:`load_system` (``fmugen cosim x.ssp``, ``fmugen.load_system``): any SSP of
  FMI 2.0 or 3.0 FMUs as the master's :class:`~fmugen.cosim.system.CosimSystem`
  (:mod:`fmugen.ssp.loader`), read and validated as untrusted input by
  :mod:`fmugen.ssp.ssd`.
"""
from .export import export_ssp
from .loader import load_system
from .ssd import is_ssp, open_ssp

__all__ = ["export_ssp", "load_system", "open_ssp", "is_ssp"]
