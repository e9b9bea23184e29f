"""Read a run's log (MCAP written by `cosim.record.recorder`) into NumPy arrays and ROS messages.

    log = open_log("logs/warehouse-20250101-120000.mcap")
    log.topics                      # [TopicInfo(name, type, count, rate), ...]
    vehicle = log.signals("vehicle")
    vehicle.t, vehicle["v_actual"]  # time [s], one column per variable
    grid, plan = log.map(), log.plan()

A log cut short by a killed run (no summary, no footer) is read up to its last complete chunk;
`log.is_complete` is False and `log.warnings` says what is missing.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np

import cosim.logs.index as log_index
from cosim.errors import CosimError
from cosim.record import rosmsg
from cosim.record.rosmsg import COMPONENT_KEY, SIGNAL_NAMES_KEY, SIGNAL_UNITS_KEY, path_poses
from cosim.world.shapes import Circle, Polygon, Rectangle


class TopicInfo(NamedTuple):
    name: str
    type: str  # schema name, e.g. "nav_msgs/msg/Odometry"
    count: int
    rate: float  # mean messages per second of log time [Hz]; 0 for fewer than two messages


class LogMessage(NamedTuple):
    t: float  # log time [s]
    t_ns: int  # log time [ns]
    message: object  # rosbags message (dataclass)


@dataclass(frozen=True)
class Signals:
    """One component's recorded signals: `values[i, j]` is variable `names[j]` at time `t[i]` [s]."""

    component: str
    t: np.ndarray  # [s], float64
    t_ns: np.ndarray  # [ns], int64 (exact)
    names: list[str]  # original variable names
    fields: list[str]  # their ROS 2 field names in the log
    values: np.ndarray  # (len(t), len(names)) float64
    units: list[str] = dataclass_field(default_factory=list)  # per name, "" when unknown (older logs)

    def unit(self, name: str) -> str:
        """The unit of a variable (from the FMU's model description), "" when the log has none."""
        index = self.names.index(name) if name in self.names else self.fields.index(name)
        return self.units[index] if index < len(self.units) else ""

    def __getitem__(self, name: str) -> np.ndarray:
        """The column of a variable, by its original name or its ROS 2 field name."""
        if name in self.names:
            return self.values[:, self.names.index(name)]
        if name in self.fields:
            return self.values[:, self.fields.index(name)]
        raise CosimError(
            f"component {self.component!r} has no signal {name!r} (signals: {', '.join(self.names)})"
        )

    def __contains__(self, name: str) -> bool:
        return name in self.names or name in self.fields


@dataclass(frozen=True)
class TextSignals:
    """One component's String and Binary signals (`/text_signals/<component>`): `rows[i]` holds
    every variable (`names`, FMI types `types`: str for a String, bytes for a Binary) from time
    `t[i]` [s] until the next record (a record is written when a value changes)."""

    component: str
    t: np.ndarray  # [s]
    names: list[str]
    types: list[str]
    rows: list[list[str | bytes]]

    def __getitem__(self, name: str) -> list[str | bytes]:
        if name not in self.names:
            raise CosimError(
                f"component {self.component!r} has no text signal {name!r} "
                f"(text signals: {', '.join(self.names)})"
            )
        index = self.names.index(name)
        return [row[index] for row in self.rows]


@dataclass(frozen=True)
class Trajectory:
    t: np.ndarray  # [s]
    x: np.ndarray  # [m]
    y: np.ndarray  # [m]
    theta: np.ndarray  # [rad]


def open_log(path: str | Path) -> Log:
    """Open and index a log; raises CosimError (one line) for a file that is not MCAP."""
    return Log(Path(path))


