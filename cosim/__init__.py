"""navcosim orchestrator: scenarios, components, master algorithm, lidar, MCAP logs, CLI."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

    from cosim.errors import CosimError

__all__ = ["CosimError", "builtin_fmu", "sweep"]

_collector_held = [False]


def hold_collector() -> None:
    """For a program that sets up a run and then steps it (`cosim run`): no cyclic garbage
    collection while it imports, loads and builds (~10^5 objects that live as long as the process:
    modules, every FMU's variables and ports; the young-generation collections walked them all once
    more, ~35 ms of a run, and found little). `release_collector()` ends it."""
    import gc

    gc.disable()
    _collector_held[0] = True


def release_collector() -> None:
    """What was made since `hold_collector()` (a run's setup, the plot) is moved out of the
    collector's reach (`gc.freeze`: kept, never walked again) and the collector runs as usual from
    here on. A no-op unless `hold_collector()` was called (a library caller's collector is left
    alone)."""
    if _collector_held[0]:
        import gc

        _collector_held[0] = False
        gc.freeze()
        gc.enable()


def builtin_fmu(name: str, fmi_version: int = 2) -> Path:
    """The built `.fmu` of a project FMU (a folder of `fmus/`: DifferentialDrive, Bicycle,
    PurePursuit, VectorFieldHistogram, AvoidanceMixer, ArtificialPotentialField) as an FMI 2.0 or
    (`fmi_version=3`) FMI 3.0 co-simulation FMU, built from its C sources if needed."""
    from cosim.fmi.builtin import builtin_fmu as _builtin_fmu

    return _builtin_fmu(name, fmi_version)


def __getattr__(name: str):
    # `cosim.sweep` is the sweep package, callable as the API function (`cosim.sweep(...)` returns
    # a pandas DataFrame); imported on first use so `import cosim` does not load Dask.
    if name == "sweep":
        import importlib

        return importlib.import_module("cosim.sweep")
    # `cosim.CosimError` too: importing the package runs no import of its own, so a Ctrl-C as the
    # `cosim` program starts comes inside its handling (`cosim.__main__.run`), not before it with a
    # traceback (the package is imported first, by the program's script and by `python -m`).
    if name == "CosimError":
        from cosim.errors import CosimError

        return CosimError
    raise AttributeError(f"module 'cosim' has no attribute {name!r}")
