"""Robots of a fleet meeting each other: exact contact between footprint circles.

Each robot's footprint is a circle (its `[vehicle] radius`) at its position. Within one macro step
of length h a robot moves from its pose at t to its pose at t + h; over so short a step (1.5 cm at
1.5 m/s and 10 ms) its path is taken as the straight segment between them. Two circles of radii
r_a, r_b moving linearly touch when their centres' distance equals r_a + r_b: with the offset
d(s) = d0 + s w between the centres (s in [0, 1] the fraction of the step, d0 the offset at t, w
the change of the offset over the step), |d(s)|^2 = (r_a + r_b)^2 is a quadratic in s, and the
first contact is its smaller root when it lies in [0, 1] (`first_contact`). The closest approach
within the step is at s* = -d0.w / w.w, clamped to [0, 1] (`closest_approach`).

`FleetContacts` checks every pair of robots each step (the gaps in C, `fleet_gaps` of
native/fleet.c), reports a contact once when it begins (`Contact`: both names, the time, both
centres and radii at that time), and keeps each robot's minimum clearance to the other robots
(footprint to footprint).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cosim.world import kernels


def first_contact(a0, a1, b0, b1, reach: float) -> float | None:
    """The first fraction s in [0, 1] of a step at which points moving linearly from a0 to a1 and
    from b0 to b1 come within `reach` [m] of each other (0 when they already are), or None."""
    d0x, d0y = b0[0] - a0[0], b0[1] - a0[1]
    wx, wy = (b1[0] - b0[0]) - (a1[0] - a0[0]), (b1[1] - b0[1]) - (a1[1] - a0[1])
    c = d0x * d0x + d0y * d0y - reach * reach
    if c <= 0.0:
        return 0.0
    a = wx * wx + wy * wy
    b = d0x * wx + d0y * wy  # half the linear coefficient
    if a == 0.0 or b >= 0.0:  # no relative motion, or moving apart from the start
        return None
    discriminant = b * b - a * c
    if discriminant < 0.0:
        return None
    # The smaller root (-b - sqrt(disc)) / a, written as c / (-b + sqrt(disc)) (b < 0: no cancellation).
    s = c / (-b + math.sqrt(discriminant))
    return s if s <= 1.0 else None


def closest_approach(a0, a1, b0, b1) -> tuple[float, float]:
    """(s, distance): the fraction of the step at which the two linearly moving points are
    closest, and their distance [m] then."""
    d0 = np.subtract(b0, a0, dtype=float)
    w = np.subtract(b1, b0, dtype=float) - np.subtract(a1, a0, dtype=float)
    ww = float(w @ w)
    s = 0.0 if ww == 0.0 else min(1.0, max(0.0, -float(d0 @ w) / ww))
    return s, float(np.hypot(*(d0 + s * w)))


@dataclass(frozen=True)
class Contact:
    """Two robots' footprints touching: the robots, the time [s] of the first contact, their
    centres [m] then and their footprint radii [m]."""

    first: str
    second: str
    time: float
    first_center: tuple[float, float]
    second_center: tuple[float, float]
    first_radius: float
    second_radius: float

    def describe(self) -> str:
        return (
            f"{self.first} and {self.second} collide at t = {self.time:.3f} s: footprints "
            f"(r {self.first_radius:g} m at ({self.first_center[0]:.3f}, {self.first_center[1]:.3f})) and "
            f"(r {self.second_radius:g} m at ({self.second_center[0]:.3f}, {self.second_center[1]:.3f}))"
        )


_contacts = None


def _contacts_function():
    """`fleet_contacts` of native/fleet.c, typed (once per process)."""
    global _contacts
    if _contacts is None:
        import ctypes

        function = kernels.fleet_library().fleet_contacts
        function.restype = ctypes.c_int64
        pointer, count = ctypes.c_void_p, ctypes.c_int64
        function.argtypes = [pointer, count, count, pointer, pointer, count] + [pointer] * 5
        _contacts = function
    return _contacts


class FleetContacts:
    """Contacts and clearances between the robots' footprints, step by step (module docstring)."""

    def __init__(self, names: Sequence[str], radii: Sequence[float]) -> None:
        self.names = tuple(names)
        self.radii = np.asarray(radii, dtype=float)
        n = len(self.names)
        self.first, self.second = (
            np.ascontiguousarray(index, dtype=np.int64) for index in np.triu_indices(n, k=1)
        )
        self.reach = np.ascontiguousarray(self.radii[self.first] + self.radii[self.second])
        self.touching = np.zeros(len(self.first), dtype=bool)  # pairs in contact at the last check
        self.min_clearance = np.full(n, math.inf)  # [m] footprint to footprint, per robot
        self.contacts: list[Contact] = []
        self._floor = np.empty(n)  # scratch of `steps`
        self._began = np.empty((0, 2), dtype=np.int64)  # (step, pair) of the contacts `steps` found

    def start(self, positions) -> list[Contact]:
        """The positions (N x 2) at the start: contacts there are reported at time 0 (a scenario's
        starts may not overlap, but positions given in code may)."""
        return self.step(0.0, 0.0, positions, positions)

    def steps(self, starts: Sequence[float], lengths: Sequence[float], positions) -> list[list[Contact]]:
        """`step` for consecutive steps at once: step s from starts[s] to starts[s] + lengths[s]
        [s], the robots moving from positions[s] to positions[s + 1] (S + 1 x N x 2 positions [m]);
        the contacts that began in each step. The same arithmetic as `step`, a step per row, in one
        C call (`fleet_contacts` of native/fleet.c: the gaps, the minimum clearances, the steps in
        which contacts began)."""
        positions = np.ascontiguousarray(positions, dtype=float)
        count, pairs = len(positions) - 1, len(self.first)
        if len(self._began) < count * pairs:
            self._began = np.empty((count * pairs, 2), dtype=np.int64)
        began_at = _contacts_function()(
            positions.ctypes.data, count, positions.shape[1], self.first.ctypes.data, self.second.ctypes.data,
            pairs, self.reach.ctypes.data, self.min_clearance.ctypes.data, self._floor.ctypes.data,
            self.touching.ctypes.data, self._began.ctypes.data,
        )  # fmt: skip
        began: list[list[Contact]] = [[] for _ in range(count)]
        for step, pair in self._began[:began_at].tolist():
            before, after = positions[step], positions[step + 1]
            began[step].append(self._contact(pair, starts[step], lengths[step], before, after))
        for contacts in began:
            self.contacts += contacts
        return began

    def _gaps(self, positions: np.ndarray, floor: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """For each step k (robots from positions[k] to positions[k + 1], S + 1 x N x 2 [m],
        C-contiguous float64) and pair: the least gap [m] over the step (the distance at the
        closest approach of the linearly moving offset, minus the pair's reach) and the gap at the
        step's end; S x pairs each (`fleet_gaps` of native/fleet.c). Both are +inf for a pair
        certainly farther apart than 0 and both robots' `floor` (N, default: the minimum
        clearances; inf: every gap exact)."""
        count, pairs = len(positions) - 1, len(self.first)
        gap, end_gap = np.empty((count, pairs)), np.empty((count, pairs))
        floor = self.min_clearance if floor is None else np.ascontiguousarray(floor, dtype=float)
        kernels.fleet_library().fleet_gaps(
            positions.ctypes.data, count, positions.shape[1], self.first.ctypes.data, self.second.ctypes.data,
            pairs, self.reach.ctypes.data, floor.ctypes.data, gap.ctypes.data, end_gap.ctypes.data,
        )  # fmt: skip
        return gap, end_gap

    def _contact(self, pair: int, t: float, h: float, before, after) -> Contact:
        """The contact of `pair`, which began in the step from t to t + h [s]."""
        a, b = int(self.first[pair]), int(self.second[pair])
        s = first_contact(before[a], after[a], before[b], after[b], float(self.reach[pair]))
        s = 0.0 if s is None else s  # rounding at a grazing touch: the closest approach's step
        at_a = before[a] + s * (after[a] - before[a])
        at_b = before[b] + s * (after[b] - before[b])
        return Contact(
            self.names[a], self.names[b], t + s * h,
            (float(at_a[0]), float(at_a[1])), (float(at_b[0]), float(at_b[1])),
            float(self.radii[a]), float(self.radii[b]),
        )  # fmt: skip

    def step(self, t: float, h: float, before, after) -> list[Contact]:
        """Check the step from t to t + h [s] in which the robots moved from `before` to `after`
        (N x 2 positions [m]); return the contacts that began in it (also kept in `contacts`)."""
        before = np.asarray(before, dtype=float)
        after = np.asarray(after, dtype=float)
        i, j = self.first, self.second
        gaps, end_gaps = self._gaps(np.stack((before, after)))
        gap, end_gap = gaps[0], end_gaps[0]
        np.minimum.at(self.min_clearance, i, gap)
        np.minimum.at(self.min_clearance, j, gap)
        touching = gap <= 0.0
        began = [
            self._contact(int(pair), t, h, before, after)
            for pair in np.flatnonzero(touching & ~self.touching)
        ]
        # A pair still touching at the step's end stays "in contact"; one that separated may touch again.
        self.touching = end_gap <= 0.0
        self.contacts += began
        return began
