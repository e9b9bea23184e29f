"""VectorFieldHistogram FMU: VFH+ behaviour on hand-built scans, and a second implementation
(MATLAB's matrix formulation with cross products, in NumPy) compared on random scans."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fmu_harness import FmuInstance, array_inputs

CAPACITY = 720
ANGLES = np.linspace(-math.pi, math.pi, CAPACITY, endpoint=False)  # a 360-degree lidar, 0.5 degree apart
DEFAULTS = {
    "num_angular_sectors": 180,
    "distance_limit_min": 0.05,
    "distance_limit_max": 2.0,
    "robot_radius": 0.1,
    "safety_distance": 0.1,
    "min_turning_radius": 0.1,
    "target_direction_weight": 5.0,
    "current_direction_weight": 2.0,
    "previous_direction_weight": 2.0,
    "histogram_threshold_low": 3.0,
    "histogram_threshold_high": 10.0,
    "narrow_opening_threshold": 0.8,
}


def scan_inputs(ranges, angles=ANGLES, target_dir: float = 0.0) -> dict[str, float]:
    return {
        **array_inputs("ranges", ranges, CAPACITY),
        **array_inputs("angles", angles, CAPACITY),
        "target_dir": target_dir,
    }


def vfh(**parameters) -> FmuInstance:
    return FmuInstance("VectorFieldHistogram").initialize(parameters)


def run(fmu: FmuInstance, ranges, target_dir: float = 0.0, angles=ANGLES) -> dict:
    fmu.set(scan_inputs(ranges, angles, target_dir))
    fmu.step()
    return fmu.outputs()


def wall_ranges(x: float, y_low: float, y_high: float, angles=ANGLES) -> np.ndarray:
    """Ranges to the segment x = const, y in [y_low, y_high]; NaN for beams that miss it."""
    with np.errstate(divide="ignore", invalid="ignore"):
        distance = x / np.cos(angles)
        y = distance * np.sin(angles)
    return np.where((np.cos(angles) > 0) & (y >= y_low) & (y <= y_high), distance, np.nan)


def test_free_scan_steers_to_the_target():
    with vfh() as fmu:
        out = run(fmu, np.full(CAPACITY, np.nan), target_dir=0.7)
        assert out["steering_dir"] == pytest.approx(0.7)
        assert out["free_sectors"] == 180 and out["num_valleys"] == 1 and out["target_dir_free"]
        # Readings beyond the distance limits do not count either.
        out = run(fmu, np.full(CAPACITY, 5.0), target_dir=-1.2)
        assert out["steering_dir"] == pytest.approx(-1.2) and out["free_sectors"] == 180


def test_wall_ahead_gives_a_free_valley_on_the_nearer_side_clear_of_the_wall():
    clearance = DEFAULTS["robot_radius"] + DEFAULTS["safety_distance"]
    ranges = wall_ranges(1.0, -0.3, 0.8)  # reaches farther to the left than to the right
    with vfh() as fmu:
        out = run(fmu, ranges, target_dir=0.0)
    assert not out["target_dir_free"]
    steering = out["steering_dir"]
    assert steering < 0  # the right end of the wall is nearer
    # The ray along the steering direction passes the wall's right end (1, -0.3) with clearance.
    end = np.array([1.0, -0.3])
    direction = np.array([math.cos(steering), math.sin(steering)])
    miss_distance = abs(direction[0] * end[1] - direction[1] * end[0])
    assert math.atan2(end[1], end[0]) - steering > 0 and miss_distance > clearance
    # The free space around the back is split at +-pi: valleys are not circular (as MATLAB).
    assert out["num_valleys"] == 2 and 0 < out["free_sectors"] < 180


def test_fully_enclosed_gives_nan_then_recovers_without_a_stale_previous_direction():
    with vfh() as fmu:
        out = run(fmu, np.full(CAPACITY, 0.5), target_dir=0.3)
        assert math.isnan(out["steering_dir"])
        assert out["free_sectors"] == 0 and out["num_valleys"] == 0 and not out["target_dir_free"]
        out = run(fmu, np.full(CAPACITY, np.nan), target_dir=0.3)
        assert out["steering_dir"] == pytest.approx(0.3)


def test_hysteresis_keeps_the_previous_state_between_the_thresholds():
    # One reading on the mid-point of the sector at 1 degree (always within its own enlargement
    # angle); its weight a - d = 20 - d is that sector's density, and the target points at it.
    sector_midpoint = math.radians(1.0)
    with vfh(distance_limit_max=20.0) as fmu:

        def target_free(distance: float) -> bool:
            out = run(fmu, [distance], target_dir=sector_midpoint, angles=[sector_midpoint])
            return bool(out["target_dir_free"])

        assert target_free(15.0)  # density 5, between 3 and 10: stays free (initially free)
        assert not target_free(5.0)  # density 15 > 10: occupied
        assert not target_free(15.0)  # density 5 again: stays occupied
        assert target_free(18.0)  # density 2 < 3: free
        assert target_free(15.0)  # density 5: stays free


def test_turning_radius_mask_closes_the_side_behind_a_close_obstacle():
    # A close reading at -0.5 rad: its density (2 - 0.5 = 1.5) is below the low threshold, so only
    # the mask can close anything. It lies inside the enlarged right turning circle of radius 1.
    ranges, angles = [0.5], [-0.5]
    with vfh(min_turning_radius=1.0) as fmu:
        out = run(fmu, ranges, target_dir=-2.0, angles=angles)
        assert not out["target_dir_free"]
        assert out["steering_dir"] >= -0.5
        mirrored = run(fmu, ranges, target_dir=2.0, angles=[0.5])
        assert not mirrored["target_dir_free"] and mirrored["steering_dir"] <= 0.5
    with vfh(min_turning_radius=0.0) as fmu:
        out = run(fmu, ranges, target_dir=-2.0, angles=angles)
        assert out["target_dir_free"] and out["steering_dir"] == pytest.approx(-2.0)


def test_more_than_720_readings_cannot_be_given():
    with vfh() as fmu:
        assert "ranges[720]" in fmu.variables and "angles[720]" in fmu.variables
        assert "ranges[721]" not in fmu.variables and "angles[721]" not in fmu.variables


def angle_difference(a, b):
    """b - a wrapped to [-pi, pi] (MATLAB angdiff)."""
    return np.arctan2(np.sin(b - a), np.cos(b - a))


class ReferenceVfh:
    """VFH+ in MATLAB's matrix form: sector membership by the signs of cross products of
    the range-end, sector and range-start vectors; valleys from diff([0 free 0])."""

    def __init__(self, p: dict) -> None:
        self.p = p
        n = p["num_angular_sectors"]
        self.midpoints = np.linspace(-math.pi + math.pi / n, math.pi - math.pi / n, n)
        self.binary = np.zeros(n, dtype=bool)
        self.previous = 0.0

    def density(self, ranges: np.ndarray, angles: np.ndarray) -> np.ndarray:
        p = self.p
        sine = (p["robot_radius"] + p["safety_distance"]) / ranges
        sine[sine >= 1] = 1 - np.finfo(float).eps
        enlargement = np.arcsin(sine)
        lower, higher = angles - enlargement, angles + enlargement
        mid = self.midpoints[:, None]
        lower_to_mid = np.sign(np.sin(mid - lower))  # z of cross(lower, mid)
        mid_to_higher = np.sign(np.sin(higher - mid))
        lower_to_higher = np.sign(np.sin(higher - lower))
        inside = np.abs(lower_to_mid + mid_to_higher + lower_to_higher) > 1
        return inside.astype(float) @ (p["distance_limit_max"] - ranges)

    def step(self, ranges, angles, target: float):
        p = self.p
        ranges, angles = np.asarray(ranges, float), np.asarray(angles, float)
        keep = (ranges >= p["distance_limit_min"]) & (ranges <= p["distance_limit_max"]) & np.isfinite(angles)
        ranges, angles = ranges[keep], np.arctan2(np.sin(angles[keep]), np.cos(angles[keep]))
        density = self.density(ranges, angles)
        self.binary[density > p["histogram_threshold_high"]] = True
        self.binary[density < p["histogram_threshold_low"]] = False

        turning = p["min_turning_radius"]
        blocking = turning + p["robot_radius"] + p["safety_distance"]
        x, y = ranges * np.cos(angles), ranges * np.sin(angles)
        right = np.flatnonzero((np.hypot(x, y + turning) < blocking) & (angles <= 0))
        left = np.flatnonzero((np.hypot(x, y - turning) < blocking) & (angles >= 0))
        mids = self.midpoints
        phi_right, phi_left = mids[0], mids[-1]
        if right.size:  # the last right-blocking reading; one inside the end sector closes it
            phi_right = mids[1] if angles[right[-1]] <= mids[0] else angles[right[-1]]
        if left.size:
            phi_left = mids[-2] if angles[left[0]] >= mids[-1] else angles[left[0]]
        masked = self.binary | (mids < phi_right) | (mids > phi_left)

        changes = np.diff(np.concatenate([[0], (~masked).astype(int), [0]]))
        starts, ends = np.flatnonzero(changes == 1), np.flatnonzero(changes == -1) - 1
        free_count = int(np.sum(~masked))
        if starts.size == 0:
            self.previous = math.nan
            return math.nan, 0, 0, False
        if math.isnan(self.previous):
            self.previous = 0.0
        widths = 2 * math.pi / mids.size * (ends - starts)
        narrow = widths < p["narrow_opening_threshold"]
        half = p["narrow_opening_threshold"] / 2
        candidates = np.concatenate(
            [
                mids[starts[~narrow]] + half,
                mids[ends[~narrow]] - half,
                (mids[starts[narrow]] + mids[ends[narrow]]) / 2,
                [target, 0.0, self.previous],
            ]
        )
        distance = np.abs(angle_difference(mids[None, :], candidates[:, None]))
        nearest = distance - distance.min(axis=1, keepdims=True) < math.sqrt(np.finfo(float).eps)
        free = ~np.any(nearest & masked[None, :], axis=1)
        target_free = bool(free[-3])
        candidates = candidates[free]
        weights = p["target_direction_weight"], p["current_direction_weight"], p["previous_direction_weight"]
        cost = (
            weights[0] * np.abs(angle_difference(candidates, target))
            + weights[1] * np.abs(angle_difference(candidates, 0.0))
            + weights[2] * np.abs(angle_difference(candidates, self.previous))
        )
        best = cost - cost.min() < math.sqrt(np.finfo(float).eps)
        self.previous = float(np.min(candidates[best]))
        return self.previous, free_count, int(starts.size), target_free


@pytest.mark.parametrize("seed", range(6))
def test_random_scans_match_the_matrix_formulation(seed):
    rng = np.random.default_rng(seed)
    parameters = {
        **DEFAULTS,
        "num_angular_sectors": int(rng.choice([36, 72, 180, 360])),
        "distance_limit_max": float(rng.uniform(1.5, 4.0)),
        "robot_radius": float(rng.uniform(0.05, 0.4)),
        "min_turning_radius": float(rng.uniform(0.0, 1.0)),
        "histogram_threshold_low": 2.0,
        "histogram_threshold_high": 6.0,
    }
    reference = ReferenceVfh(parameters)
    beams = int(rng.integers(50, CAPACITY + 1))
    field_of_view = float(rng.uniform(math.pi, 2 * math.pi))
    angles = np.linspace(-field_of_view / 2, field_of_view / 2, beams, endpoint=field_of_view < 2 * math.pi)
    with vfh(**parameters) as fmu:
        for _ in range(8):
            # A few obstacles (runs of similar ranges), the rest beyond the limits or missing.
            ranges = np.full(beams, np.nan)
            for _obstacle in range(int(rng.integers(0, 6))):
                start, length = int(rng.integers(0, beams)), int(rng.integers(1, beams // 4 + 2))
                run_length = len(ranges[start : start + length])
                ranges[start : start + length] = rng.uniform(0.1, 4.0) + rng.normal(0, 0.05, run_length)
            target = float(rng.uniform(-math.pi, math.pi))
            out = run(fmu, ranges, target, angles)
            steering, free_count, valleys, target_free = reference.step(ranges, angles, target)
            assert (out["free_sectors"], out["num_valleys"], bool(out["target_dir_free"])) == (
                free_count,
                valleys,
                target_free,
            )
            if math.isnan(steering):
                assert math.isnan(out["steering_dir"])
            else:
                assert out["steering_dir"] == pytest.approx(steering, abs=1e-12)


def test_a_reading_whose_enlargement_falls_between_two_midpoints_adds_to_no_sector():
    # gamma = asin(0.001 / 1) spans 0.057 sector widths; the range starts just past mid-point 100,
    # where the sector-range guess is checked exactly, and ends before mid-point 101.
    width = 2 * math.pi / 180
    midpoint = -math.pi + width * 100.5
    angle = midpoint + math.asin(0.001) + 0.001 * width
    parameters = {"robot_radius": 0.001, "safety_distance": 0.0, "histogram_threshold_low": 0.5}
    parameters["histogram_threshold_high"] = 0.6
    with vfh(**parameters) as fmu:
        out = run(fmu, [1.0], target_dir=angle, angles=[angle])
    reference = ReferenceVfh({**DEFAULTS, **parameters}).step(np.array([1.0]), np.array([angle]), angle)
    assert out["free_sectors"] == reference[1] == 180


def _held_scans(seed: int, count: int):
    """`count` random scans (ranges, angles), each to be held for several steps."""
    rng = np.random.default_rng(seed)
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    scans = []
    for _ in range(count):
        ranges = np.full(angles.size, np.nan)
        for _obstacle in range(int(rng.integers(1, 6))):
            start, length = int(rng.integers(0, angles.size)), int(rng.integers(5, 90))
            ranges[start : start + length] = rng.uniform(0.15, 2.5)
        scans.append(ranges)
    targets = rng.uniform(-math.pi, math.pi, 4 * count)
    return angles, scans, targets


@pytest.mark.parametrize("seed", range(3))
def test_a_scan_held_for_several_steps_gives_what_each_step_computed_anew_gives(seed):
    # The FMU builds its histograms once per scan (a lidar at 10 Hz, VFH stepped at 100 Hz) and
    # keeps them while the ranges are bit for bit the same; the reference builds them at every
    # step, with the hysteresis applied again each time. Thresholds near the densities make the
    # hysteresis matter; the targets change at every step, so the previous direction does too.
    parameters = {**DEFAULTS, "histogram_threshold_low": 2.0, "histogram_threshold_high": 4.0}
    angles, scans, targets = _held_scans(seed, 6)
    reference = ReferenceVfh(parameters)
    with vfh(**parameters) as fmu:
        for step, target in enumerate(targets):
            ranges = scans[step // 4]
            out = run(fmu, ranges, float(target), angles)
            expected = reference.step(ranges, angles, float(target))
            assert (out["free_sectors"], out["num_valleys"], bool(out["target_dir_free"])) == expected[1:]
            if math.isnan(expected[0]):
                assert math.isnan(out["steering_dir"])
            else:
                assert out["steering_dir"] == pytest.approx(expected[0], abs=1e-12)


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_a_restored_state_steps_as_it_would_have_with_a_held_scan(fmi_version):
    # A state saved while a scan is held, restored after other scans were stepped: the next steps
    # (the same held scan, then a new one) give bit for bit what they gave without the detour
    # (what the FMU keeps of the scan it built its histograms from is part of its state).
    angles, scans, targets = _held_scans(7, 4)
    padding = np.full(CAPACITY - angles.size, np.nan)
    with FmuInstance("VectorFieldHistogram", fmi_version).initialize() as fmu:
        fmu.set_array("angles", np.concatenate([angles, padding]))

        def step(scan: int, target: float) -> dict:
            fmu.set_array("ranges", np.concatenate([scans[scan], padding]))
            fmu.set({"target_dir": target})
            fmu.step()
            return fmu.outputs()

        step(0, float(targets[0]))
        state = fmu.fmu.getFMUState()
        after = [step(0, float(targets[1])), step(1, float(targets[2]))]
        step(2, float(targets[3]))
        step(3, float(targets[4]))
        fmu.fmu.setFMUState(state)
        again = [step(0, float(targets[1])), step(1, float(targets[2]))]
        fmu.fmu.freeFMUState(state)
    assert after[0] != after[1]  # the scans differ: the test sees a change of scan
    for got, expected in zip(again, after, strict=True):
        assert got.keys() == expected.keys()
        for name in got:
            assert np.array_equal(got[name], expected[name], equal_nan=True), name


def test_a_scan_given_during_initialisation_and_held_starts_the_histogram_memory():
    # Initialisation computes the first outputs from the scan given then without touching the
    # histogram memory; the first step, on the same scan, starts that memory as a step on a new
    # scan would: the sector occupied then stays occupied when its density drops between the
    # thresholds (as in the hysteresis test above: one reading at the sector's mid-point).
    sector_midpoint = math.radians(1.0)
    inputs = {"ranges[1]": 5.0, "angles[1]": sector_midpoint, "target_dir": sector_midpoint}
    with vfh(distance_limit_max=20.0, **inputs) as fmu:
        assert not fmu.outputs()["target_dir_free"]  # density 15 > 10: occupied
        fmu.step()
        assert not fmu.outputs()["target_dir_free"]
        out = run(fmu, [15.0], target_dir=sector_midpoint, angles=[sector_midpoint])
        assert not out["target_dir_free"]  # density 5, between 3 and 10: stays occupied
