"""Live view of a run: every channel the recorder writes, streamed as it is written.

The recorder hands each schema, channel and message that goes into the MCAP file to a sink as
well (`Recorder(path, sink=...)`, through `tee_writer`), so a live client sees the same topics,
the same schemas (ros2msg) and the same CDR bytes as the file. Two sinks:

- `Pacer(realtime)`: holds each message until its simulated time, divided by `realtime`, has
  passed on the wall clock since the first message (`cosim run --realtime R`); when the run falls
  behind, the schedule restarts from the late message, so the stream never runs faster than R.
- `FoxgloveLive(port, realtime)`: a Foxglove WebSocket server (foxglove-sdk) with a channel per
  recorded channel (`cosim run --live`); paced like `Pacer`. It is also a `GoalSource`: clients
  may publish (capability `clientPublish`, encoding `cdr`) a `geometry_msgs/msg/PoseStamped` on
  `/goal_pose` (Foxglove's "Publish pose" tool), decoded here with rosbags and handed to the run
  thread through a queue; the run takes the newest one between steps (`cosim.navigation.run`).
  Services (`/navcosim/pause`, `resume`, `step`, `speed`, `goal`) pause, step and pace the run
  (`LiveControl`); what they did goes into the log as metadata `live_control/N`. Clients reach
  the server through `cosim.record.live_front` (timeouts, limits, token, both subprotocols).

Messages reach the sink in blocks (the recorder packs a block of steps at a time); pacing per
message keeps the stream's wall-clock timing right regardless.
"""

from __future__ import annotations

import json
import logging
import math
import queue
import struct
import sys
import threading
import time
from typing import Protocol

import numpy as np

from cosim.core import interrupt
from cosim.errors import CosimError, say
from cosim.record.mcap_format import MESSAGE_HEAD, RECORD_HEAD
from cosim.scenario.topics import LATCHED_TOPICS  # a client joining late gets their last message

_LENGTH = struct.Struct("<Q")
LATE = 0.05  # [s] of wall time behind schedule after which the pacer starts again from now
GOAL_TOPIC = "/goal_pose"
GOAL_SCHEMAS = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/PoseStamped")
GOAL_FRAMES = ("map", "")  # the log's fixed frame; an empty frame_id is taken as it


def latched(topic: str) -> bool:
    """Whether a client joining late gets `topic`'s last message: a latched topic of the table
    (`/plan`), under a fleet robot's namespace too (`/robot1/plan`)."""
    return topic in LATCHED_TOPICS or topic[topic.find("/", 1) :] in LATCHED_TOPICS


class Sink(Protocol):
    def channel(
        self, channel_id: int, topic: str, encoding: str, schema: tuple[str, str, bytes] | None, metadata
    ) -> None:
        """A channel was registered: id, topic, message encoding, (schema name, encoding, data)."""

    def message(self, channel_id: int, t_ns: int, payload: bytes) -> None:
        """A message of a registered channel at log time t_ns [ns]."""


def tee_writer(writer, sink: Sink):
    """`writer` (a `cosim.record.writer.ChunkWriter`) that also hands everything to `sink`."""
    return _Tee(writer, sink)


class _Tee:
    def __init__(self, writer, sink: Sink) -> None:
        self._writer = writer
        self._sink = sink
        self._schemas: dict[int, tuple[str, str, bytes]] = {}

    def __getattr__(self, name: str):
        return getattr(self._writer, name)

    def register_schema(self, name: str, encoding: str, data: bytes, *args, **kwargs) -> int:
        schema_id = self._writer.register_schema(name, encoding, data, *args, **kwargs)
        self._schemas[schema_id] = (name, encoding, bytes(data))
        return schema_id

    def register_channel(self, topic: str, encoding: str, schema_id: int, metadata, *args, **kwargs) -> int:
        channel_id = self._writer.register_channel(topic, encoding, schema_id, metadata, *args, **kwargs)
        self._sink.channel(channel_id, topic, encoding, self._schemas.get(schema_id), dict(metadata))
        return channel_id

    def add_message(self, channel: int, t_ns: int, data: bytes, *args, **kwargs) -> None:
        self._writer.add_message(channel, t_ns, data, *args, **kwargs)
        self._sink.message(channel, int(t_ns), bytes(data))

    def add_records(
        self, records: bytes, channels: np.ndarray, times: np.ndarray, offsets: np.ndarray
    ) -> None:
        self._writer.add_records(records, channels, times, offsets)
        view = memoryview(records)
        for channel, t_ns, offset in zip(channels.tolist(), times.tolist(), offsets.tolist(), strict=True):
            (length,) = _LENGTH.unpack_from(view, offset + 1)  # after the opcode byte
            data = view[offset + MESSAGE_HEAD.size : offset + RECORD_HEAD.size + length]
            self._sink.message(channel, t_ns, bytes(data))


