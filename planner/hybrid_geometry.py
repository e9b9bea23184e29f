"""Geometry shared by Reeds-Shepp, Dubins and hybrid A*: paths made of arcs and straights.

A path is a list of segments, each a curvature kappa [1/m] (0 for straight, +1/R left,
-1/R right) and a signed length [m] (negative = driven in reverse). The functions here place
poses (x, y, theta) [m, m, rad] along such a path and check it against an occupancy grid.

The hybrid A* search runs them in C (`planner/native/hybrid_geometry.h`, part of the library
`planner/native/hybrid.c`, which `library()` loads); the Python functions here do the same
operations in the same order, so both give the same floats.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np

from native.load import bind, load

TWO_PI = 2.0 * math.pi
SOURCE = Path(__file__).resolve().parent / "native" / "hybrid.c"
_library: ctypes.CDLL | None = None

_P = ctypes.c_void_p
_I = ctypes.c_int64
_D = ctypes.c_double
# name: (restype, argtypes) of the functions of hybrid.c called from Python
_SIGNATURES = {
    "hy_search": (_I, [_P]),
    "hy_argsort": (None, [_P, _I, _P]),
    "hy_reeds_shepp_enumerate": (_I, [_D, _D, _D, _P, _P, _I]),
    "hy_reeds_shepp_shortest": (_D, [_D, _D, _D, _P, _P, _I]),
    "hy_dubins_enumerate_normalized": (_I, [_D, _D, _D, _P, _P, _I]),
    "hy_dubins_shortest_length": (_D, [_D, _D, _D, _P, _P, _I]),
    "hy_segments_free_grid": (_I, [_P, _I, _I, _D, _D, _D, _D, _D, _D, _P, _P, _I, _D]),
}


def library() -> ctypes.CDLL:
    """The hybrid A* kernels (`planner/native/hybrid.c`), built on first use, loaded once."""
    global _library
    if _library is None:
        _library = bind(load(SOURCE), _SIGNATURES)
    return _library


def candidate_buffers(letters, lengths, rows: int, columns: int) -> tuple[int, int, int]:
    """(address of letters, address of lengths, their row stride) for a kernel that writes up to
    `rows` candidates of `columns` segments into them: int64 and float64 arrays, C-contiguous,
    writeable, 2-D, at least rows x columns and of one width. ValueError otherwise."""
    for name, array, dtype in (("letters", letters, np.int64), ("lengths", lengths, np.float64)):
        if (
            not isinstance(array, np.ndarray)
            or array.dtype != dtype
            or array.ndim != 2
            or not array.flags.c_contiguous
            or not array.flags.writeable
            or array.shape[0] < rows
            or array.shape[1] < columns
        ):
            raise ValueError(
                f"{name} must be a writeable C-contiguous {np.dtype(dtype).name} array of at least "
                f"{rows} x {columns}"
            )
    if letters.shape[1] != lengths.shape[1]:
        raise ValueError("letters and lengths must have the same number of columns")
    return letters.ctypes.data, lengths.ctypes.data, letters.shape[1]


def wrap_angle(angle: float) -> float:
    """Angle [rad] wrapped into (-pi, pi]."""
    # -(angle) mod 2pi in [0, 2pi) maps to angle wrapped into (-pi, pi]
    return math.pi - (math.pi - angle) % TWO_PI


def advance(x: float, y: float, theta: float, curvature: float, signed_length: float):
    """Pose reached after driving `signed_length` [m] at `curvature` [1/m] from (x, y, theta)."""
    if curvature == 0.0:
        return x + signed_length * math.cos(theta), y + signed_length * math.sin(theta), theta
    new_theta = theta + curvature * signed_length
    # Exact arc: the centre sits at distance 1/kappa to the left (kappa > 0) of the heading.
    new_x = x + (math.sin(new_theta) - math.sin(theta)) / curvature
    new_y = y - (math.cos(new_theta) - math.cos(theta)) / curvature
    return new_x, new_y, new_theta


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
    """True if every sample every <= `step` [m] along the first `count` segments lies in a free cell."""
    occupied = np.ascontiguousarray(occupied, dtype=bool)
    curvatures = np.ascontiguousarray(curvatures, dtype=np.float64)
    signed_lengths = np.ascontiguousarray(signed_lengths, dtype=np.float64)
    count = int(count)
    if occupied.ndim != 2 or not 0 <= count <= min(len(curvatures), len(signed_lengths)):
        raise ValueError("segments_free needs a 2-D grid and count <= the number of segments")
    rows, cols = occupied.shape
    grid = (occupied.ctypes.data, rows, cols, resolution, origin_x, origin_y)
    path = (x, y, theta, curvatures.ctypes.data, signed_lengths.ctypes.data, count, step)
    return bool(library().hy_segments_free_grid(*grid, *path))


def sample_segments(
    start: tuple[float, float, float],
    curvatures: np.ndarray,
    signed_lengths: np.ndarray,
    step: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Poses (N x 3) every <= `step` [m] along a segment path from `start`, and directions (N).

    Every segment end is a sample, so cusps (direction changes) are exact poses. directions[i] is
    the driving direction (+1 / -1) of the segment that reaches pose i (pose 0 takes the first
    segment's). Run by the interpreter: a plan samples a few hundred poses once.
    """
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
            poses.append(advance(x, y, theta, curvature, length * piece / pieces))
            directions.append(sign)
        x, y, theta = poses[-1]
    return np.array(poses, dtype=np.float64).reshape(-1, 3), np.array(directions, dtype=np.int8)