class Log:
    """A navcosim run log. Cheap to open: message data is decompressed only when asked for."""

    def __init__(self, path: Path) -> None:
        self.path = path
        if path.is_dir() or not path.exists():
            raise CosimError(f"{path}: no such log file")
        self._index = log_index.read_index(path)
        self._handle = open(path, "rb")  # noqa: SIM115 - closed by close() / finaliser
        if any(
            channel not in self._index.channels for block in self._index.blocks for channel in block.index
        ):
            log_index.discover_channels_in_blocks(self._handle, self._index)
        self._signals: dict[str, Signals] = {}
        self._typestore = None
        self.warnings: list[str] = []
        self.warnings.extend(self._index.skipped)
        if not self.is_complete:
            self.warnings.append(
                f"incomplete log ({self._index.problem}): read up to its last complete chunk, "
                f"t = {self.end_time:.3f} s"
            )
        elif "outcome" not in self.metadata and "fleet_outcome" not in self.metadata:
            self.warnings.append("the log records no outcome (the run ended by an error)")
        profile = self._index.header.profile if self._index.header else ""
        if profile != "ros2":
            self.warnings.append(f"profile {profile!r} is not 'ros2': ROS 2 tools may not read this file")

    def close(self) -> None:
        self._handle.close()

    def __enter__(self) -> Log:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def __del__(self) -> None:
        handle = getattr(self, "_handle", None)
        if handle is not None:
            handle.close()

    # --- what is in the file -------------------------------------------------------------

    @property
    def is_complete(self) -> bool:
        """True when the file has its footer (the recorder was closed)."""
        return self._index.complete

    @cached_property
    def _channel_times(self) -> dict[int, np.ndarray]:
        """Log times [ns] of every message per channel id, sorted."""
        per_channel: dict[int, list[np.ndarray]] = {}
        for block in self._index.blocks:
            for channel, entries in block.index.items():
                per_channel.setdefault(channel, []).append(entries[:, 0])
        return {
            channel: np.sort(np.concatenate(parts)).astype(np.int64) for channel, parts in per_channel.items()
        }

    @cached_property
    def topics(self) -> list[TopicInfo]:
        """Every channel with messages or declared, sorted by name."""
        topics = []
        for channel_id, channel in self._index.channels.items():
            times = self._channel_times.get(channel_id, np.zeros(0, dtype=np.int64))
            schema = self._index.schemas.get(channel.schema_id)
            span = float(times[-1] - times[0]) / 1e9 if len(times) > 1 else 0.0
            rate = float((len(times) - 1) / span) if span > 0 else 0.0
            topics.append(TopicInfo(channel.topic, schema.name if schema else "", len(times), rate))
        return sorted(topics, key=lambda topic: topic.name)

    @property
    def start_time(self) -> float:
        """Log time [s] of the first message (0 when empty)."""
        firsts = [times[0] for times in self._channel_times.values() if len(times)]
        return min(firsts) / 1e9 if firsts else 0.0

    @property
    def end_time(self) -> float:
        """Log time [s] of the last message read (0 when empty)."""
        lasts = [times[-1] for times in self._channel_times.values() if len(times)]
        return max(lasts) / 1e9 if lasts else 0.0

    @property
    def duration(self) -> float:
        """[s] between the first and the last message."""
        return self.end_time - self.start_time

    @cached_property
    def metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records by name (`navcosim`, `fmu/<component>`, `outcome`, ...)."""
        return {record.name: dict(record.metadata) for record in self._index.metadata}

    @cached_property
    def attachments(self) -> dict[str, tuple[str, bytes]]:
        """Attached files: name -> (media type, bytes)."""
        return {record.name: (record.media_type, bytes(record.data)) for record in self._index.attachments}

    @property
    def scenario_text(self) -> str | None:
        """The scenario TOML the run used, when attached."""
        attachment = self.attachments.get("scenario.toml")
        return attachment[1].decode("utf-8", errors="replace") if attachment else None

    @property
    def scenario_name(self) -> str | None:
        name = self.metadata.get("navcosim", {}).get("scenario_name")
        if name is None and self.fleet_outcome is not None and self.scenario_text:
            # a fleet log has no `navcosim` record: its attached scenario names it
            import tomllib

            try:
                name = tomllib.loads(self.scenario_text).get("scenario", {}).get("name")
            except tomllib.TOMLDecodeError:
                name = None
        return name

    @property
    def fleet_outcome(self) -> dict | None:
        """A fleet run's outcome (metadata `fleet_outcome`, each value JSON): reason, time [s],
        makespan [s] or None, throughput_per_hour, deadlocks (names), robots (name -> status,
        goals_reached, goals, completion_time, distance, clearances, collision [t, x, y] or None),
        collisions ({robots: [a, b], time, centers: [[x, y], [x, y]], radii}); None for a log
        that is not a fleet's (or a fleet run that did not end)."""
        written = self.metadata.get("fleet_outcome")
        return None if written is None else {key: json.loads(text) for key, text in written.items()}

    @cached_property
    def robots(self) -> list[str]:
        """The fleet's robots: the namespaces of `/<robot>/odom` topics, in name order ([] for a
        single robot's log)."""
        names = {topic.name[1:-5] for topic in self.topics if re.fullmatch(r"/[^/]+/odom", topic.name)}
        return sorted(names, key=_natural)

    def robot_trajectory(self, robot: str) -> Trajectory:
        """A fleet robot's driven poses: its `/<robot>/odom` messages (in `map`: its odom frame is
        the identity under `map`)."""
        rows = [
            (
                item.t,
                item.message.pose.pose.position.x,
                item.message.pose.pose.position.y,
                rosmsg.yaw_of(item.message.pose.pose.orientation),
            )
            for item in self.messages(f"/{robot}/odom")
        ]
        t, x, y, theta = np.array(rows, dtype=float).reshape(-1, 4).T
        return Trajectory(t, x, y, theta)

    def robot_goals(self, robot: str) -> list[tuple[float, float, float]]:
        """A fleet robot's goals as (log time [s], x, y [m]): its `/<robot>/goal` messages."""
        if not self.has_topic(f"/{robot}/goal"):
            return []
        return [
            (item.t, item.message.pose.position.x, item.message.pose.position.y)
            for item in self.messages(f"/{robot}/goal")
        ]

    def robot_plans(self, robot: str) -> list[tuple[float, np.ndarray]]:
        """A fleet robot's plans as (log time [s], N x 3 poses), as `plans()`."""
        if not self.has_topic(f"/{robot}/plan"):
            return []
        return [(item.t, path_poses(item.message)) for item in self.messages(f"/{robot}/plan")]

    @property
    def outcome(self) -> dict[str, bool | int | float | str] | None:
        """The run's outcome (reached, reason, time, ...) with typed values: `reached` a bool, times
        and distances floats, counts ints, reasons and messages strings; None when the run did not
        end. MCAP metadata holds only strings: `metadata["outcome"]` keeps them as written."""
        written = self.metadata.get("outcome")
        return None if written is None else {key: typed_value(text) for key, text in written.items()}

    @property
    def fmus(self) -> dict[str, dict[str, str]]:
        """FMU descriptions by component (path, model_name, guid, generation_tool, fmi_version)."""
        return {
            name.removeprefix("fmu/"): data for name, data in self.metadata.items() if name.startswith("fmu/")
        }

    @cached_property
    def _signal_channels(self) -> dict[str, int]:
        channels = {}
        for channel_id, channel in sorted(self._index.channels.items()):
            if COMPONENT_KEY in channel.metadata and SIGNAL_NAMES_KEY in channel.metadata:
                channels[channel.metadata[COMPONENT_KEY]] = channel_id
        return channels

    @property
    def components(self) -> list[str]:
        """Components with a signal channel, in the order they were registered."""
        return list(self._signal_channels)

    def signal_names(self, component: str) -> list[str]:
        """The original variable names of a component's signals (from the channel metadata)."""
        channel_id = self._signal_channels.get(component)
        if channel_id is None:
            raise CosimError(f"{self.path}: no signals of component {component!r}")
        return list(json.loads(self._index.channels[channel_id].metadata[SIGNAL_NAMES_KEY]))

    def signal_units(self, component: str) -> list[str]:
        """The units of a component's signals, in `signal_names` order ("" for none; all "" for a
        log written before units were recorded)."""
        names = self.signal_names(component)
        metadata = self._index.channels[self._signal_channels[component]].metadata
        units = json.loads(metadata[SIGNAL_UNITS_KEY]) if SIGNAL_UNITS_KEY in metadata else []
        return [str(unit) for unit in units] if len(units) == len(names) else [""] * len(names)

    @cached_property
    def _text_channels(self) -> dict[str, object]:
        return {
            channel.metadata[rosmsg.TEXT_COMPONENT_KEY]: channel
            for _, channel in sorted(self._index.channels.items())
            if rosmsg.TEXT_COMPONENT_KEY in channel.metadata and rosmsg.TEXT_NAMES_KEY in channel.metadata
        }

    @property
    def text_components(self) -> list[str]:
        """Components with String or Binary signals (`/text_signals/<component>`)."""
        return list(self._text_channels)

    def text_signals(self, component: str) -> TextSignals:
        """Every record of `/text_signals/<component>`, decoded."""
        channel = self._text_channels.get(component)
        if channel is None:
            known = ", ".join(self._text_channels) or "none"
            raise CosimError(f"{self.path}: no text signals of component {component!r} (components: {known})")
        names = [str(name) for name in json.loads(channel.metadata[rosmsg.TEXT_NAMES_KEY])]
        types = [str(kind) for kind in json.loads(channel.metadata[rosmsg.TEXT_TYPES_KEY])]
        fields = rosmsg.field_names(names)
        times, rows = [], []
        for item in self.messages(channel.topic):
            times.append(item.t_ns)
            rows.append(
                [
                    getattr(item.message, field) if kind == "String" else bytes(getattr(item.message, field))
                    for field, kind in zip(fields, types, strict=True)
                ]
            )
        return TextSignals(component, np.array(times, dtype=np.int64) / 1e9, names, types, rows)

    # --- signals -------------------------------------------------------------------------

    def signals(self, component: str) -> Signals:
        """All records of `/signals/<component>` as arrays (one vectorised pass over the chunks)."""
        if component not in self._signals:
            self._signals[component] = self._read_signals(component)
        return self._signals[component]

    def _read_signals(self, component: str) -> Signals:
        """Read every component's signals in one pass (each chunk is decompressed once)."""
        if component not in self._signal_channels:
            known = ", ".join(self.components) or "none: not a navcosim run log"
            raise CosimError(f"{self.path}: no signals of component {component!r} (components: {known})")
        layouts, described = {}, {}
        for name, channel_id in self._signal_channels.items():
            if name in self._signals:
                continue
            channel = self._index.channels[channel_id]
            names = self.signal_names(name)
            schema = self._index.schemas[channel.schema_id]
            fields = _signal_fields(schema.data.decode())
            if len(fields) != len(names):
                raise CosimError(
                    f"{self.path}: {channel.topic}: schema has {len(fields)} fields for {len(names)} names"
                )
            layouts[channel_id] = (rosmsg.SIGNAL_VALUES_OFFSET, 8 * len(names))
            described[channel_id] = (name, names, fields)
        payloads = log_index.fixed_payloads(self._handle, self._index, layouts)
        for channel_id, (name, names, fields) in described.items():
            t_ns, rows = payloads[channel_id]
            values = rows.view("<f8").reshape(len(t_ns), len(names))
            units = self.signal_units(name)
            self._signals[name] = Signals(name, t_ns / 1e9, t_ns, names, fields, values, units)
        return self._signals[component]

    # --- ROS messages --------------------------------------------------------------------

    def topic_name(self, topic: str) -> str:
        """The name `topic` ("/odom") has in this log: remapped by the run's [output.topics]."""
        remap = self.metadata.get("navcosim", {}).get("topics", "")
        names = dict(item.split("=", 1) for item in remap.split(",") if "=" in item)
        return names.get(topic, topic)

    def _topic_channels(self, topic: str) -> dict[int, str]:
        topic = self.topic_name(topic)
        channels = {cid: channel for cid, channel in self._index.channels.items() if channel.topic == topic}
        if not channels:
            raise CosimError(f"{self.path}: no topic {topic} in the log")
        typestore = self._types()
        result = {}
        for channel_id, channel in channels.items():
            schema = self._index.schemas.get(channel.schema_id)
            if channel.message_encoding != "cdr" or schema is None or schema.encoding != "ros2msg":
                raise CosimError(f"{self.path}: {topic} is not a ROS 2 topic ({channel.message_encoding})")
            if schema.name not in typestore.types:
                rosmsg.register_definition(typestore, schema.name, schema.data.decode())
            result[channel_id] = schema.name
        return result

    def _types(self):
        if self._typestore is None:
            self._typestore = rosmsg.new_typestore()
        return self._typestore

    def messages(self, topic: str):
        """Iterate the messages of `topic` as LogMessage(t [s], t_ns, message), decoded by rosbags."""
        channels = self._topic_channels(topic)
        typestore = self._types()
        for channel_id, t_ns, payload in log_index.iter_payloads(self._handle, self._index, set(channels)):
            yield LogMessage(t_ns / 1e9, t_ns, typestore.deserialize_cdr(payload, channels[channel_id]))

    def has_topic(self, topic: str) -> bool:
        topic = self.topic_name(topic)
        return any(info.name == topic and info.count for info in self.topics)

    def last_message(self, topic: str):
        """The last message of `topic`, or None when the topic is absent or empty."""
        if not self.has_topic(topic):
            return None
        last = None
        for item in self.messages(topic):
            last = item
        return last.message if last else None

    # --- the robot's world -------------------------------------------------------------

    def map(self, topic: str = "/map"):
        """The last grid on `topic` as a `planner.OccupancyGrid` (cells >= 50 occupied), or None."""
        from planner.grid import OccupancyGrid

        message = self.last_message(topic)
        if message is None:
            return None
        info = message.info
        cells = np.asarray(message.data, dtype=np.int8).reshape(info.height, info.width)
        resolution = float(f"{info.resolution:.7g}")  # stored as float32
        origin = (info.origin.position.x, info.origin.position.y)
        return OccupancyGrid(np.flipud(cells >= 50), resolution, origin)

    def plan(self) -> np.ndarray | None:
        """The last planned path on /plan as N x 2 [m], or None."""
        message = self.last_message("/plan")
        return None if message is None else _path_points(message)

    def plans(self) -> list[tuple[float, np.ndarray]]:
        """Every published plan (the first and each replan) as (log time [s], N x 3 poses: x, y [m],
        heading [rad]), in order."""
        if not self.has_topic("/plan"):
            return []
        return [(item.t, path_poses(item.message)) for item in self.messages("/plan")]

    def trajectory(self) -> Trajectory | None:
        """The driven trajectory: the vehicle's x, y, theta signals, else the /pose messages."""
        if "vehicle" in self._signal_channels:
            vehicle = self.signals("vehicle")
            if all(name in vehicle for name in ("x", "y", "theta")):
                return Trajectory(vehicle.t, vehicle["x"], vehicle["y"], vehicle["theta"])
        if not self.has_topic("/pose"):
            return None
        rows = [
            (
                item.t,
                item.message.pose.position.x,
                item.message.pose.position.y,
                rosmsg.yaw_of(item.message.pose.orientation),
            )
            for item in self.messages("/pose")
        ]
        t, x, y, theta = np.array(rows, dtype=float).reshape(-1, 4).T
        return Trajectory(t, x, y, theta)

    def obstacles(self) -> list:
        """The unknown obstacles (last /obstacles message) as `cosim.world.shapes` shapes."""
        message = self.last_message("/obstacles")
        return [] if message is None else _marker_shapes(message)

    def obstacle_frames(self) -> list[tuple[float, list]]:
        """Every /obstacles message as (log time [s], shapes): moving obstacles where they stood."""
        if not self.has_topic("/obstacles"):
            return []
        return [(item.t, _marker_shapes(item.message)) for item in self.messages("/obstacles")]

    def obstacle_tracks(self) -> list[np.ndarray]:
        """Where each unknown obstacle was: per marker id, rows (t [s], x [m], y [m]) of its centre
        (a polygon's vertex mean) in every /obstacles message; one row for a still obstacle."""
        if not self.has_topic("/obstacles"):
            return []
        tracks: dict[int, list[tuple[float, float, float]]] = {}
        for item in self.messages("/obstacles"):
            for marker in item.message.markers:
                if marker.type == 4 and len(marker.points) > 1:
                    points = marker.points[:-1]
                    x = sum(point.x for point in points) / len(points)
                    y = sum(point.y for point in points) / len(points)
                else:
                    x, y = marker.pose.position.x, marker.pose.position.y
                tracks.setdefault(marker.id, []).append((item.t, x, y))
        return [np.array(tracks[key], dtype=float) for key in sorted(tracks)]

    def goals(self) -> list[tuple[float, float, float]]:
        """Every goal the run was given as (log time [s], x, y [m]): the /goal messages (the first
        goal and each change), else the goal of the run's metadata from the log's start."""
        if self.has_topic("/goal"):
            return [
                (item.t, item.message.pose.position.x, item.message.pose.position.y)
                for item in self.messages("/goal")
            ]
        goal = metadata_goal(self.metadata)
        return [] if goal is None else [(self.start_time, *goal)]

    def goal(self) -> tuple[float, float] | None:
        """The goal (x, y) [m] in force at the end (`final_goal`)."""
        return final_goal(self.metadata, self.goals)

    def start(self) -> tuple[float, float, float] | None:
        """Start pose (x, y [m], theta [rad]) from the run's metadata, else the first trajectory point."""
        return start_pose(self.metadata, self.trajectory)


