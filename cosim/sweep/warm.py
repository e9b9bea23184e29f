"""Warm-up of a local cluster's fork server: its workers start with the run stage loaded and compiled.

A `LocalCluster` of the sweep starts its worker processes by forking them from one server process
(multiprocessing's "forkserver"), which imports the modules it is told to preload before it forks
anything. This module starts that server (`start_fork_server`, first thing in a sweep, so that it
warms up while the sweep is planned): a fork of the sweep's own process once that has imported
Dask and the run stage (`_fork_server_here`: one import of them for both), or, where forking this
process is not safe, a fresh interpreter as multiprocessing starts it, which preloads them itself
and this module last: when the sweep set `WARM_ENV` (the scenario path and the sweep's fixed
overrides, as JSON) in the server's environment, importing it warms up. Warming up (`warm_up`) is
a short run of that scenario (`WARM_STOP_TIME` simulated seconds) into a scratch folder, which
imports the whole run stage, loads every C kernel the run uses (building any that is missing) and
loads the FMUs' descriptions. Each forked worker inherits all of that, so the work is done once per
sweep, while the client plans and starts the cluster, instead of once per worker in its first run.

A forked server warms up on the sweep's first run itself, laid out from its bundle as a worker lays
it out, and tells the sweep whether that run builds (`first_run_checked`): the sweep checks its
first run before it keeps any row, and when the warm-up built it no worker builds it again for that
(a build is ~0.05 s of a worker's time, on the critical path of a short sweep).

Best effort: whatever goes wrong here is swallowed (the sweep's check of its first run, on a
worker, reports a bad scenario with its own message), and nothing is printed; but a TMPDIR too long
a path for the server's socket is a one-line error (`_check_socket_path`): no local worker could
start.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

from cosim.errors import CosimError
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


def warm_up(scenario: str, overrides: list[str], announce: bool = False, first=None) -> bool:
    """Run `scenario` with `overrides` for `WARM_STOP_TIME` s into a scratch folder, then remove it.
    `scenario` may be a sweep file: then its scenario, with its `set` overrides before `overrides`
    (as `cosim.sweep.build` merges them). `announce`: say on stderr what the first use builds
    (`cosim.fmi.builtin.prepare`: one line per kind of build, as `cosim run` does; the workers
    forked later find it built).

    `first`: (bundle, run), the sweep's first run (`cosim.sweep.engine.first_run`), run instead,
    from the bundle's files laid out in the scratch folder as a worker lays them out, with its own
    overrides and the stop time cut. Returns whether that run builds as the sweep's check of it on a
    worker finds (`cosim.sweep.worker.check_task`): its overrides load as they are, and the cut run
    was built and started (the build does not read the stop time); False without `first`."""
    import contextlib
    import shutil
    import tempfile

    import cosim.sweep.adapter as adapter
    from cosim.sweep.spec import is_sweep_file, read_sweep_file

    path = Path(scenario)
    if first is None and path.suffix == ".toml" and is_sweep_file(path):
        fields, _ = read_sweep_file(path)
        path, overrides = Path(fields["scenario"]), [*fields["overrides"], *overrides]
    folder = tempfile.mkdtemp(prefix="navcosim-warm-")
    try:
        with (
            open(os.devnull, "w") as sink,
            contextlib.redirect_stdout(sink),
            contextlib.redirect_stderr(sink),
        ):
            if first is not None:
                from cosim.sweep.worker import redirects

                bundle, run = first
                files = Path(folder) / "files"
                bundle.materialize(files)
                path, overrides = files / bundle.scenario, [*run.overrides, *redirects(run, files)]
                adapter.load(path, overrides)  # as the check loads it (the stop time as it is)
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
    return first is not None


def import_dask(html: bool = True) -> None:
    """Import Dask (`distributed`), its configuration files (~1,200 lines of YAML: Dask's and
    distributed's defaults, and a user's own) read with libyaml's parser where PyYAML has it
    (`yaml_parsed_in_c`): ~3 ms of CPU instead of ~29 ms on the way to the local cluster's start.

    Without `html` (the `cosim` program, which shows no HTML): Dask's templates engine, jinja2, is
    not imported with it (~30 ms of the import's ~0.3 s, on the way to the cluster's start too).
    Dask takes jinja2 as optional (`dask.widgets` falls back to functions that raise ImportError,
    called only for the HTML that a notebook shows of a client or a cluster); it is seen as missing
    while Dask is imported, and importable afterwards by anyone else."""
    import sys

    if "distributed" in sys.modules:
        return
    hidden = not html and "jinja2" not in sys.modules
    if hidden:
        sys.modules["jinja2"] = None  # (an import of it raises ImportError)
    try:
        with yaml_parsed_in_c():
            import distributed  # noqa: F401
    finally:
        if hidden:
            del sys.modules["jinja2"]


@contextlib.contextmanager
def yaml_parsed_in_c():
    """PyYAML's `safe_load` parses with libyaml (`yaml.CSafeLoader`) inside the block: the same
    safe constructor and resolver over libyaml's parser, so the same values (a malformed file is an
    error there too, its message libyaml's). `safe_load` looks `SafeLoader` up in PyYAML's module
    each time, so that name is the C loader's while the block runs, and the pure-Python one's again
    after it. Without PyYAML, or a PyYAML built without libyaml: nothing changes."""
    try:
        import yaml
    except ImportError:
        yield
        return
    fast, saved = getattr(yaml, "CSafeLoader", None), yaml.SafeLoader
    if fast is not None:
        yaml.SafeLoader = fast
    try:
        yield
    finally:
        yaml.SafeLoader = saved


# The fork server listens on an AF_UNIX socket at <multiprocessing's folder under TMPDIR>/listener-
# and 8 characters; such a path holds at most 107 bytes (108 with its NUL).
SOCKET_PATH_MAX = 107
_LISTENER = len("/listener-12345678")


def _check_socket_path() -> None:
    """A one-line CosimError when TMPDIR is too long a path for the fork server's socket (binding it
    would fail with "AF_UNIX path too long", here or in multiprocessing's own server)."""
    from multiprocessing import util

    folder = util.get_temp_dir()
    if len(os.fsencode(folder)) + _LISTENER > SOCKET_PATH_MAX:
        raise CosimError(
            f"a local sweep starts its workers through a socket in {folder}, a path too long for one "
            f"({len(os.fsencode(folder))} bytes, at most {SOCKET_PATH_MAX - _LISTENER}): set TMPDIR to a "
            "shorter folder (e.g. TMPDIR=/tmp)"
        )