class GoalSource(Protocol):
    def take(self) -> tuple[float, float] | None:
        """The newest goal (x, y) [m] in frame map given since the last call, or None."""

    def report(self, text: str, warning: bool = True) -> None:
        """What became of a goal (one line)."""


def decode_goal_pose(encoding: str, schema_name: str, data: bytes) -> tuple[float, float]:
    """(x, y) [m] of a CDR `geometry_msgs/msg/PoseStamped` in frame map. Raises ValueError (one
    line) for anything else."""
    from cosim.record.rosmsg import TYPESTORE

    if encoding != "cdr" or schema_name not in GOAL_SCHEMAS:
        raise ValueError(f"expected encoding cdr and schema {GOAL_SCHEMAS[0]}, got {encoding} {schema_name}")
    try:
        message = TYPESTORE.deserialize_cdr(bytes(data), GOAL_SCHEMAS[0])
    except Exception as error:  # rosbags raises assorted errors for a short or malformed buffer
        raise ValueError(f"not a CDR PoseStamped ({type(error).__name__}: {error})") from None
    if message.header.frame_id not in GOAL_FRAMES:
        raise ValueError(f"frame_id {message.header.frame_id!r} is not map")
    return float(message.pose.position.x), float(message.pose.position.y)


class Pacer:
    """Holds messages back so simulated time runs `realtime` times as fast as the wall clock.

    Nothing watches a paced run's messages as they come, so its log keeps the chunk windows of an
    unpaced run (`watched` False): `--realtime` alone writes the same bytes as no pacing."""

    watched = False

    def __init__(self, realtime: float) -> None:
        if not realtime > 0:
            raise CosimError(f"--realtime must be > 0, got {realtime}")
        self.realtime = realtime
        self._origin: tuple[float, int] | None = None  # (wall clock [s], log time [ns]) of the first

    def channel(self, channel_id, topic, encoding, schema, metadata) -> None:
        pass

    def message(self, channel_id: int, t_ns: int, payload: bytes) -> None:
        self.wait(t_ns)

    def wait(self, t_ns: int) -> None:
        now = time.monotonic()
        if self._origin is None:
            self._origin = (now, t_ns)
            return
        wall0, t0 = self._origin
        ahead = wall0 + (t_ns - t0) / 1e9 / self.realtime - now
        if ahead > 0.0005:  # sleeping for less costs more than it is worth
            time.sleep(ahead)
        elif ahead < -LATE:
            # The run fell behind (start-up of the loop, a slow step): the stream slips instead
            # of catching up in a burst faster than R x real time.
            self._origin = (now, t_ns)

    def restart(self) -> None:
        """The schedule starts again from the next message (after a pause, a new factor)."""
        self._origin = None


CONTROL = "/navcosim/"  # the services' prefix: pause, resume, step, speed, goal
MAX_REALTIME = 1e4