def metadata_goal(metadata: dict) -> tuple[float, float] | None:
    """Goal (x, y) [m] in a run's `navcosim` metadata, or None."""
    goal = _floats(metadata.get("navcosim", {}).get("goal"))
    return (goal[0], goal[1]) if goal is not None and len(goal) >= 2 else None


def final_goal(metadata: dict, goals) -> tuple[float, float] | None:
    """The goal (x, y) [m] in force at the end of a run: the outcome's (a run whose goal changed
    records its last one there), else the last of `goals()` ((t, x, y) each; called only then: a
    log reads them from the file), else the run's `navcosim` metadata."""
    goal = _floats(metadata.get("outcome", {}).get("goal"))
    if goal is not None and len(goal) >= 2:
        return goal[0], goal[1]
    given = goals()
    return (given[-1][1], given[-1][2]) if given else metadata_goal(metadata)


def start_pose(metadata: dict, trajectory) -> tuple[float, float, float] | None:
    """Start pose from a run's `navcosim` metadata, else the first point of `trajectory()` (called
    only then: a log reads it from the file)."""
    start = _floats(metadata.get("navcosim", {}).get("start"))
    if start is not None and len(start) >= 2:
        return start[0], start[1], start[2] if len(start) > 2 else 0.0
    points = trajectory()
    if points is None or len(points.t) == 0:
        return None
    return float(points.x[0]), float(points.y[0]), float(points.theta[0])


