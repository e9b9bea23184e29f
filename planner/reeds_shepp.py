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

Each base formula below is solved from the geometry of the turning circles' centres: the centre
of a left circle is the pose plus i*e^{i theta} (complex notation), of a right circle minus it,
and consecutive tangent circles have centres 2 apart. Segment lengths are signed (negative =
reverse); arcs are in radians of the unit circle, i.e. metres / R.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from planner.hybrid_geometry import sample_segments, wrap_angle

HALF_PI = 0.5 * math.pi
# Tolerance on the sign conditions of segment lengths, so that a zero-length segment that
# rounding made -1e-15 still counts.
_SIGN_TOL = 1e-10
# Letters per base formula: +1 left arc, 0 straight, -1 right arc (zero padded to 5).
_LETTERS = np.array(
    [
        [1, 0, 1, 0, 0],  # LSL   (CSC)
        [1, 0, -1, 0, 0],  # LSR   (CSC)
        [1, -1, 1, 0, 0],  # LRL   (C|C|C and C|CC)
        [1, -1, 1, -1, 0],  # LRLR  (CCu|CuC), first branch
        [1, -1, 1, -1, 0],  # LRLR  (CCu|CuC), second branch
        [1, -1, 1, -1, 0],  # LRLR  (C|CuCu|C)
        [1, -1, 0, 1, 0],  # LRSL  (C|C[pi/2]SC)
        [1, -1, 0, -1, 0],  # LRSR  (C|C[pi/2]SC)
        [1, -1, 0, 1, -1],  # LRSLR (C|C[pi/2]SC[pi/2]|C)
    ],
    dtype=np.int64,
)
_SEGMENT_COUNTS = np.array([3, 3, 3, 4, 4, 4, 4, 4, 5], dtype=np.int64)
# The reversed reading only yields new words for the asymmetric families CCC and CCSC.
_HAS_BACKWARDS = np.array([False, False, True, False, False, False, True, True, False])
MAX_CANDIDATES = 64


@njit(cache=True, inline="always")
def _polar(x: float, y: float):
    return math.hypot(x, y), math.atan2(y, x)


@njit(cache=True)
def _base(family: int, x: float, y: float, phi: float, out: np.ndarray) -> bool:
    """Solve base formula `family` for goal (x, y, phi) (R = 1); signed lengths into `out`."""
    sin_phi = math.sin(phi)
    cos_phi = math.cos(phi)
    if family == 0:  # L+ S+ L+: both circles left, the straight is parallel to their centre line
        u, t = _polar(x - sin_phi, y - 1.0 + cos_phi)
        t = wrap_angle(t)
        v = wrap_angle(phi - t)
        out[0], out[1], out[2] = t, u, v
        return t >= -_SIGN_TOL and v >= -_SIGN_TOL
    if family == 1:  # L+ S+ R+: inner tangent, centre distance^2 = u^2 + 4
        distance, angle = _polar(x + sin_phi, y - 1.0 - cos_phi)
        if distance < 2.0:
            return False
        u = math.sqrt(max(distance * distance - 4.0, 0.0))
        t = wrap_angle(angle + math.atan2(2.0, u))
        v = wrap_angle(t - phi)
        out[0], out[1], out[2] = t, u, v
        return t >= -_SIGN_TOL and v >= -_SIGN_TOL
    if family == 2:  # L+ R- L+/-: outer centres 4|sin(u/2)| apart
        distance, angle = _polar(x - sin_phi, y - 1.0 + cos_phi)
        if distance > 4.0:
            return False
        u = -2.0 * math.asin(distance / 4.0)
        t = wrap_angle(angle + 0.5 * u + math.pi)
        v = wrap_angle(phi - t + u)
        out[0], out[1], out[2] = t, u, v
        return t >= -_SIGN_TOL
    if family == 3 or family == 4:  # L+ R+ L- R-: centre offset -2i(2cos u - 1)e^{i(t-u)}
        distance, angle = _polar(x + sin_phi, y - 1.0 - cos_phi)
        if family == 3:
            cos_u = (2.0 + distance) / 4.0
        else:
            cos_u = (2.0 - distance) / 4.0
        if cos_u > 1.0 or cos_u < -1.0:
            return False
        u = math.acos(cos_u)
        t = wrap_angle(angle + u + HALF_PI) if family == 3 else wrap_angle(angle + u - HALF_PI)
        v = wrap_angle(t - 2.0 * u - phi)
        out[0], out[1], out[2], out[3] = t, u, -u, v
        return t >= -_SIGN_TOL and v <= _SIGN_TOL
    if family == 5:  # L+ R- L- R+: centre offset -2i(2 - e^{iu})e^{it}
        distance, angle = _polar(x + sin_phi, y - 1.0 - cos_phi)
        cos_u = (20.0 - distance * distance) / 16.0
        if cos_u > 1.0 or cos_u < -1.0:
            return False
        u = math.acos(cos_u)
        t = wrap_angle(angle + HALF_PI + math.atan2(math.sin(u), 2.0 - cos_u))
        v = wrap_angle(t - phi)
        out[0], out[1], out[2], out[3] = t, -u, -u, v
        return t >= -_SIGN_TOL and v >= -_SIGN_TOL
    if family == 6:  # L+ R-(pi/2) S- L-: centre offset -(2 + (2+u)i)e^{it}
        distance, angle = _polar(x - sin_phi, y - 1.0 + cos_phi)
        if distance < 2.0:
            return False
        root = math.sqrt(distance * distance - 4.0)
        u = root - 2.0
        t = wrap_angle(angle - math.pi - math.atan2(root, 2.0))
        v = wrap_angle(t + HALF_PI - phi)
        out[0], out[1], out[2], out[3] = t, -HALF_PI, -u, -v
        return u >= -_SIGN_TOL and t >= -_SIGN_TOL and v >= -_SIGN_TOL
    if family == 7:  # L+ R-(pi/2) S- R-: centre offset -(2+u)i e^{it}
        distance, angle = _polar(x + sin_phi, y - 1.0 - cos_phi)
        u = distance - 2.0
        t = wrap_angle(angle + HALF_PI)
        v = wrap_angle(phi - t - HALF_PI)
        out[0], out[1], out[2], out[3] = t, -HALF_PI, -u, -v
        return u >= -_SIGN_TOL and t >= -_SIGN_TOL and v >= -_SIGN_TOL
    # family 8, L+ R-(pi/2) S- L-(pi/2) R+: centre offset -(2 + (4+u)i)e^{it}
    distance, angle = _polar(x + sin_phi, y - 1.0 - cos_phi)
    if distance < 2.0:
        return False
    root = math.sqrt(distance * distance - 4.0)
    u = root - 4.0
    t = wrap_angle(angle - math.pi - math.atan2(root, 2.0))
    v = wrap_angle(t - phi)
    out[0], out[1], out[2], out[3], out[4] = t, -HALF_PI, -u, -HALF_PI, v
    return u >= -_SIGN_TOL and t >= -_SIGN_TOL and v >= -_SIGN_TOL


