"""DifferentialDrive and Bicycle against closed-form motion for constant inputs (<= 1e-9)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fmu_harness import FmuInstance

TOLERANCE = 1e-9


def run(name: str, steps: int, step_size: float, **settings) -> FmuInstance:
    instance = FmuInstance(name)
    instance.initialize(**settings)
    for k in range(steps):
        instance.fmu.doStep(k * step_size, step_size)
    return instance


def unicycle_pose(x0, y0, theta0, v, omega, t):
    """Closed form of x' = v cos(theta), y' = v sin(theta), theta' = omega with constant v, omega."""
    if omega == 0.0:
        return x0 + v * t * math.cos(theta0), y0 + v * t * math.sin(theta0), theta0
    theta = theta0 + omega * t
    return (
        x0 + v / omega * (math.sin(theta) - math.sin(theta0)),
        y0 - v / omega * (math.cos(theta) - math.cos(theta0)),
        theta,
    )


def angle_difference(a, b):
    return math.remainder(a - b, 2 * math.pi)


def assert_pose(instance: FmuInstance, expected) -> None:
    x, y, theta = instance.values("x", "y", "theta")
    assert abs(x - expected[0]) <= TOLERANCE and abs(y - expected[1]) <= TOLERANCE
    assert abs(angle_difference(theta, expected[2])) <= TOLERANCE
    assert -math.pi < theta <= math.pi


# ---------------------------------------------------------------- DifferentialDrive


@pytest.mark.parametrize(
    ("v", "omega", "theta0", "step_size"),
    [(1.0, 0.5, 0.3, 0.1), (0.7, -2.0, -2.9, 0.05), (-0.4, 0.0, 1.0, 0.2), (0.5, 1e-12, 0.0, 0.1)],
)
def test_differential_drive_follows_the_arc(v, omega, theta0, step_size):
    steps = 60
    drive = run("DifferentialDrive", steps, step_size, x0=1.0, y0=-2.0, theta0=theta0, v=v, omega=omega)
    assert_pose(drive, unicycle_pose(1.0, -2.0, theta0, v, omega, steps * step_size))
    drive.free()


def test_differential_drive_full_circle_returns_to_start():
    # omega = 2 pi / 4 s: 40 steps of 0.1 s close the circle.
    drive = run("DifferentialDrive", 40, 0.1, v=1.0, omega=math.pi / 2)
    assert_pose(drive, (0.0, 0.0, 0.0))
    drive.free()


def test_differential_drive_wheel_speed_inputs_eq_4_4():
    r, d, left, right = 0.1, 0.5, 3.0, 5.0
    drive = run(
        "DifferentialDrive",
        20,
        0.1,
        input_mode=1,
        wheel_radius=r,
        track_width=d,
        wheel_speed_left=left,
        wheel_speed_right=right,
    )
    v, omega = r * (right + left) / 2, r * (right - left) / d
    assert drive.values("v_actual", "omega_actual") == pytest.approx([v, omega], abs=1e-15)
    assert_pose(drive, unicycle_pose(0.0, 0.0, 0.0, v, omega, 2.0))
    drive.free()


def test_differential_drive_clips_wheel_speeds_and_converts_back():
    # r = 0.05, d = 0.2: v = 1, omega = 2 needs wheels (16, 24) rad/s (eq 4.5); 24 clips to 20.
    drive = run("DifferentialDrive", 10, 0.1, wheel_speed_min=-20.0, wheel_speed_max=20.0, v=1.0, omega=2.0)
    assert drive.values("wheel_speed_left_actual", "wheel_speed_right_actual") == pytest.approx([16.0, 20.0])
    v, omega = 0.05 * (20.0 + 16.0) / 2, 0.05 * (20.0 - 16.0) / 0.2
    assert drive.values("v_actual", "omega_actual") == pytest.approx([v, omega], abs=1e-14)
    assert_pose(drive, unicycle_pose(0.0, 0.0, 0.0, v, omega, 1.0))
    drive.free()


# ---------------------------------------------------------------- Bicycle

WHEELBASE = 2.5


def rear_axle_tan(mode: int, tan_front: float) -> float:
    """tan(delta_r) of each steering mode (front wheel angle delta_f, same sign convention)."""
    return {0: 0.0, 1: -tan_front, 2: tan_front}[mode]


def bicycle_pose(mode, v, delta, distance, t, pose0=(0.0, 0.0, 0.0)):
    """Pose of the point `distance` ahead of the rear axle, by a route other than the FMU's: the
    point of the body axis with no lateral velocity (the foot of the ICR) moves as a unicycle, and
    the reference point sits at a fixed offset from it along the body axis."""
    tan_f, tan_r = math.tan(delta), rear_axle_tan(mode, math.tan(delta))
    x0, y0, theta0 = pose0
    if mode == 2:  # parallel: no yaw, every point crabs at angle delta
        return (
            x0 + v * t * (math.cos(theta0) - tan_f * math.sin(theta0)),
            y0 + v * t * (math.sin(theta0) + tan_f * math.cos(theta0)),
            theta0,
        )
    yaw_rate = v * (tan_f - tan_r) / WHEELBASE
    # Lateral velocity at body position s is v tan_r + yaw_rate s: zero at s0.
    s0 = -v * tan_r / yaw_rate if yaw_rate != 0.0 else 0.0
    foot = (x0 + (s0 - distance) * math.cos(theta0), y0 + (s0 - distance) * math.sin(theta0))
    fx, fy, theta = unicycle_pose(*foot, theta0, v, yaw_rate, t)
    return fx + (distance - s0) * math.cos(theta), fy + (distance - s0) * math.sin(theta), theta


