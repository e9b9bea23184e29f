"""Geometry shared by Reeds-Shepp, Dubins and hybrid A*: paths made of arcs and straights.

A path is a list of segments, each a curvature kappa [1/m] (0 for straight, +1/R left,
-1/R right) and a signed length [m] (negative = driven in reverse). The functions here place
poses (x, y, theta) [m, m, rad] along such a path and check it against an occupancy grid.
They are compiled with numba because the hybrid A* search calls them in its inner loop.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always")
def wrap_angle(angle: float) -> float:
    """Angle [rad] wrapped into (-pi, pi]."""
    # -(angle) mod 2pi in [0, 2pi) maps to angle wrapped into (-pi, pi]
    return math.pi - (math.pi - angle) % TWO_PI


@njit(cache=True, inline="always")
def advance(x: float, y: float, theta: float, curvature: float, signed_length: float):
    """Pose reached after driving `signed_length` [m] at `curvature` [1/m] from (x, y, theta)."""
    if curvature == 0.0:
        return x + signed_length * math.cos(theta), y + signed_length * math.sin(theta), theta
    new_theta = theta + curvature * signed_length
    # Exact arc: the centre sits at distance 1/kappa to the left (kappa > 0) of the heading.
    new_x = x + (math.sin(new_theta) - math.sin(theta)) / curvature
    new_y = y - (math.cos(new_theta) - math.cos(theta)) / curvature
    return new_x, new_y, new_theta


@njit(cache=True, inline="always")
def point_free(
    occupied: np.ndarray, resolution: float, origin_x: float, origin_y: float, x: float, y: float
) -> bool:
    """True if the point (x, y) [m] lies in a free cell of `occupied` (row 0 = top)."""
    col = int(math.floor((x - origin_x) / resolution))
    row_from_bottom = int(math.floor((y - origin_y) / resolution))
    rows, cols = occupied.shape
    row = rows - 1 - row_from_bottom
    if row < 0 or row >= rows or col < 0 or col >= cols:
        return False
    return not occupied[row, col]


@njit(cache=True)
def segments_free(
    occupied: np.ndarray,
    resolution: float,
    origin_x: float,
    origin_y: float,
    x: float,
    y: float,
    theta: float,
    curvatures: np.ndarray,
    signed_lengths: np.ndarray,
    count: int,
    step: float,
) -> bool:
    """True if every sample every <= `step` [m] along the segments lies in a free cell."""
    if not point_free(occupied, resolution, origin_x, origin_y, x, y):
        return False
    for k in range(count):
        length = signed_lengths[k]
        if length == 0.0:
            continue
        pieces = max(1, int(math.ceil(abs(length) / step - 1e-9)))
        for piece in range(1, pieces + 1):
            px, py, _ = advance(x, y, theta, curvatures[k], length * piece / pieces)
            if not point_free(occupied, resolution, origin_x, origin_y, px, py):
                return False
        x, y, theta = advance(x, y, theta, curvatures[k], length)
    return True


def sample_segments(
    start: tuple[float, float, float],
    curvatures: np.ndarray,
    signed_lengths: np.ndarray,
    step: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Poses (N x 3) every <= `step` [m] along a segment path from `start`, and directions (N).

    Every segment end is a sample, so cusps (direction changes) are exact poses. directions[i] is
    the driving direction (+1 / -1) of the segment that reaches pose i (pose 0 takes the first
    segment's). Run by the interpreter (`advance.py_func`, the same arithmetic as the compiled
    `advance`): a plan samples a few hundred poses once, which is not worth a kernel to compile.
    """
    move = advance.py_func
    x, y, theta = float(start[0]), float(start[1]), float(start[2])
    poses = [(x, y, theta)]
    directions = [1]
    first = True
    for curvature, length in zip(np.asarray(curvatures, dtype=float), np.asarray(signed_lengths, dtype=float),
                                 strict=True):  # fmt: skip
        curvature, length = float(curvature), float(length)
        if length == 0.0:
            continue
        sign = 1 if length > 0.0 else -1
        if first:
            directions[0] = sign
            first = False
        pieces = max(1, int(math.ceil(abs(length) / step - 1e-9)))
        for piece in range(1, pieces + 1):
            poses.append(move(x, y, theta, curvature, length * piece / pieces))
            directions.append(sign)
        x, y, theta = poses[-1]
    return np.array(poses, dtype=np.float64).reshape(-1, 3), np.array(directions, dtype=np.int8)
