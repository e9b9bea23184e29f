"""navcosim orchestrator: scenarios, components, master algorithm, lidar, MCAP logs, CLI."""

from __future__ import annotations

from typing import TYPE_CHECKING

from cosim.errors import CosimError

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["CosimError", "builtin_fmu"]


def builtin_fmu(name: str) -> Path:
    """The built `.fmu` of a project FMU (DifferentialDrive, Bicycle, PurePursuit,
    VectorFieldHistogram, AvoidanceMixer), built from its C sources if needed."""
    from cosim.fmi.builtin import builtin_fmu as _builtin_fmu

    return _builtin_fmu(name)
