"""A fleet run's log: every robot under its ROS namespace, one TF tree under `map`.

One MCAP file (ROS 2 messages, cdr, profile "ros2"), written by `mcap.writer.Writer`:
- `/tf` (tf2_msgs/TFMessage) at t = 0, every 1/pose_rate s and at the end: for every robot
  `map -> robotN/odom` (the identity: odometry without drift, REP-105) and
  `robotN/odom -> robotN/base_link` (its true pose), so one tree under `map` holds every robot;
- `/robotN/odom` (nav_msgs/Odometry, frame `robotN/odom`, child `robotN/base_link`) at the same
  times, twist = the robot's command (`Observed.command`) or NaN;
- `/robotN/goal` (geometry_msgs/PoseStamped in `map`) at t = 0 and when the robot takes its next goal;
- `/robotN/plan` (nav_msgs/Path in `map`) at t = 0 and after each block in which it replanned;
- `/robotN/scan` (sensor_msgs/LaserScan in `robotN/base_link`) at each lidar step, as the
  single-robot log's /scan (REP-117: no return is +inf; beams on a uniform angle grid);
- `/map` (nav_msgs/OccupancyGrid) once at t = 0: the known map;
- metadata `fleet_outcome` (per robot and fleet figures, collisions) and attachment `scenario.toml`.

The single-robot log (`cosim.record.recorder`) also has `/signals/<component>`, `/cmd_vel` and
`/obstacles`; a fleet's will have them under the namespaces once a fleet is recorded through the
same recorder.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from cosim.record import rosmsg
from cosim.record.recorder import scan_layout

ODOM = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"
POSE = "geometry_msgs/msg/PoseStamped"
PATH = "nav_msgs/msg/Path"
SCAN = "sensor_msgs/msg/LaserScan"
GRID = "nav_msgs/msg/OccupancyGrid"


def odom_frame(robot: str) -> str:
    return f"{robot}/{rosmsg.ODOM_FRAME}"


def base_frame(robot: str) -> str:
    return f"{robot}/{rosmsg.ROBOT_FRAME}"


class FleetLog:
    """Writes one fleet run (module docstring); `close(outcome)` adds the outcome and finishes."""

    def __init__(self, path: Path, names: list[str], scenario_text: str) -> None:
        self.path = Path(path)
        self._stream = open(self.path, "wb")  # noqa: SIM115 - closed by close()
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="navcosim fleet")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence = 0
        self.names = list(names)
        self._writer.add_attachment(0, 0, "scenario.toml", "application/toml", scenario_text.encode())

    def _channel(self, topic: str, typename: str) -> int:
        if topic not in self._channels:
            if typename not in self._schemas:
                definition = rosmsg.message_definition(typename).encode()
                self._schemas[typename] = self._writer.register_schema(typename, "ros2msg", definition)
            self._channels[topic] = self._writer.register_channel(topic, "cdr", self._schemas[typename])
        return self._channels[topic]

    def _write(self, topic: str, typename: str, t_ns: int, message) -> None:
        channel = self._channel(topic, typename)
        self._sequence += 1
        self._writer.add_message(channel, t_ns, rosmsg.serialize(message, typename), t_ns, self._sequence)

    def write_poses(self, t_ns: int, poses, commands) -> None:
        """Every robot's pose (x, y, theta) and command (v, omega) at t_ns: /tf and /robotN/odom."""
        transforms = []
        for name, (x, y, theta), (v, omega) in zip(self.names, poses, commands, strict=True):
            transforms.append(_transform(t_ns, rosmsg.MAP_FRAME, odom_frame(name), 0.0, 0.0, 0.0))
            transforms.append(_transform(t_ns, odom_frame(name), base_frame(name), x, y, theta))
            odometry = rosmsg.make(
                ODOM,
                header=rosmsg.header(t_ns, odom_frame(name)),
                child_frame_id=base_frame(name),
                pose=rosmsg.make(
                    "geometry_msgs/msg/PoseWithCovariance", pose=rosmsg.pose(x, y, theta), covariance=_zeros()
                ),
                twist=rosmsg.make(
                    "geometry_msgs/msg/TwistWithCovariance", twist=rosmsg.twist(v, omega), covariance=_zeros()
                ),
            )
            self._write(f"/{name}/odom", ODOM, t_ns, odometry)
        self._write("/tf", TF, t_ns, rosmsg.make(TF, transforms=transforms))

    def write_goal(self, t_ns: int, name: str, x: float, y: float) -> None:
        self._write(f"/{name}/goal", POSE, t_ns, rosmsg.pose_stamped(t_ns, x, y, 0.0))

    def write_map(self, grid) -> None:
        """The known map (`planner.OccupancyGrid`) as nav_msgs/OccupancyGrid at t = 0: rows bottom
        to top, occupied 100, free 0."""
        occupied = np.asarray(grid.occupied, dtype=bool)
        info = rosmsg.make(
            "nav_msgs/msg/MapMetaData",
            map_load_time=rosmsg.time_msg(0),
            resolution=float(grid.resolution),
            width=int(occupied.shape[1]),
            height=int(occupied.shape[0]),
            origin=rosmsg.pose(float(grid.origin[0]), float(grid.origin[1]), 0.0),
        )
        data = np.ascontiguousarray(np.flipud(occupied.astype(np.int8) * 100)).reshape(-1)
        message = rosmsg.make(GRID, header=rosmsg.header(0, rosmsg.MAP_FRAME), info=info, data=data)
        self._write("/map", GRID, 0, message)

    def write_plan(self, t_ns: int, name: str, waypoints) -> None:
        points = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        headings = np.arctan2(*np.diff(points, axis=0)[:, ::-1].T) if len(points) > 1 else np.zeros(0)
        headings = np.append(headings, headings[-1] if len(headings) else 0.0)
        poses = [rosmsg.pose_stamped(t_ns, x, y, yaw) for (x, y), yaw in zip(points, headings, strict=True)]
        message = rosmsg.make(PATH, header=rosmsg.header(t_ns, rosmsg.MAP_FRAME), poses=poses)
        self._write(f"/{name}/plan", PATH, t_ns, message)

    def write_scan(
        self, t_ns: int, name: str, angles, ranges, range_min: float, range_max: float, period: float
    ):
        """One sweep: beam angles [rad] and ranges [m] (NaN: no return, written +inf)."""
        angle_min, increment, bins, _ = scan_layout(np.asarray(angles, dtype=float))
        binned = np.full(int(bins[-1]) + 1 if len(bins) else 0, np.nan, dtype=np.float32)
        values = np.asarray(ranges, dtype=np.float32)
        binned[bins] = np.where(np.isnan(values), np.float32(np.inf), values)
        message = rosmsg.laser_scan(
            t_ns, base_frame(name), angle_min, increment, binned, period, range_min, range_max
        )
        self._write(f"/{name}/scan", SCAN, t_ns, message)

    def close(self, outcome: dict) -> None:
        self._writer.add_metadata("fleet_outcome", {key: json.dumps(value) for key, value in outcome.items()})
        self._writer.finish()
        self._stream.close()


