"""Warm-up of a local cluster's fork server: its workers start with the run stage loaded and compiled.

A `LocalCluster` of the sweep starts its worker processes by forking them from one server process
(multiprocessing's "forkserver"), which imports the modules it is told to preload before it forks
anything. This module starts that server (`start_fork_server`, first thing in a sweep, so that it
warms up while the sweep is planned and Dask imported) and is one of the modules it preloads: when
the sweep set `WARM_ENV` (the scenario path and the sweep's fixed overrides, as JSON) in the
server's environment, importing it makes a short run of
that scenario (`WARM_STOP_TIME` simulated seconds) into a scratch folder, which imports the whole
run stage, loads every C kernel the run uses (building any that is missing) and loads the FMUs'
descriptions. Each forked worker inherits all of that, so the work is done once per sweep,
while the client is still importing Dask and planning, instead of once per worker in its first run.

Best effort: whatever goes wrong here is swallowed (the sweep's check of its first run, on a
worker, reports a bad scenario with its own message), and nothing is printed.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from cosim.sweep.hold import WARM_ENV

# Imported once by the local cluster's fork server, so its workers start with them loaded; the last
# one (this module) also makes a short run of the sweep's scenario there, and switches the
# collector, which the first one switched off, on again.
WORKER_PRELOAD = [
    "cosim.sweep.hold",  # first: no cyclic garbage collection while the server loads and warms up
    "distributed",
    "cosim.scenario.load",
    "cosim.navigation.run",
    "cosim.sweep.worker",
    "cosim.sweep.warm",
]
WARM_STOP_TIME = 0.5  # [s] of simulated time: a few lidar, controller and pose steps


def warm_up(scenario: str, overrides: list[str], announce: bool = False) -> None:
    """Run `scenario` with `overrides` for `WARM_STOP_TIME` s into a scratch folder, then remove it.
    `scenario` may be a sweep file: then its scenario, with its `set` overrides before `overrides`
    (as `cosim.sweep.build` merges them). `announce`: say on stderr what the first use builds
    (`cosim.fmi.builtin.prepare`: one line per kind of build, as `cosim run` does; the workers
    forked later find it built)."""
    import contextlib
    import shutil
    import tempfile

    import cosim.sweep.adapter as adapter
    from cosim.sweep.spec import is_sweep_file, read_sweep_file

    path = Path(scenario)
    if path.suffix == ".toml" and is_sweep_file(path):
        fields, _ = read_sweep_file(path)
        path, overrides = Path(fields["scenario"]), [*fields["overrides"], *overrides]
    folder = tempfile.mkdtemp(prefix="navcosim-warm-")
    try:
        with (
            open(os.devnull, "w") as sink,
            contextlib.redirect_stdout(sink),
            contextlib.redirect_stderr(sink),
        ):
            loaded = adapter.load(path, [*overrides, f"simulation.stop_time={WARM_STOP_TIME}"])
        if announce:
            import sys

            from cosim.fmi.builtin import prepare

            def say(line: str) -> None:
                print(f"cosim sweep: {line}", file=sys.stderr, flush=True)

            prepare(loaded.project_fmus, loaded.fmi_version, announce=say)
        with (
            open(os.devnull, "w") as sink,
            contextlib.redirect_stdout(sink),
            contextlib.redirect_stderr(sink),
        ):
            adapter.run(loaded, Path(folder) / "warm.mcap")
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def start_fork_server(scenario: Path, overrides: tuple[str, ...], announce: bool = False) -> None:
    """Start the local cluster's fork server now, warming it up on `scenario` with `overrides`
    (`announce`: saying what a first use builds, `warm_up`).

    The server imports `WORKER_PRELOAD` and makes a short run (`cosim.sweep.warm`) while this
    process goes on importing Dask and planning; the workers forked from it later start warm. It
    inherits an ignored SIGINT (the only disposition that survives exec), and so do the workers it
    forks: Ctrl-C in a terminal reaches the whole process group, and the interrupt must end the
    sweep here, which then closes them, instead of each one printing its own traceback. Does
    nothing when the server already runs (an earlier sweep of this process started it).
    """
    import multiprocessing
    import signal
    from multiprocessing import forkserver

    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(WORKER_PRELOAD)
    request = json.dumps(
        {"scenario": str(Path(scenario).resolve()), "overrides": list(overrides), "announce": announce}
    )
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    saved = os.environ.get(WARM_ENV)
    os.environ[WARM_ENV] = request
    try:
        forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, previous)
        if saved is None:
            os.environ.pop(WARM_ENV, None)
        else:
            os.environ[WARM_ENV] = saved


def stop_fork_server() -> None:
    """Stop the local cluster's fork server (started by `start_fork_server`) and wait for it.

    Left running, it would only stop when this process exits, with this process's stdout and
    stderr still open, so whoever reads them would wait for it too. Stopped here, it goes while
    the sweep draws its plot, at once (`_exit_at_once`: no teardown of the run stage it holds, its
    C kernels, the FMUs, which took 0.1-0.5 s). A later sweep of this process starts a new one (warmed up
    on its own scenario). Uses `ForkServer._stop` (CPython's, since 3.8; nothing when not running).
    """
    from multiprocessing import forkserver

    stop = getattr(getattr(forkserver, "_forkserver", None), "_stop", None)
    if stop is None:
        return
    try:
        stop()
    except OSError:  # already gone
        pass


def _exit_at_once() -> None:
    """The fork server's way out (an `atexit` handler registered after every other, so it runs
    first): its streams flushed, then `os._exit`. An ordinary interpreter exit tears down every
    module and object the warm-up left (distributed, numpy, scipy, the run stage: 0.1-0.5 s on a
    busy 2-core machine), which the sweep waits for (`stop_fork_server`). The workers it forked
    never run it: they leave through `os._exit` too (multiprocessing's forkserver)."""
    import sys

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):
            pass
    os._exit(0)


def _from_environment() -> None:
    text = os.environ.pop(WARM_ENV, None)
    if not text:
        return
    try:
        request = json.loads(text)
        warm_up(
            str(request["scenario"]),
            [str(item) for item in request["overrides"]],
            bool(request.get("announce", False)),
        )
    except BaseException:  # noqa: BLE001 - a warm-up must never stop the fork server
        pass
    import atexit
    import gc

    atexit.register(_exit_at_once)
    # What the workers inherit (~10^5 objects: the modules, the FMUs' descriptions) is never walked
    # by their collector again, and it looks at young objects every 20,000 allocations instead of
    # 700, as in `cosim run` (`cosim.cli`): ~5 % of a worker's CPU time otherwise. The collector was
    # off since the server's first import (`cosim.sweep.hold`).
    gc.freeze()
    gc.set_threshold(20_000, 20, 10)
    gc.enable()


_from_environment()
