"""ArtificialPotentialField FMU: hand-computed Khatib force sums on small scans, a second
implementation (NumPy) on random scans, VFH's ports, the AvoidanceMixer taking its direction, and
a shipped warehouse run with it in VFH's place."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu
from fmu_harness import FmuInstance, array_inputs

from cosim import builtin_fmu
from cosim.logs import open_log
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

CAPACITY = 720
ANGLES = np.linspace(-math.pi, math.pi, CAPACITY, endpoint=False)  # a 360-degree lidar, 0.5 degree apart
FORCE, DEFLECTED, TRAPPED, ENCLOSED = 0, 1, 2, 3  # direction_status
# Round numbers for the hand computations: a reading at clearance rho repels with
# 0.1 (1/rho - 1) / rho^2, e.g. 0.4 at rho = 0.5.
PARAMETERS = {
    "robot_radius": 0.1,
    "safety_distance": 0.1,
    "influence_distance": 1.0,
    "attractive_gain": 1.0,
    "repulsive_gain": 0.1,
    "distance_limit_min": 0.05,
    "distance_limit_max": 3.0,
}


def apf(**overrides) -> FmuInstance:
    return FmuInstance("ArtificialPotentialField").initialize({**PARAMETERS, **overrides})


def run(fmu: FmuInstance, ranges, angles=ANGLES, target_dir: float = 0.0) -> dict:
    fmu.set(
        {
            **array_inputs("ranges", ranges, CAPACITY),
            **array_inputs("angles", angles, CAPACITY),
            "target_dir": target_dir,
        }
    )
    fmu.step()
    return fmu.outputs()


def khatib(clearance: float, eta: float = 0.1, rho_0: float = 1.0) -> float:
    return eta * (1.0 / clearance - 1.0 / rho_0) / clearance**2


def test_no_reading_steers_exactly_to_the_target():
    with apf() as fmu:
        for target in (0.0, 0.7, -1.2, 2.9, -3.1, math.pi):
            out = run(fmu, [], target_dir=target)
            assert out["steering_dir"] == target  # exactly: nothing repels
            assert (out["force_x"], out["force_y"]) == pytest.approx((math.cos(target), math.sin(target)))
            assert (
                out["repelling_readings"] == 0 and out["direction_status"] == FORCE and out["target_dir_free"]
            )
            assert math.isnan(out["nearest_distance"])
        # Readings outside the distance limits do not count; a target beyond pi is wrapped.
        out = run(fmu, np.full(CAPACITY, 3.5), target_dir=4.0)
        assert out["steering_dir"] == pytest.approx(4.0 - 2 * math.pi, abs=1e-12)
        assert math.isnan(out["nearest_distance"])
        out = run(fmu, np.full(CAPACITY, 0.04), target_dir=math.nan)  # inside the robot, but below the limit
        assert (
            out["steering_dir"] == 0.0 and out["direction_status"] == FORCE
        )  # NaN target counts as 0, like VFH


def test_one_reading_ahead_left_steers_right_by_the_predicted_angle():
    # Range 0.6 at 0.3 rad: clearance 0.5, repulsion 0.1 (1/0.5 - 1) / 0.5^2 = 0.4 away from it.
    with apf() as fmu:
        out = run(fmu, [0.6], angles=[0.3])
        force = (1.0 - 0.4 * math.cos(0.3), -0.4 * math.sin(0.3))
        assert (out["force_x"], out["force_y"]) == pytest.approx(force, abs=1e-12)
        assert out["steering_dir"] == pytest.approx(math.atan2(force[1], force[0]), abs=1e-12)
        assert out["steering_dir"] == pytest.approx(-0.1890, abs=1e-4)  # to the right
        assert out["repelling_readings"] == 1 and out["nearest_distance"] == 0.6
        # 0.6 sin 0.3 = 0.18 m beside the target ray: inside the 0.2 m corridor.
        assert not out["target_dir_free"] and out["direction_status"] == FORCE

        mirrored = run(fmu, [0.6], angles=[-0.3])
        assert mirrored["steering_dir"] == -out["steering_dir"]

        # The same reading relative to a target at 1.0 rad: the field turns with the frame.
        out = run(fmu, [0.6], angles=[1.3], target_dir=1.0)
        force = (math.cos(1.0) - 0.4 * math.cos(1.3), math.sin(1.0) - 0.4 * math.sin(1.3))
        assert out["steering_dir"] == pytest.approx(math.atan2(force[1], force[0]), abs=1e-12)
        assert out["steering_dir"] == pytest.approx(1.0 - 0.1890, abs=1e-4)

        # 0.6 sin 0.4 = 0.234 m beside the ray: the target direction is free, the field still acts.
        out = run(fmu, [0.6], angles=[0.4])
        assert out["target_dir_free"] and out["steering_dir"] < 0


def test_reading_beyond_the_influence_distance_has_no_effect():
    with apf() as fmu:
        out = run(fmu, [1.15], angles=[0.2], target_dir=0.1)  # clearance 1.05 > 1
        assert out["steering_dir"] == 0.1 and out["repelling_readings"] == 0
        assert out["nearest_distance"] == 1.15 and out["target_dir_free"]
        out = run(fmu, [1.09], angles=[0.2], target_dir=0.1)  # clearance 0.99: a small push
        magnitude = khatib(1.09 - 0.1)
        force = (math.cos(0.1) - magnitude * math.cos(0.2), math.sin(0.1) - magnitude * math.sin(0.2))
        assert out["repelling_readings"] == 1
        assert out["steering_dir"] == pytest.approx(math.atan2(force[1], force[0]), abs=1e-12)
        assert 0.09 < out["steering_dir"] < 0.1


def test_symmetric_readings_keep_straight_and_add_their_push_back():
    angles = [0.4, -0.4, 1.1, -1.1, 2.5, -2.5]
    ranges = [0.9, 0.9, 0.7, 0.7, 0.9, 0.9]
    with apf() as fmu:
        out = run(fmu, ranges, angles=angles)
    assert out["steering_dir"] == 0.0 and out["force_y"] == 0.0
    push = sum(khatib(r - 0.1) * math.cos(a) for r, a in zip(ranges, angles, strict=True))
    assert out["force_x"] == pytest.approx(1.0 - push, abs=1e-14)
    assert out["repelling_readings"] == 6 and out["direction_status"] == FORCE
    # The same pattern about a target at -2.0 rad: steering stays on the target.
    with apf() as fmu:
        out = run(fmu, ranges, angles=[a - 2.0 for a in angles], target_dir=-2.0)
    assert out["steering_dir"] == pytest.approx(-2.0, abs=1e-14)


def test_an_obstacle_straight_ahead_turns_the_vehicle_back_or_traps_it():
    # Range 0.4 dead ahead: clearance 0.3, repulsion 2.59 > the pull of 1, so the force points back.
    with apf() as fmu:
        out = run(fmu, [0.4], angles=[0.0])
    assert out["force_x"] == pytest.approx(1.0 - khatib(0.3), abs=1e-14) and out["force_x"] < 0
    # By default any deviation from the target is followed: straight back.
    assert out["steering_dir"] == pytest.approx(math.pi) and out["direction_status"] == FORCE
    with apf(max_target_deviation=math.pi / 2) as fmu:
        out = run(fmu, [0.4], angles=[0.0])
        assert math.isnan(out["steering_dir"]) and out["direction_status"] == TRAPPED
        # The field keeps no memory: the next free scan steers to the target again.
        out = run(fmu, [], target_dir=0.2)
        assert out["steering_dir"] == 0.2 and out["direction_status"] == FORCE
        # At the limit: a force 80 degrees off the target is a direction, 100 degrees is a trap.
        for deviation, trapped in ((80, False), (100, True)):
            # A pull (1, 0) plus a push p from a reading at the angle of -p gives a force of
            # length 1 at angle d when p = (cos d - 1, sin d).
            d = math.radians(-deviation)
            push = (math.cos(d) - 1.0, math.sin(d))
            clearance = _clearance_for(math.hypot(*push))
            out = run(fmu, [clearance + 0.1], angles=[math.atan2(-push[1], -push[0])])
            if trapped:
                assert math.isnan(out["steering_dir"]) and out["direction_status"] == TRAPPED
            else:
                assert out["steering_dir"] == pytest.approx(d, abs=1e-9)


def _clearance_for(magnitude: float) -> float:
    """The clearance at which the test's Khatib repulsion has `magnitude` (bisection)."""
    low, high = 1e-3, 1.0
    for _ in range(200):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if khatib(middle) > magnitude else (low, middle)
    return 0.5 * (low + high)