@njit(cache=True)
def enumerate_normalized(x: float, y: float, phi: float, letters: np.ndarray, lengths: np.ndarray) -> int:
    """All Reeds-Shepp candidates from the origin to (x, y, phi) for R = 1.

    Writes letters (K x 5, +1 L / 0 S / -1 R) and signed lengths (K x 5, zero padded) into the
    buffers (K >= MAX_CANDIDATES) and returns the number of candidates K.
    """
    count = 0
    base_lengths = np.zeros(5)
    cos_phi = math.cos(phi)
    sin_phi = math.sin(phi)
    for family in range(9):
        segments = _SEGMENT_COUNTS[family]
        for backwards in range(2 if _HAS_BACKWARDS[family] else 1):
            if backwards:
                bx = x * cos_phi + y * sin_phi
                by = x * sin_phi - y * cos_phi
            else:
                bx, by = x, y
            for flip in range(4):
                time_flip = flip & 1
                reflect = flip >> 1
                fx = -bx if time_flip else bx
                fy = -by if reflect else by
                fphi = -phi if (time_flip ^ reflect) else phi
                base_lengths[:] = 0.0
                if not _base(family, fx, fy, fphi, base_lengths):
                    continue
                for k in range(5):
                    source = segments - 1 - k if backwards else k
                    if k < segments:
                        length = base_lengths[source]
                        letter = _LETTERS[family, source]
                        lengths[count, k] = -length if time_flip else length
                        letters[count, k] = -letter if reflect else letter
                    else:
                        lengths[count, k] = 0.0
                        letters[count, k] = 0
                count += 1
    return count


@njit(cache=True)
def shortest_length_normalized(
    x: float, y: float, phi: float, letters: np.ndarray, lengths: np.ndarray
) -> float:
    """Length of the shortest Reeds-Shepp path from the origin to (x, y, phi) for R = 1; letters and
    lengths are enumerate_normalized's buffers (the caller's: hybrid A* calls this for most of its
    nodes, and an allocation here would be one more thing to compile)."""
    count = enumerate_normalized(x, y, phi, letters, lengths)
    best = np.inf
    for k in range(count):
        total = 0.0
        for j in range(5):
            total += abs(lengths[k, j])
        best = min(best, total)
    return best


@njit(cache=True, inline="always")
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
