"""Reeds-Shepp lengths and curves against symmetries, straight lines and a brute-force solver.

The brute force is written independently of planner.reeds_shepp: it lists the 48 words of
Reeds & Shepp (1990) explicitly and solves each word's three free segment lengths from the
endpoint equations with scipy, from many starting guesses, then keeps the shortest solution.
"""

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import fsolve

from planner import reeds_shepp

HALF_PI = math.pi / 2


def _end_pose(word, lengths):
    """End pose (x, y, theta) from the origin, R = 1, by composing segments in complex form."""
    position = 0j
    heading = 0.0
    for letter, length in zip(word, lengths, strict=True):
        if letter == "S":
            position += length * np.exp(1j * heading)
        else:
            side = 1.0 if letter == "L" else -1.0
            centre = position + side * 1j * np.exp(1j * heading)
            heading += side * length
            position = centre - side * 1j * np.exp(1j * heading)
    return position.real, position.imag, heading


def _words():
    """The 48 words: (letters, function of the 3 free magnitudes -> signed lengths)."""
    other = {"L": "R", "R": "L"}
    words = []
    for a, s in itertools.product("LR", (1.0, -1.0)):
        b = other[a]
        for c in "LR":  # CSC
            words.append((a + "S" + c, lambda t, u, v, s=s: (s * t, s * u, s * v)))
        words.append((a + b + a, lambda t, u, v, s=s: (s * t, -s * u, s * v)))  # C|C|C
        words.append((a + b + a, lambda t, u, v, s=s: (s * t, -s * u, -s * v)))  # C|CC
        words.append((a + b + a, lambda t, u, v, s=s: (s * t, s * u, -s * v)))  # CC|C
        words.append((a + b + a + b, lambda t, u, v, s=s: (s * t, s * u, -s * u, -s * v)))  # CCu|CuC
        words.append((a + b + a + b, lambda t, u, v, s=s: (s * t, -s * u, -s * u, s * v)))  # C|CuCu|C
        for c in (a, b):  # C|C(pi/2)SC and its reverse CSC(pi/2)|C
            words.append((a + b + "S" + c, lambda t, u, v, s=s: (s * t, -s * HALF_PI, -s * u, -s * v)))
            words.append((c + "S" + b + a, lambda t, u, v, s=s: (-s * v, -s * u, -s * HALF_PI, s * t)))
        words.append(  # C|C(pi/2)SC(pi/2)|C
            (a + b + "S" + a + b, lambda t, u, v, s=s: (s * t, -s * HALF_PI, -s * u, -s * HALF_PI, s * v))
        )
    return words


WORDS = _words()
GUESSES = [np.array(g) for g in itertools.product((0.4, 1.6, 3.0), (0.4, 2.0, 5.0), (0.4, 1.6, 3.0))]


def brute_force_length(goal, words=WORDS, guesses=GUESSES):
    """Shortest solution length over all words (R = 1) by root finding on the endpoint equations."""
    gx, gy, gphi = goal
    best = math.inf
    for word, signed in words:

        def residual(p, word=word, signed=signed):
            x, y, theta = _end_pose(word, signed(*p))
            return [x - gx, y - gy, math.sin(theta - gphi)]

        for guess in guesses:
            solution, info, status, _ = fsolve(residual, guess, full_output=True, xtol=1e-13)
            if status != 1 or np.any(solution < -1e-9):
                continue
            x, y, theta = _end_pose(word, signed(*solution))
            heading_error = abs(math.remainder(theta - gphi, 2 * math.pi))
            if math.hypot(x - gx, y - gy) < 1e-9 and heading_error < 1e-9:
                best = min(best, sum(abs(v) for v in signed(*solution)))
    return best


def test_the_brute_force_lists_48_distinct_words():
    signatures = set()
    for word, signed in WORDS:
        signs = tuple(np.sign(signed(1.0, 1.0, 1.0)))
        signatures.add((word, signs))
    assert len(signatures) == 48


@pytest.mark.slow
def test_every_candidate_ends_at_the_goal_and_all_48_words_occur():
    rng = np.random.default_rng(1)
    seen = set()
    for _ in range(1500):
        start = (*rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi))
        goal = (*rng.uniform(-9, 9, 2), rng.uniform(-math.pi, math.pi))
        radius = rng.uniform(0.5, 3.0)
        for path in reeds_shepp.all_paths(start, goal, radius):
            poses, directions = path.sample(start, 0.05)
            assert np.hypot(*(poses[-1, :2] - goal[:2])) < 1e-7
            assert abs(math.remainder(poses[-1, 2] - goal[2], 2 * math.pi)) < 1e-7
            assert set(directions) <= {int(np.sign(v)) for v in path.lengths}
            seen.add((path.word, tuple(np.sign(path.lengths))))
    expected = {(word, tuple(np.sign(signed(1.0, 1.0, 1.0)))) for word, signed in WORDS}
    assert expected <= seen


