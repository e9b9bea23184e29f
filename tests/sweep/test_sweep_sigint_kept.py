"""A Ctrl-C (or SIGTERM) while a local sweep starts ends it with one line, wherever it lands (it
went on to its end, or printed Dask's or Python's traceback, before):

- in the start of the local cluster's fork server (`forkserver.ensure_running`), where SIGINT was
  ignored for the processes started there, and multiprocessing's resource tracker, started in
  the same call, let it through while it was ignored;
- in a weakref callback (as the import machinery's module locks have), where Python drops the
  `Interrupted` the handler raises, and prints it;
- a SIGTERM to the process group as a worker starts, which ended the fork server: the worker's
  start failed, the cluster's close waited ~10 s, and Dask's "Nanny failed to start" came with
  its traceback (the fork server and its workers now ignore SIGTERM as they ignore SIGINT).

Each is made certain here: the command runs in a process that sends itself SIGINT at that point.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"

PREAMBLE = r"""
import os, signal, sys, weakref
from multiprocessing import forkserver
"""

IN_THE_FORK_SERVER_START = r"""
started = forkserver.ensure_running

def ensure_running():
    os.kill(os.getpid(), signal.SIGINT)  # a Ctrl-C while the server (and the tracker) start
    return started()

forkserver.ensure_running = ensure_running
"""

IN_A_WEAKREF_CALLBACK = r"""
import cosim.sweep.engine as engine
planned = engine.plan

class Thing:
    pass

def plan(spec):
    thing = Thing()
    reference = weakref.ref(thing, lambda _: signal.raise_signal(signal.SIGINT))
    del thing  # the handler's Interrupted is raised in the callback: printed, and dropped
    return planned(spec)

engine.plan = plan
"""

TERMINATED_AS_THE_WORKERS_START = r"""
from distributed.nanny import Nanny
start = Nanny.start_unsafe

async def start_unsafe(self):
    os.killpg(os.getpgrp(), signal.SIGTERM)  # the whole group, as a worker starts: the fork server ends
    return await start(self)

Nanny.start_unsafe = start_unsafe
"""

COMMAND = r"""
sys.argv = ["cosim", "sweep", sys.argv[1], "--vary", "lidar.seed=0:1:2", "--out", sys.argv[2], "--quiet"]
from cosim.__main__ import run
run()
"""


@pytest.mark.parametrize(
    "where, name",
    [
        (IN_THE_FORK_SERVER_START, "SIGINT"),
        (IN_A_WEAKREF_CALLBACK, "SIGINT"),
        (TERMINATED_AS_THE_WORKERS_START, "SIGTERM"),
    ],
    ids=["fork server start", "weakref callback", "SIGTERM to the group as the workers start"],
)
def test_an_interrupt_while_the_sweep_starts_ends_it_in_one_line(where, name, tmp_path):
    out = tmp_path / "sweep"
    done = subprocess.run(
        [sys.executable, "-c", PREAMBLE + where + COMMAND, str(SCENARIO), str(out)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
        start_new_session=True,  # (its own process group: the one SIGTERM ends)
    )
    assert done.returncode == 1, done.stderr[-2000:]
    assert done.stderr.rstrip().endswith(f"cosim: interrupted ({name})"), done.stderr[-2000:]
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr[-2000:]
    results = out / "results.csv"
    assert not results.exists() or len(results.read_text().splitlines()) <= 1  # no run was kept


FRESH_SERVER = r"""
import multiprocessing, signal, sys, time
from multiprocessing import forkserver
from cosim.core import interrupt
from cosim.sweep.warm import ensure_fork_server

def ignored_and_blocked(pid):
    lines = open(f"/proc/{pid}/status").read().splitlines()
    fields = dict(line.split(":\t") for line in lines if ":\t" in line)
    bits = 1 << (signal.SIGINT - 1) | 1 << (signal.SIGTERM - 1)  # both
    return int(fields["SigIgn"], 16) & bits == bits, int(fields["SigBlk"], 16) & bits == bits

context = multiprocessing.get_context("forkserver")
with interrupt.catching_signals():
    ensure_fork_server()  # (no request: no warm-up)
    worker = context.Process(target=time.sleep, args=(30,))
    worker.start()
    print(ignored_and_blocked(forkserver._forkserver._forkserver_pid), ignored_and_blocked(worker.pid))
    print(signal.getsignal(signal.SIGTERM) is interrupt._handle, ignored_and_blocked("self"))
    worker.kill()
    worker.join()
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_fork_server_started_afresh_and_its_workers_ignore_interrupts_and_this_process_does_not():
    """The fresh interpreter multiprocessing starts (where this process may not fork it) ignores
    SIGINT and SIGTERM from its first module on, blocked until then; the workers it forks ignore
    them too; this process keeps its handlers, neither blocked."""
    done = subprocess.run(
        [sys.executable, "-c", FRESH_SERVER], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    server_and_worker, here = done.stdout.splitlines()
    assert server_and_worker == "(True, True) (True, True)"  # ignored (and still blocked: either way deaf)
    assert here == "True (False, False)"
