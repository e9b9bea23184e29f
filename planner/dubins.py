"""Dubins curves: shortest forward-only paths with a minimum turning radius (Dubins 1957).

The shortest path is one of six words, LSL, RSR, LSR, RSL, LRL, RLR, all driven forwards.
The formulas work in the normalised frame of `planner.reeds_shepp` (start at the origin heading
+x, R = 1), from the geometry of the turning circles' centres; RSR, RSL and RLR are the
reflections (x, y, phi) -> (x, -y, -phi) of LSL, LSR and LRL. Arc lengths lie in [0, 2pi).
"""

from __future__ import annotations

import numpy as np

from planner.hybrid_geometry import candidate_buffers, library
from planner.reeds_shepp import CurvePath, normalize

MAX_CANDIDATES = 8  # candidates (words) of one query at most


def enumerate_normalized(x: float, y: float, phi: float, letters: np.ndarray, lengths: np.ndarray) -> int:
    """All Dubins candidates from the origin to (x, y, phi) for R = 1 into the buffers (int64 and
    float64, C-contiguous, at least MAX_CANDIDATES x 3; the first 3 columns are written); returns
    their number. The formulas are C (`planner/native/hybrid_curves.h`, hy_dubins_base)."""
    buffers = candidate_buffers(letters, lengths, MAX_CANDIDATES, 3)
    return int(library().hy_dubins_enumerate_normalized(x, y, phi, *buffers))


def shortest_length_normalized(
    x: float, y: float, phi: float, letters: np.ndarray, lengths: np.ndarray
) -> float:
    """Length of the shortest Dubins path from the origin to (x, y, phi) for R = 1; letters and
    lengths are enumerate_normalized's buffers (K x 3 or wider; only the first 3 columns are used)."""
    buffers = candidate_buffers(letters, lengths, MAX_CANDIDATES, 3)
    return float(library().hy_dubins_shortest_length(x, y, phi, *buffers))


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