@pytest.mark.parametrize("seed", range(6))
def test_shortest_length_matches_brute_force(seed):
    rng = np.random.default_rng(100 + seed)
    goal = (*rng.uniform(-6, 6, 2), rng.uniform(-math.pi, math.pi))
    analytic = reeds_shepp.path_length((0.0, 0.0, 0.0), goal, 1.0)
    assert analytic == pytest.approx(brute_force_length(goal), abs=1e-6)


def test_brute_force_agreement_on_close_manoeuvres():
    # Short parallel-parking-like offsets are where the CCCC and CCSCC words win.
    for goal in [(0.5, 1.0, 0.0), (-0.3, 0.8, 0.5), (1.0, 0.2, math.pi / 2), (0.2, -1.5, 2.8)]:
        analytic = reeds_shepp.path_length((0.0, 0.0, 0.0), goal, 1.0)
        assert analytic == pytest.approx(brute_force_length(goal), abs=1e-6)


def test_symmetries_of_the_length():
    rng = np.random.default_rng(7)
    for _ in range(300):
        x, y = rng.uniform(-8, 8, 2)
        phi = rng.uniform(-math.pi, math.pi)
        radius = rng.uniform(0.5, 2.0)
        length = reeds_shepp.path_length((0, 0, 0), (x, y, phi), radius)
        # reversing the motion: a -> b equals b -> a
        assert reeds_shepp.path_length((x, y, phi), (0, 0, 0), radius) == pytest.approx(length, abs=1e-9)
        # time flip and reflection
        assert reeds_shepp.path_length((0, 0, 0), (-x, y, -phi), radius) == pytest.approx(length, abs=1e-9)
        assert reeds_shepp.path_length((0, 0, 0), (x, -y, -phi), radius) == pytest.approx(length, abs=1e-9)
        # invariance under a rigid motion of both poses
        shift, turn = rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi)
        rotation = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
        a = (*shift, turn)
        b = (*(rotation @ [x, y] + shift), phi + turn)
        assert reeds_shepp.path_length(a, b, radius) == pytest.approx(length, abs=1e-9)


def test_triangle_inequality():
    rng = np.random.default_rng(8)
    for _ in range(500):
        a, b, c = ((*rng.uniform(-6, 6, 2), rng.uniform(-math.pi, math.pi)) for _ in range(3))
        ab = reeds_shepp.path_length(a, b, 1.3)
        bc = reeds_shepp.path_length(b, c, 1.3)
        ac = reeds_shepp.path_length(a, c, 1.3)
        assert ac <= ab + bc + 1e-9


def test_straight_line_goals_give_the_euclidean_distance():
    for distance in (0.1, 1.0, 7.5):
        for heading in (0.0, 1.0, -2.5):
            start = (1.0, 2.0, heading)
            ahead = (1.0 + distance * math.cos(heading), 2.0 + distance * math.sin(heading), heading)
            behind = (1.0 - distance * math.cos(heading), 2.0 - distance * math.sin(heading), heading)
            assert reeds_shepp.path_length(start, ahead, 2.0) == pytest.approx(distance, abs=1e-9)
            assert reeds_shepp.path_length(start, behind, 2.0) == pytest.approx(distance, abs=1e-9)
            path = reeds_shepp.shortest_path(start, behind, 2.0)
            assert path.word == "S" and path.lengths[0] < 0


def test_quarter_turn_is_a_quarter_circle():
    radius = 2.0
    assert reeds_shepp.path_length((0, 0, 0), (radius, radius, HALF_PI), radius) == pytest.approx(
        HALF_PI * radius, abs=1e-9
    )


def test_sampled_curve_keeps_curvature_and_spacing():
    rng = np.random.default_rng(3)
    radius, step = 1.5, 0.1
    for _ in range(50):
        goal = (*rng.uniform(-8, 8, 2), rng.uniform(-math.pi, math.pi))
        path = reeds_shepp.shortest_path((0, 0, 0), goal, radius)
        poses, _ = path.sample((0, 0, 0), step)
        spacing = np.hypot(*np.diff(poses[:, :2], axis=0).T)
        assert spacing.max() <= step + 1e-9
        turn = np.abs(np.remainder(np.diff(poses[:, 2]) + math.pi, 2 * math.pi) - math.pi)
        # heading change per arc length never exceeds 1/R (chord <= arc, so divide by chord)
        moving = spacing > 1e-6
        assert np.all(turn[moving] <= spacing[moving] / radius * (1 + 1e-3) + 1e-9)
