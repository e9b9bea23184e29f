"""What makes big fleets cheaper must not change a result: the lidar skipping robots beyond its
range (against the analytic ray-circle distance at the range's edge and a scan of the same world
without the skip), the pairwise contact check (against a plain loop over the pairs with the
module's own per-pair functions) and FMU instances sharing one unpacked folder."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from cosim.fmi.archive import unpack_instance
from cosim.world.fleet import FleetContacts, closest_approach, first_contact
from cosim.world.lidar import Lidar
from cosim.world.shapes import Circle

RANGE = 20.0


def _scan(lidar: Lidar, pose, others) -> np.ndarray:
    lidar.instantiate()
    lidar.setup(0.0, {})
    count = len(others)
    values = [*pose, *(p[0] for p in others), *(p[1] for p in others)]
    lidar.set_inputs(list(range(3 + 2 * count)), values)
    lidar.initialize()
    return lidar.get_outputs()[: len(lidar.beam_angles)].copy()


@pytest.mark.parametrize("gap", [-1e-6, 1e-6, 0.3])
def test_a_robot_at_the_edge_of_the_range_is_seen_exactly_when_its_outline_is_in_range(gap):
    """A robot of radius r straight ahead at distance RANGE + r - gap: its outline at RANGE - gap."""
    radius = 0.5
    distance = RANGE + radius - gap
    lidar = Lidar(angles=[0.0, 0.01, math.pi], range_max=RANGE, robot_radii=[radius, 0.5])
    ranges = _scan(lidar, (1.0, 2.0, 0.0), [(1.0 + distance, 2.0), (math.nan, math.nan)])
    if gap > 0:
        assert ranges[0] == pytest.approx(RANGE - gap, abs=1e-9)
        b = distance * math.cos(0.01)  # the beam at 0.01 rad: the smaller root of the ray-circle quadratic
        hit = b - math.sqrt(b * b - distance**2 + radius**2)
        if hit <= RANGE:
            assert ranges[1] == pytest.approx(hit, abs=1e-9)
        else:
            assert np.isnan(ranges[1])
    else:
        assert np.isnan(ranges[:2]).all()  # beyond the range: a missed reading
    assert np.isnan(ranges[2])


def test_skipping_far_robots_changes_no_range():
    """Fifty robots scattered over 100 m: the scan equals the true distances of `measure` (which
    skips nothing) wherever those are within the range, NaN elsewhere, bit for bit."""
    rng = np.random.default_rng(7)
    positions = rng.uniform(-50.0, 50.0, (50, 2))
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    lidar = Lidar(angles=angles, range_max=RANGE, robot_radii=[0.5] * 50, obstacles=[Circle((3.0, 4.0), 1.0)])
    pose = (0.5, -0.25, 0.3)
    ranges = _scan(lidar, pose, [tuple(p) for p in positions])
    directions = np.column_stack([np.cos(angles + pose[2]), np.sin(angles + pose[2])])
    truth = lidar.measure(pose[0], pose[1], pose[2], directions)
    expected = np.where(truth <= RANGE, truth, np.nan)
    assert np.isfinite(expected).sum() > 20  # some robots are within the range
    assert np.array_equal(ranges, expected, equal_nan=True)


def test_contacts_equal_a_loop_over_the_pairs():
    rng = np.random.default_rng(3)
    n, steps, h = 12, 300, 0.01
    radii = rng.uniform(0.3, 0.6, n)
    start = rng.uniform(0.0, 8.0, (n, 2))
    velocity = rng.normal(0.0, 1.0, (n, 2))
    path = [start + k * h * velocity for k in range(steps + 1)]
    contacts = FleetContacts([f"r{k}" for k in range(n)], radii)
    contacts.start(path[0])
    clearance = np.full(n, math.inf)
    touching: set[tuple[int, int]] = set()
    expected = []
    for a in range(n):  # the start: overlaps at t = 0
        for b in range(a + 1, n):
            gap = math.dist(path[0][a], path[0][b]) - radii[a] - radii[b]
            clearance[a], clearance[b] = min(clearance[a], gap), min(clearance[b], gap)
            if gap <= 0:
                expected.append((f"r{a}", f"r{b}", 0.0))
                touching.add((a, b))
    for k in range(steps):
        t = k * h
        contacts.step(t, h, path[k], path[k + 1])
        for a in range(n):
            for b in range(a + 1, n):
                reach = radii[a] + radii[b]
                _, distance = closest_approach(path[k][a], path[k + 1][a], path[k][b], path[k + 1][b])
                gap = distance - reach
                clearance[a], clearance[b] = min(clearance[a], gap), min(clearance[b], gap)
                if gap <= 0 and (a, b) not in touching:
                    s = first_contact(path[k][a], path[k + 1][a], path[k][b], path[k + 1][b], reach)
                    expected.append((f"r{a}", f"r{b}", t + (0.0 if s is None else s) * h))
                if math.dist(path[k + 1][a], path[k + 1][b]) <= reach:
                    touching.add((a, b))
                else:
                    touching.discard((a, b))
    assert len(expected) > 5
    assert [(c.first, c.second) for c in contacts.contacts] == [e[:2] for e in expected]
    assert [c.time for c in contacts.contacts] == pytest.approx([e[2] for e in expected], abs=1e-12)
    assert contacts.min_clearance == pytest.approx(clearance, abs=1e-12)


def test_shareable_fmu_instances_share_one_folder_until_the_last_lets_go():
    from fixtures.conftest_helpers import fixture_fmu

    path = fixture_fmu("diffdrive_fmi2")
    everything = lambda member: True  # noqa: E731
    first, release_first = unpack_instance(path, everything, "t-", shareable=True)
    second, release_second = unpack_instance(path, everything, "t-", shareable=True)
    assert first == second and os.path.isfile(os.path.join(first, "modelDescription.xml"))
    release_first()
    release_first()  # a second call gives nothing back twice
    assert os.path.isdir(first)  # the second instance still uses it
    release_second()
    assert not os.path.exists(first)
    own, release_own = unpack_instance(path, everything, "t-", shareable=False)
    other, release_other = unpack_instance(path, everything, "t-", shareable=False)
    assert own != other and os.path.isfile(os.path.join(own, "modelDescription.xml"))
    release_own()
    assert not os.path.exists(own) and os.path.isdir(other)
    release_other()
    assert not os.path.exists(other)
