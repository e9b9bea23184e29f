"""The live view's public socket: a WebSocket front of the foxglove-sdk server.

The foxglove-sdk server (`cosim.record.live.FoxgloveLive`) listens on an ephemeral port of
127.0.0.1; clients connect here, at `--host`:`--port`. The front reads each client's opening
handshake itself and passes it on, so that the server behind it serves and never holds:

- A client that does not finish its handshake within `HANDSHAKE_TIMEOUT` is closed; the SDK
  never sees it (an unfinished handshake used to keep the SDK's `stop()`, and the process, alive).
- Subprotocols: `foxglove.sdk.v1` (what the SDK speaks) and the classic `foxglove.websocket.v1`
  (the @foxglove/ws-protocol client's default), which Foxglove maintains as the same protocol
  under its old name. A client offering only the classic name gets it in the answer; the SDK is
  asked for `foxglove.sdk.v1`. No extension is negotiated (the front reads the client's frames).
- `token`: a client must give it as `?token=...` in the URL (Foxglove's *Open connection* keeps
  the query) or as `Authorization: Bearer ...`; otherwise HTTP 401.
- At most `MAX_CLIENTS` connections at a time (HTTP 503 beyond).
- Keep-alive: a ping every `PING_INTERVAL` to each client; one that sends nothing (not even the
  pong) for `IDLE_TIMEOUT`, or does not read what it is sent for as long, is closed.
- Per client: a message larger than `MAX_MESSAGE` closes it (1009); beyond `MESSAGE_RATE`
  messages per second (a burst of `MESSAGE_BURST`), messages are dropped; at most
  `MAX_SUBSCRIPTIONS` subscriptions, and only to channels the server has; a text message that is
  not a JSON object is dropped. Each limit is one warning line per client, however many items.
- `close()` ends every connection, then the front; the SDK server can then stop at once.

The front runs an asyncio loop in one daemon thread. It parses the client's frames (masked,
RFC 6455 section 5) in full and only the boundaries of the server's frames, to put its pings
between them.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import os
import threading
import time
from urllib.parse import parse_qs, urlsplit

from cosim.errors import say

HANDSHAKE_TIMEOUT = 5.0  # [s] from the TCP connection to the end of the client's request head
PING_INTERVAL = 10.0  # [s]
IDLE_TIMEOUT = 30.0  # [s] without a byte from the client, or without it reading what it is sent
MAX_HEAD = 16 * 1024  # [bytes] of a request head
MAX_CLIENTS = 32
MAX_MESSAGE = 1 << 20  # [bytes] a client's message (a PoseStamped is ~100; a schema a few kB)
MESSAGE_RATE = 200.0  # [1/s] a client's messages
MESSAGE_BURST = 1000
MAX_SUBSCRIPTIONS = 1024  # per client (a run has tens of channels)
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")  # the SDK's first, then the classic
GOING_AWAY = (1001).to_bytes(2, "big") + b"navcosim: closed"
CLOSE_GRACE = 0.2  # [s] for the close frames to go out before the connections are cut
PING_TAG = b"navcosim"  # the front's pings; their pongs are not passed on
_CLOSE, _PING, _PONG = 0x8, 0x9, 0xA
_DROPPED_REQUEST_HEADERS = {"sec-websocket-protocol", "sec-websocket-extensions", "authorization"}


def unmask(data: bytes, key: bytes) -> bytes:
    """`data` XOR the 4-byte `key` repeated (masking is its own inverse)."""
    n = len(data)
    if n == 0:
        return b""
    pad = (key * (n // 4 + 1))[:n]
    return (int.from_bytes(data, "little") ^ int.from_bytes(pad, "little")).to_bytes(n, "little")


def frame(opcode: int, payload: bytes, mask: bool) -> bytes:
    """One final WebSocket frame; `mask` for the client-to-server direction."""
    n = len(payload)
    if n < 126:
        head = bytes((0x80 | opcode, (0x80 if mask else 0) | n))
    elif n < 1 << 16:
        head = bytes((0x80 | opcode, (0x80 if mask else 0) | 126)) + n.to_bytes(2, "big")
    else:
        head = bytes((0x80 | opcode, (0x80 if mask else 0) | 127)) + n.to_bytes(8, "big")
    if not mask:
        return head + payload
    key = os.urandom(4)
    return head + key + unmask(payload, key)


def frame_boundary(buffer: bytes, remaining: int) -> tuple[int, bytes]:
    """Walk server frames (headers only) over `buffer`, whose first `remaining` bytes end a frame
    begun before. Returns (the bytes of the last frame still to come, an incomplete header at the
    end of `buffer`); (0, b"") is a boundary."""
    i, n = remaining, len(buffer)
    while i < n:
        if n - i < 2:
            return 0, buffer[i:]
        second = buffer[i + 1]
        size = second & 0x7F
        head = 2 + {126: 2, 127: 8}.get(size, 0) + (4 if second & 0x80 else 0)
        if n - i < head:
            return 0, buffer[i:]
        if size == 126:
            size = int.from_bytes(buffer[i + 2 : i + 4], "big")
        elif size == 127:
            size = int.from_bytes(buffer[i + 2 : i + 10], "big")
        i += head + size
    return i - n, b""


def parse_head(head: bytes) -> tuple[str, list[tuple[str, str]]] | None:
    """(start line, [(lower-case name, value)]) of an HTTP head, or None if it is not one."""
    try:
        lines = head.decode("latin-1").split("\r\n")
    except UnicodeDecodeError:
        return None
    headers = []
    for line in lines[1:]:
        if not line:
            continue
        name, colon, value = line.partition(":")
        if not colon or not name.strip():
            return None
        headers.append((name.strip().lower(), value.strip()))
    return lines[0], headers


def offered_subprotocols(headers: list[tuple[str, str]]) -> list[str]:
    return [
        item.strip()
        for name, value in headers
        if name == "sec-websocket-protocol"
        for item in value.split(",")
        if item.strip()
    ]


async def _discard(client) -> None:
    while await client.reader.read(1 << 16):
        client.heard = time.monotonic()


class Warnings:
    """One stderr line per (client, limit); refused connections: the first of each reason, and
    how many more at the end."""

    def __init__(self) -> None:
        self.refused: dict[str, int] = {}

    def once(self, seen: set, kind: str, text: str) -> None:
        if kind not in seen:
            seen.add(kind)
            say(f"cosim: warning: live view: {text}")

    def refusal(self, reason: str, text: str) -> None:
        count = self.refused.get(reason, 0)
        self.refused[reason] = count + 1
        if count == 0:
            say(f"cosim: warning: live view: {text}")

    def summary(self) -> None:
        for reason, count in self.refused.items():
            if count > 1:
                say(f"cosim: warning: live view: {count - 1} more connection(s) refused ({reason})")


class _Client:
    def __init__(self, name: str, reader, writer) -> None:
        self.name = name
        self.reader, self.writer = reader, writer
        self.upstream = None  # (reader, writer) to the SDK server
        self.warned: set[str] = set()
        self.subscriptions: set[int] = set()
        now = time.monotonic()
        self.heard = now  # the last byte from the client
        self.pinged = now
        self.tokens, self.refilled = float(MESSAGE_BURST), now
        self.at_boundary = True  # between two of the server's frames
        self.upstream_closing = False
        self.closing = False  # the front sent its close frame: no more idle checks

    def allow(self, now: float) -> bool:
        """Token bucket: MESSAGE_RATE per second, MESSAGE_BURST at most."""
        self.tokens = min(MESSAGE_BURST, self.tokens + (now - self.refilled) * MESSAGE_RATE)
        self.refilled = now
        if self.tokens < 1:
            return False
        self.tokens -= 1
        return True

    def going_away(self) -> None:
        """Close frames (1001) to both ends, where a frame may begin; `close` follows."""
        self._close_upstream()
        if self.upstream is not None and self.at_boundary:
            self.writer.write(frame(_CLOSE, GOING_AWAY, False))

    def _close_upstream(self) -> None:
        # The front writes whole frames to the server: a close frame may always go next.
        if self.upstream is not None and not self.upstream_closing:
            self.upstream_closing = True
            self.upstream[1].write(frame(_CLOSE, GOING_AWAY, True))

    def close(self) -> None:
        """Cut the client; the server gets a close frame first (it always reads)."""
        self.writer.transport.abort()
        if self.upstream is not None:
            self._close_upstream()
            self.upstream[1].close()


class Front:
    """Serve `host`:`port` (0: any free port), passing clients on to 127.0.0.1:`upstream`.
    `known(channel_id)`: whether the SDK server has that channel. Raises OSError if it cannot
    listen."""

    def __init__(self, host: str, port: int, upstream: int, known, token: str | None = None) -> None:
        self.upstream = upstream
        self.known = known
        self.token = token
        self.warnings = Warnings()
        self.clients: set[_Client] = set()
        self.closing = False
        self.loop = asyncio.new_event_loop()
        try:
            self.server = self.loop.run_until_complete(
                asyncio.start_server(self._serve, host, port, limit=MAX_HEAD)
            )
        except BaseException:
            self.loop.close()
            raise
        self.port = self.server.sockets[0].getsockname()[1]
        self._thread = threading.Thread(target=self.loop.run_forever, name="navcosim-live-front", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """End every connection and stop listening; returns when done (a second call: no-op)."""
        if self.loop.is_closed():
            return

        async def shut() -> None:
            self.closing = True  # a connection accepted from now on is cut at once
            # Stop accepting but close the listening socket only at the end: a connection accepted
            # after Server.close() would be left open by asyncio (3.11: its transport is refused).
            for listening in self.server.sockets:
                self.loop.remove_reader(listening.fileno())
            clients = list(self.clients)
            for client in clients:
                client.going_away()
            if clients:
                await asyncio.sleep(CLOSE_GRACE)
            # Until every connection's task has ended (one accepted just before close() may only
            # now get its task), cut what is open.
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                for client in list(self.clients):
                    client.close()
                others = [task for task in asyncio.all_tasks() if task is not asyncio.current_task()]
                if not others:
                    break
                await asyncio.wait(others, timeout=0.05)
            for _ in range(2):  # the sockets close in the callbacks the aborts scheduled
                await asyncio.sleep(0)
            self.server.close()  # connections still queued in the kernel are reset

        try:
            asyncio.run_coroutine_threadsafe(shut(), self.loop).result(timeout=5)
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self._thread.join(timeout=5)
            if not self._thread.is_alive():
                self.loop.close()
        self.warnings.summary()

    # --- one connection ------------------------------------------------------------------

    async def _serve(self, reader, writer) -> None:
        peer = writer.get_extra_info("peername") or ("?", 0)
        client = _Client(f"{peer[0]}:{peer[1]}", reader, writer)
        if self.closing:
            writer.transport.abort()
            return
        if len(self.clients) >= MAX_CLIENTS:
            self.warnings.refusal("too many clients", f"{client.name} refused: {MAX_CLIENTS} clients already")
            await self._answer(writer, 503, "Service Unavailable")
            return
        self.clients.add(client)
        try:
            if await self._handshake(client):
                await self._relay(client)
        except (ConnectionError, asyncio.IncompleteReadError, OSError):
            pass
        finally:
            self.clients.discard(client)
            client.close()

    async def _answer(self, writer, status: int, reason: str, text: str = "") -> None:
        body = (text or reason).encode() + b"\n"
        writer.write(
            f"HTTP/1.1 {status} {reason}\r\nContent-Type: text/plain\r\nContent-Length: {len(body)}\r\n"
            f"Connection: close\r\n\r\n".encode()
            + body
        )
        try:
            await asyncio.wait_for(writer.drain(), HANDSHAKE_TIMEOUT)
        except (TimeoutError, ConnectionError):
            pass
        writer.transport.abort()

    async def _handshake(self, client: _Client) -> bool:
        """Read the client's request, pass it on, pass the answer back: whether it upgraded."""
        writer = client.writer
        try:
            head = await asyncio.wait_for(client.reader.readuntil(b"\r\n\r\n"), HANDSHAKE_TIMEOUT)
        except TimeoutError:
            self.warnings.refusal(
                "no handshake", f"{client.name} closed: no WebSocket handshake within {HANDSHAKE_TIMEOUT:g} s"
            )
            return False
        except (asyncio.LimitOverrunError, asyncio.IncompleteReadError, ValueError):
            if self.closing:
                return False
            self.warnings.refusal("bad request", f"{client.name} refused: not an HTTP request")
            await self._answer(writer, 400, "Bad Request")
            return False
        parsed = parse_head(head)
        start = parsed[0].split(" ") if parsed else []
        headers = parsed[1] if parsed else []
        fields = dict(headers)
        if len(start) != 3 or start[0] != "GET" or fields.get("upgrade", "").lower() != "websocket":
            self.warnings.refusal("bad request", f"{client.name} refused: not a WebSocket handshake")
            await self._answer(writer, 400, "Bad Request", "a WebSocket (Foxglove) server")
            return False
        if self.token is not None and not self._authorised(start[1], fields):
            self.warnings.refusal("no token", f"{client.name} refused: no or a wrong token")
            await self._answer(writer, 401, "Unauthorized", "this server needs ?token=...")
            return False
        offered = offered_subprotocols(headers)
        chosen = next((name for name in SUBPROTOCOLS if name in offered), None)
        if chosen is None:
            self.warnings.refusal(
                "no subprotocol", f"{client.name} refused: offers none of {', '.join(SUBPROTOCOLS)}"
            )
            await self._answer(writer, 400, "Bad Request", f"offer a subprotocol: {', '.join(SUBPROTOCOLS)}")
            return False
        lines = ["GET / HTTP/1.1"]
        lines += [f"{name}: {value}" for name, value in headers if name not in _DROPPED_REQUEST_HEADERS]
        lines.append(f"sec-websocket-protocol: {SUBPROTOCOLS[0]}")
        client.upstream = await asyncio.wait_for(
            asyncio.open_connection("127.0.0.1", self.upstream, limit=MAX_HEAD), HANDSHAKE_TIMEOUT
        )
        upstream_reader, upstream_writer = client.upstream
        upstream_writer.write(("\r\n".join(lines) + "\r\n\r\n").encode("latin-1"))
        answer = await asyncio.wait_for(upstream_reader.readuntil(b"\r\n\r\n"), HANDSHAKE_TIMEOUT)
        parsed = parse_head(answer)
        if parsed is None or parsed[0].split(" ")[1:2] != ["101"]:
            writer.write(answer)  # the SDK's refusal, as it gave it
            await writer.drain()
            return False
        lines = [parsed[0]]
        lines += [f"{name}: {value}" for name, value in parsed[1] if name != "sec-websocket-protocol"]
        lines.append(f"Sec-WebSocket-Protocol: {chosen}")
        writer.write(("\r\n".join(lines) + "\r\n\r\n").encode("latin-1"))
        await writer.drain()
        return True

    def _authorised(self, target: str, fields: dict[str, str]) -> bool:
        given = parse_qs(urlsplit(target).query).get("token", [""])[0]
        scheme, _, bearer = fields.get("authorization", "").partition(" ")
        if scheme.lower() == "bearer" and not given:
            given = bearer.strip()
        return hmac.compare_digest(given.encode(), self.token.encode())

    async def _relay(self, client: _Client) -> None:
        tasks = [
            asyncio.ensure_future(self._from_client(client)),
            asyncio.ensure_future(self._to_client(client)),
        ]
        try:
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    # --- client to server: every frame read, checked, passed on ----------------------------

    async def _from_client(self, client: _Client) -> None:
        reader, upstream = client.reader, client.upstream[1]
        message: tuple[int, list[bytes]] | None = None  # a fragmented message being collected
        size = 0
        while True:
            first, second = await reader.readexactly(2)
            client.heard = time.monotonic()
            opcode, length = first & 0x0F, second & 0x7F
            if first & 0x70 or not second & 0x80:  # reserved bits (no extension), an unmasked frame
                self._warn(client, "protocol", "a frame that breaks RFC 6455 (unmasked or RSV bits): closed")
                return
            if length >= 126:
                length = int.from_bytes(await reader.readexactly(2 if length == 126 else 8), "big")
            if size + length > MAX_MESSAGE:
                self._warn(client, "size", f"a message over {MAX_MESSAGE} bytes: closed (1009)")
                client.writer.write(frame(_CLOSE, (1009).to_bytes(2, "big") + b"message too big", False))
                await client.writer.drain()
                client.closing = True
                # Read on for a moment: cut with the rest of the message unread, the connection
                # would be reset and the client could lose the close frame.
                try:
                    await asyncio.wait_for(_discard(client), CLOSE_GRACE * 5)
                except TimeoutError:
                    pass
                return
            key = await reader.readexactly(4)
            payload = unmask(await reader.readexactly(length), key)
            client.heard = time.monotonic()
            if opcode >= _CLOSE:  # control frames: never fragmented, may come between fragments
                if not (opcode == _PONG and payload.startswith(PING_TAG)):
                    upstream.write(frame(opcode, payload, True))
                    await upstream.drain()
                continue
            if (opcode == 0) != (message is not None):
                self._warn(client, "protocol", "a continuation frame out of place: closed")
                return
            if message is None:
                message = (opcode, [])
            message[1].append(payload)
            size += length
            if not first & 0x80:
                continue
            opcode, data = message[0], b"".join(message[1])
            message, size = None, 0
            if not client.allow(time.monotonic()):
                self._warn(client, "rate", f"more than {MESSAGE_RATE:g} messages/s: messages dropped")
                continue
            if opcode == 1:
                data = self._text(client, data)
                if data is None:
                    continue
            upstream.write(frame(opcode, data, True))
            await upstream.drain()

    def _text(self, client: _Client, data: bytes) -> bytes | None:
        """A client's JSON message as passed on (subscriptions filtered), or None: dropped."""
        try:
            message = json.loads(data)
        except ValueError:
            message = None
        if not isinstance(message, dict):
            self._warn(client, "json", "a text message that is not a JSON object: dropped")
            return None
        op = message.get("op")
        if op == "unsubscribe" and isinstance(message.get("subscriptionIds"), list):
            for subscription in message["subscriptionIds"]:
                if isinstance(subscription, int):
                    client.subscriptions.discard(subscription)
        if op != "subscribe":
            return data
        items = message.get("subscriptions")
        kept, dropped = [], 0
        for item in items if isinstance(items, list) else []:
            subscription = item.get("id") if isinstance(item, dict) else None
            channel = item.get("channelId") if isinstance(item, dict) else None
            fits = subscription in client.subscriptions or len(client.subscriptions) < MAX_SUBSCRIPTIONS
            if isinstance(subscription, int) and isinstance(channel, int) and self.known(channel) and fits:
                client.subscriptions.add(subscription)
                kept.append(item)
            else:
                dropped += 1
        if dropped or not isinstance(items, list):
            self._warn(
                client,
                "subscriptions",
                f"subscriptions to unknown channels or beyond {MAX_SUBSCRIPTIONS} dropped "
                f"({dropped} in the first such message)",
            )
        if not kept:
            return None
        message["subscriptions"] = kept
        return json.dumps(message, separators=(",", ":")).encode()

    def _warn(self, client: _Client, kind: str, text: str) -> None:
        self.warnings.once(client.warned, kind, f"client {client.name}: {text}")

    # --- server to client: passed through, pings put between frames ------------------------

    async def _to_client(self, client: _Client) -> None:
        upstream, writer = client.upstream[0], client.writer
        remaining, partial = 0, b""
        while True:
            try:
                chunk = await asyncio.wait_for(upstream.read(1 << 16), PING_INTERVAL)
            except TimeoutError:
                chunk = None
            if chunk == b"":
                return  # the server closed
            if chunk:
                writer.write(chunk)
                remaining, partial = frame_boundary(partial + chunk, remaining)
                client.at_boundary = remaining == 0 and not partial
            now = time.monotonic()
            if now - client.heard > IDLE_TIMEOUT and not client.closing:
                self._warn(client, "idle", f"nothing heard for {IDLE_TIMEOUT:g} s (not even a pong): closed")
                return
            if client.at_boundary and now - client.pinged >= PING_INTERVAL:
                writer.write(frame(_PING, PING_TAG, False))
                client.pinged = now
            try:
                await asyncio.wait_for(writer.drain(), IDLE_TIMEOUT)
            except TimeoutError:
                self._warn(client, "reading", f"did not read for {IDLE_TIMEOUT:g} s: closed")
                return
