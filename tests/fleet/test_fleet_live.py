"""`cosim run FLEET.toml --live`: a WebSocket client gets every robot's topics, under their
namespaces, with the log's bytes at the log's times; a client joining late gets each robot's
latched plan."""

from __future__ import annotations

import asyncio
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("foxglove")
pytest.importorskip("websockets")

from test_live import _listen, _log_messages  # noqa: E402 (tests/record: the client, the log's messages)

ROOT = Path(__file__).resolve().parents[2]
FLEET = ROOT / "scenarios" / "fleet_head_on.toml"
TOPICS = ("/tf", "/robot1/odom", "/robot2/scan", "/robot2/signals/vehicle")


@pytest.mark.slow
def test_a_fleets_live_view_streams_every_robots_topics_as_logged(tmp_path):
    log = tmp_path / "live.mcap"
    command = [
        sys.executable, "-m", "cosim", "run", str(FLEET), "--out", str(log), "--no-plot", "--quiet",
        "--set", "simulation.stop_time=4", "--live", "--port", "0", "--realtime", "2", "--linger", "3",
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stderr.readline()
        assert line.startswith("live view: ws://"), line
        url = line.split()[2]
        advertised, received = asyncio.run(asyncio.wait_for(_listen(url, TOPICS, enough=5), timeout=120))
        while "run ended" not in (line := process.stderr.readline()):
            assert line, "the run ended without lingering"
        latched = ("/robot1/plan", "/robot2/plan")
        _, late = asyncio.run(asyncio.wait_for(_listen(url, latched, enough=1), timeout=60))
        rest = process.stderr.read()
        assert process.wait(timeout=120) == 1, rest  # the stop time comes before any goal
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    messages, schemas = _log_messages(log, TOPICS + latched)
    for topic in TOPICS:
        assert advertised[topic]["schema"].encode() == schemas[topic]
        assert len(received[topic]) >= 5, topic
        for stamp, payload in received[topic]:
            assert messages[topic][stamp] == payload
    for topic in latched:  # the last plan of each robot, to a client that joined after the run
        stamp, payload = late[topic][0]
        assert stamp == max(messages[topic]) and messages[topic][stamp] == payload
