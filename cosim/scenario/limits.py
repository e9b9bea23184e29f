"""The documented limits of a scenario (README "Limits"), each checked on load with a message that
names the key and the limit.

They keep every accepted scenario runnable in bounded time and memory: a run is at most
`[simulation].max_steps` macro steps (default `MAX_STEPS`, raised with `--max-steps`), of at most
`[simulation].max_components` FMU components (the template's and `[components.*]`; default `MAX_COMPONENTS`,
raised with `--set simulation.max_components=N`); times fit
the integer nanosecond time base; obstacles, lidar beams and speeds have ceilings far above any
scenario of the thesis. The map's own limit (cells) is `planner.mapio.MAX_MAP_CELLS`.
"""

from __future__ import annotations

from cosim.scenario.schema import TableReader, describe, is_number

MAX_STEPS = 100_000_000  # macro steps per run, default of [simulation].max_steps
# FMU components of one system (the template's and [components.*]). Each is an FMU instance that
# describing the system loads and every macro step calls: 2,000 of them take minutes to set up
# before the first step, far beyond any robot's system.
MAX_COMPONENTS = 1_000
MIN_MACRO_STEP = 1e-9  # [s] the time base counts nanoseconds
MAX_TIME = 1e9  # [s] stop time, macro step and component periods (int64 nanoseconds hold 292 years)
MAX_OBSTACLES = 1_000  # [[obstacles]]: each one is tested by every lidar beam and collision check
MAX_LIDAR_BEAMS = 720  # the VectorFieldHistogram FMU's input size
# [m] longest lidar range: /scan's sensor_msgs/LaserScan holds ranges as float32, and a lidar
# reaching farther than any map is no sensor (the widest Moving AI maps are a few km).
MAX_LIDAR_RANGE = 1e6
MAX_NAME_LENGTH = 100  # [scenario].name: it becomes part of the log's file name
MAX_LINEAR_SPEED = 100.0  # [m/s] commanded speeds of the robot and speeds of moving obstacles
MAX_ANGULAR_SPEED = 100.0  # [rad/s] commanded yaw rates
# The template roles' commanded speeds. A run's own ceiling, not a range of the FMU (those live in
# its modelDescription.xml): the world is checked once per macro step, and at 100 m/s and the
# default 10 ms step the robot already moves 1 m between two collision checks.
ROLE_SPEEDS = {
    "pure_pursuit": {"desired_linear_velocity": (MAX_LINEAR_SPEED, "m/s"),
                     "max_angular_velocity": (MAX_ANGULAR_SPEED, "rad/s")},
    "mixer": {"recovery_linear_velocity": (MAX_LINEAR_SPEED, "m/s"),
              "recovery_angular_velocity": (MAX_ANGULAR_SPEED, "rad/s")},
}  # fmt: skip


def check_run_length(simulation: TableReader, macro_step: float, stop_time: float) -> int:
    """Read `[simulation].max_steps` and check that stop_time / macro_step stays within it."""
    max_steps = simulation.integer("max_steps", MAX_STEPS, minimum=1)
    steps = stop_time / macro_step
    if steps > max_steps + 0.5:
        raise simulation.error(
            "stop_time",
            f"{stop_time:g} s at macro_step {macro_step:g} s is {steps:.3g} steps, above max_steps = "
            f"{max_steps:.3g} (raise [simulation].max_steps or give --max-steps)",
        )
    return max_steps


def check_time_base(table: TableReader, key: str, seconds: float) -> None:
    """A macro step is a whole number (>= 1) of nanoseconds: the master's integer time base."""
    nanoseconds = seconds * 1e9
    if seconds < MIN_MACRO_STEP:
        raise table.error(
            key,
            f"must be at least 1 ns ({MIN_MACRO_STEP:g} s, the time base), got {seconds:g}",
        )
    if abs(nanoseconds - round(nanoseconds)) > 1e-6 * nanoseconds:
        raise table.error(key, f"must be a whole number of nanoseconds, got {seconds!r} s")


def check_speeds(table: TableReader, role: str, parameters: dict[str, object]) -> None:
    """The commanded speeds a role's section sets stay within `ROLE_SPEEDS` (in magnitude)."""
    for key, (ceiling, unit) in ROLE_SPEEDS.get(role, {}).items():
        value = parameters.get(key)
        if is_number(value) and not abs(value) <= ceiling:
            raise table.error(key, f"must be at most {ceiling:g} {unit} in magnitude, got {describe(value)}")


def check_component_count(table: TableReader, key: str, count: int, max_components: int) -> None:
    """A system of `count` components stays within `[simulation].max_components`."""
    if count > max_components:
        raise table.error(
            key,
            f"{count} components, above max_components = {max_components} (raise "
            "[simulation].max_components, or --set simulation.max_components=N)",
        )
