"""Robots seeing and touching each other: against geometry computed here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.world.fleet import FleetContacts, closest_approach, first_contact
from cosim.world.lidar import Lidar


def _sampled_first_contact(a0, a1, b0, b1, reach, samples=200_001):
    """First sample s (of a fine grid on [0, 1]) at which the centres are within `reach`."""
    s = np.linspace(0.0, 1.0, samples)
    a = np.asarray(a0) + s[:, None] * (np.asarray(a1) - a0)
    b = np.asarray(b0) + s[:, None] * (np.asarray(b1) - b0)
    inside = np.flatnonzero(np.hypot(*(b - a).T) <= reach)
    return None if inside.size == 0 else s[inside[0]]


def test_head_on_contact_time_is_where_the_gap_closes():
    # Centres 10 m apart closing at 1 + 2 m/s over a 5 s "step": radii 0.5 + 0.5 touch after 3 s.
    s = first_contact((0.0, 0.0), (5.0, 0.0), (10.0, 0.0), (0.0, 0.0), reach=1.0)
    assert s * 5.0 == pytest.approx(3.0, abs=1e-12)


@pytest.mark.parametrize("seed", range(40))
def test_contact_time_matches_a_sampled_distance(seed):
    rng = np.random.default_rng(seed)
    a0, a1, b0, b1 = (rng.uniform(-3, 3, 2) for _ in range(4))
    reach = rng.uniform(0.2, 2.0)
    expected = _sampled_first_contact(a0, a1, b0, b1, reach)
    got = first_contact(a0, a1, b0, b1, reach)
    if expected is None:
        assert got is None or _sampled_first_contact(a0, a1, b0, b1, reach * (1 + 1e-6)) is not None
    else:
        assert got == pytest.approx(expected, abs=2e-5)
    s, distance = closest_approach(a0, a1, b0, b1)
    sampled = np.linspace(0, 1, 200_001)
    gaps = np.hypot(*((b0 - a0) + sampled[:, None] * ((b1 - b0) - (a1 - a0))).T)
    assert distance == pytest.approx(gaps.min(), abs=1e-9)


def test_contacts_report_both_names_time_and_footprints_once():
    contacts = FleetContacts(["r1", "r2", "r3"], [0.5, 0.3, 0.4])
    # r1 and r2 close at 2 m/s from 2 m apart; r3 far away. Steps of 0.1 s.
    h = 0.1
    positions = lambda t: np.array([[0.0 + t, 0.0], [2.0 - t, 0.0], [50.0, 50.0]])  # noqa: E731
    began = []
    for k in range(15):
        began += contacts.step(k * h, h, positions(k * h), positions((k + 1) * h))
    (contact,) = began  # reported when it begins, not at every step in contact
    # Touching when 2 - 2 t = 0.8: t = 0.6 s.
    assert (contact.first, contact.second) == ("r1", "r2")
    assert contact.time == pytest.approx(0.6, abs=1e-12)
    assert contact.first_center == pytest.approx((0.6, 0.0)) and contact.second_center == pytest.approx(
        (1.4, 0.0)
    )
    assert (contact.first_radius, contact.second_radius) == (0.5, 0.3)
    assert "r1 and r2 collide at t = 0.600 s" in contact.describe()
    # r3's clearance: to r2 at its nearest (x = 2 - 1.5 = 0.5 at the end): distance - 0.7.
    nearest = min(math.hypot(50 - x2, 50) for x2 in (2.0 - t * h for t in range(16)))
    assert contacts.min_clearance[2] == pytest.approx(min(nearest - 0.7, math.hypot(50 - 1.5, 50) - 0.9))
    assert contacts.min_clearance[0] < 0  # overlapping after the contact


def _lidar_with_robots(radii, angles):
    return Lidar(angles=angles, range_max=30.0, robot_radii=radii)


def test_lidar_sees_other_robots_circles_at_their_inputs():
    angles = np.linspace(-0.3, 0.3, 61)
    lidar = _lidar_with_robots([0.5, 0.8], angles)
    assert [p.name for p in lidar.inputs][3:] == ["robots_x[1]", "robots_x[2]", "robots_y[1]", "robots_y[2]"]
    x, y, theta = 1.0, 2.0, 0.4
    others = [(1.0 + 6 * math.cos(0.4), 2.0 + 6 * math.sin(0.4)), (math.nan, math.nan)]
    lidar.instantiate()
    lidar.setup(0.0, {})
    lidar.set_inputs(list(range(7)), [x, y, theta, others[0][0], others[1][0], others[0][1], others[1][1]])
    lidar.initialize()
    ranges = lidar.get_outputs()[: len(angles)]
    # A beam at angle a from the line of sight to a circle at distance d, radius r, meets it at
    # d cos a - sqrt(r^2 - d^2 sin^2 a), when d |sin a| <= r.
    d, r = 6.0, 0.5
    expected = np.array(
        [
            d * math.cos(a) - math.sqrt(r * r - (d * math.sin(a)) ** 2)
            if d * abs(math.sin(a)) <= r
            else np.nan
            for a in angles
        ]
    )
    np.testing.assert_allclose(ranges, expected, rtol=0, atol=1e-9, equal_nan=True)
    assert np.isfinite(ranges).sum() > 3
    # The second robot arrives 3 m straight ahead (radius 0.8): the next scan sees it in front.
    lidar.set_inputs([4, 6], [x + 3 * math.cos(theta), y + 3 * math.sin(theta)])
    lidar.do_step(0.0, 0.1)
    assert lidar.get_outputs()[30] == pytest.approx(3 - 0.8, abs=1e-12)


def test_a_lidar_without_robots_has_its_three_inputs():
    lidar = Lidar(angles=[0.0])
    assert [p.name for p in lidar.inputs] == ["x", "y", "theta"]


def _numpy_gaps(positions, first, second, reach):
    """The NumPy description the C kernel replaced: per step and pair, the least gap over the step
    (closest approach of the linearly moving offset minus reach) and the gap at the step's end."""
    x, y = positions[:, :, 0], positions[:, :, 1]
    dx, dy = x[:, second] - x[:, first], y[:, second] - y[:, first]
    d0x, d0y, d1x, d1y = dx[:-1], dy[:-1], dx[1:], dy[1:]
    wx, wy = d1x - d0x, d1y - d0y
    ww = wx * wx + wy * wy
    dw = d0x * wx + d0y * wy
    s_star = np.zeros_like(ww)
    np.divide(-dw, ww, out=s_star, where=ww > 0.0)
    np.clip(s_star, 0.0, 1.0, out=s_star)
    return np.hypot(d0x + s_star * wx, d0y + s_star * wy) - reach, np.hypot(d1x, d1y) - reach


