"""Run a sweep on Dask: validate it, start or reach a cluster, run every point, collect the table.

Engine: a `distributed.Client` on a `LocalCluster` (one process per worker, one thread each, on
127.0.0.1) or on the scheduler given by address. The scenario and its files go to each worker
once (`cosim.sweep.worker.BundlePlugin`); each task returns its log's bytes, which land in
`DIR/runs/<run-id>.mcap`. Rows are appended to `DIR/results.csv` as runs finish, so Ctrl-C keeps
every finished row and log; at the end the file is rewritten in sweep order, so the same sweep
gives the same table (apart from wall time and worker). `resume` skips runs whose completed row and
log are already in DIR; failed runs are run again.
"""

from __future__ import annotations

import logging
import os
import secrets
import signal
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import cosim.sweep.adapter as adapter
from cosim.core.interrupt import raise_swallowed, raised
from cosim.errors import CosimError
from cosim.sweep.bundle import Bundle, BundleBuilder, Run
from cosim.sweep.results import (
    AGGREGATE_FILE,
    COMPLETED,
    FAILED,
    RESULTS_FILE,
    ResultsFile,
    SummaryInput,
    columns,
    format_summary,
    group_points,
    read_rows,
    read_table,
    write_aggregate,
)
from cosim.sweep.spec import (
    SEED_LIMIT,
    SweepOptions,
    SweepSpec,
    display_value,
    replicate_seeds,
    sample_points,
    toml_value,
)
from cosim.sweep.warm import (
    ensure_fork_server,
    first_run_answered,
    first_run_checked,
    import_dask,
    start_fork_server,
    stop_fork_server,
)

CONNECT_TIMEOUT = 5.0  # [s] to reach a scheduler
WORKER_WAIT = 30.0  # [s] for a reached scheduler to have at least one worker
PLOT_FILE = "sweep.png"


@dataclass
class SweepResult:
    """A finished (or interrupted) sweep: its rows in sweep order and where they are."""

    spec: SweepSpec
    scenario_name: str
    out_dir: Path
    rows: list[dict[str, str]]
    outcome_keys: tuple[str, ...]
    wall_time: float  # [s] from the start of the cluster to the last row
    workers: int | None
    plot_path: Path | None
    skipped: int  # runs found in DIR by resume
    warnings: list[str] = field(default_factory=list)

    @property
    def failed(self) -> int:
        return sum(row["status"] != COMPLETED for row in self.rows)

    @property
    def exit_code(self) -> int:
        """0 every run completed, 1 some failed."""
        return 1 if self.failed else 0

    @property
    def results_path(self) -> Path:
        return self.out_dir / RESULTS_FILE

    @property
    def aggregate_path(self) -> Path | None:
        """`aggregate.csv`, one row per point, written when the sweep has replicates."""
        return self.out_dir / AGGREGATE_FILE if self.spec.replicates > 1 else None

    def table(self):
        """The results as a pandas DataFrame (read back from results.csv)."""
        return read_table(self.results_path)

    def summary(self) -> str:
        runs = f"{len(self.rows)} runs"
        if self.spec.replicates > 1:
            runs = f"{self.spec.replicates} replicates a point, {runs}"
        title = f"{self.scenario_name} ({self.spec.method}, {runs}"
        title += f", {self.skipped} from an earlier sweep)" if self.skipped else ")"
        files = [("results", self.results_path)]
        if self.aggregate_path is not None:
            files.append(("aggregate", self.aggregate_path))
        if self.plot_path is not None:
            files.append(("plot", self.plot_path))
        return format_summary(
            SummaryInput(
                title,
                self.rows,
                self.spec.keys,
                self.outcome_keys,
                self.wall_time,
                len(self.rows) - self.skipped,
                self.workers,
                files,
                self.spec.replicates,
                self.warnings,
                self.spec.table_keys,
            )
        )


