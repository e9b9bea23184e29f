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

Messages reach the sink in blocks (the recorder packs a block of steps at a time); pacing per
message keeps the stream's wall-clock timing right regardless.
"""

from __future__ import annotations

import math
import queue
import struct
import sys
import threading
import time
from typing import Protocol

import numpy as np

from cosim.errors import CosimError
from cosim.record.mcap_format import MESSAGE_HEAD, RECORD_HEAD
from cosim.scenario.topics import LATCHED_TOPICS  # a client joining late gets their last message

_LENGTH = struct.Struct("<Q")
LATE = 0.05  # [s] of wall time behind schedule after which the pacer starts again from now
GOAL_TOPIC = "/goal_pose"
GOAL_SCHEMAS = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/PoseStamped")
GOAL_FRAMES = ("map", "")  # the log's fixed frame; an empty frame_id is taken as it


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
    """Holds messages back so simulated time runs `realtime` times as fast as the wall clock."""

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


class FoxgloveLive:
    """A Foxglove WebSocket server streaming every recorded channel (ros2msg schemas, CDR)."""

    def __init__(self, port: int = 8765, realtime: float | None = 1.0, host: str = "127.0.0.1") -> None:
        import foxglove

        self._foxglove = foxglove
        self._pacer = Pacer(realtime) if realtime is not None else None
        self._context = foxglove.Context()
        self._channels: dict[int, object] = {}
        self._latched: dict[str, tuple[int, bytes]] = {}  # topic -> last (t_ns, payload)
        self._lock = threading.Lock()
        self._goals: queue.SimpleQueue[tuple[float, float]] = queue.SimpleQueue()
        self._client_channels: dict[tuple[int, int], object] = {}  # (client id, channel id) -> ClientChannel
        try:
            self.server = foxglove.start_server(
                name="navcosim",
                host=host,
                port=port,
                context=self._context,
                capabilities=[foxglove.Capability.Time, foxglove.Capability.ClientPublish],
                supported_encodings=["cdr"],
                server_listener=_listener(self),
            )
        except Exception as error:  # the SDK raises a plain RuntimeError for a taken port
            text = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise CosimError(f"--live: cannot serve on {host}:{port} ({text})") from None
        self.port = self.server.port
        self.url = f"ws://{host}:{self.port}"
        self._last_time = -1

    def channel(self, channel_id, topic, encoding, schema, metadata) -> None:
        foxglove = self._foxglove
        described = foxglove.Schema(name=schema[0], encoding=schema[1], data=schema[2]) if schema else None
        self._channels[channel_id] = foxglove.Channel(
            topic, schema=described, message_encoding=encoding, context=self._context, metadata=metadata
        )

    def message(self, channel_id: int, t_ns: int, payload: bytes) -> None:
        if self._pacer is not None:
            self._pacer.wait(t_ns)
        channel = self._channels[channel_id]
        topic = channel.topic()
        if topic in LATCHED_TOPICS:
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
        if math.isfinite(x) and math.isfinite(y):
            self._goals.put((x, y))
        else:
            self.report(f"{GOAL_TOPIC} ignored: position ({x}, {y}) is not finite")

    def take(self) -> tuple[float, float] | None:
        """The newest goal published since the last call (older ones are superseded), or None."""
        goal = None
        while True:
            try:
                goal = self._goals.get_nowait()
            except queue.Empty:
                return goal

    def report(self, text: str, warning: bool = True) -> None:
        """A line on stderr and a status message to the clients (Foxglove shows it)."""
        level = self._foxglove.websocket.StatusLevel
        print(f"cosim: {'warning: ' if warning else ''}{text}", file=sys.stderr, flush=True)
        self.server.publish_status(text, level.Warning if warning else level.Info)

    def linger(self, seconds: float | None) -> None:
        """Keep serving after the run: `seconds`, or until Ctrl-C when None."""
        try:
            if seconds is None:
                while True:
                    time.sleep(3600)
            elif seconds > 0:
                time.sleep(seconds)
        except KeyboardInterrupt:
            pass

    def stop(self) -> None:
        self.server.stop()


def _listener(live: FoxgloveLive):
    """Foxglove server callbacks: a new subscriber of a latched topic gets its last message; a
    client's /goal_pose becomes a goal."""
    from foxglove import ServerListener

    class Listener(ServerListener):
        def on_subscribe(self, client, channel) -> None:
            if channel.topic in LATCHED_TOPICS:
                live.replay(channel.topic)

        def on_client_advertise(self, client, channel) -> None:
            live._client_channels[(client.id, channel.id)] = channel

        def on_client_unadvertise(self, client, client_channel_id: int) -> None:
            live._client_channels.pop((client.id, client_channel_id), None)

        def on_message_data(self, client, client_channel_id: int, data: bytes) -> None:
            live.client_message(client.id, client_channel_id, data)

    return Listener()
