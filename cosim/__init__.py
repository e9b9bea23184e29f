"""navcosim orchestrator: scenarios, components, master algorithm, lidar, MCAP logs, CLI."""

from __future__ import annotations

from typing import TYPE_CHECKING

from cosim.errors import CosimError

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["CosimError", "builtin_fmu", "sweep"]


def builtin_fmu(name: str, fmi_version: int = 2) -> Path:
    """The built `.fmu` of a project FMU (DifferentialDrive, Bicycle, PurePursuit,
    VectorFieldHistogram, AvoidanceMixer) as an FMI 2.0 or (`fmi_version=3`) FMI 3.0 co-simulation
    FMU, built from its C sources if needed."""
    from cosim.fmi.builtin import builtin_fmu as _builtin_fmu

    return _builtin_fmu(name, fmi_version)


def __getattr__(name: str):
    # `cosim.sweep` is the sweep package, callable as the API function (`cosim.sweep(...)` returns
    # a pandas DataFrame); imported on first use so `import cosim` does not load Dask.
    if name == "sweep":
        import importlib

        return importlib.import_module("cosim.sweep")
    raise AttributeError(f"module 'cosim' has no attribute {name!r}")