def plan(spec: SweepSpec) -> tuple[Bundle, list[Run], str]:
    """Validate the sweep's keys and values and list its runs; raises `CosimError` (one line).

    Each varied key's extreme values pass the scenario's validation with the base overrides: of
    numbers the smallest and the largest (of an interval: both ends), every other value once (a
    choice, a flag, a list). So a wrong key, type or range is caught before anything runs, in a
    time that grows with the keys and not with the points. A value inside the range that the
    scenario still refuses (a macro step that no rate divides) fails its own run, with the reason
    in its row. Returns the bundle, the runs in sweep order and the scenario's name.
    """
    base = adapter.load(spec.scenario, spec.overrides, check_world=False)
    for dimension in spec.dimensions:
        for value in _checked_values(dimension):
            override = f"{dimension.key}={toml_value(value)}"
            try:
                adapter.load(spec.scenario, [*spec.overrides, override], check_world=False)
            except CosimError as error:
                raise CosimError(f"{dimension.describe()}: {_without_set(str(error))}") from None
    for key in spec.seed_keys:  # each replicate sets it to a value in [0, SEED_LIMIT)
        for value in (0, SEED_LIMIT - 1):
            try:
                adapter.load(spec.scenario, [*spec.overrides, f"{key}={value}"], check_world=False)
            except CosimError as error:
                raise CosimError(f"--replicates {spec.replicates}: {_without_set(str(error))}") from None
    builder = BundleBuilder(spec.scenario)
    for count, (values, overrides, point) in enumerate(_run_points(spec)):
        builder.add_run(count, values, overrides, point)
    bundle, runs = builder.finish()
    return bundle, runs, base.name


def _run_points(spec: SweepSpec) -> Iterator[tuple[tuple, tuple[str, ...], int]]:
    """(values, overrides, point) of each run of `spec` in sweep order: the base overrides, then the
    point's varied keys (and with replicates the replicate's seed keys) sorted by key; a point drawn
    twice (a random draw from a list) is one run."""
    seen: set[tuple[str, ...]] = set()
    by_key = lambda text: text.partition("=")[0]  # noqa: E731
    for values in sample_points(spec):
        varied = tuple(
            sorted(
                (f"{d.key}={toml_value(v)}" for d, v in zip(spec.dimensions, values, strict=True)), key=by_key
            )
        )
        if varied in seen:  # a random draw from a list may repeat a point: it would be the same run
            continue
        seen.add(varied)
        if spec.replicates == 1:
            yield values, (*spec.overrides, *varied), len(seen) - 1
            continue
        for replicate, seed in enumerate(replicate_seeds(varied, spec.replicates)):
            seeded = sorted([*varied, *(f"{key}={seed}" for key in spec.seed_keys)], key=by_key)
            point_values = (*values, replicate, *(seed for _ in spec.seed_keys))
            yield point_values, (*spec.overrides, *seeded), len(seen) - 1


def first_run(spec: SweepSpec) -> tuple[Bundle, Run] | None:
    """The first run `plan(spec)` lists (the one the sweep checks) and a bundle of its own files,
    made without validating the sweep: what the local cluster's fork server warms up on
    (`cosim.sweep.warm.start_fork_server`); None where it cannot be made (`plan` says why)."""
    try:
        values, overrides, point = next(iter(_run_points(spec)))
        builder = BundleBuilder(spec.scenario)
        builder.add_run(0, values, overrides, point)
        bundle, runs = builder.finish()
    except Exception:  # noqa: BLE001 - a sweep that `plan` refuses, with its own message
        return None
    return bundle, runs[0]