def start_fork_server(
    scenario: Path, overrides: tuple[str, ...], announce: bool = False, first=None, html: bool = True
) -> None:
    """Start the local cluster's fork server now, warming it up on `scenario` with `overrides`
    (`announce`: saying what a first use builds, `warm_up`); given `first` (bundle, run: the sweep's
    first run), on that run, and the server then tells whether it builds (`first_run_checked`).
    `html`: as `import_dask`, when this process imports Dask here.

    The server has `WORKER_PRELOAD` imported (here, before this process forks it; or by itself, a
    fresh interpreter) and makes a short run while this process goes on planning; the workers
    forked from it later start warm. It ignores SIGINT and SIGTERM, and so do the workers it forks:
    a Ctrl-C in a terminal (or a SIGTERM to the process group) reaches the whole group, and the
    interrupt must end the sweep here, which then closes them, instead of each one printing its own
    traceback, or its workers dying as the cluster starts or closes (Dask's start then failed, its
    close waited ~10 s and printed "Nanny failed to start"). Does nothing when the server
    already runs (an earlier sweep of this process started it).
    """
    _check_socket_path()
    _forget_check()
    fields = {"scenario": str(Path(scenario).resolve()), "overrides": list(overrides), "announce": announce}
    if _fork_server_here(fields, first, html):
        return
    ensure_fork_server(json.dumps(fields))


def ensure_fork_server(request: str = "") -> None:
    """Start the local cluster's fork server as multiprocessing starts it, a fresh interpreter,
    unless one runs; `request`: the warm-up it makes (`WARM_ENV`; "" for none). Its preload is
    `WORKER_PRELOAD`, whoever starts it (multiprocessing starts one afresh when a worker is asked
    of a server that ended; Dask, told the preload is set, leaves it). It ignores SIGINT
    and SIGTERM from its start on: it starts with them blocked
    (`cosim.core.interrupt.interrupts_blocked`, which leaves one meanwhile to this process), and the
    first module it imports ignores them (`cosim.sweep.hold`, given `WARM_ENV`); the workers it forks
    inherit that. multiprocessing's resource tracker, which this starts too, is started first: it
    unblocks them once it has started."""
    import multiprocessing
    from multiprocessing import forkserver, resource_tracker

    from cosim.core.interrupt import interrupts_blocked

    multiprocessing.get_context("forkserver").set_forkserver_preload(WORKER_PRELOAD)
    resource_tracker.ensure_running()
    saved = os.environ.get(WARM_ENV)
    os.environ[WARM_ENV] = request
    try:
        with interrupts_blocked():
            forkserver.ensure_running()
    finally:
        if saved is None:
            os.environ.pop(WARM_ENV, None)
        else:
            os.environ[WARM_ENV] = saved


