"""The unknown obstacles as flat arrays for the compiled kernels, moved to their pose at a time.

The lidar and the exact clearance both need the shapes as arrays: circles (C x 3: cx, cy, r),
polygon edges (S x 4: ax, ay, bx, by), polygon vertices (V x 2) with `starts` (polygon p is
vertices[starts[p]:starts[p + 1]]) and bounding circles of the polygons (P x 3). `at(t)` rewrites
the rows of the moving obstacles in place (a translation of their declared rows), so the kernels
keep reading the same arrays and a world without moving obstacles pays nothing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cosim.world.shapes import Circle, Obstacle, moves


class ObstacleArrays:
    """Array form of `obstacles` (see the module docstring); `at(t)` poses them at t [s]."""

    def __init__(self, obstacles: Sequence[Obstacle]) -> None:
        self.obstacles = tuple(obstacles)
        circles = [o for o in self.obstacles if isinstance(o, Circle)]
        polygons = [o for o in self.obstacles if not isinstance(o, Circle)]
        shapes = [np.asarray(o.polygon(), dtype=float) for o in polygons]
        self.circles = np.array([(*o.center, o.radius) for o in circles], dtype=float).reshape(-1, 3)
        edges = [np.hstack((p, np.roll(p, -1, axis=0))) for p in shapes]
        self.segments = np.ascontiguousarray(np.vstack(edges) if edges else np.zeros((0, 4)))
        self.vertices = np.ascontiguousarray(np.vstack(shapes) if shapes else np.zeros((0, 2)))
        self.starts = np.cumsum([0] + [len(p) for p in shapes]).astype(np.int64)
        bounds = []
        for vertices in shapes:
            cx, cy = vertices.mean(axis=0)
            bounds.append((cx, cy, float(np.hypot(vertices[:, 0] - cx, vertices[:, 1] - cy).max())))
        self.bounds = np.array(bounds, dtype=float).reshape(-1, 3)
        # Declared rows of the moving obstacles, to translate from: (motion, arrays, rows, base).
        self._moving = []
        for index, obstacle in enumerate(circles):
            if moves(obstacle):
                self._moving.append((obstacle.motion, self.circles, slice(index, index + 1), 2))
        for index, obstacle in enumerate(polygons):
            if moves(obstacle):
                first, stop = int(self.starts[index]), int(self.starts[index + 1])
                self._moving.append((obstacle.motion, self.segments, slice(first, stop), 4))
                self._moving.append((obstacle.motion, self.vertices, slice(first, stop), 2))
                self._moving.append((obstacle.motion, self.bounds, slice(index, index + 1), 2))
        self._declared = [array[rows].copy() for _, array, rows, _ in self._moving]
        self.moving = bool(self._moving)
        self.max_speed = max((o.motion.max_speed for o in self.obstacles if moves(o)), default=0.0)
        self.time = math.nan  # the arrays hold the declared poses until the first `at`

    def at(self, t: float) -> None:
        """Put every moving obstacle at its pose at time t [s] (rewrites the arrays in place)."""
        if not self.moving or t == self.time:
            return
        self.time = t
        for (motion, array, rows, columns), declared in zip(self._moving, self._declared, strict=True):
            dx, dy = motion.offset(t)
            shift = np.array([dx, dy] * (columns // 2))
            array[rows, :columns] = declared[:, :columns] + shift

    def shapes(self, t: float) -> list[Obstacle]:
        """The obstacles at their poses at time t [s] (for `/obstacles`)."""
        return [obstacle.at(t) for obstacle in self.obstacles]