def _checked_values(dimension) -> list:
    """The values of `dimension` that `plan` validates: numbers' extremes, the others once each."""
    values = dimension.values if dimension.values is not None else dimension.interval
    numbers = [v for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
    others: list = []
    for value in values:
        if value not in numbers and value not in others:
            others.append(value)
    return ([min(numbers), max(numbers)] if numbers else []) + others


def _without_set(message: str) -> str:
    """Override errors say `--set K=V: ...`; under --vary the prefix would only repeat the key."""
    return message.split(": ", 1)[1] if message.startswith("--set ") and ": " in message else message


def default_out_dir(scenario_name: str, now: datetime | None = None) -> Path:
    stamp = (now or datetime.now()).strftime("%Y%m%d-%H%M%S")
    return Path("logs") / f"sweep-{scenario_name}-{stamp}"


def _prepare_out_dir(out_dir: Path, resume: bool) -> list[Path]:
    """Create DIR/runs and check that DIR takes files; returns the folders it created."""
    created = [
        folder for folder in (*reversed((out_dir / "runs").parents), out_dir / "runs") if not folder.exists()
    ]
    try:
        (out_dir / "runs").mkdir(parents=True, exist_ok=True)
        probe = out_dir / f".write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as error:
        raise CosimError(f"--out {out_dir}: not writable: {error.strerror or error}") from None
    if not resume and (out_dir / RESULTS_FILE).exists():
        raise CosimError(
            f"--out {out_dir}: holds an earlier sweep ({RESULTS_FILE}); add --resume or choose another folder"
        )
    return created


def _remove_empty(folders: list[Path]) -> None:
    for folder in reversed(folders):
        try:
            folder.rmdir()
        except OSError:
            return


# Largest first frame a Dask comm handshake may announce [bytes]; a real one is a few dozen bytes.
HANDSHAKE_LIMIT = 1 << 20


def probe_scheduler(address: str, timeout: float) -> None:
    """Check within `timeout` seconds that a tcp:// `address` answers as a Dask scheduler does.

    A scheduler sends its comm handshake as soon as it accepts a connection: an 8-byte
    little-endian length, then that many bytes of message. A server that accepts and stays silent
    would hang `distributed.Client` past its own timeout, which does not cover the handshake; one
    that answers something else (an HTTP server) makes Dask read the first 8 bytes as a frame
    length and try to allocate exabytes. Other schemes (tls://, ucx://) are left to Dask.
    """
    import socket

    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)
        if scheme != "tcp":
            return
        host, port = parse_host_port(location)
    except (TypeError, ValueError) as error:
        raise CosimError(f"--scheduler {address}: not a scheduler address ({error})") from None
    deadline = time.monotonic() + timeout
    try:
        with socket.create_connection((host, port), timeout=timeout) as connection:
            head = b""
            while len(head) < 8:
                connection.settimeout(max(deadline - time.monotonic(), 1e-3))
                chunk = connection.recv(8 - len(head))
                if not chunk:
                    raise CosimError(f"--scheduler {address}: closed the connection: not a Dask scheduler")
                head += chunk
    except TimeoutError:
        raise CosimError(
            f"--scheduler {address}: no Dask handshake within {timeout:g} s (is it a Dask scheduler?)"
        ) from None
    except OSError as error:
        raise CosimError(
            f"--scheduler {address}: cannot reach the Dask scheduler: {error.strerror or error}"
        ) from None
    length = int.from_bytes(head, "little")
    if not 0 < length <= HANDSHAKE_LIMIT:
        shown = head.decode("latin-1").encode("unicode_escape").decode()
        raise CosimError(f"--scheduler {address}: not a Dask scheduler (it answered {shown!r})")


class _UnboundSyncFuture(logging.Filter):
    """Drops one error that distributed logs after a Ctrl-C: when the interrupt reaches a blocking
    client call (`distributed.utils.sync`) before its coroutine has made the future it waits on,
    the cancel callback it schedules reads that still-unbound variable and tornado logs the
    NameError with its traceback (distributed 2026.8). The interrupt itself is handled; the
    traceback only told the user of a bug that is not theirs. Every other callback error passes."""

    def filter(self, record: logging.LogRecord) -> bool:
        kind, _, trace = record.exc_info or (None, None, None)
        if kind is not NameError or trace is None:
            return True
        while trace.tb_next is not None:
            trace = trace.tb_next
        code = trace.tb_frame.f_code
        return not (code.co_name == "cancel" and Path(code.co_filename).match("distributed/utils.py"))


_SYNC_FILTER = _UnboundSyncFuture()


class _InterruptedStart(logging.Filter):
    """Drops the error asyncio logs for a worker's start that an interrupt cut short: a SIGTERM to
    the sweep's process group ends the fork server as the workers start, the interrupt ends the
    sweep, and the nanny's start task, which nobody waits for then, fails ("Nanny failed to
    start"); asyncio logs it with its traceback when the task is freed ("Task exception was never
    retrieved"), before the one line that says the sweep was interrupted. Only once an interrupt
    was raised (`cosim.core.interrupt.raised`): a worker that fails to start otherwise is still
    told."""

    def filter(self, record: logging.LogRecord) -> bool:
        error = (record.exc_info or (None, None, None))[1]
        if not isinstance(error, RuntimeError) or str(error) != "Nanny failed to start.":
            return True
        return raised() is None


_START_FILTER = _InterruptedStart()


