"""The live view's front (`cosim.record.live_front`): it serves and never holds.

In-process tests start a `FoxgloveLive` on 127.0.0.1 with port 0 and one channel of their own
and talk to it with raw sockets (RFC 6455 frames built here) or the `websockets` client, offering
only the classic `foxglove.websocket.v1` subprotocol. The timeouts are shortened for the tests
(module constants). Run tests start `cosim run --live` and stop it by its PID.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")

from cosim.record import live_front  # noqa: E402
from cosim.record.live import FoxgloveLive  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
CLASSIC = "foxglove.websocket.v1"


@pytest.fixture
def server(monkeypatch):
    monkeypatch.setattr(live_front, "HANDSHAKE_TIMEOUT", 0.5)
    monkeypatch.setattr(live_front, "PING_INTERVAL", 0.2)
    monkeypatch.setattr(live_front, "IDLE_TIMEOUT", 0.8)
    live = FoxgloveLive(0, 1e4)
    live.channel(1, "/odom", "cdr", ("test/msg/Count", "ros2msg", b"uint32 count"), {})
    yield live
    live.stop()


def _feed(live: FoxgloveLive, stop: threading.Event) -> threading.Thread:
    """Messages on /odom (CDR uint32: the count) every 10 ms until `stop`."""

    def run() -> None:
        count = 0
        while not stop.is_set():
            live.message(1, count * 10_000_000, b"\x00\x01\x00\x00" + struct.pack("<I", count))
            count += 1
            time.sleep(0.01)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def _handshake(port: int, protocol: str = CLASSIC, path: str = "/") -> tuple[socket.socket, bytes]:
    """A raw WebSocket opening handshake; the socket and the server's answer head."""
    connection = socket.create_connection(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    connection.sendall(
        f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
        f"Sec-WebSocket-Protocol: {protocol}\r\n\r\n".encode()
    )
    head = b""
    while b"\r\n\r\n" not in head:
        chunk = connection.recv(4096)
        if not chunk:
            break
        head += chunk
    return connection, head


def _read_until_closed(connection: socket.socket) -> bytes:
    data = b""
    connection.settimeout(30)
    while chunk := connection.recv(65536):
        data += chunk
    return data


def test_a_connection_without_handshake_is_closed_and_the_server_stops(server):
    silent = socket.create_connection(("127.0.0.1", server.port))
    assert _read_until_closed(silent) == b""  # closed by the front after HANDSHAKE_TIMEOUT
    held = socket.create_connection(("127.0.0.1", server.port))  # and one still open at stop
    server.stop()  # returns: the SDK never saw either (it used to wait for such a client)
    assert _read_until_closed(held) == b""


def test_the_classic_subprotocol_is_answered_and_a_silent_client_is_pinged_then_closed(server):
    connection, head = _handshake(server.port)
    assert head.startswith(b"HTTP/1.1 101"), head
    assert f"sec-websocket-protocol: {CLASSIC}".encode() in head.lower()
    rest = head.split(b"\r\n\r\n", 1)[1] + _read_until_closed(connection)  # it answers nothing
    assert b'"op":"serverInfo"' in rest
    assert bytes((0x89, len(live_front.PING_TAG))) + live_front.PING_TAG in rest  # a ping frame


def test_no_supported_subprotocol_is_refused_with_400(server):
    connection, head = _handshake(server.port, protocol="chat")
    assert head.startswith(b"HTTP/1.1 400"), head
    connection.close()


async def _subscribe(url: str, subscriptions, count: int) -> tuple[list[str], list[int]]:
    """Connect offering only the classic subprotocol, send `subscriptions(channel_id)`, collect
    `count` counts from /odom; the status messages and the counts."""
    statuses, counts = [], []
    async with websockets.connect(url, subprotocols=[CLASSIC], max_size=None) as client:
        assert client.subprotocol == CLASSIC
        async for frame in client:
            if isinstance(frame, str):
                message = json.loads(frame)
                if message["op"] == "advertise":
                    for item in subscriptions(message["channels"][0]["id"]):
                        await client.send(json.dumps(item))
                elif message["op"] == "status":
                    statuses.append(message["message"])
            elif frame[0] == 1:
                counts.append(struct.unpack_from("<I", frame, 13 + 4)[0])
                if len(counts) == count:
                    return statuses, counts
    return statuses, counts


def test_a_flood_of_unknown_subscriptions_is_one_warning_and_the_stream_goes_on(server, capfd):
    stop = threading.Event()
    feed = _feed(server, stop)

    def subscriptions(channel_id):
        unknown = [{"id": i, "channelId": 10_000 + i} for i in range(20_000)]  # 0.7 MB, under the limit
        return [{"op": "subscribe", "subscriptions": unknown}, {"op": "not json"}, "not an object",
                {"op": "subscribe", "subscriptions": [{"id": 100_001, "channelId": channel_id}]}]  # fmt: skip

    try:
        statuses, counts = asyncio.run(asyncio.wait_for(_subscribe(server.url, subscriptions, 5), 60))
    finally:
        stop.set()
        feed.join()
    assert counts == sorted(counts) and len(counts) == 5  # the known one was subscribed
    assert not any("Unknown channel" in status for status in statuses)
    err = capfd.readouterr().err
    lines = err.strip().splitlines()
    assert sum("subscriptions to unknown channels" in line for line in lines) == 1, err
    assert sum("not a JSON object" in line for line in lines) == 1, err
    assert len(lines) <= 3, err


@pytest.mark.slow
def test_a_message_over_the_size_limit_closes_that_client_with_one_line(server, capfd):
    async def flood() -> int:
        async with websockets.connect(server.url, subprotocols=[CLASSIC]) as client:
            unknown = [{"id": i, "channelId": 10_000 + i} for i in range(100_000)]  # 4.5 MB
            await client.send(json.dumps({"op": "subscribe", "subscriptions": unknown}))
            with pytest.raises(websockets.ConnectionClosed):
                while True:
                    await client.recv()
            return client.close_code

    assert asyncio.run(asyncio.wait_for(flood(), 60)) == 1009
    lines = capfd.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "over 1048576 bytes" in lines[0], lines


def test_a_token_is_required_when_set(monkeypatch):
    live = FoxgloveLive(0, 1e4, token="s3cret-token")
    try:

        async def enter(url: str) -> str:
            async with websockets.connect(url, subprotocols=[CLASSIC]) as client:
                return json.loads(await client.recv())["op"]

        bare = live.url.split("/?")[0]
        for url in (bare, bare + "/?token=wrong"):
            with pytest.raises(websockets.InvalidStatus) as refused:
                asyncio.run(enter(url))
            assert refused.value.response.status_code == 401
        assert live.url.endswith("/?token=s3cret-token")
        assert asyncio.run(enter(live.url)) == "serverInfo"
    finally:
        live.stop()


def test_frame_boundaries_over_chunks():
    frames = [live_front.frame(2, bytes(n), False) for n in (3, 200, 70_000)]
    stream = b"".join(frames)
    for cut in range(0, len(stream), 997):
        remaining, partial = live_front.frame_boundary(stream[:cut], 0)
        rest_remaining, rest_partial = live_front.frame_boundary(partial + stream[cut:], remaining)
        assert (rest_remaining, rest_partial) == (0, b"")
        ends = {len(frames[0]), len(frames[0]) + len(frames[1]), 0}
        assert (remaining == 0 and not partial) == (cut in ends)


def test_loopback_hosts():
    from cosim.cli.run import _is_loopback

    assert _is_loopback("127.0.0.1") and _is_loopback("localhost") and _is_loopback("::1")
    assert not _is_loopback("0.0.0.0")


def _start(tmp_path: Path, *extra: str) -> tuple[subprocess.Popen, str]:
    command = [
        sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(tmp_path / "run.mcap"),
        "--no-plot", "--quiet", "--live", "--port", "0", *extra,
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    return process, process.stderr.readline().split()[2]


def _port(url: str) -> int:
    return int(url.rsplit(":", 1)[1].split("/")[0])


@pytest.mark.slow
def test_sigterm_ends_the_wait_after_the_run_though_a_client_never_handshakes(tmp_path):
    process, url = _start(tmp_path, "--set", "simulation.stop_time=0.5", "--realtime", "50")
    try:
        held = socket.create_connection(("127.0.0.1", _port(url)))
        while "run ended" not in (line := process.stderr.readline()):
            assert line, "the run ended without lingering"
        assert "until Ctrl-C" in line
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=120) == 1
        assert _read_until_closed(held) == b""
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def _service_call(service_id: int, call_id: int, request: dict) -> bytes:
    return struct.pack("<BIII", 2, service_id, call_id, 4) + b"json" + json.dumps(request).encode()


async def _control(url: str) -> dict:
    """Offering only the classic subprotocol: subscribe /odom; once it flows pause, step, speed
    (a refused factor, then 8), resume, a goal. The answers, and the /odom times received while
    paused (after the pause's answer, before the step was asked) and after the step (after its
    answer, before the next call)."""
    calls = [
        ("pause", {}), ("step", {"steps": 3}), ("speed", {"factor": -1.0}), ("speed", {"factor": 8}),
        ("resume", {}), ("goal", {"x": 42.0, "y": 30.0}),
    ]  # fmt: skip
    services: dict[str, int] = {}
    answers: list[dict] = []
    odom: list[tuple[int, int, int]] = []  # (time [ns], answers received, calls sent) on arrival
    sent = [0]
    flowing, answered = asyncio.Event(), asyncio.Event()

    async with websockets.connect(url, subprotocols=[CLASSIC], max_size=None) as client:
        subprotocol = client.subprotocol

        async def read() -> None:
            try:
                async for frame in client:
                    if isinstance(frame, str):
                        message = json.loads(frame)
                        if message["op"] == "advertise":
                            ids = [c["id"] for c in message["channels"] if c["topic"] == "/odom"]
                            if ids:
                                subscription = [{"id": 1, "channelId": ids[0]}]
                                await client.send(
                                    json.dumps({"op": "subscribe", "subscriptions": subscription})
                                )
                        elif message["op"] == "advertiseServices":
                            services.update({s["name"]: s["id"] for s in message["services"]})
                    elif frame[0] == 1:
                        odom.append((struct.unpack_from("<Q", frame, 5)[0], len(answers), sent[0]))
                        if len(odom) >= 10 and services:
                            flowing.set()
                    elif frame[0] == 3:
                        _, _, length = struct.unpack_from("<III", frame, 1)
                        answers.append(json.loads(frame[13 + length :]))
                        answered.set()
            except websockets.ConnectionClosed:
                pass

        reader = asyncio.ensure_future(read())
        await flowing.wait()
        for index, (name, request) in enumerate(calls):
            answered.clear()
            sent[0] += 1
            await client.send(_service_call(services[f"/navcosim/{name}"], index, request))
            await answered.wait()
            if name in ("pause", "step"):
                await asyncio.sleep(1.0)  # what comes meanwhile: held by the pause, or the step's
        await reader
    paused = [t for t, received, calls_sent in odom if received == 1 and calls_sent == 1]
    stepped = [t for t, received, calls_sent in odom if received == 2 and calls_sent == 2]
    return {"subprotocol": subprotocol, "answers": answers, "while_paused": paused, "after_step": stepped}


@pytest.mark.slow
def test_pause_step_speed_resume_and_goal_from_a_classic_client_are_acknowledged_in_the_log(tmp_path):
    process, url = _start(tmp_path, "--set", "simulation.stop_time=4", "--realtime", "2", "--linger", "0")
    try:
        seen = asyncio.run(asyncio.wait_for(_control(url), 300))
        rest = process.stderr.read()
        assert process.wait(timeout=120) == 1, rest  # the stop time comes before the new goal
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert seen["subprotocol"] == CLASSIC
    assert [answer["ok"] for answer in seen["answers"]] == [True, True, False, True, True, True], seen
    paused_at = round(float(seen["answers"][0]["message"].split("t = ")[1].split()[0]) * 1e9)
    step_to = round(float(seen["answers"][1]["message"].split("to t = ")[1].split()[0]) * 1e9)
    assert all(stamp <= paused_at for stamp in seen["while_paused"])  # paused: nothing newer came
    assert step_to == paused_at + 3 * 10_000_000  # 3 macro steps of 0.01 s
    assert seen["after_step"] and all(paused_at < stamp <= step_to for stamp in seen["after_step"])
    for text in ("paused at", "step from", "real-time factor 8", "resumed at", "new goal, replanned"):
        assert text in rest, rest

    from mcap.reader import make_reader

    with open(tmp_path / "run.mcap", "rb") as handle:
        acks = [m.metadata for m in make_reader(handle).iter_metadata() if m.name.startswith("live_control/")]
    assert [(ack["command"], ack["done"]) for ack in acks] == [
        ("pause", "true"), ("step", "true"), ("speed", "false"), ("speed", "true"), ("resume", "true"),
        ("goal", "true"),
    ]  # fmt: skip
    assert float(acks[0]["t"]) == paused_at / 1e9
    assert "new goal" in acks[-1]["result"] and "(42.00, 30.00)" in acks[-1]["result"]