class LiveControl:
    """Pause, resume, single steps and the real-time factor of a paced stream, and so of the run:
    the recorder hands its messages to the sink in the run's thread, so holding a message there
    holds the run (`gate`). Commands come from other threads (the server's)."""

    def __init__(self, realtime: float, step_ns: int) -> None:
        self.pacer = Pacer(realtime)
        self.step_ns = max(1, int(step_ns))
        self._condition = threading.Condition()
        self._paused = False
        self._step_until: int | None = None  # while paused: messages up to this time pass
        self._shown = 0  # [ns] the time of the last message that went out
        self._held: int | None = None  # [ns] the time of the message held by the pause
        self._log: list[dict[str, str]] = []  # acknowledgements the run has not written yet

    def gate(self, t_ns: int) -> None:
        """Before each message goes out (run thread): wait while paused, then keep the pace. A
        signal (SIGINT/SIGTERM) ends the wait, so the run can stop."""
        with self._condition:
            waited = False
            while self._paused and not interrupt.pending():
                if self._step_until is not None and t_ns <= self._step_until:
                    break
                self._held = t_ns
                waited = True
                self._condition.wait(0.1)
            self._held = None
            if waited:
                self.pacer.restart()
            self._shown = max(self._shown, t_ns)
        self.pacer.wait(t_ns)

    def command(self, name: str, arguments: dict, client: str) -> tuple[bool, str]:
        """Carry out pause, resume, step ({"steps": N}, default 1) or speed ({"factor": R});
        (done, what became of it), acknowledged on stderr and in the run's log."""
        with self._condition:
            t = self._shown / 1e9
            if name == "pause":
                done, text = (
                    not self._paused,
                    f"paused at t = {t:.3f} s" if not self._paused else "already paused",
                )
                self._paused, self._step_until = True, None
            elif name == "resume":
                done = self._paused
                text = f"resumed at t = {t:.3f} s" if done else "not paused"
                self._paused, self._step_until = False, None
            elif name == "step":
                steps = arguments.get("steps", 1)
                if not isinstance(steps, int) or isinstance(steps, bool) or not 1 <= steps <= 10**6:
                    done, text = False, f"step: steps must be a whole number 1..1000000, got {steps!r}"
                else:
                    base = self._step_until if self._step_until is not None else self._shown
                    until = base + steps * self.step_ns
                    if self._held is not None:
                        until = max(until, self._held)
                    self._paused, self._step_until = True, until
                    done, text = True, f"step from t = {t:.3f} s to t = {until / 1e9:.3f} s, then paused"
            elif name == "speed":
                factor = arguments.get("factor")
                if isinstance(factor, bool) or not isinstance(factor, (int, float)):
                    done, text = False, f"speed: factor must be a number, got {factor!r}"
                elif not (0 < factor <= MAX_REALTIME):
                    done, text = False, f"speed: factor must be in (0, {MAX_REALTIME:g}], got {factor!r}"
                else:
                    self.pacer.realtime = float(factor)
                    self.pacer.restart()
                    done, text = True, f"real-time factor {float(factor):g} from t = {t:.3f} s"
            else:
                done, text = False, f"unknown command {name!r}"
            self._condition.notify_all()
        self.acknowledge(name, text, client, done)
        return done, text

    def acknowledge(self, command: str, text: str, client: str, done: bool) -> None:
        """One line on stderr and a record for the log (`acknowledged`)."""
        say(f"cosim: {'' if done else 'warning: '}live view: {text} ({client})")
        self.record({"command": command, "client": client, "result": text, "done": str(done).lower()})

    def record(self, record: dict[str, str]) -> None:
        """An acknowledgement for the log, at the time last shown ("t" [s])."""
        with self._condition:
            self._log.append({**record, "t": f"{self._shown / 1e9:.9f}"})

    def acknowledged(self) -> list[dict[str, str]]:
        """The acknowledgements since the last call (run thread: it writes them to the log)."""
        with self._condition:
            taken, self._log = self._log, []
        return taken