@contextmanager
def connect(
    scheduler: str | None, workers: int | None, pending: int, html: bool = True
) -> Iterator[tuple[object, int, object]]:
    """A client on `scheduler`, or on a new LocalCluster of `workers` processes (default: one per
    core, never more than there are runs); yields (client, number of workers, `grow`): `grow()`
    starts a local cluster's workers, once the sweep's tasks are in (None for a scheduler's).
    `html`: as `cosim.sweep.warm.import_dask`, when Dask is imported here."""
    import_dask(html)
    from distributed import Client, LocalCluster

    logging.getLogger("tornado.application").addFilter(_SYNC_FILTER)  # once: filters are a set
    logging.getLogger("asyncio").addFilter(_START_FILTER)

    if scheduler is not None:
        probe_scheduler(scheduler, CONNECT_TIMEOUT)
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as error:
            raise CosimError(f"--scheduler {scheduler}: cannot reach the Dask scheduler: {error}") from None
        except Exception as error:  # it answered, but not as a scheduler does (MemoryError, ...)
            raise CosimError(
                f"--scheduler {scheduler}: not a Dask scheduler ({type(error).__name__}: {str(error)[:120]})"
            ) from None
        try:
            try:
                client.wait_for_workers(1, timeout=WORKER_WAIT)
            except TimeoutError:
                raise CosimError(
                    f"--scheduler {scheduler}: the scheduler has no workers (waited {WORKER_WAIT:g} s); "
                    f"start some with `dask worker {scheduler}`"
                ) from None
            yield client, len(client.scheduler_info()["workers"]), None
        finally:
            client.close()
        return
    import distributed.utils
    from distributed import versions

    count = max(1, min(workers or os.cpu_count() or 1, pending))
    # The workers fork from the fork server (`start_fork_server`), which ignores SIGINT, as they do;
    # one that is not running (the sweep did not start it, or it ended) starts here, ignoring it
    # too (`ensure_fork_server`), before the cluster would start it. Distributed's sampling
    # profiler is off: it costs a run about a sixth more CPU time and nobody reads it here.
    # Distributed would import its optional packages here (pandas: most of a second) only to name
    # them as the server's preload, which `start_fork_server` set already.
    ensure_fork_server()
    # The scheduler reads its host's and packages' versions when the first worker registers
    # (`distributed.versions.get_versions`: `uname -p` run as a subprocess, a dozen packages'
    # metadata read, the metadata parser imported: 10-20 ms), on the way to the cluster's start.
    # Read now, while the fork server warms up, the answer is kept then.
    versions.get_versions()
    settings = {
        "distributed.worker.profile.enabled": False,
        "distributed.worker.multiprocessing-method": "forkserver",
        # Each server (the scheduler and the nannies here, each worker) checks that its event
        # loop is responsive every 20 ms and samples its host's CPU, memory, network and disk
        # every 0.5 s, for warnings and dashboards that a sweep silences or never opens: 5 %
        # of a sweep's CPU time (sampled: 0.1 s in this process, 0.07 s a worker for 8 runs),
        # and each wake-up takes the GIL from the run or the plot. The memory limits still
        # read the process's memory afresh every 0.1 s.
        "distributed.admin.tick.interval": "1s",
        "distributed.admin.system-monitor.interval": "5s",
        "distributed.admin.system-monitor.disk": False,
    }
    if hasattr(distributed.utils, "_forkserver_preload_set"):
        distributed.utils._forkserver_preload_set = True
    # The scheduler first, alone (no worker to wait for): the sweep's plugin and tasks are in before
    # any worker is (`_execute`), and each worker runs as soon as it has registered.
    interrupts: list[int] = []
    with _starting(settings, interrupts):
        cluster = LocalCluster(
            n_workers=0,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            # No dashboard, but the scheduler serves HTTP anyway, by default on port 8787: where
            # that port is taken (another Dask, a second sweep) it warned on stderr, even under
            # --quiet, and bound another. A free port of 127.0.0.1 from the start.
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
            silence_logs=logging.CRITICAL,
        )

    def grow() -> None:
        """Start the `count` workers and return once they have (their fork server serves them when
        it has warmed up); as Dask's `LocalCluster` starts the workers it is given."""
        try:
            with _starting(settings, interrupts):
                while len(cluster.worker_spec) < count:
                    cluster.worker_spec.update(cluster.new_worker_spec())
                cluster.sync(cluster._correct_state)
        except Exception:
            if not interrupts:
                raise
            # (an interrupt held meanwhile ended the start: a SIGTERM to the process group stops
            # the workers as they start, and Dask's start fails with "Nanny failed to start")
        if interrupts:  # to the handler held before (`Interrupted`, KeyboardInterrupt); then closed
            signal.raise_signal(interrupts[0])

    try:
        if interrupts:
            signal.raise_signal(interrupts[0])
        client = Client(cluster, set_as_default=False)
        try:
            yield client, count, grow
        finally:
            client.close()
    finally:
        cluster.close()


