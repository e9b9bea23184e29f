"""Live mutants (issue 26): malformed WebSocket traffic at `cosim run --live` while the run goes.

One run of a shipped scenario serves its live view (`cosim run --live --port 0`, a subprocess: the
server's threads and the run must be seen from outside, as a user sees them). Hypothesis makes
the clients, derandomized; they connect one after another, each doing one hostile thing:
garbage bytes before any handshake, a connection that says nothing, HTTP without the upgrade or
with a wrong key, version or subprotocol, a handshake cut short; after a handshake made by hand,
frames the standard forbids (unmasked, reserved opcodes and bits, a length of 2**63 - 1 with a
few bytes behind it, fragmented control frames, text that is not UTF-8), JSON that is not JSON,
not an object, an unknown op, known ops with wrong types and unknown ids; binary frames of
unknown opcodes; a /goal_pose advertised and then published with truncated, empty, NaN, huge or
wrongly typed CDR, or advertised under another schema; pings in a flood; many connections left
open at once.

The public behaviour checked: a well-behaved client that connects after them still gets /odom,
and the run ends by itself at its stop time (or goal) with exit 0 or 1 and no traceback on
stderr. The counts of mutants by kind are printed.
"""

from __future__ import annotations

import asyncio
import base64
import collections
import json
import os
import signal
import struct
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
SUBPROTOCOL = "foxglove.sdk.v1"
MUTANTS = 150
CLIENT_TIMEOUT = 5.0  # [s] a client gives up waiting for the server (then closes); not a failure
RUN_TIMEOUT = 600.0  # [s] the run not ended by then is a hang

KINDS = ("garbage", "silent", "http", "half_handshake", "bad_frame", "json", "binary", "goal", "flood",
         "crowd")  # fmt: skip


def handshake(
    port: int, protocol: str | None = SUBPROTOCOL, version: str = "13", key: str | None = None
) -> bytes:
    key = key if key is not None else base64.b64encode(os.urandom(16)).decode()
    lines = [
        "GET / HTTP/1.1",
        f"Host: 127.0.0.1:{port}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        f"Sec-WebSocket-Version: {version}",
    ]
    if protocol is not None:
        lines.append(f"Sec-WebSocket-Protocol: {protocol}")
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def frame(opcode: int, payload: bytes, fin: bool = True, masked: bool = True, rsv: int = 0,
          length: int | None = None) -> bytes:  # fmt: skip
    """One WebSocket frame as a client sends it (RFC 6455 section 5.2), or bent: unmasked, RSV
    bits set, a declared length other than the payload's."""
    length = len(payload) if length is None else length
    head = bytes([(0x80 if fin else 0) | (rsv << 4) | opcode])
    mask_bit = 0x80 if masked else 0
    if length < 126:
        head += bytes([mask_bit | length])
    elif length < 2**16:
        head += bytes([mask_bit | 126]) + struct.pack(">H", length)
    else:
        head += bytes([mask_bit | 127]) + struct.pack(">Q", length)
    if not masked:
        return head + payload
    if len(payload) > 4096:  # a zero mask is a mask too, and leaves a large payload as it is
        return head + bytes(4) + payload
    mask = os.urandom(4)
    return head + mask + bytes(byte ^ mask[i % 4] for i, byte in enumerate(payload))


def pose_cdr(x: float, y: float, frame_id: bytes = b"map") -> bytes:
    """A geometry_msgs/msg/PoseStamped in CDR (little endian): stamp, frame_id, position, orientation."""
    text = frame_id + b"\0"
    body = struct.pack("<iI", 0, 0) + struct.pack("<I", len(text)) + text
    body += b"\0" * (-len(body) % 8)
    body += struct.pack("<7d", x, y, 0.0, 0.0, 0.0, 0.0, 1.0)
    return b"\x00\x01\x00\x00" + body


GOAL_CHANNEL = {"id": 7, "topic": "/goal_pose", "encoding": "cdr", "schema": "",
                "schemaName": "geometry_msgs/msg/PoseStamped", "schemaEncoding": "ros2msg"}  # fmt: skip
JSON_MESSAGES = [
    "not json", "{", "[]", "1", "null", '"subscribe"', "{}", '{"op": 1}', '{"op": "nosuchop"}',
    '{"op": "subscribe"}', '{"op": "subscribe", "subscriptions": "x"}',
    '{"op": "subscribe", "subscriptions": [{"id": -1, "channelId": 18446744073709551615}]}',
    '{"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 1}, {"id": 1, "channelId": 1}]}',
    '{"op": "unsubscribe", "subscriptionIds": [99, "x"]}',
    '{"op": "advertise", "channels": [{"id": 1}]}',
    '{"op": "advertise", "channels": [{"id": 1, "topic": "/goal_pose", "encoding": "json", '
    '"schemaName": "x"}]}',
    '{"op": "unadvertise", "channelIds": [12345]}',
    '{"op": "getParameters", "parameterNames": ["a"]}', '{"op": "setParameters", "parameters": [{}]}',
    '{"op": "subscribeParameterUpdates", "parameterNames": []}', '{"op": "subscribeConnectionGraph"}',
    '{"op": "fetchAsset", "uri": "file:///etc/passwd", "requestId": 1}',
    '{"op": "callService", "serviceId": 1}', '{"op": "subscribe", "subscriptions": [' + "{}," * 5000 + "{}]}",
    json.dumps({"op": "advertise", "channels": [GOAL_CHANNEL] * 1000}),
]  # fmt: skip


