"""The IMU (cosim.world.imu) against the analytic motion: arcs at constant v and omega, a constant
acceleration, a robot at rest with noise; its messages decoded by rosbags' own ROS 2 Humble store."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from cosim.world.imu import STANDARD_GRAVITY, Imu, ImuSettings

HUMBLE = get_typestore(Stores.ROS2_HUMBLE)
IMU_TYPE = "sensor_msgs/msg/Imu"


def decode(payload: bytes):
    return HUMBLE.deserialize_cdr(payload, IMU_TYPE)


def arc_pose(start, v: float, omega: float, t: float):
    """The closed-form pose at time t [s] of a unicycle from `start` at constant v [m/s], omega [rad/s]."""
    x0, y0, theta0 = start
    theta = theta0 + omega * t
    if omega == 0.0:
        return x0 + v * t * math.cos(theta0), y0 + v * t * math.sin(theta0), theta
    radius = v / omega
    return (
        x0 + radius * (math.sin(theta) - math.sin(theta0)),
        y0 - radius * (math.cos(theta) - math.cos(theta0)),
        theta,
    )


def run_imu(imu: Imu, pose_at, period: float, samples: int):
    """The decoded messages of `samples` samples at t = n * period, n = 1.., of `pose_at(t)`."""
    messages = []
    imu.start(0, *pose_at(0.0))
    for n in range(1, samples + 1):
        t_ns = round(n * period * 1e9)
        x, y, theta = pose_at(t_ns / 1e9)
        messages.append(decode(imu.sample(t_ns, x, y, math.atan2(math.sin(theta), math.cos(theta)))))
    return messages


@pytest.mark.parametrize(
    ("v", "omega", "period"),
    [(0.5, 0.5, 0.05), (1.5, -0.4, 0.5), (-0.4, 0.3, 0.1), (1.0, 0.0, 0.02), (0.8, 2.0, 1.0)],
    ids=["left", "right-coarse", "reverse", "straight", "more-than-a-radian-per-sample"],
)
def test_an_arc_at_constant_v_omega_reads_omega_and_the_centripetal_acceleration(v, omega, period):
    imu = Imu(ImuSettings(rate=1.0 / period), macro_step=period)
    start = (3.0, -2.0, 2.5)
    messages = run_imu(imu, lambda t: arc_pose(start, v, omega, t), period, 40)
    for n, message in enumerate(messages, start=1):
        assert message.angular_velocity.z == pytest.approx(omega, abs=1e-9)
        assert message.angular_velocity.x == message.angular_velocity.y == 0.0
        acceleration = message.linear_acceleration
        # Tangential: from rest to v in the first interval, then constant speed.
        assert acceleration.x == pytest.approx(v / period if n == 1 else 0.0, abs=1e-8)
        assert acceleration.y == pytest.approx(v * omega, abs=1e-9)
        assert acceleration.z == STANDARD_GRAVITY  # REP-145: gravity reported, +z up
        q = message.orientation
        theta = start[2] + omega * n * period
        assert (q.x, q.y) == (0.0, 0.0)
        assert math.atan2(2 * q.w * q.z, 1 - 2 * q.z * q.z) == pytest.approx(
            math.atan2(math.sin(theta), math.cos(theta)), abs=1e-9
        )
        assert message.header.frame_id == "base_link"
        assert message.header.stamp.sec * 10**9 + message.header.stamp.nanosec == round(n * period * 1e9)
        # No noise: zero covariances ("unknown" to ROS; the values are exact).
        assert not any(message.angular_velocity_covariance) and not any(message.orientation_covariance)


def test_a_constant_acceleration_reads_it_on_x():
    acceleration, period = 0.7, 0.1
    imu = Imu(ImuSettings(rate=10.0), macro_step=0.01)
    assert imu.steps == 10
    start = (0.0, 0.0, -1.0)

    def pose_at(t):  # s = a t^2 / 2 along the heading
        s = 0.5 * acceleration * t * t
        return start[0] + s * math.cos(start[2]), start[1] + s * math.sin(start[2]), start[2]

    messages = run_imu(imu, pose_at, period, 30)
    # The mean speeds of two intervals differ by a * dt: exact for a constant acceleration. The
    # first interval's mean speed, a * dt / 2, is compared with rest before t = 0.
    for n, message in enumerate(messages, start=1):
        expected = acceleration / 2 if n == 1 else acceleration
        assert message.linear_acceleration.x == pytest.approx(expected, abs=1e-9)
        assert message.linear_acceleration.y == 0.0 and message.angular_velocity.z == 0.0


def test_noise_and_bias_have_their_statistics():
    settings = ImuSettings(
        rate=100.0,
        acceleration_noise=0.1,
        angular_velocity_noise=0.02,
        orientation_noise=0.01,
        acceleration_bias=(0.3, -0.2, 0.1),
        angular_velocity_bias=(0.01, -0.02, 0.03),
        seed=7,
    )
    imu = Imu(settings, macro_step=0.01)
    samples = 10_000
    theta = 0.4
    messages = run_imu(imu, lambda t: (1.0, 2.0, theta), 0.01, samples)
    acceleration = np.array(
        [[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for m in messages]
    )
    angular = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for m in messages])
    yaw = np.array([2 * math.atan2(m.orientation.z, m.orientation.w) for m in messages])
    checks = [
        (acceleration, np.array([0.0, 0.0, STANDARD_GRAVITY]) + settings.acceleration_bias, 0.1),
        (angular, np.array(settings.angular_velocity_bias), 0.02),
        (yaw[:, None], np.array([theta]), 0.01),
    ]
    for values, mean, std in checks:
        # The sample mean within 5 standard errors; the sample standard deviation (its own standard
        # error std / sqrt(2 N) = 0.7 %) within 4 %.
        np.testing.assert_array_less(np.abs(values.mean(axis=0) - mean), 5 * std / math.sqrt(samples))
        np.testing.assert_allclose(values.std(axis=0, ddof=1), std, rtol=0.04)
    # The three axes' noises are independent of one another.
    assert abs(np.corrcoef(acceleration.T)[0, 1]) < 5 / math.sqrt(samples)
    covariance = messages[0]
    np.testing.assert_allclose(covariance.linear_acceleration_covariance, np.diag([0.01] * 3).reshape(-1))
    np.testing.assert_allclose(covariance.angular_velocity_covariance, np.diag([0.02**2] * 3).reshape(-1))
    np.testing.assert_allclose(covariance.orientation_covariance, np.diag([0, 0, 0.01**2]).reshape(-1))


def test_the_same_seed_gives_the_same_bytes_and_another_seed_others():
    def payloads(seed):
        imu = Imu(ImuSettings(acceleration_noise=0.1, angular_velocity_noise=0.1, seed=seed), 0.01)
        imu.start(0, 0.0, 0.0, 0.0)
        return [imu.sample(n * 10**7, 0.01 * n, 0.0, 0.0) for n in range(1, 50)]

    assert payloads(3) == payloads(3)
    assert payloads(3) != payloads(4)


def test_the_packed_message_is_what_rosbags_serialises():
    imu = Imu(
        ImuSettings(acceleration_noise=0.1, angular_velocity_noise=0.2, orientation_noise=0.3, seed=1), 0.01
    )
    imu.start(10**9 - 10**7, 0.0, 0.0, 0.0)
    imu.sample(10**9, 0.0, 0.0, 0.0)
    payload = imu.sample(1_010_000_000, 0.01, 0.001, 0.1)
    message = decode(payload)
    assert bytes(HUMBLE.serialize_cdr(message, IMU_TYPE)) == payload
    assert (message.header.stamp.sec, message.header.stamp.nanosec) == (1, 10_000_000)