@contextmanager
def _starting(settings: dict, interrupts: list[int]) -> Iterator[None]:
    """Dask's `settings` in force, and a Ctrl-C or SIGTERM held (appended to `interrupts`), while
    part of a local cluster starts (its scheduler, then its workers, which wait for the fork server
    to warm up: most of a second). Held, the interrupt goes on once that part has started, and the
    cluster is closed; ignored, the sweep went on as if no key had been pressed; raised inside
    Dask's start, it cuts that short midway, with nothing here to close (a SIGTERM, not held
    before, left Dask's "Nanny failed to start" and its traceback on stderr).
    A nanny looks for its new worker's "started" message every 50 ms (Dask's default): a worker
    that is up waits 25 ms on average, the last of them up to 50, before the cluster counts it.
    Every 5 ms instead meanwhile (~40 polls of a queue: nothing)."""
    import dask
    from distributed.nanny import WorkerProcess

    held = (signal.SIGINT, signal.SIGTERM)
    previous = {
        number: signal.signal(number, lambda number, frame: interrupts.append(number)) for number in held
    }
    polling = getattr(WorkerProcess, "_init_msg_interval", None)
    try:
        if polling is not None:
            WorkerProcess._init_msg_interval = min(polling, 0.005)
        with dask.config.set(settings):
            yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        if polling is not None:
            WorkerProcess._init_msg_interval = polling


RECORD_SUFFIX = ".outcome.json"


def record_name(run_id: str) -> str:
    """Where a completed run whose log was not kept leaves its outcome record, relative to DIR."""
    return f"runs/{run_id}{RECORD_SUFFIX}"


def _write_atomic(path: Path, data: bytes) -> None:
    temporary = path.with_name(f".{path.name}.partial")
    temporary.write_bytes(data)
    os.replace(temporary, path)  # either whole or absent


def _row(run: Run, keys: tuple[str, ...], result, out_dir: Path) -> dict[str, str]:
    """The results row of a run, writing into DIR/runs/ its log, or, for a completed run whose log
    the worker did not send (--keep-logs), its outcome record: the overrides and the outcome the log
    held, so that --resume can check the row against it."""
    import json

    row = {"run_id": run.run_id}
    row.update({key: display_value(value) for key, value in zip(keys, run.values, strict=True)})
    row["status"] = COMPLETED if result.error is None and result.outcome is not None else FAILED
    row.update(result.outcome or {})
    row["wall_time"] = f"{result.wall_time:.3f}" if result.wall_time >= 0 else ""
    row["worker"] = result.worker
    row["log"] = ""
    if result.log is not None:
        name = f"runs/{run.run_id}{result.log_suffix}"
        _write_atomic(out_dir / name, result.log)
        row["log"] = name
    elif row["status"] == COMPLETED:
        record = {"run_id": run.run_id, "overrides": list(run.overrides), "outcome": result.outcome}
        _write_atomic(out_dir / record_name(run.run_id), json.dumps(record, indent=1).encode())
    row["error"] = result.error or ""
    return row


