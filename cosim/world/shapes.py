"""Obstacles of the true world that are not on the planner's map (seen only by the lidar).

Shapes are in metres, in the map frame (x right, y up). A shape may move (`motion`,
`cosim.world.motion.Motion`); its declared position is then its pose at the motion's start, and
`at(t)` is the shape where it stands at time t [s]. The recorder reads these classes to write
`/obstacles` markers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cosim.world.motion import Motion


@dataclass(frozen=True)
class _Shape:
    def at(self, t: float):
        """This shape at its pose at time t [s] (itself when it does not move), without motion."""
        motion = getattr(self, "motion", None)
        if motion is None:
            return self
        return self.translated(*motion.offset(t))

    def reference(self) -> tuple[float, float]:
        """A point that moves with the shape [m] (centre, or a polygon's vertex mean), for tracks."""
        if self.kind == "polygon":
            x, y = self.polygon().mean(axis=0)
            return float(x), float(y)
        return float(self.center[0]), float(self.center[1])


@dataclass(frozen=True)
class Circle(_Shape):
    center: tuple[float, float]
    radius: float
    motion: Motion | None = None

    kind = "circle"

    def polygon(self, segments: int = 48) -> np.ndarray:
        """Vertices (segments x 2) of an inscribed-free approximation, counter-clockwise."""
        angles = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
        cx, cy = self.center
        return np.column_stack((cx + self.radius * np.cos(angles), cy + self.radius * np.sin(angles)))

    def translated(self, dx: float, dy: float) -> Circle:
        return Circle((self.center[0] + dx, self.center[1] + dy), self.radius)


@dataclass(frozen=True)
class Rectangle(_Shape):
    """An oriented rectangle: centre, size (length along its x axis, width), yaw [rad]."""

    center: tuple[float, float]
    size: tuple[float, float]
    yaw: float = 0.0
    motion: Motion | None = None

    kind = "rectangle"

    def polygon(self) -> np.ndarray:
        half_x, half_y = self.size[0] / 2.0, self.size[1] / 2.0
        corners = np.array([[-half_x, -half_y], [half_x, -half_y], [half_x, half_y], [-half_x, half_y]])
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return corners @ np.array([[c, s], [-s, c]]) + np.asarray(self.center)

    def translated(self, dx: float, dy: float) -> Rectangle:
        return Rectangle((self.center[0] + dx, self.center[1] + dy), self.size, self.yaw)


@dataclass(frozen=True)
class Polygon(_Shape):
    vertices: tuple[tuple[float, float], ...]
    motion: Motion | None = None

    kind = "polygon"

    def polygon(self) -> np.ndarray:
        return np.asarray(self.vertices, dtype=float)

    def translated(self, dx: float, dy: float) -> Polygon:
        return Polygon(tuple((x + dx, y + dy) for x, y in self.vertices))


Obstacle = Circle | Rectangle | Polygon


def moves(obstacle: Obstacle) -> bool:
    """True when the obstacle ever leaves its declared pose."""
    return obstacle.motion is not None and obstacle.motion.max_speed > 0


__all__ = ["Circle", "Motion", "Obstacle", "Polygon", "Rectangle", "moves"]
