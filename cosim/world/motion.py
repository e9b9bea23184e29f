"""How an unknown obstacle moves: along a path at a speed, or at a constant velocity.

An obstacle moves by translation only (it keeps its orientation). Its declared shape is its pose
at the motion's reference point: the first point of `path` (circles and rectangles have their
centre there), or where it stands before `start_time` for a `velocity`. `offset(t)` is the
displacement [m] from that pose at time t [s].

Path motions, with s = speed * (t - start_time) the arc length travelled (0 before start_time):
- `loop`: the path is closed (last point back to the first) and driven round and round;
- `bounce`: to the last point, back to the first, and again;
- `once`: to the last point, where it stays.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

MOTIONS = ("loop", "bounce", "once")


@dataclass(frozen=True)
class Motion:
    """A path [m] with speed [m/s] and a `mode` in MOTIONS, or a velocity [m/s]; from start_time [s]."""

    path: tuple[tuple[float, float], ...] = ()
    speed: float = 0.0
    mode: str = "loop"
    velocity: tuple[float, float] | None = None
    start_time: float = 0.0
    _arc: tuple[float, ...] = field(default=(), init=False, repr=False, compare=False)
    _points: tuple[tuple[float, float], ...] = field(default=(), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        points = [tuple(map(float, p)) for p in self.path]
        if self.mode == "loop" and len(points) > 1 and points[-1] != points[0]:
            points.append(points[0])
        arc = [0.0]
        for a, b in zip(points[:-1], points[1:], strict=True):
            arc.append(arc[-1] + math.hypot(b[0] - a[0], b[1] - a[1]))
        object.__setattr__(self, "_points", tuple(points))
        object.__setattr__(self, "_arc", tuple(arc))

    @property
    def max_speed(self) -> float:
        """The fastest the obstacle ever moves [m/s] (bounds how far it goes between two checks)."""
        if self.velocity is not None:
            return math.hypot(*self.velocity)
        return self.speed if self.length > 0 else 0.0

    @property
    def length(self) -> float:
        """Length [m] of one pass along the path (closed for `loop`); 0 for a velocity."""
        return self._arc[-1] if self._arc else 0.0

    def offset(self, t: float) -> tuple[float, float]:
        """Displacement (dx, dy) [m] at time t [s] from the declared pose."""
        elapsed = max(0.0, t - self.start_time)
        if self.velocity is not None:
            return self.velocity[0] * elapsed, self.velocity[1] * elapsed
        length = self.length
        if length == 0.0:
            return 0.0, 0.0
        s = self.speed * elapsed
        if self.mode == "loop":
            s = math.fmod(s, length)
        elif self.mode == "bounce":
            s = math.fmod(s, 2.0 * length)
            s = 2.0 * length - s if s > length else s
        else:
            s = min(s, length)
        x, y = self._point_at(s)
        return x - self._points[0][0], y - self._points[0][1]

    def _point_at(self, s: float) -> tuple[float, float]:
        """The path point at arc length s [m] (0 <= s <= length)."""
        arc, points = self._arc, self._points
        segment = min(max(bisect.bisect_right(arc, s) - 1, 0), len(points) - 2)
        span = arc[segment + 1] - arc[segment]
        fraction = 0.0 if span == 0.0 else (s - arc[segment]) / span
        (ax, ay), (bx, by) = points[segment], points[segment + 1]
        return ax + fraction * (bx - ax), ay + fraction * (by - ay)

    def track(self, start: tuple[float, float], t_end: float) -> np.ndarray:
        """The reference point's track (N x 2) [m] from t = 0 to t_end [s], starting at `start`, for plots."""
        if self.velocity is not None:
            dx, dy = self.offset(t_end)
            return np.array([start, (start[0] + dx, start[1] + dy)])
        base = np.asarray(self._points, dtype=float)
        return base - base[0] + np.asarray(start, dtype=float)
