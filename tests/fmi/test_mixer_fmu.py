"""AvoidanceMixer FMU: each branch of the follow / avoid / recover / stop rule, for the
differential drive and the bicycle."""

from __future__ import annotations

import math

import pytest
from fmu_harness import FmuInstance

FOLLOW, AVOID, RECOVER, STOPPED = 0, 1, 2, 3
WHEELBASE, LOCK = 2.5, 0.6


def mixer(**parameters) -> FmuInstance:
    return FmuInstance("AvoidanceMixer").initialize(parameters)


def bicycle(**parameters) -> FmuInstance:
    return mixer(vehicle_type=1, wheelbase=WHEELBASE, max_steering_angle=LOCK, **parameters)


def command(fmu: FmuInstance, v_in=0.8, omega_in=0.2, target_dir=0.3, steering_dir=0.3, goal_reached=False):
    fmu.set(
        {
            "v_in": v_in,
            "omega_in": omega_in,
            "target_dir": target_dir,
            "steering_dir": steering_dir,
            "goal_reached": goal_reached,
        }
    )
    fmu.step()
    return fmu.outputs()


def test_differential_drive_follows_when_the_target_is_free():
    with mixer() as fmu:
        out = command(fmu, target_dir=0.3, steering_dir=0.35)  # within the 0.1 rad tolerance
    assert out["mode"] == FOLLOW and (out["v"], out["omega"]) == (0.8, 0.2) and out["steering_angle"] == 0.0


def test_differential_drive_avoids_with_the_gain_and_the_speed_factor():
    with mixer(avoid_gain=0.7, avoid_speed_factor=0.5) as fmu:
        out = command(fmu, target_dir=0.3, steering_dir=-0.9)
    assert out["mode"] == AVOID
    assert out["omega"] == pytest.approx(0.7 * -0.9) and out["v"] == pytest.approx(0.4)


def test_the_direction_difference_is_taken_across_plus_minus_pi():
    with mixer() as fmu:
        out = command(fmu, target_dir=3.1, steering_dir=-3.13)  # 0.053 rad apart through pi
    assert out["mode"] == FOLLOW


def test_differential_drive_recovers_on_the_spot_toward_the_last_free_side():
    with mixer(recovery_angular_velocity=0.8) as fmu:
        command(fmu, target_dir=0.0, steering_dir=-0.6)  # last free to the right
        out = command(fmu, steering_dir=math.nan)
        assert out["mode"] == RECOVER and out["v"] == 0.0 and out["omega"] == pytest.approx(-0.8)
        command(fmu, target_dir=0.0, steering_dir=0.4)  # now free to the left
        out = command(fmu, steering_dir=math.nan)
        assert out["omega"] == pytest.approx(0.8)


def test_goal_reached_stops_everything_for_both_vehicles():
    for make in (mixer, bicycle):
        with make() as fmu:
            out = command(fmu, steering_dir=math.nan, goal_reached=True)
        assert out["mode"] == STOPPED and out["v"] == out["omega"] == out["steering_angle"] == 0.0


def test_bicycle_follow_converts_omega_to_a_steering_angle():
    with bicycle() as fmu:
        out = command(fmu, v_in=2.0, omega_in=0.3, target_dir=0.1, steering_dir=0.1)
    expected = math.atan(0.3 * WHEELBASE / 2.0)  # 0.359 rad, inside the lock
    assert out["mode"] == FOLLOW and out["steering_angle"] == pytest.approx(expected)
    assert out["v"] == 2.0 and out["omega"] == pytest.approx(0.3)  # yaw rate v tan(delta) / L


def test_bicycle_avoid_clips_to_the_steering_lock():
    with bicycle(avoid_steering_gain=2.0) as fmu:
        out = command(fmu, v_in=0.5, target_dir=0.0, steering_dir=-1.0)  # 2 * -1 rad beyond the lock
    assert out["mode"] == AVOID and out["steering_angle"] == pytest.approx(-LOCK)
    assert out["omega"] == pytest.approx(0.5 * math.tan(-LOCK) / WHEELBASE)