def test_a_reading_inside_the_safety_circle_deflects_the_force_to_its_edge():
    # A weak field (eta = 1e-5): range 0.15 at -0.3 rad, clearance 0.05, pushes with 0.076 only,
    # so the force points about 0.024 rad left, within 90 degrees of the reading: blocked. The
    # nearest direction it does not block is its edge at -0.3 + pi/2 (the other is -0.3 - pi/2).
    with apf(repulsive_gain=1e-5) as fmu:
        out = run(fmu, [0.15], angles=[-0.3])
        magnitude = khatib(0.05, eta=1e-5)
        assert out["force_y"] == pytest.approx(magnitude * math.sin(0.3), abs=1e-12)
        assert 0.0 < math.atan2(out["force_y"], out["force_x"]) < 0.03
        assert out["steering_dir"] == pytest.approx(-0.3 + math.pi / 2, abs=1e-12)
        assert out["direction_status"] == DEFLECTED
        # The same reading behind the vehicle does not block driving ahead: it pushes forward.
        behind = math.pi - 0.3
        out = run(fmu, [0.15], angles=[behind])
        force = (1.0 - magnitude * math.cos(behind), -magnitude * math.sin(behind))
        assert out["steering_dir"] == pytest.approx(math.atan2(force[1], force[0]), abs=1e-12)
        assert out["direction_status"] == FORCE
        # Walls on both sides inside the circle: straight ahead is perpendicular to both, so free.
        out = run(fmu, [0.15, 0.15], angles=[math.pi / 2, -math.pi / 2])
        assert out["steering_dir"] == 0.0 and out["direction_status"] == FORCE
        # Below distance_limit_min a reading is not seen at all (the lidar's blind zone, as in VFH).
        out = run(fmu, [0.04], angles=[-0.3])
        assert out["steering_dir"] == 0.0 and out["repelling_readings"] == 0


