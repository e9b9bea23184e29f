"""`cosim run --live`: a WebSocket client (written here with `websockets`, speaking the subprotocol
the foxglove-sdk server answers with) subscribes to /odom and /scan, decodes the messages with the
advertised schemas (rosbags), and gets the poses and ranges the log holds at the same times."""

from __future__ import annotations

import asyncio
import json
import signal
import socket
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk 0.30's server accepts (it answers 400 otherwise)
TOPICS = ("/odom", "/scan")


def _typestore(advertised: list[dict]):
    """A rosbags typestore knowing the advertised ros2msg schemas (definition + dependencies)."""
    store = get_typestore(Stores.EMPTY)
    for channel in advertised:
        name, text = channel["schemaName"], channel["schema"]
        sections = text.split("=" * 80 + "\n")
        types = dict(get_types_from_msg(sections[0], name))
        for section in sections[1:]:
            header, _, body = section.partition("\n")
            types.update(get_types_from_msg(body, header.removeprefix("MSG: ").strip()))
        store.register({key: value for key, value in types.items() if key not in store.fielddefs})
    return store


async def _listen(
    url: str, topics: tuple[str, ...] = TOPICS, enough: int | None = None
) -> tuple[dict[str, dict], dict[str, list[tuple[int, bytes]]]]:
    """Subscribe to `topics` and collect (timestamp [ns], payload) per topic until the server
    stops (or, given `enough`, until every topic has that many)."""
    advertised: dict[str, dict] = {}
    subscriptions: dict[int, str] = {}
    received: dict[str, list[tuple[int, bytes]]] = {topic: [] for topic in topics}
    pending: list[dict] = []  # every subscription sent
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as client:
        assert client.subprotocol == SUBPROTOCOL
        try:
            async for frame in client:
                if isinstance(frame, str):
                    message = json.loads(frame)
                    if message["op"] == "status" and message["message"].startswith("Unknown channel ID"):
                        # The SDK's server can answer a subscription sent right after an advertise
                        # with this (its channel table lags the advertise): subscribe again.
                        channel_id = int(message["message"].rsplit(":", 1)[1])
                        await asyncio.sleep(0.02)
                        again = [item for item in pending if item["channelId"] == channel_id]
                        await client.send(json.dumps({"op": "subscribe", "subscriptions": again}))
                        continue
                    if message["op"] != "advertise":
                        continue
                    wanted = []
                    for channel in message["channels"]:
                        if channel["topic"] in topics and channel["topic"] not in advertised:
                            advertised[channel["topic"]] = channel
                            subscription = len(subscriptions) + 1
                            subscriptions[subscription] = channel["topic"]
                            wanted.append({"id": subscription, "channelId": channel["id"]})
                    pending += wanted
                    if wanted:
                        await client.send(json.dumps({"op": "subscribe", "subscriptions": wanted}))
                elif frame[0] == 1:  # message data: subscription id, log time, payload
                    subscription, stamp = struct.unpack_from("<IQ", frame, 1)
                    received[subscriptions[subscription]].append((stamp, bytes(frame[13:])))
                    if enough is not None and all(len(items) >= enough for items in received.values()):
                        break
        except websockets.ConnectionClosed:
            pass
    return advertised, received


def _log_messages(
    path: Path, topics: tuple[str, ...] = TOPICS
) -> tuple[dict[str, dict[int, bytes]], dict[str, bytes]]:
    """Per topic {log time [ns]: payload} and the schema texts, read with the mcap package."""
    messages: dict[str, dict[int, bytes]] = {topic: {} for topic in topics}
    schemas: dict[str, bytes] = {}
    with open(path, "rb") as handle:
        for schema, channel, message in make_reader(handle).iter_messages(topics=list(topics)):
            messages[channel.topic][message.log_time] = message.data
            schemas[channel.topic] = schema.data
    return messages, schemas


