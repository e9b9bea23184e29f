"""The local cluster's fork server is a fork of the sweep's process once that has imported Dask and
the run stage (`cosim.sweep.warm._fork_server_here`), and a fresh interpreter where a second thread
makes forking unsafe. Observed from outside, through /proc: the server's command line (a fork has
its parent's, a fresh one multiprocessing's `-c ... forkserver`), the signals it and the workers it
forks ignore, the descriptors it holds, its exit once stopped. A Ctrl-C while the local cluster
starts ends the sweep's connection with KeyboardInterrupt, not a cluster that goes on."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"

PROGRAM = """
import os, select, signal, sys, threading, time
from pathlib import Path
if sys.argv[1] == "thread":
    threading.Thread(target=threading.Event().wait, daemon=True).start()
from multiprocessing import forkserver, get_context
from cosim.sweep.warm import start_fork_server, stop_fork_server

def ignores_sigint(pid):
    with open(f"/proc/{pid}/status") as status:
        mask = next(int(line.split()[1], 16) for line in status if line.startswith("SigIgn:"))
    return bool(mask & 1 << signal.SIGINT - 1)

read_end, write_end = os.pipe()  # a caller's pipe, open while the server starts
start_fork_server(Path(sys.argv[2]), ("lidar.seed=1",))
server = forkserver._forkserver._forkserver_pid
with open(f"/proc/{server}/cmdline", "rb") as theirs, open("/proc/self/cmdline", "rb") as mine:
    print("fork" if theirs.read() == mine.read() else "fresh")
os.close(write_end)
print("pipe closed", bool(select.select([read_end], [], [], 20)[0]) and os.read(read_end, 1) == b"")
worker = get_context("forkserver").Process(target=time.sleep, args=(30,))
worker.start()
# (once it serves: a fresh server starts with SIGINT blocked, and ignores it from its first module)
print("server ignores SIGINT", ignores_sigint(server), "here", ignores_sigint(os.getpid()))
with open(f"/proc/{worker.pid}/status") as status:
    parent = next(int(line.split()[1]) for line in status if line.startswith("PPid:"))
print("worker of the server", parent == server, "ignores SIGINT", ignores_sigint(worker.pid))
worker.kill()
worker.join()
stop_fork_server()
print("server gone", not os.path.exists(f"/proc/{server}"))
"""


def _program(mode: str) -> list[str]:
    result = subprocess.run(
        [sys.executable, "-c", PROGRAM, mode, str(SCENARIO)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
    )
    assert result.returncode == 0, result.stderr
    return result.stdout.splitlines()


@pytest.mark.slow
@pytest.mark.parametrize("mode, server", [("alone", "fork"), ("thread", "fresh")])
def test_the_fork_server_is_forked_when_alone_and_holds_nothing_of_the_caller(mode, server):
    assert _program(mode) == [
        server,
        "pipe closed True",  # the server does not hold the caller's pipe open
        "server ignores SIGINT True here False",
        "worker of the server True ignores SIGINT True",
        "server gone True",
    ]


INTERRUPTED = """
import os, signal, threading
import distributed
from cosim.sweep import engine
threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT)).start()
try:
    with engine.connect(None, 1, 1) as (client, count):
        print("connected", count)
except KeyboardInterrupt:
    print("interrupted")
"""


@pytest.mark.slow
def test_a_ctrl_c_while_the_local_cluster_starts_is_not_lost():
    # The cluster's start takes longer than 0.05 s anywhere: its fork server, a fresh interpreter
    # here, imports Dask before the worker can start. SIGINT was ignored over the whole start.
    process = subprocess.Popen(
        [sys.executable, "-c", INTERRUPTED],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        stdout, stderr = process.communicate(timeout=300)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode == 0, stderr
    assert stdout.splitlines() == ["interrupted"]
    assert "Traceback" not in stderr


def _sweep(tmpdir: Path, out: Path, *options: str) -> subprocess.CompletedProcess:
    """`cosim sweep` of SCENARIO over two lidar noises into `out` (no plot, quiet), TMPDIR `tmpdir`."""
    command = [sys.executable, "-m", "cosim", "sweep", str(SCENARIO), "--vary", "lidar.noise=0.0,0.1"]
    return subprocess.run(
        [*command, *options, "--out", str(out), "--no-plot", "--quiet"],
        cwd=REPO,
        env={**os.environ, "TMPDIR": str(tmpdir)},
        capture_output=True,
        text=True,
        timeout=600,
    )


@pytest.mark.slow
def test_a_local_sweep_leaves_no_files_of_its_workers_behind(tmp_path):
    # Each worker lays the bundle out in a folder of its own under TMPDIR (`BundlePlugin.setup`)
    # and removes it as it closes with the sweep's cluster; the fork server's warm-up run its own.
    # TMPDIR a short path, as the fork server's socket is made there (tmp_path may be too long).
    scratch = Path(tempfile.mkdtemp(prefix="navcosim-test-", dir="/tmp"))
    try:
        result = _sweep(scratch, tmp_path / "out", "--set", "simulation.stop_time=4", "--workers", "2")
        assert result.returncode == 0, result.stderr
        assert len(list((tmp_path / "out" / "runs").glob("*.mcap"))) == 2
        left = sorted(path.name for path in scratch.iterdir() if path.name.startswith("navcosim-"))
        assert left == []
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


@pytest.mark.slow
def test_a_tmpdir_too_long_for_the_servers_socket_is_one_line(tmp_path):
    scratch = tmp_path / ("d" * 90)
    scratch.mkdir()
    result = _sweep(scratch, tmp_path / "out")
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "a path too long for one" in lines[0] and "set TMPDIR" in lines[0], lines


LOGGING_CALLER = """
import logging, os, sys
from pathlib import Path
logging.basicConfig(filename=sys.argv[1], level=logging.DEBUG)  # a caller's file, held open
from multiprocessing import forkserver
from cosim.cli import main
from cosim.sweep import warm
stop = warm.stop_fork_server
def looked_at():  # the server's view of the caller's log file, before it stops
    handler = logging.getLogger().handlers[0]
    server = forkserver._forkserver._forkserver_pid
    print("server sees", os.readlink(f"/proc/{server}/fd/{handler.stream.fileno()}"))
    stop()
warm.stop_fork_server = looked_at
import cosim.sweep.engine as engine
engine.stop_fork_server = looked_at
code = main(["sweep", sys.argv[2], "--vary", "lidar.noise=0.0,0.1", "--set", "simulation.stop_time=2",
             "--out", sys.argv[3], "--no-plot", "--quiet", "--workers", "2"])
print("exit", code)
"""


@pytest.mark.slow
def test_a_callers_log_file_is_dev_null_in_the_fork_server_not_a_free_number(tmp_path):
    # The server once closed the caller's descriptors: the workers' Dask logging then failed on a
    # closed descriptor ("--- Logging error ---" on stderr), or wrote into a socket that had taken
    # its number, and the scheduler read "INFO    " as a frame's length (a 2 EiB allocation).
    result = subprocess.run(
        [sys.executable, "-c", LOGGING_CALLER, str(tmp_path / "caller.log"), str(SCENARIO)]
        + [str(tmp_path / "out")],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
        env={**os.environ, "TMPDIR": "/tmp"},  # (the server's socket path must be short)
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["server sees /dev/null", "exit 0"]
    assert "Logging error" not in result.stderr and "Traceback" not in result.stderr, result.stderr
    assert len(list((tmp_path / "out" / "runs").glob("*.mcap"))) == 2