@pytest.mark.parametrize("mode", [0, 1, 2])
@pytest.mark.parametrize("distance", [0.0, 1.2, WHEELBASE / 2])
def test_bicycle_modes_follow_their_closed_form(mode, distance):
    v, delta = 1.5, 0.35
    bicycle = run(
        "Bicycle",
        50,
        0.1,
        steering_mode=mode,
        wheelbase=WHEELBASE,
        rear_axle_distance=distance,
        x0=0.5,
        y0=0.25,
        theta0=0.8,
        v=v,
        steering_angle=delta,
    )
    assert_pose(bicycle, bicycle_pose(mode, v, delta, distance, 5.0, (0.5, 0.25, 0.8)))
    bicycle.free()


@pytest.mark.parametrize("mode", [0, 1, 2])
def test_bicycle_yaw_rate_and_slip_angle_eqs_4_6_and_4_7(mode):
    v, delta, distance = 2.0, -0.3, 0.9
    bicycle = run(
        "Bicycle",
        1,
        0.1,
        steering_mode=mode,
        wheelbase=WHEELBASE,
        rear_axle_distance=distance,
        v=v,
        steering_angle=delta,
    )
    tan_f, tan_r = math.tan(delta), rear_axle_tan(mode, math.tan(delta))
    lr, lf = distance, WHEELBASE - distance
    beta = math.atan((lf * tan_r + lr * tan_f) / (lf + lr))  # eq 4.7
    speed = v / math.cos(beta)  # speed of the reference point
    yaw_rate = speed * math.cos(beta) * (tan_f - tan_r) / (lf + lr)  # eq 4.6, delta_r signed as delta_f
    assert bicycle.values("slip_angle", "yaw_rate", "steering_angle_actual") == pytest.approx(
        [beta, yaw_rate, delta], abs=1e-14
    )
    bicycle.free()


def test_bicycle_full_circle_front_steering():
    # Rear axle on a circle of radius L / tan(delta); 2 pi R / v seconds close it.
    delta, v = 0.5, 1.0
    period = 2 * math.pi * WHEELBASE / math.tan(delta) / v
    bicycle = run("Bicycle", 100, period / 100, wheelbase=WHEELBASE, v=v, steering_angle=delta)
    assert_pose(bicycle, (0.0, 0.0, 0.0))
    bicycle.free()


@pytest.mark.parametrize(("mode", "divisor"), [(0, 1.0), (1, 2.0)])
@pytest.mark.parametrize(("v", "omega"), [(1.0, 0.4), (-1.0, 0.4), (0.8, -0.3)])
def test_bicycle_yaw_rate_input(mode, divisor, v, omega):
    bicycle = run("Bicycle", 30, 0.1, input_mode=1, steering_mode=mode, wheelbase=WHEELBASE, v=v, omega=omega)
    delta = math.atan(omega * WHEELBASE / (divisor * v))  # atan2 folded into (-pi/2, pi/2]
    assert bicycle.values("steering_angle_actual", "yaw_rate") == pytest.approx([delta, omega], abs=1e-14)
    assert_pose(bicycle, bicycle_pose(mode, v, delta, 0.0, 3.0))
    bicycle.free()


def test_bicycle_clips_steering_and_speed():
    bicycle = run(
        "Bicycle",
        20,
        0.1,
        wheelbase=WHEELBASE,
        max_steering_angle=0.4,
        speed_min=-1.0,
        speed_max=2.0,
        v=5.0,
        steering_angle=1.2,
    )
    assert bicycle.values("v_actual", "steering_angle_actual") == [2.0, 0.4]
    assert_pose(bicycle, bicycle_pose(0, 2.0, 0.4, 0.0, 2.0))
    bicycle.free()
    # A yaw rate the steering cannot reach: MATLAB converts, then clips the angle.
    bicycle = run("Bicycle", 1, 0.1, input_mode=1, wheelbase=WHEELBASE, v=1.0, omega=10.0)
    assert bicycle.values("steering_angle_actual") == pytest.approx([math.pi / 4], abs=1e-15)
    bicycle.free()


def test_bicycle_matches_a_fine_numerical_integration_of_eq_4_6():
    """A second, independent check: RK4 with 1000 substeps on eq 4.6 at the centre of mass."""
    v, delta, distance = 1.2, 0.25, 1.0
    bicycle = run(
        "Bicycle", 10, 0.2, wheelbase=WHEELBASE, rear_axle_distance=distance, v=v, steering_angle=delta
    )
    beta = math.atan(distance * math.tan(delta) / WHEELBASE)
    speed = v / math.cos(beta)

    def derivative(state):
        psi = state[2]
        return np.array(
            [
                speed * math.cos(psi + beta),
                speed * math.sin(psi + beta),
                speed * math.cos(beta) * math.tan(delta) / WHEELBASE,
            ]
        )

    state, h = np.zeros(3), 2.0 / 1000
    for _ in range(1000):
        k1 = derivative(state)
        k2 = derivative(state + h / 2 * k1)
        k3 = derivative(state + h / 2 * k2)
        k4 = derivative(state + h * k3)
        state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert bicycle.values("x", "y", "theta") == pytest.approx(list(state), abs=1e-11)
    bicycle.free()
