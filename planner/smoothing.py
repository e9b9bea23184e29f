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

Cells that the search only treated as untrusted points are not obstacles here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from planner.errors import PlannerError
from planner.searchspace import SearchMap

_INNER = (0.6, 0.3)  # B1, B2 as fractions of d from the corner


@njit(cache=True)
def segment_clear(blocked, width, u0, v0, u1, v1):
    """True when every cell touched by the segment (u, v in cells: u = column axis, v = row axis
    pointing down, cell (row, col) = [col, col+1) x [row, row+1)) is free in the padded map."""
    col = int(math.floor(u0))
    row = int(math.floor(v0))
    end_col = int(math.floor(u1))
    end_row = int(math.floor(v1))
    du = u1 - u0
    dv = v1 - v0
    step_col = 1 if du > 0 else -1
    step_row = 1 if dv > 0 else -1
    t_delta_u = abs(1.0 / du) if du != 0.0 else np.inf
    t_delta_v = abs(1.0 / dv) if dv != 0.0 else np.inf
    if du > 0:
        t_max_u = (col + 1 - u0) / du
    elif du < 0:
        t_max_u = (col - u0) / du
    else:
        t_max_u = np.inf
    if dv > 0:
        t_max_v = (row + 1 - v0) / dv
    elif dv < 0:
        t_max_v = (row - v0) / dv
    else:
        t_max_v = np.inf
    for _ in range(abs(end_col - col) + abs(end_row - row) + 2):
        if blocked[(row + 1) * width + col + 1] == 1:
            return False
        if col == end_col and row == end_row:
            return True
        if abs(t_max_u - t_max_v) < 1e-12:
            # Through a corner: both side cells count as touched.
            if blocked[(row + 1) * width + col + step_col + 1] == 1:
                return False
            if blocked[(row + step_row + 1) * width + col + 1] == 1:
                return False
            col += step_col
            row += step_row
            t_max_u += t_delta_u
            t_max_v += t_delta_v
        elif t_max_u < t_max_v:
            col += step_col
            t_max_u += t_delta_u
        else:
            row += step_row
            t_max_v += t_delta_v
    return False  # rounding kept the walk from reaching the end cell: refuse, to stay safe


@njit(cache=True)
def polyline_clear(blocked, width, points_uv):
    for index in range(len(points_uv) - 1):
        if not segment_clear(
            blocked,
            width,
            points_uv[index, 0],
            points_uv[index, 1],
            points_uv[index + 1, 0],
            points_uv[index + 1, 1],
        ):
            return False
    return True


@njit(cache=True)
def prune_line_of_sight(blocked, width, points_uv):
    """Indices of the waypoints kept by greedy farthest-visible pruning."""
    count = len(points_uv)
    keep = np.empty(count, dtype=np.int64)
    kept = 0
    anchor = 0
    keep[kept] = 0
    kept += 1
    while anchor < count - 1:
        chosen = anchor + 1
        for candidate in range(count - 1, anchor + 1, -1):
            if segment_clear(
                blocked,
                width,
                points_uv[anchor, 0],
                points_uv[anchor, 1],
                points_uv[candidate, 0],
                points_uv[candidate, 1],
            ):
                chosen = candidate
                break
        keep[kept] = chosen
        kept += 1
        anchor = chosen
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