def _execute(
    client,
    bundle: Bundle,
    first: Run,
    pending: list[Run],
    keys,
    out_dir,
    results,
    rows,
    progress,
    total,
    checked,
    keep_logs: str,
    grow=None,
):
    """Check `first` on a worker, then run `pending`, writing each row as it comes. `checked()` is
    called once the check passed, before any row is kept; a failed check raises `CosimError`.
    The workers send the logs that `keep_logs` keeps.
    `grow`: the sweep's own local cluster (`connect`), whose workers start once the plugin and the
    tasks are in. Its fork server may have built `first` already, warmed up on it
    (`cosim.sweep.warm.first_run_checked`): then no worker checks it. The cluster closes next,
    its workers with it: each removes the bundle's files as it closes (`BundlePlugin.teardown`),
    so the plugin is not unregistered first (a round trip to every worker); the workers of a
    scheduler stay, and it is."""
    from distributed import as_completed

    from cosim.sweep.worker import BundlePlugin, TaskResult, check_task, run_task

    raise_swallowed()  # (a Ctrl-C whose `Interrupted` was dropped while Dask or the cluster started)
    plugin = BundlePlugin(bundle)
    client.register_plugin(plugin, name=plugin.name)
    token = secrets.token_hex(4)

    def submit_check():  # (a higher priority than the runs: it goes first)
        return client.submit(
            check_task, plugin.name, first, key=f"navcosim-check-{token}", pure=False, priority=1
        )

    # The check goes first; the runs start on the other workers meanwhile, and their results wait in
    # memory until the check passed. The fork server's answer comes when it has warmed up, before
    # it serves the first worker: the check is submitted then only if that run did not build there.
    answers = grow is not None and first_run_answered(first.run_id)
    check = None if answers else submit_check()
    futures = {
        client.submit(
            run_task, plugin.name, run, keep_logs, key=f"navcosim-{run.run_id}-{token}", pure=False
        ): run
        for run in pending
    }
    bar = None
    failed = 0
    try:
        if grow is not None:
            grow()
            raise_swallowed()
            if answers and not first_run_checked(first.run_id):
                check = submit_check()
        try:
            error = None if check is None else check.result()
        except Exception as failure:  # the worker died while building
            error = f"the worker failed: {type(failure).__name__}: {' '.join(str(failure).split())}"
        if error is not None:
            raise CosimError(f"{error} (checked on the run with {' '.join(first.overrides)})")
        checked()
        if progress:  # (tqdm's import is 0.02-0.05 s of a quiet sweep's CPU otherwise)
            from tqdm import tqdm

            bar = tqdm(total=total, initial=total - len(pending), unit="run", desc="sweep")
        for future in as_completed(list(futures), loop=client.loop):
            raise_swallowed()
            run = futures.pop(future)
            try:
                result = future.result()
            except Exception as error:  # the worker died (a crashing FMU) or could not run the task
                message = f"the worker failed: {type(error).__name__}: {' '.join(str(error).split())}"
                result = TaskResult(run.run_id, None, message, -1.0, "", None, ".mcap")
            future.release()
            row = _row(run, keys, result, out_dir)
            rows[run.run_id] = row
            results.append(row, durable=bool(futures))  # the last row: rewritten next
            failed += row["status"] != COMPLETED
            if bar is not None:
                bar.update(1)
                if failed:
                    bar.set_postfix(failed=failed)
    finally:
        if bar is not None:
            bar.close()
        if check is not None:
            check.cancel()
        for future in futures:
            future.cancel()
        try:
            if grow is None:
                client.unregister_worker_plugin(plugin.name)
        except Exception:  # the cluster is going away anyway; its workers drop the plugin then
            pass


def kept_row_problem(row: dict[str, str], run: Run, out_dir: Path) -> str | None:
    """Why a completed row of an earlier sweep cannot be kept by `--resume` (None: it can).

    Nothing read back is trusted: the row's log must be a regular file inside DIR/runs, a complete
    MCAP file (its footer read), recorded with this run's overrides, and its outcome metadata
    must be the row's; no cell may hold a control character (a NUL would go on into the table). A
    row without a log (--keep-logs failed or none) is checked in the same way against its outcome
    record (`record_name`): a JSON file inside DIR/runs naming this run, with exactly this run's
    overrides and the row's outcome; a row with neither runs again.
    """
    from cosim.logs.index import read_index

    if any(any(ord(c) < 32 for c in str(value)) for value in row.values() if value is not None):
        return "row with control characters"
    if not row.get("log"):
        return _record_problem(row, run, out_dir)
    runs_dir = (out_dir / "runs").resolve()
    path = (out_dir / (row.get("log") or "")).resolve()
    if not path.is_relative_to(runs_dir) or path == runs_dir:
        return "log outside the sweep folder"
    if not path.is_file():
        return "log missing"
    try:
        index = read_index(path)
    except CosimError:
        return "log unreadable"
    if not index.complete:
        return "log incomplete"
    metadata = {record.name: record.metadata for record in index.metadata}
    recorded = f" {metadata.get('navcosim', {}).get('overrides', '')} "
    if not all(f" {override} " in recorded for override in run.overrides):
        return "log of another run"
    return _outcome_problem(row, metadata.get("outcome"), "log")


def _outcome_problem(row: dict[str, str], outcome, source: str) -> str | None:
    if not isinstance(outcome, dict) or not outcome:
        return f"row differing from its {source}"
    if any(not isinstance(value, str) or row.get(key, "") != value for key, value in outcome.items()):
        return f"row differing from its {source}"
    return None


RECORD_LIMIT = 1 << 20  # [bytes] an outcome record is a few hundred bytes


def _record_problem(row: dict[str, str], run: Run, out_dir: Path) -> str | None:
    """Why a completed row without a log cannot be kept, checked against its outcome record."""
    import json

    path = out_dir / record_name(run.run_id)
    if path.is_symlink() or not path.is_file():
        return "no log and no outcome record"
    try:
        if path.stat().st_size > RECORD_LIMIT:
            return "outcome record unreadable"
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return "outcome record unreadable"
    if not isinstance(record, dict) or not record.get("run_id") == run.run_id == row.get("run_id"):
        return "outcome record of another run"
    if record.get("overrides") != list(run.overrides):
        return "outcome record of another run"
    return _outcome_problem(row, record.get("outcome"), "outcome record")