def test_safety_circle_readings_all_round_leave_no_direction():
    # Three readings 120 degrees apart inside the circle: their half circles of blocked directions
    # cover every direction.
    angles = [0.0, 2 * math.pi / 3, -2 * math.pi / 3]
    with apf() as fmu:
        out = run(fmu, [0.15, 0.15, 0.15], angles=angles)
    assert math.isnan(out["steering_dir"]) and out["direction_status"] == ENCLOSED
    # Without the one at -120 degrees, [-150, -90] degrees is free. A weak field points about
    # straight ahead, into the reading at 0: the nearest free direction is that reading's edge, -90.
    with apf(repulsive_gain=1e-6) as fmu:
        out = run(fmu, [0.15, 0.15], angles=angles[:2])
    assert abs(math.atan2(out["force_y"], out["force_x"])) < 0.01
    assert out["steering_dir"] == pytest.approx(-math.pi / 2, abs=1e-12)
    assert out["direction_status"] == DEFLECTED


def test_changed_reading_angles_are_used():
    """The cosines and sines are cached between steps: a new angle must refresh them."""
    with apf() as fmu:
        first = run(fmu, [0.6], angles=[0.3])
        second = run(fmu, [0.6], angles=[-0.5])
        again = run(fmu, [0.6], angles=[0.3])
    force = (1.0 - 0.4 * math.cos(-0.5), -0.4 * math.sin(-0.5))
    assert second["steering_dir"] == pytest.approx(math.atan2(force[1], force[0]), abs=1e-12)
    assert again == first


