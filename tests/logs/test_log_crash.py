"""Logs of runs that did not end: SIGKILL mid-write, and files cut at arbitrary bytes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from log_synthetic import write_log

from cosim.cli import main
from cosim.errors import CosimError
from cosim.logs import open_log

WRITER = textwrap.dedent(
    """
    import sys
    import numpy as np
    from cosim.record.recorder import Recorder

    recorder = Recorder(sys.argv[1], flush_interval=0.05)
    recorder.add_metadata("navcosim", {"scenario_name": "killed", "goal": "100,0"})
    channel = recorder.signal_channel("vehicle", ["x", "y", "theta"])
    k = 0
    while True:
        t_ns = k * 1_000_000
        recorder.write_signals(channel, t_ns, np.array([k * 0.001, np.sin(k * 0.001), 0.25]))
        recorder.write_pose(t_ns, k * 0.001, np.sin(k * 0.001), 0.25, 1.0, 0.0)
        k += 1
        if k == 5000:
            recorder.flush()
            print(k, flush=True)
    """
)


@pytest.fixture(scope="module")
def killed_log(tmp_path_factory):
    target = tmp_path_factory.mktemp("crash") / "killed.mcap"
    process = subprocess.Popen([sys.executable, "-c", WRITER, str(target)], stdout=subprocess.PIPE, text=True)
    flushed = int(process.stdout.readline())
    time.sleep(0.4)  # keep writing (and flushing every 50 ms) for a while
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    process.stdout.close()
    return target, flushed


@pytest.mark.slow
def test_killed_run_reads_up_to_its_last_chunk(killed_log):
    target, flushed = killed_log
    log = open_log(target)
    assert not log.is_complete
    assert any("incomplete log" in warning for warning in log.warnings)
    vehicle = log.signals("vehicle")
    count = len(vehicle.t)
    assert count >= flushed  # everything flushed before the kill is there
    k = np.arange(count)
    np.testing.assert_array_equal(vehicle.t_ns, k * 1_000_000)  # no gap, no duplicate
    np.testing.assert_array_equal(vehicle["x"], k * 0.001)
    np.testing.assert_array_equal(vehicle["y"], np.sin(k * 0.001))
    poses = {topic.name: topic.count for topic in log.topics}
    assert abs(poses["/pose"] - count) <= 1  # a chunk may end between two topics of one step
    assert log.trajectory().x[-1] == vehicle["x"][-1]


@pytest.mark.slow
@pytest.mark.parametrize("action", ["info", "plot", "export"])
def test_commands_work_on_a_killed_run_with_a_warning(killed_log, tmp_path, capsys, action):
    target, _ = killed_log
    extra = {
        "info": [],
        "plot": ["--png", str(tmp_path / "k.png")],
        "export": ["--to", "npz", "--out", str(tmp_path)],
    }
    assert main(["log", action, str(target), *extra[action]]) == 0
    captured = capsys.readouterr()
    assert "warning" in captured.err and "incomplete log" in captured.err
    if action == "info":
        assert "INCOMPLETE" in captured.out
    if action == "plot":
        assert (tmp_path / "k.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    if action == "export":
        data = np.load(tmp_path / "killed-signals.npz")
        np.testing.assert_array_equal(data["vehicle.values"][:, 0], np.arange(len(data["vehicle.t"])) * 0.001)


def test_files_cut_anywhere_read_a_prefix_or_fail_in_one_line(tmp_path):
    full = write_log(tmp_path / "full.mcap", steps=200, flush_every=10)
    data = full.path.read_bytes()
    expected = full.signals["vehicle"]
    footer_and_magic = 1 + 8 + 20 + 8
    cuts = np.unique(np.linspace(0, len(data) - footer_and_magic - 1, 25).astype(int))
    read_counts = []
    for cut in cuts:
        target = tmp_path / f"cut{cut}.mcap"
        target.write_bytes(data[:cut])
        try:
            log = open_log(target)
        except CosimError as error:
            assert "\n" not in str(error)
            continue
        assert not log.is_complete
        if "vehicle" in log.components:
            values = log.signals("vehicle").values
            assert values.tobytes() == expected[: len(values)].tobytes()
            read_counts.append(len(values))
        for topic in ("/scan", "/plan"):
            if log.has_topic(topic):
                list(log.messages(topic))
    assert read_counts == sorted(read_counts) and 0 < read_counts[-1] <= 200