@pytest.fixture(scope="module")
def live_run(tmp_path_factory):
    log = tmp_path_factory.mktemp("live") / "live.mcap"
    command = [
        sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(log), "--no-plot", "--quiet",
        "--set", "simulation.stop_time=3", "--live", "--port", "0", "--realtime", "3", "--linger", "0.5",
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stderr.readline()
        assert line.startswith("live view: ws://"), line
        url = line.split()[2]
        advertised, received = asyncio.run(asyncio.wait_for(_listen(url), timeout=120))
        rest = process.stderr.read()
        assert process.wait(timeout=120) == 1, rest  # the stop time comes before the goal
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    return log, advertised, received


def test_live_stream_carries_the_logs_bytes_and_schemas(live_run):
    log, advertised, received = live_run
    messages, schemas = _log_messages(log)
    for topic in TOPICS:
        channel = advertised[topic]
        assert (channel["encoding"], channel["schemaEncoding"]) == ("cdr", "ros2msg")
        assert channel["schema"].encode() == schemas[topic]
        assert len(received[topic]) >= 3, topic
        for stamp, payload in received[topic]:
            assert messages[topic][stamp] == payload


def test_live_poses_and_ranges_decode_to_the_logged_ones(live_run):
    log, advertised, received = live_run
    store = _typestore(list(advertised.values()))
    messages, _ = _log_messages(log)
    odom_type, scan_type = advertised["/odom"]["schemaName"], advertised["/scan"]["schemaName"]
    poses = []
    for stamp, payload in received["/odom"]:
        live = store.deserialize_cdr(payload, odom_type).pose.pose.position
        logged = store.deserialize_cdr(messages["/odom"][stamp], odom_type).pose.pose.position
        assert (live.x, live.y) == (logged.x, logged.y)
        poses.append((live.x, live.y))
    start = np.array(poses[0])
    assert np.linalg.norm(np.array(poses[-1]) - start) > 0.1  # the robot moved while streamed
    for stamp, payload in received["/scan"]:
        live = store.deserialize_cdr(payload, scan_type)
        logged = store.deserialize_cdr(messages["/scan"][stamp], scan_type)
        np.testing.assert_array_equal(live.ranges, logged.ranges)
        assert live.header.stamp.sec * 10**9 + live.header.stamp.nanosec == stamp


def test_port_in_use_is_one_line_and_exit_2(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        command = [
            sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(tmp_path / "x.mcap"),
            "--live", "--port", str(port), "--quiet",
        ]  # fmt: skip
        done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and str(port) in lines[0], done.stderr
    assert not (tmp_path / "x.mcap").exists()


def test_a_client_joining_after_the_run_gets_the_map_and_ctrl_c_ends_the_wait(tmp_path):
    log = tmp_path / "late.mcap"
    command = [
        sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(log), "--no-plot", "--quiet",
        "--set", "simulation.stop_time=0.5", "--live", "--port", "0", "--realtime", "50",
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        url = process.stderr.readline().split()[2]
        while "run ended" not in (line := process.stderr.readline()):
            assert line, "the run ended without lingering"
        assert "until Ctrl-C" in line
        latched = ("/map", "/plan")
        _, received = asyncio.run(asyncio.wait_for(_listen(url, latched, enough=1), timeout=120))
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=120) == 1
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    messages, _ = _log_messages(log, latched)
    for topic in latched:
        stamp, payload = received[topic][0]
        assert messages[topic][stamp] == payload


def test_pacer_holds_messages_until_their_time_over_r_and_slips_when_late(monkeypatch):
    """A fake clock: each message leaves at origin + t / R; a late one restarts the schedule."""
    from cosim.record import live

    clock = [100.0]
    monkeypatch.setattr(live.time, "monotonic", lambda: clock[0])
    monkeypatch.setattr(live.time, "sleep", lambda seconds: clock.__setitem__(0, clock[0] + seconds))
    pacer = live.Pacer(2.0)
    departures = []
    for t in (0.0, 0.1, 0.2, 0.2, 0.4):
        pacer.message(1, int(t * 1e9), b"")
        departures.append(clock[0])
    assert departures == pytest.approx([100.0, 100.05, 100.1, 100.1, 100.2])
    clock[0] += 1.0  # the run stalls for a second of wall time
    pacer.message(1, int(0.5e9), b"")
    assert clock[0] == pytest.approx(101.2)  # sent at once, not held
    pacer.message(1, int(0.7e9), b"")  # and the schedule goes on from there at R = 2
    assert clock[0] == pytest.approx(101.3)