def reference(ranges, angles, target: float, p: dict) -> dict:
    """A second implementation of the documented field, vectorised, angles instead of vectors."""
    ranges, angles = np.asarray(ranges, dtype=float), np.asarray(angles, dtype=float)
    target = 0.0 if math.isnan(target) else math.remainder(target, 2 * math.pi)
    with np.errstate(invalid="ignore"):
        valid = (
            (ranges >= p["distance_limit_min"]) & (ranges <= p["distance_limit_max"]) & np.isfinite(angles)
        )
    r, a = ranges[valid], angles[valid]
    clearance = r - p["robot_radius"]
    repelling = clearance < p["influence_distance"]
    rho = np.maximum(clearance[repelling], 1e-3)
    magnitude = p["repulsive_gain"] * (1 / rho - 1 / p["influence_distance"]) / rho**2
    force = p["attractive_gain"] * np.array([math.cos(target), math.sin(target)])
    force -= np.array([np.sum(magnitude * np.cos(a[repelling])), np.sum(magnitude * np.sin(a[repelling]))])
    safety = p["robot_radius"] + p["safety_distance"]
    relative = a[repelling] - target
    in_corridor = (r[repelling] * np.cos(relative) > 0) & (np.abs(r[repelling] * np.sin(relative)) < safety)
    close = a[r < safety]

    def free(direction: float) -> bool:
        return bool(np.all(np.cos(direction - close) <= 1e-12))

    steering, status = target, FORCE
    if repelling.any():
        steering = math.atan2(force[1], force[0])
    if abs(math.remainder(steering - target, 2 * math.pi)) > p["max_target_deviation"]:
        status = TRAPPED
    elif not free(steering):
        edges = [e for e in np.concatenate([close + math.pi / 2, close - math.pi / 2]) if free(e)]
        if edges:
            steering = math.remainder(max(edges, key=lambda e: math.cos(e - steering)), 2 * math.pi)
            status = DEFLECTED
        else:
            status = ENCLOSED
    return {
        "steering_dir": steering if status in (FORCE, DEFLECTED) else math.nan,
        "direction_status": status,
        "force_x": force[0],
        "force_y": force[1],
        "repelling_readings": int(repelling.sum()),
        "target_dir_free": not in_corridor.any(),
        "nearest_distance": float(r.min()) if r.size else math.nan,
    }


def test_random_scans_match_a_second_implementation():
    rng = np.random.default_rng(7)
    # A weak field and a wide safety circle, so deflections and enclosures happen often.
    parameters = {**PARAMETERS, "repulsive_gain": 2e-4, "safety_distance": 0.3, "max_target_deviation": 2.0}
    directions = np.linspace(-math.pi, math.pi, 7200, endpoint=False)
    statuses, corridor, deflections = set(), set(), 0
    with apf(**parameters) as fmu:
        for _ in range(80):
            ranges = rng.uniform(0.0, 3.5, CAPACITY)
            ranges[rng.random(CAPACITY) < rng.uniform(0.9, 0.999)] = np.nan
            target = float(rng.uniform(-math.pi, math.pi))
            out = run(fmu, ranges, target_dir=target)
            expected = reference(ranges, ANGLES, target, parameters)
            for name, value in expected.items():
                if isinstance(value, float):
                    assert out[name] == pytest.approx(value, rel=1e-12, abs=1e-12, nan_ok=True), name
                else:
                    assert out[name] == value, name
            if out["direction_status"] == DEFLECTED:
                # No free direction on a fine grid is nearer to the force's direction.
                close = ANGLES[(ranges >= 0.05) & (ranges < 0.4)]
                free = np.all(np.cos(directions[:, None] - close[None, :]) <= 0, axis=1)
                force_dir = math.atan2(out["force_y"], out["force_x"])
                chosen = abs(math.remainder(out["steering_dir"] - force_dir, 2 * math.pi))
                grid = np.abs(np.remainder(directions[free] - force_dir + math.pi, 2 * math.pi) - math.pi)
                assert np.all(grid >= chosen - 1e-9)  # (the free set may be a lone point off the grid)
                deflections += 1
            statuses.add(out["direction_status"])
            corridor.add(out["target_dir_free"])
    assert statuses == {FORCE, DEFLECTED, TRAPPED, ENCLOSED} and corridor == {True, False}
    assert deflections >= 5


def test_has_the_ports_of_the_vector_field_histogram():
    """A drop-in: every VFH input, and the output the AvoidanceMixer reads, with the same name,
    value reference, type, causality and unit."""
    vfh = {v.name: v for v in read_model_description(str(builtin_fmu("VectorFieldHistogram"))).modelVariables}
    apf_variables = {
        v.name: v for v in read_model_description(str(builtin_fmu("ArtificialPotentialField"))).modelVariables
    }
    shared = [name for name, v in vfh.items() if v.causality == "input"] + ["steering_dir", "target_dir_free"]
    assert len(shared) == 2 * CAPACITY + 3
    for name in shared:
        ours, theirs = apf_variables[name], vfh[name]
        assert (ours.valueReference, ours.type, ours.causality, ours.unit) == (
            theirs.valueReference,
            theirs.type,
            theirs.causality,
            theirs.unit,
        ), name


