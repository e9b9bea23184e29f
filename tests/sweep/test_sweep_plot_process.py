"""`cosim sweep` forks its plot process as soon as the sweep is parsed (`cosim.cli.sweep`), before it
is planned: a sweep refused then (a key the scenario does not have, found when the sweep is
planned) ends and reaps that process before it exits itself, so it never outlives the command as
an orphan."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"

# Runs the command as a child subreaper (Linux: PR_SET_CHILD_SUBREAPER), so that whatever the
# command leaves behind is re-parented here: each such orphan is waited for, and counted when it
# led its own process group (the plot process does, `cosim.cli.plotter`; the fork server, which a
# failing sweep leaves to end with it, does not).
SUBREAPER = """
import ctypes, os, subprocess, sys
if ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0) != 0:
    sys.exit("no PR_SET_CHILD_SUBREAPER")
command = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
leaders = 0
while True:
    try:
        ended = os.waitid(os.P_ALL, 0, os.WEXITED | os.WNOWAIT)
    except ChildProcessError:
        break
    stat = open(f"/proc/{ended.si_pid}/stat").read().rpartition(")")[2].split()
    leaders += int(stat[2]) == ended.si_pid  # (state, ppid, pgrp)
    os.waitpid(ended.si_pid, 0)
print(command.returncode, leaders)
print(command.stderr, end="")
"""


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the plot process is forked on Linux only")
def test_a_refused_sweep_leaves_no_plot_process(tmp_path):
    command = [sys.executable, "-m", "cosim", "sweep", str(SCENARIO), "--vary", "lidar.no_such_key=1,2"]
    command += ["--out", str(tmp_path / "sweep")]
    done = subprocess.run(
        [sys.executable, "-c", SUBREAPER, *command],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    (code_and_leaders, error) = done.stdout.split("\n", 1)
    assert code_and_leaders == "2 0", error
    assert error.startswith("cosim: error: ") and "no_such_key" in error
    assert not (tmp_path / "sweep").exists()
