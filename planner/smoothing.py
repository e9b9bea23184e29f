"""Path smoothing that never lengthens a path and never enters an obstacle or inflated cell.

"line_of_sight": the Floyd-style pruning of section 2.1.5. From each kept waypoint, jump to the
farthest later waypoint that is in line of sight; the triangle inequality makes the result no
longer than the input. Line of sight is exact: the segment's supercover (every cell the segment
touches, both side cells where it passes exactly through a corner) must be free.

"curvature": line-of-sight pruning, then every corner W between legs towards P (before) and N
(after) is replaced by two mirrored cubic Bezier curves: B0, B1, B2 on the leg to P at distances
d, 0.6 d, 0.3 d from W, the mirrored points on the leg to N, and the joint at the midpoint of the
two inner points. Collinear B0, B1, B2 give zero curvature where the curve leaves the straight leg
and the mirror symmetry gives equal curvature at the joint, so curvature is continuous along the
whole path. The curve is convex and lies in the triangle (B0, W, E0), so it is shorter than the
2 d it replaces. d starts at half the shorter leg and is halved until the sampled curve is clear;
below half a cell the triangle lies inside W's own free cell, so the halving always ends.

Cells that the search only treated as untrusted points are not obstacles here. The line-of-sight
walks are C (planner/native/smoothing.c).
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np

from native.load import bind, load
from planner.astar import address
from planner.errors import PlannerError
from planner.searchspace import SearchMap

_INNER = (0.6, 0.3)  # B1, B2 as fractions of d from the corner


_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double
_KERNELS = bind(  # holds the GIL, as planner.astar's
    load(Path(__file__).parent / "native" / "smoothing.c"),
    {
        "navcosim_segment_clear": (_I, (_P, _I, _D, _D, _D, _D)),
        "navcosim_polyline_clear": (_I, (_P, _I, _P, _I)),
        "navcosim_prune_line_of_sight": (_I, (_P, _I, _P, _I, _P)),
    },
    hold_gil=True,
)
_segment_clear = _KERNELS.navcosim_segment_clear
_polyline_clear = _KERNELS.navcosim_polyline_clear
_prune = _KERNELS.navcosim_prune_line_of_sight


def _points(points_uv) -> np.ndarray:
    points = np.ascontiguousarray(points_uv, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2:
        raise ValueError(f"points must be n x 2 (u, v), got shape {points.shape}")
    return points


def segment_clear(blocked, width, u0, v0, u1, v1):
    """True when every cell touched by the segment (u, v in cells: u = column axis, v = row axis
    pointing down, cell (row, col) = [col, col+1) x [row, row+1)) is free in the padded map."""
    blocked_address = address(blocked, np.uint8, "blocked")
    return bool(_segment_clear(blocked_address, int(width), float(u0), float(v0), float(u1), float(v1)))


def polyline_clear(blocked, width, points_uv):
    """True when every segment between consecutive points (n x 2, u v) is clear (segment_clear)."""
    points = _points(points_uv)
    blocked_address = address(blocked, np.uint8, "blocked")
    return bool(_polyline_clear(blocked_address, int(width), points.ctypes.data, len(points)))


def prune_line_of_sight(blocked, width, points_uv):
    """Indices of the waypoints kept by greedy farthest-visible pruning."""
    points = _points(points_uv)
    keep = np.empty(len(points), dtype=np.int64)
    if len(points) == 0:
        return keep
    blocked_address = address(blocked, np.uint8, "blocked")
    kept = _prune(blocked_address, int(width), points.ctypes.data, len(points), keep.ctypes.data)
    return keep[:kept]


def _to_uv(space: SearchMap, path: np.ndarray) -> np.ndarray:
    grid = space.grid
    uv = np.empty_like(path, dtype=np.float64)
    uv[:, 0] = (path[:, 0] - grid.origin[0]) / grid.resolution
    uv[:, 1] = space.rows - (path[:, 1] - grid.origin[1]) / grid.resolution
    return uv


def _bezier(control: np.ndarray, samples: int) -> np.ndarray:
    t = np.linspace(0.0, 1.0, samples)[:, None]
    s = 1.0 - t
    return s**3 * control[0] + 3 * s**2 * t * control[1] + 3 * s * t**2 * control[2] + t**3 * control[3]


def corner_blend(previous: np.ndarray, corner: np.ndarray, following: np.ndarray, d: float, spacing: float):
    """Points [m] of the G2 blend of `corner` with legs towards `previous` and `following`, from B0 to E0."""
    towards_previous = (previous - corner) / np.linalg.norm(previous - corner)
    towards_following = (following - corner) / np.linalg.norm(following - corner)
    b0, e0 = corner + d * towards_previous, corner + d * towards_following
    b1, b2 = (corner + fraction * d * towards_previous for fraction in _INNER)
    e1, e2 = (corner + fraction * d * towards_following for fraction in _INNER)
    joint = 0.5 * (b2 + e2)
    samples = max(6, int(math.ceil(d / spacing)) + 2)
    first = _bezier(np.array([b0, b1, b2, joint]), samples)
    second = _bezier(np.array([e0, e1, e2, joint]), samples)[::-1]
    return np.vstack([first, second[1:]])


def smooth_path(space: SearchMap, path: np.ndarray, method: str) -> np.ndarray:
    """Smoothed path (N x 2, x y [m]) of a path of cell centres; method "line_of_sight" or "curvature"."""
    if method not in ("line_of_sight", "curvature"):
        raise PlannerError(f"smoothing {method!r} is not valid (choose 'line_of_sight' or 'curvature')")
    path = np.asarray(path, dtype=np.float64)
    if len(path) <= 2:
        return path.copy()
    pruned = path[prune_line_of_sight(space.blocked, space.width, _to_uv(space, path))]
    if method == "line_of_sight" or len(pruned) <= 2:
        return pruned
    resolution = space.grid.resolution
    spacing = 0.25 * resolution
    legs = np.hypot(*np.diff(pruned, axis=0).T)
    pieces = [pruned[:1]]
    for index in range(1, len(pruned) - 1):
        previous, corner, following = pruned[index - 1], pruned[index], pruned[index + 1]
        d = 0.5 * min(legs[index - 1], legs[index])
        while True:
            blend = corner_blend(previous, corner, following, d, spacing)
            if d < 0.45 * resolution or polyline_clear(space.blocked, space.width, _to_uv(space, blend)):
                break
            d *= 0.5
        pieces.append(blend)
    pieces.append(pruned[-1:])
    smoothed = np.vstack(pieces)
    steps = np.hypot(*np.diff(smoothed, axis=0).T)
    return smoothed[np.concatenate(([True], steps > 1e-9 * resolution))]
