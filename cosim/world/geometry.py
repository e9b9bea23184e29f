"""Compiled point-polygon geometry shared by the lidar (is the sensor inside an obstacle?) and the
outcome checks (distance to the true obstacles).

Polygons are rows `first` to `stop - 1` of an (N, 2) vertex array, closed implicitly, so many
polygons can share one array.

Both are inlined into the kernels that call them (numba IR, inline="always"): on a cold cache a
separately compiled helper costs a compile of its own plus one more optimisation in every caller.
"""

from __future__ import annotations

import math

import numba


@numba.njit(cache=True, inline="always")
def inside_polygon(x, y, vertices, first, stop):
    """Even-odd rule; a point on an edge may fall either way (its distance is 0 anyway)."""
    inside = False
    for index in range(first, stop):
        ax, ay = vertices[index, 0], vertices[index, 1]
        following = index + 1 if index + 1 < stop else first
        bx, by = vertices[following, 0], vertices[following, 1]
        if (ay > y) != (by > y) and x < ax + (y - ay) * (bx - ax) / (by - ay):
            inside = not inside
    return inside


@numba.njit(cache=True, inline="always")
def polygon_distance(x, y, vertices, first, stop):
    """Exact distance [m] from (x, y) to the polygon's boundary; 0 inside it."""
    if inside_polygon(x, y, vertices, first, stop):
        return 0.0
    nearest = math.inf
    for index in range(first, stop):
        ax, ay = vertices[index, 0], vertices[index, 1]
        following = index + 1 if index + 1 < stop else first
        dx, dy = vertices[following, 0] - ax, vertices[following, 1] - ay
        length_sq = dx * dx + dy * dy
        t = 0.0 if length_sq == 0 else min(1.0, max(0.0, ((x - ax) * dx + (y - ay) * dy) / length_sq))
        nearest = min(nearest, math.hypot(x - ax - t * dx, y - ay - t * dy))
    return nearest
