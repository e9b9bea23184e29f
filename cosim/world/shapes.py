"""Obstacles of the true world that are not on the planner's map (seen only by the lidar).

Shapes are in metres, in the map frame (x right, y up). The orchestrator helper owns this
module; the recorder reads these classes to write `/obstacles` markers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Circle:
    center: tuple[float, float]
    radius: float

    kind = "circle"

    def polygon(self, segments: int = 48) -> np.ndarray:
        """Vertices (segments x 2) of an inscribed-free approximation, counter-clockwise."""
        angles = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
        cx, cy = self.center
        return np.column_stack((cx + self.radius * np.cos(angles), cy + self.radius * np.sin(angles)))


@dataclass(frozen=True)
class Rectangle:
    """An oriented rectangle: centre, size (length along its x axis, width), yaw [rad]."""

    center: tuple[float, float]
    size: tuple[float, float]
    yaw: float = 0.0

    kind = "rectangle"

    def polygon(self) -> np.ndarray:
        half_x, half_y = self.size[0] / 2.0, self.size[1] / 2.0
        corners = np.array([[-half_x, -half_y], [half_x, -half_y], [half_x, half_y], [-half_x, half_y]])
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return corners @ np.array([[c, s], [-s, c]]) + np.asarray(self.center)


@dataclass(frozen=True)
class Polygon:
    vertices: tuple[tuple[float, float], ...]

    kind = "polygon"

    def polygon(self) -> np.ndarray:
        return np.asarray(self.vertices, dtype=float)


Obstacle = Circle | Rectangle | Polygon