def _transform(t_ns: int, parent: str, child: str, x: float, y: float, theta: float):
    return rosmsg.make(
        "geometry_msgs/msg/TransformStamped",
        header=rosmsg.header(t_ns, parent),
        child_frame_id=child,
        transform=rosmsg.make(
            "geometry_msgs/msg/Transform",
            translation=rosmsg.vector3(x, y, 0.0),
            rotation=rosmsg.quaternion(theta),
        ),
    )


def _zeros():
    return np.zeros(36)


def outcome_record(outcome) -> dict:
    """The fleet outcome as JSON-able values (metadata `fleet_outcome`)."""
    robots = {
        robot.name: {
            "status": robot.status,
            "goals_reached": robot.goals_reached,
            "goals": robot.goals,
            "completion_time": robot.completion_time,
            "distance": robot.distance,
            "min_clearance_walls": _finite(robot.min_clearance_walls),
            "min_clearance_robots": _finite(robot.min_clearance_robots),
            "stopped_time": robot.stopped_time,
            "recovery_time": robot.recovery_time,
            "deadlocked_at": robot.deadlocked_at,
            "collision": list(robot.collision) if robot.collision else None,
        }
        for robot in outcome.robots
    }
    collisions = [
        {
            "robots": [c.first, c.second],
            "time": c.time,
            "centers": [list(c.first_center), list(c.second_center)],
            "radii": [c.first_radius, c.second_radius],
        }
        for c in outcome.collisions
    ]
    return {
        "reason": outcome.reason,
        "time": outcome.time,
        "makespan": outcome.makespan,
        "throughput_per_hour": outcome.throughput,
        "deadlocks": [robot.name for robot in outcome.deadlocks],
        "robots": robots,
        "collisions": collisions,
    }


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None