def _path_points(message) -> np.ndarray:
    """A nav_msgs/Path's positions as N x 2 [m]."""
    return np.array([(pose.pose.position.x, pose.pose.position.y) for pose in message.poses]).reshape(-1, 2)


def _marker_shapes(message) -> list:
    """A visualization_msgs/MarkerArray of obstacles as `cosim.world.shapes` shapes."""
    shapes = []
    for marker in message.markers:
        centre = (marker.pose.position.x, marker.pose.position.y)
        if marker.type == 3:
            shapes.append(Circle(centre, marker.scale.x / 2.0))
        elif marker.type == 1:
            yaw = rosmsg.yaw_of(marker.pose.orientation)
            shapes.append(Rectangle(centre, (marker.scale.x, marker.scale.y), yaw))
        elif marker.type == 4 and len(marker.points) > 1:
            vertices = tuple((point.x, point.y) for point in marker.points[:-1])
            shapes.append(Polygon(vertices))
    return shapes


def _natural(name: str) -> tuple:
    """robot2 before robot10."""
    return tuple((0, int(part), "") if part.isdigit() else (1, 0, part) for part in re.split(r"(\d+)", name))


def _floats(text: str | None) -> tuple[float, ...] | None:
    if not text:
        return None
    try:
        return tuple(float(part) for part in text.split(","))
    except ValueError:
        return None


def _signal_fields(definition: str) -> list[str]:
    """The float64 field names of a generated signals struct (the schema's first section)."""
    main = definition.split(rosmsg.SEPARATOR)[0]
    return re.findall(r"^float64\s+(\w+)\s*$", main, flags=re.MULTILINE)


_INTEGER = re.compile(r"[+-]?[0-9]+")
_FLOAT = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?|[+-]?(nan|inf)")


def typed_value(text: str) -> bool | int | float | str:
    """A metadata value as what it is: "true"/"false" a bool, "12" an int, "41.250000", "nan" or
    "1e-3" a float, anything else (a reason, a message, "6.0,8.0") the string itself."""
    if text in ("true", "false"):
        return text == "true"
    if _INTEGER.fullmatch(text):
        return int(text)
    if _FLOAT.fullmatch(text):
        return float(text)
    return text
