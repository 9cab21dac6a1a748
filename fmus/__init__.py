"""The plant FMUs of the project, built from source.

* :func:`build_fmu` compiles ``fmus/build/ArmExoPlant.fmu`` (C FMI 2.0
  Co-Simulation) or, with ``fmi_version=3``, ``fmus/build/ArmExoPlant_fmi3.fmu`` (FMI 3.0
  Co-Simulation, same sources) with the system C compiler, and with ``n=3``
  ``fmus/build/ArmExoPlant3.fmu`` (three planar links, FMI 2.0, same sources);
* :func:`default_fmu_path` returns that path, rebuilding when a source is newer;
* :mod:`fmus.variables` is the variable table (names, value references, units,
  defaults), the single source of truth for the C header and the XML.

Command line: ``python -m fmus.build``.
"""
from __future__ import annotations

__all__ = ["FMU_NAME", "build_fmu", "default_fmu_path"]

FMU_NAME = "ArmExoPlant.fmu"


def build_fmu(out_dir=None, *, cc=None, fmi_version: int = 2, n: int = 2):
    """Build the FMU (FMI 2.0 or 3.0; n planar links); see :func:`fmus.build.build_fmu`."""
    from .build import build_fmu as _build

    return _build(out_dir, cc=cc, fmi_version=fmi_version, n=n)


def default_fmu_path(build_if_missing: bool = True, *, fmi_version: int = 2, n: int = 2):
    """Path of the built FMU of n links; see :func:`fmus.build.default_fmu_path`."""
    from .build import default_fmu_path as _path

    return _path(build_if_missing, fmi_version=fmi_version, n=n)