@st.composite
def live_mutant(draw) -> dict:
    kind = draw(st.sampled_from(KINDS))
    mutant = {"kind": kind, "variant": draw(st.integers(0, 99)), "bytes": draw(st.binary(max_size=2048))}
    if kind == "json":
        mutant["text"] = draw(st.one_of(st.sampled_from(JSON_MESSAGES), st.text(max_size=200)))
    if kind == "goal":
        mutant["numbers"] = draw(st.tuples(st.floats(), st.floats()))
    return mutant


async def _read_response(reader: asyncio.StreamReader) -> bytes:
    try:
        return await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), CLIENT_TIMEOUT)
    except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError, ConnectionError):
        return b""


async def _drain(reader: asyncio.StreamReader, seconds: float = 0.05) -> None:
    """Read whatever the server says for a moment (so it is not blocked writing to us)."""
    try:
        await asyncio.wait_for(reader.read(1 << 16), seconds)
    except (TimeoutError, ConnectionError):
        pass


async def run_mutant(port: int, mutant: dict) -> str:
    """Do one hostile thing at the server; returns what the server did (for the counts)."""
    kind, variant, data = mutant["kind"], mutant["variant"], mutant["bytes"]
    if kind == "crowd":  # many connections at once, each left after its handshake or before it
        streams = [await asyncio.open_connection("127.0.0.1", port) for _ in range(20)]
        for index, (_, writer) in enumerate(streams):
            if index % 2:
                writer.write(handshake(port))
        await asyncio.sleep(0.1)
        for _, writer in streams:
            writer.close()
        return "crowd"
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        if kind == "garbage":
            writer.write(data or b"\xff")
            await writer.drain()
            await _drain(reader)
            return "garbage"
        if kind == "silent":
            await asyncio.sleep(0.2)
            return "silent"
        if kind == "http":
            requests = [
                f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode(),
                handshake(port, key="not base64"),
                handshake(port, version="8"),
                handshake(port, protocol="nosuch.protocol"),
                handshake(port, protocol=None),
                b"POST / HTTP/1.1\r\nContent-Length: 99999999999\r\n\r\n" + data,
                b"GET /" + b"x" * 100_000 + b" HTTP/1.1\r\n\r\n",
                b"GET / HTTP/1.1\r\n" + b"X-Long: " + b"y" * 200_000 + b"\r\n\r\n",
            ]
            writer.write(requests[variant % len(requests)])
            await writer.drain()
            response = await _read_response(reader)
            status = response.split(b" ", 2)[1].decode(errors="replace") if b" " in response else "closed"
            return f"http {status}"
        if kind == "half_handshake":
            request = handshake(port)
            writer.write(request[: len(request) * (variant + 1) // 101])
            await writer.drain()
            await asyncio.sleep(0.05)
            return "half handshake"
        writer.write(handshake(port))
        await writer.drain()
        response = await _read_response(reader)
        if b" 101 " not in response:
            return f"refused handshake {response[:20]!r}"
        if kind == "bad_frame":
            frames = [
                frame(1, b'{"op": "subscribe"}', masked=False),  # clients must mask
                frame(3, data),  # a reserved data opcode
                frame(0xB, data),  # a reserved control opcode
                frame(1, b"{}", rsv=7),
                frame(2, data[:8], length=2**63 - 1),  # a frame that never ends
                frame(1, data[:8], length=2**40),
                frame(9, b"x" * 200),  # a ping longer than a control frame may be
                frame(9, b"p", fin=False),  # a fragmented control frame
                frame(0, b"continuation of nothing"),
                frame(1, b"\xff\xfe not utf-8"),
                frame(1, b"{", fin=False) + frame(2, b"}"),  # a new message inside a fragmented one
                frame(8, b"\x03"),  # a close frame with a one-byte body
                frame(8, struct.pack(">H", 999) + b"odd code"),
                frame(1, b"x" * (8 << 20)),  # 8 MB of text
                data,  # bytes that are no frame
            ]
            writer.write(frames[variant % len(frames)])
        elif kind == "json":
            writer.write(frame(1, mutant["text"].encode()))
        elif kind == "binary":
            opcode = bytes([variant % 8 if variant % 3 else 0xFF])
            writer.write(frame(2, opcode + data))
        elif kind == "goal":
            channel = dict(GOAL_CHANNEL)
            if variant % 5 == 0:
                channel["schemaName"] = "std_msgs/msg/String"
            if variant % 7 == 0:
                channel["encoding"] = "json"
            writer.write(frame(1, json.dumps({"op": "advertise", "channels": [channel]}).encode()))
            x, y = mutant["numbers"]
            payloads = [
                b"", pose_cdr(x, y)[:11], pose_cdr(x, y), pose_cdr(x, y, b"odom"),
                pose_cdr(x, y, b"f" * 100_000), b"\x00\x01\x00\x00" + struct.pack("<iII", 0, 0, 2**31) + data,
                b"\x01\x01\x00\x00" + data, pose_cdr(float("nan"), 1.0), pose_cdr(1e300, -1e300),
            ]  # fmt: skip
            payload = payloads[variant % len(payloads)]
            # Message data on the client's channel (opcode 1), or on a channel it never advertised.
            writer.write(frame(2, struct.pack("<BI", 1, 7 if variant % 4 else 8) + payload))
        elif kind == "flood":
            writer.write(b"".join(frame(9, b"p") for _ in range(500)))
        await writer.drain()
        await _drain(reader, 0.1)
        return kind
    except ConnectionError:
        return f"{kind}: connection closed by the server"
    finally:
        writer.close()


async def _map_after_the_mutants(url: str) -> int:
    """A well-behaved client: subscribe to the latched /map; returns its messages (1 expected)."""
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as client:
        async for message in client:
            if isinstance(message, str):
                payload = json.loads(message)
                if payload.get("op") == "advertise":
                    found = [channel for channel in payload["channels"] if channel["topic"] == "/map"]
                    if found:
                        subscription = {"id": 1, "channelId": found[0]["id"]}
                        await client.send(json.dumps({"op": "subscribe", "subscriptions": [subscription]}))
            elif message[0] == 1:
                return 1
    return 0


async def _attack(port: int, mutants: list[dict]) -> collections.Counter:
    outcomes: collections.Counter = collections.Counter()
    for mutant in mutants:
        try:
            outcomes[await asyncio.wait_for(run_mutant(port, mutant), 4 * CLIENT_TIMEOUT)] += 1
        except TimeoutError:
            outcomes[f"{mutant['kind']}: client gave up"] += 1
    return outcomes


def make_mutants() -> list[dict]:
    mutants: list[dict] = []

    @settings(
        max_examples=MUTANTS,
        derandomize=True,
        deadline=None,
        database=None,
        suppress_health_check=list(HealthCheck),
        phases=[Phase.explicit, Phase.generate],
    )
    @given(mutant=live_mutant())
    def collect(mutant):
        mutants.append(mutant)

    collect()
    return mutants


class _Lines:
    """The run's stderr, read as it comes (the server logs every dropped client there: a pipe
    left unread would fill and stall it), with a wait for a line that starts with `prefix`."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream) -> None:
        for line in stream:
            with self._changed:
                self.lines.append(line)
                self._changed.notify_all()
        with self._changed:
            self.lines.append("")  # the end
            self._changed.notify_all()

    def wait_for(self, prefix: str, timeout: float) -> str | None:
        with self._changed:
            self._changed.wait_for(lambda: any(line.startswith(prefix) or line == "" for line in self.lines),
                                   timeout)  # fmt: skip
            return next((line for line in self.lines if line.startswith(prefix)), None)

    def text(self) -> str:
        self._thread.join(timeout=RUN_TIMEOUT)
        return "".join(self.lines)


@pytest.mark.slow
def test_live_view_survives_malformed_clients(tmp_path):
    """The mutants come while the run goes (30 s simulated at 6 x the wall clock) and after it,
    while the view is kept until Ctrl-C; the run must end by itself, then Ctrl-C ends the wait."""
    mutants = make_mutants()
    log = tmp_path / "live.mcap"
    command = [
        sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(log), "--no-plot", "--quiet",
        "--set", "simulation.stop_time=30", "--live", "--port", "0", "--realtime", "6",
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True, errors="replace")
    try:
        lines = _Lines(process.stderr)
        line = lines.wait_for("live view: ws://", RUN_TIMEOUT)
        assert line is not None, lines.text()
        url = line.split()[2]
        outcomes = asyncio.run(_attack(int(url.rsplit(":", 1)[1]), mutants))
        ended = lines.wait_for("live view: run ended", RUN_TIMEOUT)  # a hung run fails here
        assert ended is not None and process.poll() is None, lines.text()[-3000:]
        received = asyncio.run(asyncio.wait_for(_map_after_the_mutants(url), 60))
        process.send_signal(signal.SIGINT)
        code = process.wait(timeout=RUN_TIMEOUT)
        rest = lines.text()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    kinds = collections.Counter(mutant["kind"] for mutant in mutants)
    print(f"\nlive mutants: {len(mutants)}; by kind: {dict(sorted(kinds.items()))}")
    print(f"live mutants: what the server did: {dict(sorted(outcomes.items()))}; exit {code} after Ctrl-C")
    assert "Traceback" not in rest and "panicked" not in rest, rest[-4000:]
    assert code == 1, rest[-3000:]  # Ctrl-C while the view is kept, as documented
    assert received == 1  # the server still serves a client that follows the protocol
    from cosim.logs import open_log

    assert open_log(log).outcome["reason"] in ("stop_time", "goal_reached")


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q", "-s"]))
