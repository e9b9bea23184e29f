"""Stage 9, parameter sweeps on Dask: vary scenario keys, run every point on a cluster, collect a table.

`cosim.sweep(scenario, vary={...})` runs a sweep and returns its results as a pandas DataFrame;
`cosim sweep SCENARIO --vary KEY=...` is the same from the command line (README "Sweeps").
Modules: `spec` (what is varied, how it is sampled), `bundle` (files and run ids), `worker` (what
runs on a Dask worker), `engine` (cluster, tasks, rows), `results` (results.csv, summary), `plot`
(sweep.png), `adapter` (the only calls into the scenario and run stages).

This package is callable: `cosim.sweep` is both this package and the API function, because
importing `cosim.sweep.<module>` rebinds the attribute `sweep` of `cosim` to the package.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any


def sweep(
    scenario: str | Path,
    vary: Mapping[str, Any] | Sequence[str] | None = None,
    *,
    method: str | None = None,
    samples: int | None = None,
    seed: int | None = None,
    overrides: Sequence[str] = (),
    out: str | Path | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    replicates: int | None = None,
    keep_logs: str | None = None,
    progress: bool = True,
    plot: bool = True,
):
    """Run a sweep and return its results table (pandas DataFrame, one row per run, sweep order).

    Args:
        scenario: a scenario file, or a sweep file (TOML with [sweep] and [vary]); the other
            arguments then add to or replace what the file says.
        vary: `{"lidar.noise": [0.0, 0.05], "lidar.seed": "0:3:4"}` (a list, a
            `START:STOP:COUNT` / `START:STOP` string, or `{start, stop, count}`), or a list of
            `--vary` texts such as `["lidar.seed=0,1,2"]`.
        method: "grid" (default), "random" or "lhs"; `samples` and `seed` for the last two.
        overrides: `--set` texts applied to every run, e.g. `["simulation.stop_time=20"]`.
        out: the sweep folder (default `logs/sweep-<scenario>-<timestamp>`).
        workers: processes of the local cluster (default: one per core); or `scheduler`, the
            address of a running Dask scheduler ("tcp://host:8786").
        resume: skip runs whose completed row and log (or outcome record) are already in `out`.
        replicates: runs per point, each with its own `lidar.seed` derived from the point; the
            per-point mean, spread and counts go to `out/aggregate.csv`.
        keep_logs: "all" (default), "failed" (the logs of runs that did not reach the goal) or
            "none" (a small outcome record per run instead of its log).

    Raises `cosim.CosimError` (one line) on bad input; a failed run is a row with its error. A
    varied key that changes nothing (a seed without noise) is a `UserWarning` (printed instead when
    `progress`).
    """
    from cosim.sweep.engine import run_sweep

    spec, options = build(
        scenario,
        vary,
        method,
        samples,
        seed,
        overrides,
        out,
        workers,
        scheduler,
        resume,
        replicates,
        keep_logs,
    )
    result = run_sweep(spec, options, progress=progress, plot=plot)
    if not progress:  # with progress they were printed already
        import warnings

        for warning in result.warnings:
            warnings.warn(warning, UserWarning, stacklevel=2)
    return result.table()


def build(
    scenario,
    vary,
    method,
    samples,
    seed,
    overrides,
    out,
    workers,
    scheduler,
    resume,
    replicates=None,
    keep_logs=None,
):
    """A `SweepSpec` and `SweepOptions` from arguments, merged over a sweep file when given one."""
    from cosim.sweep.spec import (
        SweepOptions,
        checked_keep_logs,
        is_sweep_file,
        make_spec,
        read_sweep_file,
        vary_dimensions,
    )

    path = Path(scenario)
    fields: dict[str, Any] = {"scenario": path, "dimensions": [], "overrides": []}
    options = SweepOptions()
    if path.suffix == ".toml" and is_sweep_file(path):  # (a name too long for the OS is not one)
        fields, options = read_sweep_file(path)
    given = {dimension.key: dimension for dimension in vary_dimensions(vary)}
    dimensions = [given.pop(d.key, d) for d in fields["dimensions"]] + list(given.values())
    spec = make_spec(
        fields["scenario"],
        dimensions,
        method or fields.get("method") or "grid",
        samples if samples is not None else fields.get("samples"),
        seed if seed is not None else fields.get("seed"),
        [*fields["overrides"], *overrides],
        replicates if replicates is not None else fields.get("replicates"),
    )
    if out is not None:
        options.out = Path(out)
    if workers is not None or scheduler is not None:
        options.workers, options.scheduler = workers, scheduler
    options.resume = resume
    if keep_logs is not None:
        options.keep_logs = checked_keep_logs(keep_logs)
    return spec, options


class _CallableModule(types.ModuleType):
    __call__ = staticmethod(sweep)  # `cosim.sweep(...)`, with `sweep`'s signature and docstring


sys.modules[__name__].__class__ = _CallableModule