def _fork_server_here(request: dict, first=None, html: bool = True) -> bool:
    """Start the fork server as a fork of this process, once it has imported what the server
    preloads (Dask and the run stage, `WORKER_PRELOAD`); False (nothing done) where that is not
    safe, and `start_fork_server` then starts a fresh interpreter as multiprocessing does.

    A fresh server imports Dask itself: ~0.3 s of CPU, done a second time beside this process's own
    import, on a 2-core machine where the two also share the cores with the plot process. Forked,
    the server only warms up (`warm_up`) and then serves: multiprocessing's own server loop
    (`multiprocessing.forkserver.main`), set up as `ForkServer.ensure_running` sets up the one it
    starts (a listening socket, an "alive" pipe whose end stays here), so Dask's nannies ask it for
    their workers as they would ask that one; with `first` (`start_fork_server`) it warms up on that
    run and writes whether it builds into a pipe whose other end stays here. Only with one thread
    here (forking a process with others can leave their locks held in the child: `cosim.sweep(...)`
    from a notebook gets the fresh interpreter), and only with the CPython server this was written
    against (3.11-3.13)."""
    import importlib
    import inspect
    import socket
    import sys
    import threading
    from multiprocessing import connection, forkserver, util

    from cosim.core.interrupt import SIGNALS, interrupts_blocked

    server = getattr(forkserver, "_forkserver", None)
    expected = ["listener_fd", "alive_r", "preload", "main_path", "sys_path"]
    if (
        not sys.platform.startswith("linux")
        or threading.active_count() != 1
        or not hasattr(os, "fork")
        or list(inspect.signature(forkserver.main).parameters) != expected
        or any(
            not hasattr(server, name)
            for name in ("_lock", "_forkserver_address", "_forkserver_alive_fd", "_forkserver_pid")
        )
        or hasattr(server, "_forkserver_authkey")
    ):
        return False
    with server._lock:
        if server._forkserver_pid is not None:  # one runs already; one that ended is started afresh
            return os.waitpid(server._forkserver_pid, os.WNOHANG)[0] == 0
    import_dask(html)
    for name in WORKER_PRELOAD:
        if name not in ("cosim.sweep.hold", "cosim.sweep.warm"):  # (they act on a request only)
            importlib.import_module(name)
    if threading.active_count() != 1:  # an import started one
        return False
    listener = socket.socket(socket.AF_UNIX)
    address = connection.arbitrary_address("AF_UNIX")
    listener.bind(address)
    if not util.is_abstract_socket_namespace(address):
        os.chmod(address, 0o600)
    listener.listen()
    alive_r, alive_w = os.pipe()
    check_r, check_w = os.pipe() if first is not None else (None, None)
    for stream in (sys.stdout, sys.stderr):  # nothing buffered is written twice
        stream.flush()
    # The signals this process handles (SIGINT and SIGTERM raise `Interrupted` in `cosim`) wait
    # while it forks: the server sets its own dispositions first, and one that came meanwhile is
    # then ignored there or ends it, and is taken here as ever.
    try:
        with interrupts_blocked():
            pid = os.fork()
            if pid == 0:
                _serve(listener, alive_r, request, set(SIGNALS), first, check_w)  # never returns
    except OSError:  # no fork: a fresh interpreter then
        pid = None
    os.close(alive_r)
    listener.close()
    if check_w is not None:
        os.close(check_w)
    if pid is None:
        os.close(alive_w)
        if check_r is not None:
            os.close(check_r)
        return False
    with server._lock:
        server._forkserver_address = address
        server._forkserver_alive_fd = alive_w
        server._forkserver_pid = pid
    if check_r is not None:
        _CHECK.append((check_r, first[1].run_id))
    return True


# The fork server's answer about the sweep's first run: (the pipe's end it writes to, the run's id).
_CHECK: list[tuple[int, str]] = []


def first_run_answered(run_id: str) -> bool:
    """Whether the fork server will say if the sweep's run `run_id` builds (`first_run_checked`): it
    was forked from this process, warming up on that run."""
    return any(checked == run_id for _, checked in _CHECK)


def first_run_checked(run_id: str) -> bool:
    """Whether the fork server, warmed up on the sweep's first run `run_id` (`start_fork_server`
    with `first`), found that it builds; read once, without waiting: False when it has not said so
    (another run, no such server, a fresh interpreter, an answer not there yet). The server answers
    before it forks any worker, so once a worker of the local cluster has started its answer is
    there."""
    import select

    answer = b""
    for fd, checked in _CHECK:
        try:
            if checked == run_id and select.select([fd], [], [], 0)[0]:
                answer = os.read(fd, 1)
        except OSError:
            pass
    _forget_check()
    return answer == b"1"