@pytest.mark.slow
def test_fmpy_validation_finds_no_problem():
    assert validate_fmu(str(builtin_fmu("ArtificialPotentialField"))) == []


def test_the_avoidance_mixer_takes_its_direction_unchanged():
    """APF's steering_dir wired into the AvoidanceMixer as VFH's is: follow when free, avoid with
    omega = avoid_gain * steering_dir, recover on the spot when NaN."""
    cases = [
        ([], [], 0.1, 0),  # nothing near: steering = target, follow
        ([0.6], [0.3], 0.0, 1),  # obstacle ahead left: steer right, avoid
        ([0.15] * 3, [0.0, 2 * math.pi / 3, -2 * math.pi / 3], 0.0, 2),  # enclosed: NaN, recover
    ]
    with apf() as field, FmuInstance("AvoidanceMixer").initialize() as mixer:
        for ranges, angles, target, mode in cases:
            steering = run(field, ranges, angles=angles, target_dir=target)["steering_dir"]
            mixer.set({"v_in": 0.5, "omega_in": 0.2, "target_dir": target, "steering_dir": steering})
            mixer.step()
            out = mixer.outputs()
            assert out["mode"] == mode
            if mode == 0:
                assert (out["v"], out["omega"]) == (0.5, 0.2)
            elif mode == 1:
                assert out["omega"] == pytest.approx(0.5 * steering) and out["omega"] < 0
            else:
                assert out["v"] == 0.0 and out["omega"] == pytest.approx(-0.5)  # toward the last free side


SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
# The obstacle-course run's [vfh] table for the field (chosen: the robot's radius and safety
# distance of thesis Table 4.2, an influence of 3 m, eta 0.3 m^3 for its 360-beam lidar), and a
# mixer that turns harder and slows to 70 % while avoiding: at the thesis's 1.5 m/s and
# omega = 0.5 steering_dir the robot answers the field too slowly and touches a box.
APF_SECTIONS = """[vfh]
fmu = "{path}"
distance_limits = [0.05, 20.0]
robot_radius = 0.5
safety_distance = 0.3
influence_distance = 3.0
repulsive_gain = 0.3

[mixer]
avoid_gain = 1.0
avoid_speed_factor = 0.7
"""


def test_replaces_vfh_in_a_shipped_run_and_reaches_the_goal(tmp_path):
    """warehouse_diff_drive_obstacles (three boxes on the planned path) with [vfh] pointing at this
    FMU (reduced settings as tests/navigation/test_shipped_scenarios.py): goal reached, no
    collision, the field made the mixer avoid, and the log's vfh component is this FMU."""
    text = (SCENARIOS / "warehouse_diff_drive_obstacles.toml").read_text()
    map_file = (SCENARIOS / "maps" / "warehouse.yaml").resolve()
    text = re.sub(r'(?m)^file = "maps/warehouse.yaml"', f'file = "{map_file}"', text)
    start = text.index("[vfh]")
    end = text.index("\n[", start + 1)
    path = builtin_fmu("ArtificialPotentialField")
    scenario_path = tmp_path / "apf.toml"
    scenario_path.write_text(text[:start] + APF_SECTIONS.format(path=path) + text[end:])
    assert "[mixer]" not in text[end:]  # the mixer table above is the only one
    scenario = load_scenario(
        scenario_path, ["simulation.macro_step=0.05", "output.pose_rate=20", "output.plot=false"]
    )
    result = run_scenario(scenario, tmp_path / "apf.mcap")
    outcome = result.outcome
    assert outcome.reason == "goal_reached" and result.exit_code == 0, outcome
    assert outcome.min_clearance > 0.5 and outcome.vfh_interventions > 0
    log = open_log(tmp_path / "apf.mcap")
    assert log.metadata["fmu/vfh"]["fmu"] == str(path)