class FoxgloveLive:
    """A Foxglove WebSocket server streaming every recorded channel (ros2msg schemas, CDR).

    The foxglove-sdk server listens on an ephemeral port of 127.0.0.1 behind the front
    (`cosim.record.live_front`), which serves `host`:`port`: handshake and idle timeouts, both
    subprotocols, the token, per-client limits. Services `/navcosim/pause`, `resume`, `step`,
    `speed` and `goal` (JSON) control the run (`LiveControl`); each is acknowledged on stderr, in
    the service's answer, to every client as a status, and in the log (metadata `live_control/N`,
    written by the run between steps, `cosim.navigation.run`)."""

    def __init__(
        self,
        port: int = 8765,
        realtime: float = 1.0,
        host: str = "127.0.0.1",
        token: str | None = None,
        step: float = 0.01,
    ) -> None:
        import foxglove
        from cosim.record.live_front import Front

        self._foxglove = foxglove
        _quiet_sdk_log()
        self.control = LiveControl(realtime, round(step * 1e9))
        self._context = foxglove.Context()
        self._channels: dict[int, object] = {}
        self._known: set[int] = set()  # the SDK's channel ids (the front lets clients subscribe to these)
        self._latched: dict[str, tuple[int, bytes]] = {}  # topic -> last (t_ns, payload)
        self._lock = threading.Lock()
        self._goals: queue.SimpleQueue[tuple[float, float]] = queue.SimpleQueue()
        self._client_channels: dict[tuple[int, int], object] = {}  # (client id, channel id) -> ClientChannel
        self._acks = 0
        capability = foxglove.Capability
        try:
            self.server = foxglove.start_server(
                name="navcosim",
                host="127.0.0.1",
                port=0,
                context=self._context,
                capabilities=[capability.Time, capability.ClientPublish, capability.Services],
                supported_encodings=["cdr", "json"],
                server_listener=_listener(self),
                services=_services(self),
            )
        except Exception as error:  # the SDK raises a plain RuntimeError
            raise CosimError(f"--live: cannot start the server ({_first_line(error)})") from None
        try:
            self.front = Front(host, port, self.server.port, self.known, token)
        except OSError as error:
            self._stop_server()
            raise CosimError(f"--live: cannot serve on {host}:{port} ({error.strerror or error})") from None
        self.port = self.front.port
        shown = f"[{host}]" if ":" in host else host
        self.url = f"ws://{shown}:{self.port}" + (f"/?token={token}" if token else "")
        self._last_time = -1

    def channel(self, channel_id, topic, encoding, schema, metadata) -> None:
        foxglove = self._foxglove
        described = foxglove.Schema(name=schema[0], encoding=schema[1], data=schema[2]) if schema else None
        with self._lock:  # the advertise may reach a client (and its subscribe the front) at once
            channel = foxglove.Channel(
                topic, schema=described, message_encoding=encoding, context=self._context, metadata=metadata
            )
            self._known.add(channel.id())
        self._channels[channel_id] = channel

    def known(self, sdk_channel_id: int) -> bool:
        """Whether the SDK server has this channel (the front's thread asks)."""
        with self._lock:
            return sdk_channel_id in self._known

    def message(self, channel_id: int, t_ns: int, payload: bytes) -> None:
        self.control.gate(t_ns)
        channel = self._channels[channel_id]
        topic = channel.topic()
        if latched(topic):
            with self._lock:
                self._latched[topic] = (t_ns, payload)
        channel.log(payload, log_time=t_ns)
        if t_ns > self._last_time:  # the client's clock follows simulated time
            self._last_time = t_ns
            self.server.broadcast_time(t_ns)

    def replay(self, topic: str) -> None:
        """Send the last message of a latched topic again (a client just subscribed to it)."""
        with self._lock:
            last = self._latched.get(topic)
        channel = next((c for c in self._channels.values() if c.topic() == topic), None)
        if last is not None and channel is not None:
            channel.log(last[1], log_time=last[0])

    def client_message(self, client_id: int, channel_id: int, data: bytes) -> None:
        """A message a client published (server thread): a /goal_pose goes to the run's queue."""
        channel = self._client_channels.get((client_id, channel_id))
        if channel is None or channel.topic != GOAL_TOPIC:
            return
        try:
            x, y = decode_goal_pose(channel.encoding, channel.schema_name, data)
        except ValueError as error:
            self.report(f"{GOAL_TOPIC} ignored: {error}")
            return
        self.give_goal(x, y)

    def give_goal(self, x: float, y: float) -> str | None:
        """Queue a goal for the run; why not (one line), or None."""
        if not (math.isfinite(x) and math.isfinite(y)):
            why = f"position ({x}, {y}) is not finite"
            self.report(f"{GOAL_TOPIC} ignored: {why}")
            return why
        self._goals.put((x, y))
        return None

    def call(self, name: str, client_id: int, payload: bytes) -> bytes:
        """A service call (server thread): its JSON answer {"ok", "message"}."""
        client = f"client {client_id}"
        try:
            arguments = json.loads(payload) if payload.strip() else {}
        except (ValueError, UnicodeDecodeError):
            arguments = None
        if not isinstance(arguments, dict):
            done, text = False, f"{name}: the request is not a JSON object"
            self.control.acknowledge(name, text, client, done)
        elif name == "goal":
            x, y = arguments.get("x"), arguments.get("y")
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (x, y)):
                done, text = False, f"goal: x and y must be numbers [m], got {x!r}, {y!r}"
                self.control.acknowledge(name, text, client, done)
            else:
                why = self.give_goal(float(x), float(y))
                done = why is None
                text = f"goal ({x:g}, {y:g}) m " + ("queued: the run answers as a status" if done else why)
        else:
            done, text = self.control.command(name, arguments, client)
        if done and name != "goal":
            self._status(text, warning=False)
        return json.dumps({"ok": done, "message": text}).encode()

    def take(self) -> tuple[float, float] | None:
        """The newest goal given since the last call (older ones are superseded), or None."""
        goal = None
        while True:
            try:
                goal = self._goals.get_nowait()
            except queue.Empty:
                return goal

    def report(self, text: str, warning: bool = True) -> None:
        """What became of a goal: a line on stderr, a status message to the clients (Foxglove
        shows it) and an acknowledgement in the log."""
        say(f"cosim: {'warning: ' if warning else ''}{text}")
        self._status(text, warning)
        self.control.record({"command": "goal", "result": text, "done": str(not warning).lower()})

    def _status(self, text: str, warning: bool) -> None:
        level = self._foxglove.websocket.StatusLevel
        self.server.publish_status(text, level.Warning if warning else level.Info)

    def acknowledged(self) -> list[tuple[str, dict[str, str]]]:
        """(metadata name, record) of each control command since the last call, for the log."""
        records = []
        for record in self.control.acknowledged():
            self._acks += 1
            records.append((f"live_control/{self._acks}", record))
        return records

    def linger(self, seconds: float | None) -> None:
        """Keep serving after the run: `seconds`, or until Ctrl-C (SIGINT, SIGTERM) when None."""
        try:
            if seconds is None:
                while True:
                    time.sleep(3600)
            elif seconds > 0:
                time.sleep(seconds)
        except KeyboardInterrupt:
            pass

    def stop(self) -> None:
        """End every client's connection, then the server (a second call: no-op)."""
        self.front.close()
        self._stop_server()

    def _stop_server(self) -> None:
        # The front held every connection the SDK had, so it stops at once; one a local process
        # opened to the SDK's own port directly could hold it: the wait is bounded.
        stopper = threading.Thread(target=self.server.stop, name="navcosim-live-stop", daemon=True)
        stopper.start()
        stopper.join(STOP_TIMEOUT)
        if stopper.is_alive():
            print(
                f"cosim: warning: live view: the server did not stop within {STOP_TIMEOUT:g} s; left behind",
                file=sys.stderr,
                flush=True,
            )


