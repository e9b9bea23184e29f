"""What runs on a Dask worker: the plugin that unpacks a sweep's files once, and the task of one run.

A worker process keeps running between tasks, so what a first run compiles or builds stays for the
next ones: the C kernels (loaded, and built once into their cache), the project FMUs built from
their sources (in the FMU cache), the imported modules. The bundle arrives once per worker, with
the plugin (`Client.register_plugin` sends it to every worker, present or joining later), and its
files are removed when the plugin is unregistered or the worker stops (with what building an FMU
there left in the temporary folder).
"""

from __future__ import annotations

import hashlib
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from distributed import WorkerPlugin, get_worker

import cosim.sweep.adapter as adapter
from cosim.errors import CosimError
from cosim.sweep.bundle import Bundle, Run
from cosim.sweep.spec import toml_value


@dataclass(frozen=True)
class TaskResult:
    """A run as the worker saw it. `outcome` is the log's outcome metadata (None when the run never
    started); `error` says why the run did not complete; `log` is the log's bytes."""

    run_id: str
    outcome: dict[str, str] | None
    error: str | None
    wall_time: float  # [s] load, build, run and log on the worker
    worker: str
    log: bytes | None
    log_suffix: str  # ".mcap", or ".failed.mcap" for a log a broken run left


class BundlePlugin(WorkerPlugin):
    """Carries a bundle to each worker and lays its files out in a private folder there."""

    def __init__(self, bundle: Bundle) -> None:
        self.bundle = bundle
        self.name = f"navcosim-bundle-{bundle.digest[:16]}"
        self.folder: Path | None = None

    def setup(self, worker) -> None:
        self.folder = Path(tempfile.mkdtemp(prefix="navcosim-sweep-"))
        self.bundle.materialize(self.folder / "files")
        (self.folder / "runs").mkdir()

    def teardown(self, worker) -> None:
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder = None
        # What building an FMU a run needed left in the temporary folder (the C code the FMUs share,
        # compiled once): a worker process ends through `os._exit`, without the exit handler that
        # removes it.
        from cosim.fmi.builtin import remove_build_scratch

        remove_build_scratch()


def redirects(run: Run, files: Path) -> list[str]:
    """Overrides that point absolute file names at the bundle's copy, where this machine has no
    identical file at that path (on the client's machine, the names stay as written)."""
    overrides = []
    for reference in run.references:
        written = Path(reference.written)
        if reference.key is None or not written.is_absolute():
            continue
        local = files / reference.relative
        if written.is_file() and hashlib.sha256(written.read_bytes()).digest() == (
            hashlib.sha256(local.read_bytes()).digest()
        ):
            continue
        overrides.append(f"{reference.key}={toml_value(str(local))}")
    return overrides


def check_task(plugin_name: str, run: Run) -> str | None:
    """Build `run` on this worker without running it (map, plan, FMUs, parameter and port names);
    None when it builds, else the one-line error, naming the user's files.

    The sweep checks its first run this way before it keeps any row, so what only a build can tell,
    such as a misspelt FMU parameter, stops the sweep (exit 2). On a worker, not on the client: the
    workers load the run stage anyway, and the client then never has to. (A local cluster's fork
    server, warmed up on that run, may have found it builds already: `cosim.sweep.warm`.)"""
    plugin: BundlePlugin = get_worker().plugins[plugin_name]
    files = plugin.folder / "files"
    try:
        adapter.check_builds(
            adapter.load(files / plugin.bundle.scenario, [*run.overrides, *redirects(run, files)])
        )
    except CosimError as error:
        return str(error).replace(str(files), plugin.bundle.root)
    return None


def keeps_log(keep_logs: str, outcome: dict[str, str] | None, error: str | None) -> bool:
    """Whether the sweep keeps a run's log: `all`, `failed` (every run that did not reach the goal,
    failed runs included) or `none`."""
    if keep_logs == "all":
        return True
    reached = error is None and outcome is not None and outcome.get("reason") == "goal_reached"
    return keep_logs == "failed" and not reached


def run_task(plugin_name: str, run: Run, keep_logs: str = "all") -> TaskResult:
    """Run one scenario of the sweep on this worker; a run that fails is a result, not an exception.
    The log is written here in any case (the run needs a file) and sent back only when the sweep
    keeps it (`keeps_log`); this worker's copy is removed either way."""
    worker = get_worker()
    plugin: BundlePlugin = worker.plugins[plugin_name]
    files = plugin.folder / "files"
    log_path = plugin.folder / "runs" / f"{run.run_id}.mcap"
    started = time.perf_counter()
    outcome, error = None, None
    try:
        scenario = adapter.load(files / plugin.bundle.scenario, [*run.overrides, *redirects(run, files)])
        output = adapter.run(scenario, log_path)
        outcome, error = output.outcome, output.failure
    except CosimError as failure:
        error = str(failure)
    except Exception as failure:  # a bug or a broken FMU must become a row, not end the sweep
        error = f"{type(failure).__name__}: {' '.join(str(failure).split())}"
    wall_time = time.perf_counter() - started
    log, suffix = None, ".mcap"
    keep = keeps_log(keep_logs, outcome, error)
    for candidate, candidate_suffix in (
        (log_path, ".mcap"),
        (log_path.with_suffix(".failed.mcap"), ".failed.mcap"),
    ):
        if candidate.is_file():
            if keep:
                log, suffix = candidate.read_bytes(), candidate_suffix
            candidate.unlink()
            break
    if error is not None:
        # Name the user's files, not this worker's copies of them.
        error = error.replace(str(files), plugin.bundle.root)
    return TaskResult(run.run_id, outcome, error, wall_time, str(worker.address), log, suffix)
