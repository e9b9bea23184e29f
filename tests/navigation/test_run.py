"""A run's log read back with the `mcap` reader and the ROS 2 decoder; SIGINT/SIGTERM end a run cleanly."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

EXAMPLE = Path(__file__).resolve().parents[2] / "scenarios" / "example_commented.toml"
STOP_TIME = 4.0  # [s] simulated: 400 macro steps of 10 ms


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    log = tmp_path_factory.mktemp("run") / "short.mcap"
    scenario = load_scenario(EXAMPLE, [f"simulation.stop_time={STOP_TIME}"])
    result = run_scenario(scenario, log)
    return scenario, result, log


def test_short_run_stops_at_stop_time(short_run):
    _, result, _ = short_run
    assert result.outcome.reason == "stop_time"
    assert result.outcome.time == STOP_TIME
    assert result.exit_code == 1
    assert result.steps == 400
    # Driving straight at 1.5 m/s from rest (a kinematic model: no acceleration limit).
    assert 0.9 * 1.5 * STOP_TIME < result.outcome.distance <= 1.5 * STOP_TIME + 1e-9


def test_log_topics_and_counts_match_the_rates(short_run):
    _, _, log = short_run
    counts: Counter[str] = Counter()
    with open(log, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, decoded in reader.iter_decoded_messages():
            counts[channel.topic] += 1
            assert decoded is not None
        metadata = {record.name: record.metadata for record in reader.iter_metadata()}
        attachments = {attachment.name for attachment in reader.iter_attachments()}
    steps = 400
    assert counts["/odom"] == counts["/tf"] == counts["/pose"] == 1 + steps // 2  # 50 Hz plus t = 0
    assert counts["/scan"] == steps // 10  # 10 Hz
    assert counts["/cmd_vel"] == steps // 5  # 20 Hz
    # Every step of a component, plus a last record with its outputs at the end.
    assert counts["/signals/vehicle"] == steps + 1  # every macro step
    for controller in ("pure_pursuit", "vfh", "mixer"):
        assert counts[f"/signals/{controller}"] == steps // 5 + 1
    assert counts["/signals/lidar"] == steps // 10 + 1
    for once in ("/map", "/map_inflated", "/obstacles", "/goal"):
        assert counts[once] == 1
    # /plan at t = 0 and at every replan (the example's box is seen on the plan at once).
    assert counts["/plan"] == 1 + short_run[1].outcome.replans
    assert metadata["outcome"]["reason"] == "stop_time"
    assert metadata["navcosim"]["scenario_name"] == "example_commented"
    assert {"fmu/vehicle", "fmu/pure_pursuit", "fmu/vfh", "fmu/mixer"} <= set(metadata)
    assert "scenario.toml" in attachments and "warehouse.yaml" in attachments


@pytest.mark.slow
@pytest.mark.parametrize("signal_number", [signal.SIGINT, signal.SIGTERM])
def test_signal_finalises_the_log(signal_number, tmp_path: Path):
    log = tmp_path / "interrupted.mcap"
    process = subprocess.Popen(
        # A fine macro step (10 million steps) makes the run last many seconds however fast the
        # machine, so the signal arrives mid-run.
        [sys.executable, "-m", "cosim", "run", str(EXAMPLE), "--out", str(log), "--no-plot", "--quiet"]
        + ["--set", "simulation.macro_step=0.00002"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    # The log is created once the system is built and initialised; only from then on does a signal
    # end the run with a finalised log (before, it exits 1 with nothing written). Startup under
    # load can take long, so wait for the log itself, not for a fixed time.
    while not log.exists() and process.poll() is None:
        time.sleep(0.1)
    assert process.poll() is None, process.communicate()[1]
    time.sleep(1.0)
    process.send_signal(signal_number)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 1, err
    assert "Traceback" not in err
    with open(log, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None  # finalised: summary and footer written
        outcome = {record.name: record.metadata for record in reader.iter_metadata()}["outcome"]
    assert outcome["reason"] == "interrupted"
    assert 0 < float(outcome["time"]) < 200