STOP_TIMEOUT = 2.0  # [s]


def _first_line(error: BaseException) -> str:
    return str(error).splitlines()[0] if str(error) else type(error).__name__


class _SdkLog(logging.Handler):
    """foxglove-sdk's own log lines (Python logger "foxglove"): the first few on stderr."""

    SHOWN = 5

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        self.count += 1
        if self.count <= self.SHOWN:
            more = " (further foxglove-sdk lines are not shown)" if self.count == self.SHOWN else ""
            say(f"cosim: live view: foxglove-sdk: {record.getMessage()}{more}")


def _quiet_sdk_log() -> None:
    logger = logging.getLogger("foxglove")
    if not any(isinstance(handler, _SdkLog) for handler in logger.handlers):
        logger.addHandler(_SdkLog())
        logger.setLevel(logging.WARNING)
        logger.propagate = False


def _services(live: FoxgloveLive) -> list:
    """The control services: a JSON request (an object; its schema below), a JSON answer."""
    foxglove = live._foxglove
    answer = {"type": "object", "properties": {"ok": {"type": "boolean"}, "message": {"type": "string"}}}
    requests = {
        "pause": {},
        "resume": {},
        "step": {"steps": {"type": "integer", "minimum": 1, "description": "macro steps (default 1)"}},
        "speed": {"factor": {"type": "number", "exclusiveMinimum": 0, "description": "real-time factor"}},
        "goal": {"x": {"type": "number"}, "y": {"type": "number"}},
    }

    def schema(name: str, body: dict):
        data = json.dumps(body).encode()
        return foxglove.MessageSchema(
            encoding="json", schema=foxglove.Schema(name=name, encoding="jsonschema", data=data)
        )

    services = []
    for name, properties in requests.items():
        request = {"type": "object", "properties": properties}
        if name in ("speed", "goal"):
            request["required"] = list(properties)

        def handler(call, name=name) -> bytes:
            return live.call(name, call.client_id, call.payload)

        services.append(
            foxglove.Service(
                CONTROL + name,
                schema=foxglove.ServiceSchema(
                    f"navcosim/{name}",
                    request=schema(f"navcosim/{name}Request", request),
                    response=schema(f"navcosim/{name}Response", answer),
                ),
                handler=handler,
            )
        )
    return services


def _listener(live: FoxgloveLive):
    """Foxglove server callbacks: a new subscriber of a latched topic gets its last message; a
    client's /goal_pose becomes a goal."""
    from foxglove import ServerListener

    class Listener(ServerListener):
        def on_subscribe(self, client, channel) -> None:
            if latched(channel.topic):
                live.replay(channel.topic)

        def on_client_advertise(self, client, channel) -> None:
            live._client_channels[(client.id, channel.id)] = channel

        def on_client_unadvertise(self, client, client_channel_id: int) -> None:
            live._client_channels.pop((client.id, client_channel_id), None)

        def on_message_data(self, client, client_channel_id: int, data: bytes) -> None:
            live.client_message(client.id, client_channel_id, data)

    return Listener()
