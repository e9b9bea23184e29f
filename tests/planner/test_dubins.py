"""Dubins lengths and curves against straight lines, the triangle inequality and a brute force.

The brute force is independent of planner.dubins: for each of the six words it solves the three
segment lengths numerically with scipy from the endpoint equations (many starting guesses) and
keeps the shortest non-negative solution.
"""

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import fsolve

from planner import dubins, reeds_shepp

WORDS = ["LSL", "RSR", "LSR", "RSL", "LRL", "RLR"]
GUESSES = [np.array(g) for g in itertools.product((0.5, 2.5, 5.0), (0.5, 3.0, 5.5), (0.5, 2.5, 5.0))]


def _end_pose(word, lengths):
    """End pose from the origin (R = 1) by rotating about each arc's centre (rotation matrices)."""
    x, y, heading = 0.0, 0.0, 0.0
    for letter, length in zip(word, lengths, strict=True):
        if letter == "S":
            x, y = x + length * math.cos(heading), y + length * math.sin(heading)
            continue
        side = 1.0 if letter == "L" else -1.0
        cx, cy = x - side * math.sin(heading), y + side * math.cos(heading)
        angle = side * length
        rx, ry = x - cx, y - cy
        x = cx + rx * math.cos(angle) - ry * math.sin(angle)
        y = cy + rx * math.sin(angle) + ry * math.cos(angle)
        heading += angle
    return x, y, heading


def brute_force_length(goal):
    gx, gy, gphi = goal
    best = math.inf
    for word in WORDS:

        def residual(p, word=word):
            x, y, theta = _end_pose(word, p)
            return [x - gx, y - gy, math.sin(theta - gphi)]

        for guess in GUESSES:
            solution, _, status, _ = fsolve(residual, guess, full_output=True, xtol=1e-13)
            if status != 1 or np.any(solution < -1e-9) or np.any(solution[[0, 2]] > 2 * math.pi):
                continue
            x, y, theta = _end_pose(word, solution)
            if math.hypot(x - gx, y - gy) < 1e-9 and abs(math.remainder(theta - gphi, 2 * math.pi)) < 1e-9:
                best = min(best, float(np.sum(solution)))
    return best


@pytest.mark.parametrize("seed", range(10))
def test_shortest_length_matches_brute_force(seed):
    rng = np.random.default_rng(200 + seed)
    goal = (*rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi))
    assert dubins.path_length((0, 0, 0), goal, 1.0) == pytest.approx(brute_force_length(goal), abs=1e-6)


def test_close_goals_need_ccc_and_match_brute_force():
    for goal in [(0.5, 0.3, math.pi), (1.0, 0.0, 0.5), (-0.5, 0.5, -2.0)]:
        analytic = dubins.shortest_path((0, 0, 0), goal, 1.0)
        assert analytic.length == pytest.approx(brute_force_length(goal), abs=1e-6)


def test_every_candidate_ends_at_the_goal_driving_forwards():
    rng = np.random.default_rng(4)
    words = set()
    for _ in range(1000):
        start = (*rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi))
        goal = (*rng.uniform(-9, 9, 2), rng.uniform(-math.pi, math.pi))
        radius = rng.uniform(0.5, 3.0)
        for path in dubins.all_paths(start, goal, radius):
            poses, directions = path.sample(start, 0.05)
            assert np.hypot(*(poses[-1, :2] - goal[:2])) < 1e-7
            assert abs(math.remainder(poses[-1, 2] - goal[2], 2 * math.pi)) < 1e-7
            assert np.all(directions == 1) and min(path.lengths) >= 0
            words.add(path.word)
    assert words == set(WORDS)


def test_straight_ahead_is_the_euclidean_distance():
    for distance, heading in [(0.2, 0.0), (3.0, 1.2), (12.0, -2.0)]:
        goal = (distance * math.cos(heading), distance * math.sin(heading), heading)
        assert dubins.path_length((0, 0, heading), goal, 1.7) == pytest.approx(distance, abs=1e-9)


def test_goal_behind_needs_a_turn_and_is_longer_than_reeds_shepp():
    # Straight behind: Reeds-Shepp reverses (length d); a forward-only car must turn around.
    start, goal = (0.0, 0.0, 0.0), (-4.0, 0.0, 0.0)
    assert reeds_shepp.path_length(start, goal, 1.0) == pytest.approx(4.0)
    assert dubins.path_length(start, goal, 1.0) > 4.0 + 2 * math.pi - 1e-9


def test_triangle_inequality_and_dubins_never_beats_reeds_shepp():
    rng = np.random.default_rng(9)
    for _ in range(500):
        a, b, c = ((*rng.uniform(-6, 6, 2), rng.uniform(-math.pi, math.pi)) for _ in range(3))
        ab, bc, ac = (dubins.path_length(p, q, 1.2) for p, q in ((a, b), (b, c), (a, c)))
        assert ac <= ab + bc + 1e-9
        assert ac >= reeds_shepp.path_length(a, c, 1.2) - 1e-9


def test_reflection_symmetry_and_rigid_motion_invariance():
    rng = np.random.default_rng(10)
    for _ in range(200):
        x, y, phi = *rng.uniform(-6, 6, 2), rng.uniform(-math.pi, math.pi)
        length = dubins.path_length((0, 0, 0), (x, y, phi), 1.0)
        assert dubins.path_length((0, 0, 0), (x, -y, -phi), 1.0) == pytest.approx(length, abs=1e-9)
        # Reversing a forward path: b -> a mirrored through the heading axis.
        backwards = (x * math.cos(phi) + y * math.sin(phi), x * math.sin(phi) - y * math.cos(phi), phi)
        assert dubins.path_length((0, 0, 0), backwards, 1.0) == pytest.approx(length, abs=1e-9)
        turn = rng.uniform(-math.pi, math.pi)
        moved = (x * math.cos(turn) - y * math.sin(turn) + 2, x * math.sin(turn) + y * math.cos(turn) - 1)
        assert dubins.path_length((2, -1, turn), (*moved, phi + turn), 1.0) == pytest.approx(length, abs=1e-9)
