"""/imu and /bumper in a robot run: the vehicle driven at held v and omega (an exact circle), and
straight into a wall; the log read with the mcap reader and decoded by rosbags' ROS 2 Humble store."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore

from cosim.errors import CosimError
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario
from cosim.world.imu import STANDARD_GRAVITY

MAP = Path(__file__).resolve().parents[2] / "scenarios" / "maps" / "warehouse.yaml"
HUMBLE = get_typestore(Stores.ROS2_HUMBLE)
V, OMEGA = 0.5, 0.5  # [m/s], [rad/s]: a circle of 1 m radius, free in the warehouse at (6, 6)
RATE = 20.0  # [Hz] of the IMU: 5 macro steps of 10 ms
STOP_TIME = 20.0  # [s]

SCENARIO = """
[scenario]
name = "held_command"
[map]
file = "{map}"
[start]
x = 6.0
y = 6.0
theta = {theta}
[goal]
x = 84.0
y = 53.0
[planner]
replan = false
[vehicle]
fmu = "DifferentialDrive"
radius = 0.5
v = {v}
omega = {omega}
[system]
remove = ["pure_pursuit", "vfh", "mixer"]
[simulation]
macro_step = 0.01
stop_time = {stop}
{extra}
"""


def write(tmp_path: Path, extra: str, v=V, omega=OMEGA, theta=0.0, stop=STOP_TIME) -> Path:
    path = tmp_path / "held.toml"
    path.write_text(SCENARIO.format(map=MAP, v=v, omega=omega, theta=theta, stop=stop, extra=extra))
    return path


def decoded(log: Path, topic: str) -> list[tuple[int, object]]:
    """(log time [ns], message) of every message on `topic`, decoded by rosbags."""
    with log.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        types = {
            channel.topic: summary.schemas[channel.schema_id].name for channel in summary.channels.values()
        }
        return [
            (message.log_time, HUMBLE.deserialize_cdr(message.data, types[topic]))
            for _, _, message in reader.iter_messages(topics=[topic])
        ]


IMU = f"""
[imu]
rate = {RATE}
[bumper]
"""


@pytest.fixture(scope="module", params=["kernel", "python"])
def circle(request, tmp_path_factory):
    """The circle run, by the compiled kernel's blocks and by the Python loop."""
    tmp_path = tmp_path_factory.mktemp(request.param)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("NAVCOSIM_LOOP", request.param)
        result = run_scenario(load_scenario(write(tmp_path, IMU), ["output.plot=false"]), tmp_path / "c.mcap")
    return result, tmp_path / "c.mcap"


def test_a_circle_reads_omega_and_v_omega_at_the_imu_rate(circle):
    result, log = circle
    assert result.outcome.reason == "stop_time"
    messages = decoded(log, "/imu")
    samples = round(STOP_TIME * RATE)
    assert [t_ns for t_ns, _ in messages] == [round(n / RATE * 1e9) for n in range(1, samples + 1)]
    for n, (t_ns, message) in enumerate(messages, start=1):
        assert message.header.stamp.sec * 10**9 + message.header.stamp.nanosec == t_ns
        assert message.header.frame_id == "base_link"
        assert message.angular_velocity.z == pytest.approx(OMEGA, abs=1e-9)
        acceleration = message.linear_acceleration
        assert acceleration.x == pytest.approx(V * RATE if n == 1 else 0.0, abs=1e-6)  # from rest at t = 0
        assert acceleration.y == pytest.approx(V * OMEGA, abs=1e-9)
        assert acceleration.z == STANDARD_GRAVITY
        theta = OMEGA * n / RATE
        yaw = 2 * math.atan2(message.orientation.z, message.orientation.w)
        assert math.cos(yaw - theta) == pytest.approx(1.0, abs=1e-12)
    # No collision: the bumper says so once, at t = 0.
    assert [(t_ns, message.data) for t_ns, message in decoded(log, "/bumper")] == [(0, False)]


