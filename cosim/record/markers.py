"""The unknown obstacles as markers: the /obstacles topic's `visualization_msgs/MarkerArray`.

Circles are cylinders, rectangles cubes (same centre, size, yaw), polygons closed line strips, all
in the map frame, red, `OBSTACLE_HEIGHT` tall in a 3D view (Foxglove, RViz). Moving obstacles are
republished with every scan, so `ObstacleMarkers` keeps, for circles and rectangles, the CDR bytes
of the first message of the same shapes and writes only the stamps and the centres into them (the
bytes equal a full serialisation: checked once per set of shapes).
"""

from __future__ import annotations

import dataclasses
import struct

import numpy as np

from cosim.errors import CosimError
from cosim.record import rosmsg
from cosim.scenario.topics import TOPIC_TYPES

OBSTACLE_HEIGHT = 0.5  # [m], only for the 3D view
LINE_WIDTH = 0.05  # [m] of polygon outlines
_STAMP = struct.Struct("<iI")  # builtin_interfaces/Time: int32 sec, uint32 nanosec
_FLOAT64 = struct.Struct("<d")
_SENTINEL_NS = 1_234_567_891_987_654_321  # a stamp no run writes, to find in the template


def marker(t_ns: int, index: int, obstacle):
    """The `visualization_msgs/Marker` of one `cosim.world.shapes` shape, id `index`, stamped `t_ns`."""
    kind = getattr(obstacle, "kind", None)
    scale, points = rosmsg.vector3(LINE_WIDTH, LINE_WIDTH, LINE_WIDTH), []
    if kind == "circle":
        marker_type, (cx, cy), yaw = 3, obstacle.center, 0.0
        diameter = 2.0 * float(obstacle.radius)
        scale = rosmsg.vector3(diameter, diameter, OBSTACLE_HEIGHT)
    elif kind == "rectangle":
        marker_type, (cx, cy), yaw = 1, obstacle.center, float(obstacle.yaw)
        scale = rosmsg.vector3(obstacle.size[0], obstacle.size[1], OBSTACLE_HEIGHT)
    elif kind == "polygon":
        marker_type, (cx, cy), yaw = 4, (0.0, 0.0), 0.0
        vertices = np.asarray(obstacle.polygon(), dtype=float)
        points = [rosmsg.point(px, py) for px, py in np.vstack([vertices, vertices[:1]])]
    else:
        raise CosimError(f"cannot write obstacle {obstacle!r} as a marker (not a cosim.world.shapes shape)")
    height = OBSTACLE_HEIGHT / 2.0 if marker_type != 4 else 0.0
    empty = np.zeros(0, dtype=np.uint8)
    return rosmsg.make(
        "visualization_msgs/msg/Marker",
        header=rosmsg.header(t_ns, rosmsg.MAP_FRAME),
        ns="obstacles",
        id=index,
        type=marker_type,
        action=0,
        pose=rosmsg.pose(float(cx), float(cy), yaw, height),
        scale=scale,
        color=rosmsg.color(0.85, 0.2, 0.15, 0.8),
        lifetime=rosmsg.make("builtin_interfaces/msg/Duration", sec=0, nanosec=0),
        frame_locked=False,
        points=points,
        colors=[],
        texture_resource="",
        texture=rosmsg.make(
            "sensor_msgs/msg/CompressedImage",
            header=rosmsg.header(t_ns, rosmsg.MAP_FRAME),
            format="",
            data=empty,
        ),
        uv_coordinates=[],
        text=kind,
        mesh_resource="",
        mesh_file=rosmsg.make("visualization_msgs/msg/MeshFile", filename="", data=empty),
        mesh_use_embedded_materials=False,
    )


def marker_array(t_ns: int, obstacles: list):
    """The /obstacles message: one marker per shape of `obstacles`, ids in their order."""
    markers = [marker(t_ns, index, obstacle) for index, obstacle in enumerate(obstacles)]
    return rosmsg.make("visualization_msgs/msg/MarkerArray", markers=markers)


def obstacles_cdr(t_ns: int, obstacles: list) -> bytes:
    """The CDR bytes of `marker_array(t_ns, obstacles)`, serialised in full."""
    return rosmsg.serialize(marker_array(t_ns, obstacles), TOPIC_TYPES["/obstacles"])


class ObstacleMarkers:
    """The /obstacles CDR bytes of a run, reusing one template per set of circle and rectangle
    shapes (a polygon's points change when it moves: serialised in full). `where` (the log's path)
    starts the message of a layout error."""

    def __init__(self, where: str) -> None:
        self.where = where
        self._templates: dict[tuple, _ObstacleTemplate] = {}  # shapes -> template

    def payload(self, t_ns: int, obstacles: list) -> bytes:
        key = tuple(_marker_key(obstacle) for obstacle in obstacles)
        if None in key:
            return obstacles_cdr(t_ns, obstacles)
        template = self._templates.get(key)
        if template is None:
            template = _ObstacleTemplate(obstacles)
            if template.fill(t_ns, obstacles) != obstacles_cdr(t_ns, obstacles):
                raise CosimError(f"{self.where}: unexpected MarkerArray CDR layout")
            self._templates[key] = template
        return template.fill(t_ns, obstacles)


def _marker_key(obstacle) -> tuple | None:
    """What fixes a marker's bytes apart from its stamp and centre (None: more changes, a polygon)."""
    kind = getattr(obstacle, "kind", None)
    if kind == "circle":
        return (kind, float(obstacle.radius))
    if kind == "rectangle":
        return (kind, tuple(float(v) for v in obstacle.size), float(obstacle.yaw))
    return None


class _ObstacleTemplate:
    """The /obstacles CDR of circles and rectangles with the byte offsets of every stamp and of each
    marker's centre (x, y), found by serialising sentinel values (checked once against the full
    serialisation by `ObstacleMarkers.payload`)."""

    def __init__(self, obstacles: list) -> None:
        sentinels = [(-1.0e250 * (index + 1.5), 1.0e250 * (index + 1.5)) for index in range(len(obstacles))]
        placed = [
            dataclasses.replace(obstacle, center=centre)
            for obstacle, centre in zip(obstacles, sentinels, strict=True)
        ]
        data = obstacles_cdr(_SENTINEL_NS, placed)
        self.data = bytearray(data)
        stamp = _STAMP.pack(*divmod(_SENTINEL_NS, 1_000_000_000))
        self.stamps = rosmsg.pattern_offsets(data, stamp)
        if len(self.stamps) != 2 * len(obstacles):  # the marker's header and its texture's
            raise CosimError("unexpected MarkerArray CDR layout (stamps)")
        self.centres = []
        for cx, cy in sentinels:
            (x_at,) = rosmsg.pattern_offsets(data, _FLOAT64.pack(cx))
            (y_at,) = rosmsg.pattern_offsets(data, _FLOAT64.pack(cy))
            self.centres.append((x_at, y_at))

    def fill(self, t_ns: int, obstacles: list) -> bytes:
        data = self.data
        stamp = _STAMP.pack(*divmod(int(t_ns), 1_000_000_000))
        for at in self.stamps:
            data[at : at + 8] = stamp
        for (x_at, y_at), obstacle in zip(self.centres, obstacles, strict=True):
            cx, cy = obstacle.center
            data[x_at : x_at + 8] = _FLOAT64.pack(float(cx))
            data[y_at : y_at + 8] = _FLOAT64.pack(float(cy))
        return bytes(data)
