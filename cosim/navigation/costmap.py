"""The planner's costmap: the known map plus what the lidar has seen.

Cells are those of the known map (same shape, resolution and origin). `marked` holds the lidar's
obstacles: every scan marks the cell of each return, and clears the marked cells its rays pass
through before they end (at the return, or at `range_max` for a beam without one), so an obstacle
that moved away is forgotten once a ray crosses where it stood. Known occupied cells are never
cleared. A beam reads NaN both without a return and below `range_min`; with `range_min` > 0 a
NaN beam is not used to clear (the obstacle may be closer than the sensor sees).

`inflated(radius)` is the known map plus the marks, inflated by `radius` [m] with the planner's
rule (a cell is blocked when its centre is within `radius` of an obstacle cell's centre).
`new_marks_near(points, radius, since)` says whether a cell marked after the snapshot `since`
lies within `radius` of any of the points: a newly seen obstacle on the plan.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from planner.grid import OccupancyGrid


@numba.njit(cache=True)
def _integrate_scan(marked, known, origin_x, origin_y, resolution, x, y, theta, angles, ranges, clear_to):
    """Mark each return's cell and clear the marked cells before it (see the module docstring).

    `marked`/`known` are [row, col] with row 0 at the top (the grid's convention); `clear_to` [m]
    is how far a beam without a return clears (0: not at all). Returns the number of changed cells.
    """
    rows, cols = marked.shape
    gx = (x - origin_x) / resolution
    gy = (y - origin_y) / resolution
    changed = 0
    for beam in range(angles.shape[0]):
        distance = ranges[beam]
        hit = math.isfinite(distance)
        if not hit:
            distance = clear_to
            if distance <= 0.0:
                continue
        dx = math.cos(theta + angles[beam])
        dy = math.sin(theta + angles[beam])
        # Cells the ray crosses before reaching `distance` (Amanatides-Woo, in cell units).
        limit = distance / resolution
        ix, iy = int(math.floor(gx)), int(math.floor(gy))
        step_x = 1 if dx > 0 else -1
        step_y = 1 if dy > 0 else -1
        next_x = ((ix + 1) - gx) / dx if dx > 0 else ((gx - ix) / -dx if dx < 0 else np.inf)
        next_y = ((iy + 1) - gy) / dy if dy > 0 else ((gy - iy) / -dy if dy < 0 else np.inf)
        delta_x = 1.0 / abs(dx) if dx != 0 else np.inf
        delta_y = 1.0 / abs(dy) if dy != 0 else np.inf
        while True:
            leaving = min(next_x, next_y)  # where the ray leaves cell (ix, iy)
            if hit and leaving >= limit:
                break  # the return's own cell
            if 0 <= ix < cols and 0 <= iy < rows:
                row = rows - 1 - iy
                if marked[row, ix] and not known[row, ix]:
                    marked[row, ix] = False
                    changed += 1
            if leaving >= limit:
                break
            if next_x < next_y:
                next_x += delta_x
                ix += step_x
            else:
                next_y += delta_y
                iy += step_y
        if hit:
            # Just past the surface, so a return on a cell boundary marks the cell behind it.
            px = gx + dx * (limit + 1e-6)
            py = gy + dy * (limit + 1e-6)
            cx, cy = int(math.floor(px)), int(math.floor(py))
            if 0 <= cx < cols and 0 <= cy < rows:
                row = rows - 1 - cy
                if not marked[row, cx] and not known[row, cx]:
                    marked[row, cx] = True
                    changed += 1
    return changed


@numba.njit(cache=True)
def _new_marks_near(marked, since, origin_x, origin_y, resolution, points, radius):
    """True when a cell marked now but not in `since` has its centre within `radius` [m] of a point."""
    rows, cols = marked.shape
    reach = int(math.ceil(radius / resolution)) + 1
    for index in range(points.shape[0]):
        px, py = points[index, 0], points[index, 1]
        col = int(math.floor((px - origin_x) / resolution))
        iy = int(math.floor((py - origin_y) / resolution))
        for cy in range(max(iy - reach, 0), min(iy + reach + 1, rows)):
            row = rows - 1 - cy
            centre_y = origin_y + (cy + 0.5) * resolution
            for cx in range(max(col - reach, 0), min(col + reach + 1, cols)):
                if marked[row, cx] and not since[row, cx]:
                    centre_x = origin_x + (cx + 0.5) * resolution
                    if math.hypot(centre_x - px, centre_y - py) <= radius:
                        return True
    return False


class Costmap:
    """The known map (`planner.OccupancyGrid`) plus lidar marks; see the module docstring."""

    def __init__(self, known: OccupancyGrid, angles: np.ndarray, range_min: float, range_max: float):
        self.known = known
        self.marked = np.zeros(known.shape, dtype=np.bool_)
        self._known = np.ascontiguousarray(known.occupied, dtype=np.bool_)
        self.angles = np.ascontiguousarray(angles, dtype=float)
        self.clear_to = float(range_max) if range_min == 0.0 else 0.0

    def integrate(self, x: float, y: float, theta: float, ranges: np.ndarray) -> int:
        """Add one scan taken at pose (x, y [m], theta [rad]); returns the number of changed cells."""
        ranges = np.ascontiguousarray(ranges[: len(self.angles)], dtype=float)
        origin_x, origin_y = self.known.origin
        return _integrate_scan(
            self.marked, self._known, float(origin_x), float(origin_y), float(self.known.resolution),
            float(x), float(y), float(theta), self.angles, ranges, self.clear_to,
        )  # fmt: skip

    def grid(self) -> OccupancyGrid:
        """Known obstacles plus the marks, as a grid."""
        return OccupancyGrid(self._known | self.marked, self.known.resolution, self.known.origin)

    def inflated(self, radius: float) -> OccupancyGrid:
        """`grid()` inflated by `radius` [m] (the planner's rule)."""
        grid = self.grid()
        return grid.inflate(radius) if radius > 0 else grid

    def snapshot(self) -> np.ndarray:
        """A copy of the marks, for `new_marks_near` later."""
        return self.marked.copy()

    def new_marks_near(self, points: np.ndarray, radius: float, since: np.ndarray) -> bool:
        """True when a cell marked after `since` has its centre within `radius` [m] of a point (N x 2)."""
        if len(points) == 0:
            return False
        origin_x, origin_y = self.known.origin
        return bool(
            _new_marks_near(
                self.marked, since, float(origin_x), float(origin_y), float(self.known.resolution),
                np.ascontiguousarray(points, dtype=float), float(radius),
            )
        )  # fmt: skip