def _load_plotting(exits: bool) -> None:
    """Import the plot module (matplotlib: ~0.3 s of CPU) while the local cluster starts: the
    cluster waits for its fork server to warm up (`cosim.sweep.warm`), which takes longer than
    this process's import of Dask and the cluster's start, so the import fits in that wait
    instead of delaying the plot.
    `exits` (the process ends after the sweep, as `cosim sweep` does): as `cosim run`'s plot, skip
    the docstrings matplotlib writes for `help()` (0.1 s of the import's 0.27 s of CPU) and load
    the font now (`cosim.logs.plot.prepare_drawing`). The collector is paused meanwhile, in every
    thread (the main thread imports Dask then), as `prepare_drawing` pauses it."""
    from cosim.logs.plot import collector_paused, prepare_drawing

    with collector_paused():
        if exits:
            prepare_drawing()
        import cosim.sweep.plot  # noqa: F401


def check_options(options: SweepOptions) -> None:
    """`CosimError` (one line) on options that exclude each other or are out of range."""
    if options.workers is not None and options.scheduler is not None:
        raise CosimError("--workers and --scheduler exclude each other (a scheduler has its own workers)")
    if options.workers is not None and options.workers < 1:
        raise CosimError(f"--workers {options.workers}: must be >= 1")


def run_sweep(
    spec: SweepSpec,
    options: SweepOptions,
    progress: bool = True,
    plot: bool = True,
    exits: bool = False,
    plotter=None,
) -> SweepResult:
    """Run the sweep; the rows of finished runs are in DIR even when this is interrupted (the
    interrupt then carries a note saying which rows are kept and how to resume). `exits`: the
    process ends after the sweep (`cosim sweep`), so the plot may skip what only a later `help()`
    would use (`_load_plotting`), and Dask what only a notebook's HTML would
    (`cosim.sweep.warm.import_dask`). `plotter()`: a process that prepares to draw sweep.png while the
    sweep runs, then draws it while the cluster closes (`cosim sweep` gives the
    `cosim.cli.plotter.PlotProcess` it started first, drawing with `cosim.sweep.plot.draw_png`),
    called before this process has a thread; None, or when it gives None: sweep.png is drawn here."""
    from concurrent.futures import ThreadPoolExecutor

    from cosim.sweep.effect import outcome_warnings, seed_warnings

    check_options(options)
    if options.scheduler is None:
        # The local cluster's fork server warms up while the sweep is planned and Dask imported, on
        # the sweep's first run: when that builds there, no worker checks it again (`_execute`).
        start_fork_server(spec.scenario, spec.overrides, exits and progress, first_run(spec), html=not exits)
    bundle, runs, name = plan(spec)
    warnings = seed_warnings(
        spec, adapter.noise_levels(adapter.load(spec.scenario, spec.overrides, check_world=False))
    )
    out_dir = Path(options.out) if options.out is not None else default_out_dir(name)
    created = _prepare_out_dir(out_dir, options.resume)
    keys = spec.table_keys
    outcome_keys = adapter.outcome_keys()
    results = ResultsFile(out_dir / RESULTS_FILE, columns(keys, outcome_keys))
    rows: dict[str, dict[str, str]] = {}
    rerun: dict[str, int] = {}
    if options.resume:
        by_id = {run.run_id: run for run in runs}
        for row in read_rows(out_dir / RESULTS_FILE):
            run = by_id.get(row.get("run_id") or "")
            if run is None or row.get("status") != COMPLETED:
                continue
            problem = kept_row_problem(row, run, out_dir)
            if problem is None:
                rows[run.run_id] = {key: row.get(key) or "" for key in results.header}
            else:
                rerun[problem] = rerun.get(problem, 0) + 1
        if rerun and progress:
            reasons = ", ".join(f"{count} {why}" for why, count in sorted(rerun.items()))
            print(f"resume: {len(rows)} runs kept; run again: {reasons}", file=sys.stderr)
    skipped = len(rows)
    pending = [run for run in runs if run.run_id not in rows]

    def ordered() -> list[dict[str, str]]:
        return [rows[run.run_id] for run in runs if run.run_id in rows]

    def finish_tables() -> None:
        results.rewrite(ordered())
        if spec.replicates > 1:
            points = group_points(ordered(), spec.keys, outcome_keys)
            write_aggregate(out_dir / AGGREGATE_FILE, points, spec.keys, outcome_keys)

    def plot_arguments() -> dict:
        return {
            "rows": ordered(),
            "keys": spec.keys,
            "outcome_keys": outcome_keys,
            "grid": spec.method == "grid",
            "title": f"{name}: {spec.method} sweep",
            "replicates": spec.replicates,
        }

    def draw() -> Path | None:
        """Draw sweep.png here; None when there is no row."""
        from cosim.sweep.plot import draw_png

        return draw_png(plot_arguments(), out_dir / PLOT_FILE)

    def draw_in(child) -> Path | None:
        """Have the plot process draw; when it cannot (it says why), draw here, as without one."""
        if not ordered():
            child.cancel()
            return None
        if child.draw(plot_arguments(), out_dir / PLOT_FILE) is not None:
            return draw()
        return out_dir / PLOT_FILE

    started = time.perf_counter()
    workers, plot_path, plotting, child = None, None, None, None
    if pending:
        writing = False

        def checked() -> None:
            nonlocal writing
            results.rewrite(ordered())
            writing = True
            if progress:  # now, not only in the summary: the runs may take hours
                for warning in warnings:
                    print(f"warning: {warning}", file=sys.stderr)

        # On an error or an interrupt the fork server is left to stop with this process (as it
        # would, being told by its closed pipe): it may still be warming up, and waiting is slower.
        stopping = None
        try:
            with ThreadPoolExecutor(2) as pool:
                if plot:
                    child = plotter() if plotter is not None else None  # (no thread has started yet)
                    if child is None:  # its errors surface when `draw` imports it again
                        # After Dask's import, which would share this process's interpreter lock
                        # with it and so reach the cluster's start later.
                        import_dask(html=not exits)

                        pool.submit(_load_plotting, exits)
                cluster = connect(options.scheduler, options.workers, len(pending), html=not exits)
                with cluster as (client, workers, grow):
                    _execute(
                        client,
                        bundle,
                        runs[0],
                        pending,
                        keys,
                        out_dir,
                        results,
                        rows,
                        progress,
                        len(runs),
                        checked,
                        options.keep_logs,
                        grow,
                    )
                    finish_tables()
                    if plot:  # drawn while the cluster closes
                        plotting = pool.submit(draw) if child is None else pool.submit(draw_in, child)
                if options.scheduler is None:  # stops while the plot is drawn
                    stopping = pool.submit(stop_fork_server)
                plot_path = plotting.result() if plotting is not None else None
                if stopping is not None:
                    stopping.result()
        except CosimError:
            if not writing:  # refused before anything ran: leave nothing behind
                _remove_empty(created)
            raise
        except KeyboardInterrupt as interrupt:
            if writing:
                finish_tables()
                interrupt.sweep_kept = kept_text(ordered(), len(runs), out_dir, options.keep_logs)
                interrupt.sweep_out = out_dir
                interrupt.add_note(
                    f"{interrupt.sweep_kept}; run the rest with resume=True, out={str(out_dir)!r}"
                )
            raise
        finally:
            if child is not None:  # no plot (an error, an interrupt): it ends at once
                child.cancel()
            if writing:
                results.rewrite(ordered())
    else:
        if options.scheduler is None:
            stop_fork_server()  # every run was kept (--resume): no cluster
        finish_tables()
        plot_path = draw() if plot else None
    wall_time = time.perf_counter() - started
    seeds = [key for key in spec.keys if any(key in warning for warning in warnings)]
    group_keys = (*spec.keys, "replicate") if spec.replicates > 1 else spec.keys
    warnings += outcome_warnings(ordered(), spec.keys, group_keys, outcome_keys, skip=seeds)
    return SweepResult(
        spec, name, out_dir, ordered(), outcome_keys, wall_time, workers, plot_path, skipped, warnings
    )


def kept_text(rows: list[dict[str, str]], total: int, out_dir: Path, keep_logs: str) -> str:
    """What an interrupted sweep kept, in one line."""
    completed = sum(row.get("status") == COMPLETED for row in rows)
    logs = {"all": "their logs", "failed": "logs of the runs without the goal"}.get(
        keep_logs, "outcome records"
    )
    return (
        f"interrupted: kept {len(rows)} of {total} rows in {out_dir / RESULTS_FILE} ({completed} completed, "
        f"{len(rows) - completed} failed; {logs} in {out_dir / 'runs'}); --resume keeps the {completed} "
        f"completed and runs the other {total - completed}"
    )
