"""Motion primitives of hybrid A*: short arcs and straights of a bicycle-model car.

A primitive is driven from a node's pose for `length` [m] at a fixed curvature, forwards or in
reverse. Its end pose and its collision samples are computed once in the node's local frame
(origin, heading +x) and rotated onto each node during the search.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.hybrid_geometry import advance


@dataclass(frozen=True)
class Primitives:
    """The table of motion primitives (P of them) used by the compiled search.

    curvature: [1/m] per primitive (+ left, - right, 0 straight).
    signed_length: [m], negative for reverse.
    cost: g increment per primitive [m-equivalent] (length x reverse/steering multipliers).
    direction: +1 forward, -1 reverse.
    samples: P x M x 3 local poses (x, y, theta) every <= sample_step along the primitive; the
        last valid sample (index sample_count - 1) is the end pose.
    sample_count: samples per primitive.
    """

    curvature: np.ndarray
    signed_length: np.ndarray
    cost: np.ndarray
    direction: np.ndarray
    samples: np.ndarray
    sample_count: np.ndarray


def build_primitives(
    min_turning_radius: float,
    length: float,
    num_curvatures: int,
    reverse: bool,
    reverse_cost: float,
    steering_cost: float,
    sample_step: float,
) -> Primitives:
    """Primitives with curvatures linspace(-1/R, 1/R, num_curvatures) (odd, so straight is one).

    min_turning_radius R [m], length [m] of each primitive, sample_step [m] between collision
    samples. The cost of a primitive is length x (reverse_cost if reverse) x (1 + steering_cost
    x |curvature| R): straight driving is cheapest, full lock costs steering_cost more per metre.
    """
    curvatures = np.linspace(-1.0 / min_turning_radius, 1.0 / min_turning_radius, num_curvatures)
    curvatures[num_curvatures // 2] = 0.0  # exact zero: the straight primitive
    directions = (1, -1) if reverse else (1,)
    pieces = max(1, int(np.ceil(length / sample_step - 1e-9)))
    rows = []
    for direction in directions:
        for curvature in curvatures:
            samples = np.array(
                [
                    advance(0.0, 0.0, 0.0, curvature, direction * length * k / pieces)
                    for k in range(1, pieces + 1)
                ]
            )
            multiplier = (reverse_cost if direction < 0 else 1.0) * (
                1.0 + steering_cost * abs(curvature) * min_turning_radius
            )
            rows.append((curvature, direction * length, length * multiplier, direction, samples))
    return Primitives(
        curvature=np.array([row[0] for row in rows]),
        signed_length=np.array([row[1] for row in rows]),
        cost=np.array([row[2] for row in rows]),
        direction=np.array([row[3] for row in rows], dtype=np.int64),
        samples=np.ascontiguousarray(np.stack([row[4] for row in rows])),
        sample_count=np.full(len(rows), pieces, dtype=np.int64),
    )
