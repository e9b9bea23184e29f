"""An IMU on the robot: sensor_msgs/Imu from the vehicle's planar motion (scenario `[imu]`).

The IMU sits at base_link, axes as base_link's (REP-103: x forward, y left, z up). It is sampled
every 1/rate s, from the robot's pose (x, y, theta) at each sample, as the log's /odom has it:
- between two samples the vehicle is taken to move at constant v and omega (an arc, or a line when
  omega = 0: what the project's vehicles integrate within a step, `planar_advance` in
  fmus/common/planar_motion.h), so omega = dtheta / dt and v = chord / (dt * sinc(dtheta / 2)),
  signed by whether the chord points forward: exact for such a motion, whatever the sample period;
- angular velocity (0, 0, omega) [rad/s];
- linear acceleration [m/s^2] in base_link: x the tangential dv/dt (the change of v between the
  last two intervals over dt; the robot is at rest before t = 0), y the centripetal v * omega, z
  +9.80665 (standard gravity). A real accelerometer measures specific force, so a level IMU at
  rest reads +g on z (REP-145: IMU data is reported with gravity, and robot_localization removes it
  when told `imu0_remove_gravitational_acceleration`); a planar robot never tilts, so roll and
  pitch are 0 and gravity is on z alone;
- orientation: the quaternion of the yaw theta (roll = pitch = 0), in the map frame's axes.
Noise: each component gets an independent Gaussian of the `noise` standard deviation plus its
`bias` (acceleration and angular velocity, per axis; orientation: yaw noise only), drawn from one
generator seeded with `seed`: the same scenario writes the same log. The covariances are the noise
variances on the diagonal (sensor_msgs/Imu: row-major 3 x 3; all zeros, when a noise is 0, means
"unknown" to ROS: the value is exact here).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

STANDARD_GRAVITY = 9.80665  # [m/s^2]
FRAME = b"base_link\0"

# CDR of sensor_msgs/msg/Imu with frame "base_link": stamp, frame_id (length, 10 bytes, pad to 8),
# orientation (4d) + covariance (9d), angular velocity (3d) + covariance (9d), linear acceleration
# (3d) + covariance (9d). Offsets count from the end of the 4-byte encapsulation header.
_CDR_HEADER = b"\x00\x01\x00\x00"
_IMU = struct.Struct(f"<iII10s2x{4 + 9 + 3 + 9 + 3 + 9}d")


@dataclass(frozen=True)
class ImuSettings:
    """`[imu]`: rate [Hz]; Gaussian noise standard deviations: acceleration [m/s^2], angular
    velocity [rad/s], orientation (yaw) [rad]; biases (x, y, z) of acceleration [m/s^2] and angular
    velocity [rad/s]; the seed of the noise."""

    rate: float = 100.0
    acceleration_noise: float = 0.0
    angular_velocity_noise: float = 0.0
    orientation_noise: float = 0.0
    acceleration_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular_velocity_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    seed: int = 0


def sinc(x: float) -> float:
    """sin(x) / x, 1 at 0."""
    return 1.0 - x * x / 6.0 if abs(x) < 1e-4 else math.sin(x) / x


def wrap(angle: float) -> float:
    """`angle` [rad] in [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class Imu:
    """The IMU of one run (module docstring): `reading` turns each pose sample into the true
    values, `sample` adds the noise and packs the message. `steps`: its period in macro steps of
    `macro_step` [s] (the scenario loader checks that the rate fits)."""

    topic = "/imu"

    def __init__(self, settings: ImuSettings, macro_step: float) -> None:
        self.settings = settings
        self.steps = max(1, round(1.0 / (settings.rate * macro_step)))
        self.rng = np.random.default_rng(settings.seed)
        self.last: tuple[float, float, float, float] | None = None  # t [s], x, y, theta
        self.v = 0.0  # [m/s] over the last interval: at rest before the first
        s = settings
        self.covariances = tuple(
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, variance) if axis == "yaw" else (
                variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0, variance
            )
            for axis, variance in (
                ("yaw", s.orientation_noise**2),
                ("xyz", s.angular_velocity_noise**2),
                ("xyz", s.acceleration_noise**2),
            )
        )  # fmt: skip

    def start(self, t_ns: int, x: float, y: float, theta: float) -> None:
        """The pose [m, m, rad] at t_ns [ns], where the first interval begins (no message)."""
        self.last = (t_ns / 1e9, x, y, theta)

    def reading(self, t: float, x: float, y: float, theta: float) -> tuple[float, float, float, float]:
        """The true (omega [rad/s], a_x, a_y, a_z [m/s^2]) at time t [s] from the pose [m, m, rad]
        then and at the previous sample (or the start)."""
        last, self.last = self.last, (t, x, y, theta)
        if last is None or t <= last[0]:
            raise ValueError(f"an IMU sample at t = {t} s without an earlier pose")
        dt = t - last[0]
        turn = wrap(theta - last[3])
        dx, dy = x - last[1], y - last[2]
        chord = math.hypot(dx, dy)
        heading = last[3] + 0.5 * turn  # the chord's direction on an arc
        forward = dx * math.cos(heading) + dy * math.sin(heading) >= 0.0
        v = (chord if forward else -chord) / (dt * sinc(0.5 * turn))
        omega = turn / dt
        tangential = (v - self.v) / dt
        self.v = v
        return omega, tangential, v * omega, STANDARD_GRAVITY

    def sample(self, t_ns: int, x: float, y: float, theta: float) -> bytes:
        """The CDR payload of the /imu message at t_ns [ns] for the pose (x, y, theta) then."""
        omega, ax, ay, az = self.reading(t_ns / 1e9, x, y, theta)
        s = self.settings
        noise = self.rng.standard_normal(7).tolist()  # acceleration x y z, angular velocity x y z, yaw
        a_noise, w_noise = s.acceleration_noise, s.angular_velocity_noise
        acceleration = [
            value + bias + a_noise * n
            for value, bias, n in zip((ax, ay, az), s.acceleration_bias, noise[0:3], strict=True)
        ]
        angular = [
            value + bias + w_noise * n
            for value, bias, n in zip((0.0, 0.0, omega), s.angular_velocity_bias, noise[3:6], strict=True)
        ]
        yaw = theta + s.orientation_noise * noise[6]
        orientation = (0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw))
        orientation_cov, angular_cov, acceleration_cov = self.covariances
        sec, nanosec = divmod(int(t_ns), 1_000_000_000)
        return _CDR_HEADER + _IMU.pack(
            sec,
            nanosec,
            len(FRAME),
            FRAME,
            *orientation,
            *orientation_cov,
            *angular,
            *angular_cov,
            *acceleration,
            *acceleration_cov,
        )