def _forget_check() -> None:
    while _CHECK:
        os.close(_CHECK.pop()[0])


def _serve(listener, alive_r: int, request: dict, held: set, first=None, check_w: int | None = None) -> None:
    """The forked fork server: the sweep's signal handlers undone (SIGINT and SIGTERM ignored, as in
    the workers it forks: `start_fork_server`; `held`, the signals blocked over the fork, let through
    then), a warm-up with the collector off, the heap frozen (`_from_environment`), then
    multiprocessing's server loop until the alive pipe closes; out by `os._exit`, never through
    this process's exit handlers or teardown, nor back into the sweep's code whatever happens.
    Given `first` (`start_fork_server`), the warm-up is that run, and whether it builds is written
    to `check_w` ("1" or "0") before the server forks any worker."""
    import gc
    import signal
    import threading
    from multiprocessing import forkserver

    try:
        gc.disable()
        signal.set_wakeup_fd(-1)
        for number in signal.valid_signals():
            try:
                if callable(signal.getsignal(number)):
                    signal.signal(number, signal.SIG_DFL)
            except (OSError, ValueError):
                pass
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, held)
        forkserver._forkserver._lock = threading.Lock()  # (held by no thread here)
        listener_fd = listener.detach()
        sever_descriptors({fd for fd in (listener_fd, alive_r, check_w) if fd is not None})
        built = False
        try:
            built = warm_up(
                str(request["scenario"]), list(request["overrides"]), bool(request["announce"]), first
            )
        except BaseException:  # noqa: BLE001 - a warm-up must never stop the fork server
            pass
        if check_w is not None:
            try:
                os.write(check_w, b"1" if built else b"0")
                os.close(check_w)
            except OSError:
                pass
        gc.freeze()
        gc.set_threshold(20_000, 20, 10)
        gc.enable()
        forkserver.main(listener_fd, alive_r, [])
    finally:
        _exit_at_once()


def sever_descriptors(kept: set[int]) -> None:
    """Point every descriptor of this process from 3 on, but `kept`, at /dev/null.

    The forked fork server inherits the sweep process's descriptors (a caller's files and pipes),
    which a fresh server would not hold: whoever reads such a pipe to its end would wait for the
    server and its workers too. Closed, their numbers would be free for the sockets the server's
    workers open, while the objects inherited with them still write there: a logging handler of
    the caller (a file, pytest's own) then wrote its lines into a worker's connection to the
    scheduler, which read "INFO    " as a frame's length and failed the sweep on a 2 EiB
    allocation. On /dev/null, each number stays taken and whatever writes to it is dropped."""
    try:
        numbers = sorted(int(name) for name in os.listdir("/proc/self/fd"))
    except OSError:  # no procfs: every number the process may hold
        numbers = range(3, os.sysconf("SC_OPEN_MAX"))
    null = os.open(os.devnull, os.O_RDWR)
    try:
        for fd in numbers:
            if fd < 3 or fd == null or fd in kept:
                continue
            try:
                os.fstat(fd)  # (the listing's own descriptor, closed since, is not made anew)
            except OSError:
                continue
            os.dup2(null, fd)
    finally:
        os.close(null)


def stop_fork_server() -> None:
    """Stop the local cluster's fork server (started by `start_fork_server`) and wait for it.

    Left running, it would only stop when this process exits, with this process's stdout and
    stderr still open, so whoever reads them would wait for it too. Stopped here, it goes while
    the sweep draws its plot, at once (`_exit_at_once`: no teardown of the run stage it holds, its
    C kernels, the FMUs, which took 0.1-0.5 s). A later sweep of this process starts a new one (warmed up
    on its own scenario). Uses `ForkServer._stop` (CPython's, since 3.8; nothing when not running).
    """
    from multiprocessing import forkserver

    _forget_check()
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
    never run it: they leave through `os._exit` too (multiprocessing's forkserver). What building
    the warm-up's FMUs left in the temporary folder, which an exit handler would remove, goes first
    (`cosim.fmi.builtin.remove_build_scratch`)."""
    import sys

    builtin = sys.modules.get("cosim.fmi.builtin")
    if builtin is not None:
        try:
            builtin.remove_build_scratch()
        except Exception:  # noqa: BLE001 (a folder left in the temporary folder, as before)
            pass

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