def test_bicycle_avoid_steers_at_the_vfh_direction_whatever_the_speed():
    # The thesis's car takes the VFH steering direction as its steering angle (section 4.4.2);
    # omega = avoid_gain * steering_dir would give atan(0.5 * 0.4 * 2.5 / 7) = 0.07 rad at 7 m/s.
    with bicycle(avoid_steering_gain=1.0, avoid_speed_factor=0.5) as fmu:
        out = command(fmu, v_in=7.0, omega_in=0.0, target_dir=0.0, steering_dir=0.4)
    assert out["mode"] == AVOID and out["steering_angle"] == pytest.approx(0.4)
    assert out["v"] == pytest.approx(3.5) and out["omega"] == pytest.approx(3.5 * math.tan(0.4) / WHEELBASE)


def test_avoid_hold_keeps_the_offset_from_the_moving_target_then_follows():
    with bicycle(avoid_hold_time=0.15) as fmu:  # three steps of 0.05 s
        command(fmu, v_in=2.0, target_dir=0.1, steering_dir=-0.3)  # VFH: offset -0.4 rad
        held = []
        for target in (0.2, 0.3, 0.35, 0.4):  # VFH calls the target free again each time
            held.append(command(fmu, v_in=2.0, omega_in=0.1, target_dir=target, steering_dir=target))
    for out, target in zip(held[:3], (0.2, 0.3, 0.35), strict=True):
        assert out["mode"] == AVOID and out["steering_angle"] == pytest.approx(target - 0.4)
    assert held[3]["mode"] == FOLLOW
    assert held[3]["steering_angle"] == pytest.approx(math.atan(0.1 * WHEELBASE / 2.0))


def test_without_hold_the_mixer_follows_as_soon_as_the_target_is_free():
    with mixer() as fmu:
        command(fmu, target_dir=0.1, steering_dir=-0.3)
        out = command(fmu, target_dir=0.2, steering_dir=0.2)
    assert out["mode"] == FOLLOW and out["omega"] == 0.2


def test_recovery_lasts_the_minimum_duration_on_the_side_it_started():
    with bicycle(recovery_min_duration=0.2, recovery_linear_velocity=1.0) as fmu:
        command(fmu, target_dir=0.0, steering_dir=0.5)  # last free to the left
        modes = [command(fmu, steering_dir=math.nan)]
        # Free again at once, on the other side: recovery still holds for 0.2 s = 4 steps in all.
        modes += [command(fmu, v_in=2.0, target_dir=-0.3, steering_dir=-0.3) for _ in range(4)]
    assert [out["mode"] for out in modes] == [RECOVER] * 4 + [FOLLOW]
    assert all(out["steering_angle"] == pytest.approx(-LOCK) and out["v"] == -1.0 for out in modes[:4])


def test_recovery_without_minimum_ends_when_a_direction_is_free():
    with bicycle() as fmu:
        command(fmu, steering_dir=math.nan)
        out = command(fmu, target_dir=0.2, steering_dir=0.2)
    assert out["mode"] == FOLLOW


def test_bicycle_reversing_command_folds_the_steering_angle():
    with bicycle() as fmu:
        out = command(fmu, v_in=-1.0, omega_in=0.2, target_dir=0.0, steering_dir=0.0)
    # atan2(0.5, -1) is in the second quadrant; folded by -pi it gives tan(delta) = omega L / v.
    assert out["steering_angle"] == pytest.approx(math.atan(0.2 * WHEELBASE / -1.0))
    assert out["omega"] == pytest.approx(0.2)


def test_bicycle_recovers_by_reversing_at_full_lock_swinging_toward_the_free_side():
    with bicycle(recovery_linear_velocity=0.3) as fmu:
        command(fmu, target_dir=0.0, steering_dir=0.5)  # last free to the left
        out = command(fmu, steering_dir=math.nan)
    assert out["mode"] == RECOVER and out["v"] == pytest.approx(-0.3)
    assert out["steering_angle"] == pytest.approx(-LOCK)  # steer right while reversing ...
    assert out["omega"] > 0  # ... so the heading turns left, toward the free side
    assert out["omega"] == pytest.approx(-0.3 * math.tan(-LOCK) / WHEELBASE)


def test_wheelbase_is_not_checked_for_the_differential_drive():
    with mixer(wheelbase=0.0) as fmu:
        assert command(fmu)["mode"] == FOLLOW