def test_both_loops_write_the_same_log_with_noise(tmp_path):
    noisy = f"[imu]\nrate = {RATE}\nnoise = {{acceleration = 0.1, angular_velocity = 0.05}}\nseed = 4\n"
    path = write(tmp_path, noisy + "[bumper]\n", stop=5.0)
    logs = []
    for loop in ("kernel", "python"):
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv("NAVCOSIM_LOOP", loop)
            run_scenario(load_scenario(path, ["output.plot=false"]), tmp_path / f"{loop}.mcap")
        logs.append((tmp_path / f"{loop}.mcap").read_bytes())
    assert logs[0] == logs[1]
    assert len(decoded(tmp_path / "kernel.mcap", "/imu")) == 5 * RATE


def test_the_bumper_turns_on_at_the_collision_the_outcome_reports(tmp_path):
    # Straight south from (6, 6) into the warehouse's wall.
    path = write(tmp_path, IMU, v=1.0, omega=0.0, theta=-math.pi / 2, stop=30.0)
    result = run_scenario(load_scenario(path, ["output.plot=false"]), tmp_path / "hit.mcap")
    assert result.outcome.reason == "collision"
    collision_ns = round(result.outcome.time * 1e9)
    bumper = [(t_ns, message.data) for t_ns, message in decoded(tmp_path / "hit.mcap", "/bumper")]
    assert bumper == [(0, False), (collision_ns, True)]
    # The IMU read the straight line up to the collision: no turn, no centripetal acceleration.
    imu = decoded(tmp_path / "hit.mcap", "/imu")
    assert imu[-1][0] <= collision_ns < imu[-1][0] + 1e9 / RATE
    assert all(
        message.angular_velocity.z == 0.0 and message.linear_acceleration.y == 0.0 for _, message in imu
    )


def test_a_run_without_the_sections_has_neither_topic(tmp_path):
    log = tmp_path / "plain.mcap"
    run_scenario(load_scenario(write(tmp_path, "", stop=1.0), ["output.plot=false"]), log)
    assert decoded(log, "/imu") == [] and decoded(log, "/bumper") == []


def test_output_topics_remaps_them(tmp_path):
    log = tmp_path / "remapped.mcap"
    extra = IMU + '[output.topics]\nimu = "/sensors/imu"\nbumper = "/base/bumper"\n'
    run_scenario(load_scenario(write(tmp_path, extra, stop=1.0), ["output.plot=false"]), log)
    assert len(decoded(log, "/sensors/imu")) == 20 and len(decoded(log, "/base/bumper")) == 1
    assert decoded(log, "/imu") == []


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ("[imu]\nrate = 30.0\n", "[imu].rate: 30 Hz is not a whole number of macro steps"),
        ("[imu]\nnoise = {accel = 0.1}\n", "[imu].noise.accel: unknown key"),
        ("[imu]\nnoise = {acceleration = -0.1}\n", "[imu].noise.acceleration: must be >= 0"),
        ("[imu]\nbias = {acceleration = [0.1, 0.2]}\n", "[imu].bias.acceleration: must have 3 numbers"),
        ("[imu]\nseed = -1\n", "[imu].seed: must be >= 0"),
        ("[bumper]\nradius = 0.5\n", "[bumper].radius: unknown key"),
    ],
)
def test_bad_sections_are_one_line_errors(tmp_path, extra, message):
    with pytest.raises(CosimError, match=message.replace("[", r"\[").replace("]", r"\]").replace(".", r"\.")):
        load_scenario(write(tmp_path, extra))


def test_example_commented_sensor_blocks_are_valid_when_uncommented(tmp_path):
    example = (MAP.parents[1] / "example_commented.toml").read_text().splitlines()
    start = example.index("# [imu]")
    block = []
    for line in example[start:]:
        if line.strip() == "#":
            break
        block.append(line.removeprefix("# "))
    block.append(example[example.index("# [bumper]")].removeprefix("# "))
    scenario = load_scenario(write(tmp_path, "\n".join(block) + "\n"))
    assert scenario.bumper
    imu = scenario.imu
    assert imu.rate == 100.0 and imu.acceleration_noise == 0.02 and imu.angular_velocity_noise == 0.001
    assert imu.acceleration_bias == imu.angular_velocity_bias == (0.0, 0.0, 0.0) and imu.seed == 0
