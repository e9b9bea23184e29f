"""Dubins curves: shortest forward-only paths with a minimum turning radius (Dubins 1957).

The shortest path is one of six words, LSL, RSR, LSR, RSL, LRL, RLR, all driven forwards.
The formulas work in the normalised frame of `planner.reeds_shepp` (start at the origin heading
+x, R = 1), from the geometry of the turning circles' centres; RSR, RSL and RLR are the
reflections (x, y, phi) -> (x, -y, -phi) of LSL, LSR and LRL. Arc lengths lie in [0, 2pi).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from planner.hybrid_geometry import TWO_PI
from planner.reeds_shepp import CurvePath, normalize

# +1 left arc, 0 straight, -1 right arc; the three base words then their reflections.
_LETTERS = np.array([[1, 0, 1], [1, 0, -1], [1, -1, 1], [1, -1, 1]], dtype=np.int64)
MAX_CANDIDATES = 8
# A turn this close to a full circle is a rounding artefact of a zero-length arc.
_FULL_TURN_TOL = 1e-9


@njit(cache=True, inline="always")
def _mod_turn(angle: float) -> float:
    """Angle [rad] in [0, 2pi), with values within rounding of 2pi mapped to 0."""
    wrapped = angle % TWO_PI
    if wrapped > TWO_PI - _FULL_TURN_TOL:
        return 0.0
    return wrapped


@njit(cache=True)
def _base(family: int, x: float, y: float, phi: float, out: np.ndarray) -> bool:
    """Solve base word `family` (0 LSL, 1 LSR, 2/3 LRL) for goal (x, y, phi), R = 1."""
    sin_phi = math.sin(phi)
    cos_phi = math.cos(phi)
    if family == 0:  # centres of both left circles; the straight is parallel to their line
        dx = x - sin_phi
        dy = y - 1.0 + cos_phi
        t = _mod_turn(math.atan2(dy, dx))
        out[0], out[1], out[2] = t, math.hypot(dx, dy), _mod_turn(phi - t)
        return True
    if family == 1:  # inner tangent of a left and a right circle: centre distance^2 = u^2 + 4
        dx = x + sin_phi
        dy = y - 1.0 - cos_phi
        distance = math.hypot(dx, dy)
        if distance < 2.0:
            return False
        u = math.sqrt(max(distance * distance - 4.0, 0.0))
        t = _mod_turn(math.atan2(dy, dx) + math.atan2(2.0, u))
        out[0], out[1], out[2] = t, u, _mod_turn(t - phi)
        return True
    # LRL: the outer centres are 4 sin(u/2) apart, u in (0, 2pi); two solutions for u
    dx = x - sin_phi
    dy = y - 1.0 + cos_phi
    distance = math.hypot(dx, dy)
    if distance > 4.0:
        return False
    u = 2.0 * math.asin(distance / 4.0)
    if family == 3:
        u = TWO_PI - u
    t = _mod_turn(math.atan2(dy, dx) + 0.5 * u)
    out[0], out[1], out[2] = t, u, _mod_turn(phi - t + u)
    return True


@njit(cache=True)
def enumerate_normalized(x: float, y: float, phi: float, letters: np.ndarray, lengths: np.ndarray) -> int:
    """All Dubins candidates from the origin to (x, y, phi) for R = 1 into the buffers (K x 3)."""
    count = 0
    base_lengths = np.zeros(3)
    for family in range(4):
        for reflect in range(2):
            fy = -y if reflect else y
            fphi = -phi if reflect else phi
            if not _base(family, x, fy, fphi, base_lengths):
                continue
            for k in range(3):
                lengths[count, k] = base_lengths[k]
                letters[count, k] = -_LETTERS[family, k] if reflect else _LETTERS[family, k]
            count += 1
    return count


@njit(cache=True)
def shortest_length_normalized(
    x: float, y: float, phi: float, letters: np.ndarray, lengths: np.ndarray
) -> float:
    """Length of the shortest Dubins path from the origin to (x, y, phi) for R = 1; letters and
    lengths are enumerate_normalized's buffers (K x 3 or wider; only the first 3 columns are used)."""
    count = enumerate_normalized(x, y, phi, letters, lengths)
    best = np.inf
    for k in range(count):
        best = min(best, lengths[k, 0] + lengths[k, 1] + lengths[k, 2])
    return best


def all_paths(start, goal, turning_radius: float) -> list[CurvePath]:
    """Every Dubins candidate from `start` to `goal` (x, y, theta) [m, m, rad]."""
    radius = float(turning_radius)
    x, y, phi = normalize(*map(float, start), *map(float, goal), radius)
    letters = np.empty((MAX_CANDIDATES, 3), dtype=np.int64)
    lengths = np.empty((MAX_CANDIDATES, 3))
    count = enumerate_normalized(x, y, phi, letters, lengths)
    paths = []
    for k in range(count):
        word = "".join({1: "L", 0: "S", -1: "R"}[int(c)] for c in letters[k])
        paths.append(CurvePath(word, tuple(float(v) * radius for v in lengths[k]), radius))
    return paths


def shortest_path(start, goal, turning_radius: float) -> CurvePath:
    """The shortest Dubins path from `start` to `goal` (x, y, theta) [m, m, rad]."""
    return min(all_paths(start, goal, turning_radius), key=lambda path: path.length)


def path_length(start, goal, turning_radius: float) -> float:
    """Length [m] of the shortest Dubins path from `start` to `goal`."""
    x, y, phi = normalize(*map(float, start), *map(float, goal), float(turning_radius))
    letters = np.empty((MAX_CANDIDATES, 3), dtype=np.int64)
    lengths = np.empty((MAX_CANDIDATES, 3))
    return float(shortest_length_normalized(x, y, phi, letters, lengths)) * float(turning_radius)
