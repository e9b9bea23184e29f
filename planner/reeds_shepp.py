"""Reeds-Shepp curves: shortest paths of a car that drives forwards and backwards.

Reeds & Shepp (1990) showed that the shortest path between two poses for a car with minimum
turning radius R is one of 48 words over the letters C (arc of radius R, left L or right R),
S (straight) with cusps "|" where the direction flips. They are nine base formulas in the
normalised frame (start at the origin heading +x, R = 1), each turned into up to eight words by
three symmetries of the problem:

- time-flip: drive the path backwards, (x, y, phi) -> (-x, y, -phi), lengths change sign;
- reflection: mirror about the x axis, (x, y, phi) -> (x, -y, -phi), L and R swap;
- backwards: read the word in reverse order,
  (x, y, phi) -> (x cos phi + y sin phi, x sin phi - y cos phi, phi).

Each base formula (`hy_rs_base`) is solved from the geometry of the turning circles' centres: the centre
of a left circle is the pose plus i*e^{i theta} (complex notation), of a right circle minus it,
and consecutive tangent circles have centres 2 apart. Segment lengths are signed (negative =
reverse); arcs are in radians of the unit circle, i.e. metres / R.

The formulas run in C (`planner/native/hybrid_curves.h`), which the hybrid A* search calls for
most of the nodes it creates; the functions here are their Python entry points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.hybrid_geometry import candidate_buffers, library, sample_segments, wrap_angle

MAX_CANDIDATES = 64  # candidates (words) of one query at most


def enumerate_normalized(x: float, y: float, phi: float, letters: np.ndarray, lengths: np.ndarray) -> int:
    """All Reeds-Shepp candidates from the origin to (x, y, phi) for R = 1.

    Writes letters (K x 5, +1 L / 0 S / -1 R) and signed lengths (K x 5, zero padded) into the
    buffers (int64 and float64, C-contiguous, at least MAX_CANDIDATES x 5) and returns the number
    of candidates K. The formulas are C (`planner/native/hybrid_curves.h`, hy_rs_base: the nine
    base formulas; hy_rs_enumerate: the time-flip, reflection and backwards symmetries).
    """
    buffers = candidate_buffers(letters, lengths, MAX_CANDIDATES, 5)
    return int(library().hy_reeds_shepp_enumerate(x, y, phi, *buffers))


def shortest_length_normalized(
    x: float, y: float, phi: float, letters: np.ndarray, lengths: np.ndarray
) -> float:
    """Length of the shortest Reeds-Shepp path from the origin to (x, y, phi) for R = 1; letters and
    lengths are enumerate_normalized's buffers."""
    buffers = candidate_buffers(letters, lengths, MAX_CANDIDATES, 5)
    return float(library().hy_reeds_shepp_shortest(x, y, phi, *buffers))


def normalize(start_x, start_y, start_theta, goal_x, goal_y, goal_theta, radius):
    """Goal in the start's frame, scaled by 1/radius: (x, y, phi) for the R = 1 formulas."""
    dx = goal_x - start_x
    dy = goal_y - start_y
    cos_t = math.cos(start_theta)
    sin_t = math.sin(start_theta)
    x = (cos_t * dx + sin_t * dy) / radius
    y = (-sin_t * dx + cos_t * dy) / radius
    return x, y, wrap_angle(goal_theta - start_theta)


@dataclass(frozen=True)
class CurvePath:
    """A Reeds-Shepp or Dubins path: a word of arcs/straights with signed lengths [m].

    word: letters such as "LSR" (L left arc, R right arc, S straight).
    lengths: signed segment lengths [m] (negative = reverse), one per letter.
    radius: turning radius [m].
    """

    word: str
    lengths: tuple[float, ...]
    radius: float

    @property
    def length(self) -> float:
        """Total length [m]."""
        return float(sum(abs(v) for v in self.lengths))

    @property
    def curvatures(self) -> np.ndarray:
        """Curvature of each segment [1/m]."""
        return np.array([{"L": 1.0, "S": 0.0, "R": -1.0}[c] / self.radius for c in self.word])

    def sample(self, start: tuple[float, float, float], step: float) -> tuple[np.ndarray, np.ndarray]:
        """Poses (N x 3) every <= `step` [m] from `start`, and directions (+1/-1) per pose."""
        return sample_segments(start, self.curvatures, np.array(self.lengths), step)


def _to_paths(letters: np.ndarray, lengths: np.ndarray, count: int, radius: float) -> list[CurvePath]:
    paths = []
    for k in range(count):
        word = []
        signed = []
        for letter, length in zip(letters[k], lengths[k], strict=True):
            if abs(length) <= 1e-12:
                continue
            word.append({1: "L", 0: "S", -1: "R"}[int(letter)])
            signed.append(float(length) * radius)
        paths.append(CurvePath("".join(word), tuple(signed), radius))
    return paths


def all_paths(start, goal, turning_radius: float) -> list[CurvePath]:
    """Every Reeds-Shepp candidate (among the 48 words) from `start` to `goal` (x, y, theta)."""
    x, y, phi = normalize(*map(float, start), *map(float, goal), float(turning_radius))
    letters = np.empty((MAX_CANDIDATES, 5), dtype=np.int64)
    lengths = np.empty((MAX_CANDIDATES, 5))
    count = enumerate_normalized(x, y, phi, letters, lengths)
    return _to_paths(letters, lengths, count, float(turning_radius))


def shortest_path(start, goal, turning_radius: float) -> CurvePath:
    """The shortest Reeds-Shepp path from `start` to `goal` (x, y, theta) [m, m, rad]."""
    return min(all_paths(start, goal, turning_radius), key=lambda path: path.length)


def path_length(start, goal, turning_radius: float) -> float:
    """Length [m] of the shortest Reeds-Shepp path from `start` to `goal`."""
    x, y, phi = normalize(*map(float, start), *map(float, goal), float(turning_radius))
    letters = np.empty((MAX_CANDIDATES, 5), dtype=np.int64)
    lengths = np.empty((MAX_CANDIDATES, 5))
    return float(shortest_length_normalized(x, y, phi, letters, lengths)) * float(turning_radius)