def test_the_gaps_are_the_numpy_descriptions_bit_for_bit():
    """`fleet_gaps` (C) against the NumPy arithmetic it replaced: robots moving, standing still
    (no relative motion), on top of each other, approaching and passing within a step."""
    rng = np.random.default_rng(4)
    n, steps = 9, 12
    radii = rng.uniform(0.2, 0.8, n)
    contacts = FleetContacts([f"r{k}" for k in range(n)], radii)
    start = rng.uniform(0.0, 6.0, (1, n, 2))
    moves = rng.normal(0.0, 0.3, (steps, n, 2))
    moves[:, 2] = 0.0  # stands still
    moves[:, 3] = moves[:, 4]  # moves with robot 4: no relative motion
    positions = np.concatenate((start, start + np.cumsum(moves, axis=0)))
    positions[:, 5] = positions[:, 6]  # on top of each other
    positions = np.ascontiguousarray(positions)
    gap, end_gap = contacts._gaps(positions, np.full(n, np.inf))
    expected_gap, expected_end = _numpy_gaps(positions, contacts.first, contacts.second, contacts.reach)
    assert np.array_equal(gap, expected_gap) and np.array_equal(end_gap, expected_end)
    assert (gap <= 0).any() and (gap > 0).any()
    # With floors (the clearances so far), a pair certainly farther apart than both robots' floor
    # and 0 gets +inf: every other gap is exact, and no skipped one was within the floors.
    floor = rng.uniform(-0.2, 1.5, n)
    gap, end_gap = contacts._gaps(positions, floor)
    skipped = np.isinf(gap)
    assert np.array_equal(np.isinf(end_gap), skipped) and 0 < skipped.sum() < skipped.size
    assert np.array_equal(gap[~skipped], expected_gap[~skipped])
    assert np.array_equal(end_gap[~skipped], expected_end[~skipped])
    above = np.maximum(np.maximum(floor[contacts.first], floor[contacts.second]), 0.0)
    assert (expected_gap[skipped] > np.broadcast_to(above, gap.shape)[skipped]).all()
    assert (expected_end[skipped] > 0).all()


@pytest.mark.parametrize("seed", range(4))
def test_steps_at_once_report_what_step_by_step_reports(seed):
    """`FleetContacts.steps` (one C pass over a block's steps) against `step` called for each step
    (the gaps, then NumPy): the same contacts, in the same order, the same clearances and touching
    pairs, over blocks in which pairs touch, separate and touch again."""
    rng = np.random.default_rng(seed)
    n, blocks, count, h = 7, 6, 10, 0.1
    radii = rng.uniform(0.2, 0.6, n)
    start = rng.uniform(0.0, 3.0, (1, n, 2))
    moves = rng.normal(0.0, 0.25, (blocks * count, n, 2))
    positions = np.concatenate((start, start + np.cumsum(moves, axis=0)))
    at_once = FleetContacts([f"r{k}" for k in range(n)], radii)
    one_by_one = FleetContacts([f"r{k}" for k in range(n)], radii)
    for contacts in (at_once, one_by_one):
        contacts.start(positions[0])
    for b in range(blocks):
        first = b * count
        starts = [(first + i) * h for i in range(count)]
        began = at_once.steps(starts, [h] * count, positions[first : first + count + 1])
        expected = [
            one_by_one.step(starts[i], h, positions[first + i], positions[first + i + 1])
            for i in range(count)
        ]
        assert began == expected
        assert np.array_equal(at_once.min_clearance, one_by_one.min_clearance)
        assert np.array_equal(at_once.touching, one_by_one.touching)
    assert at_once.contacts == one_by_one.contacts
    # Pairs began touching in several blocks, some more than once (the test sees contacts begin).
    assert len({(c.first, c.second) for c in at_once.contacts}) < len(at_once.contacts)
