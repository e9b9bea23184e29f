"""The fleet loop's block-at-a-time shortcuts against the step-at-a-time code they replace: contacts
checked for a whole block (`FleetContacts.steps`) against `FleetContacts.step` per step; the bytes
of /plan and of the fleet's pose messages patched into layouts against the serialised messages; and
a fleet run (judged a robot at a time per block, its Python components stepped apart from the
compiled kernel, its planners by their C step where that needs no Python, the kernel's rows keeping
only the scalar inputs) against the same run judged step by step with the kernel handing each Python
component back, the planners stepping in Python, and keeping whole rows: the same outcome and the
same log, message for message."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from fixtures.mcap_messages import logged_messages
from mcap.reader import make_reader

from cosim.core.master import Master
from cosim.navigation import fleet as fleet_module
from cosim.navigation.fleet_log import outcome_record
from cosim.navigation.planner import PlannerComponent
from cosim.record import recorder, rosmsg
from cosim.record.fleet_steps import _Filled, _layout, _odometry, _pose_stamped, _Template, _tf
from cosim.scenario.load import load_scenario
from cosim.world.fleet import FleetContacts

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _walk(rng, robots: int, steps: int) -> np.ndarray:
    """Positions (steps + 1 x robots x 2) of robots wandering in a 3 m square: they meet often."""
    start = rng.uniform(0.0, 3.0, (robots, 2))
    moves = rng.normal(0.0, 0.08, (steps, robots, 2))
    moves[steps // 2] = 0.0  # a step without motion (no relative motion: ww = 0)
    return np.concatenate((start[None], start[None] + np.cumsum(moves, axis=0)))


@pytest.mark.parametrize("seed", range(4))
def test_contacts_of_a_block_are_those_of_its_steps(seed):
    rng = np.random.default_rng(seed)
    names = [f"robot{k}" for k in range(6)]
    radii = rng.uniform(0.2, 0.5, len(names))
    path = _walk(rng, len(names), 60)
    h = 0.01
    by_step, by_block = FleetContacts(names, radii), FleetContacts(names, radii)
    by_step.start(path[0])
    by_block.start(path[0])
    expected = [by_step.step(k * h, h, path[k], path[k + 1]) for k in range(60)]
    found: list = []
    for first, end in ((0, 7), (7, 17), (17, 18), (18, 40), (40, 60)):  # blocks of any length
        starts = [k * h for k in range(first, end)]
        found += by_block.steps(starts, [h] * (end - first), path[first : end + 1])
    assert sum(len(contacts) for contacts in expected) > 0  # the robots did touch
    assert found == expected
    assert by_block.contacts == by_step.contacts
    assert np.array_equal(by_block.min_clearance, by_step.min_clearance)
    assert np.array_equal(by_block.touching, by_step.touching)


@pytest.mark.parametrize("count", [1, 2, 3, 17, 400])
def test_plan_bytes_are_those_of_the_serialised_path(count):
    rng = np.random.default_rng(count)
    points = np.cumsum(rng.normal(0.0, 0.3, (count, 2)), axis=0)
    steps = np.diff(points, axis=0)
    headings = np.append(np.arctan2(steps[:, 1], steps[:, 0]), 0.0)[:count]
    t_ns = int(rng.integers(0, 10**12))
    layout = recorder._path_layout()
    assert layout.usable
    expected = rosmsg.serialize(
        rosmsg.make(
            "nav_msgs/msg/Path",
            header=rosmsg.header(t_ns, "map"),
            poses=[
                rosmsg.pose_stamped(t_ns, x, y, yaw) for (x, y), yaw in zip(points, headings, strict=True)
            ],
        ),
        "nav_msgs/msg/Path",
    )
    assert layout.cdr(t_ns, points[:, 0], points[:, 1], headings) == expected


def test_fleet_pose_bytes_are_those_of_the_serialised_messages(tmp_path):
    # Each robot's /odom and /pose are rows of a fixed layout packed in C, the /tf of every robot a
    # template filled per time: the bytes of the messages serialised in full, read back.
    from functools import partial

    robots = [SimpleNamespace(odom_frame=f"{name}/odom", base_frame=f"{name}/base_link")
              for name in ("robot1", "robot10", "r")]  # fmt: skip
    rng = np.random.default_rng(7)
    stamps = [0, 1_500_000_000, 123_456_789_012]
    rows = rng.normal(0.0, 3.0, (len(stamps), len(robots), 5))  # x, y, theta, v, omega
    rows[1, 2, 3:] = math.nan  # no command: a NaN twist
    quaternions = np.stack((np.sin(rows[..., 2] / 2.0), np.cos(rows[..., 2] / 2.0)), axis=-1)
    for (k, r), theta in np.ndenumerate(rows[..., 2]):
        quaternions[k, r] = (math.sin(theta / 2.0), math.cos(theta / 2.0))  # as `rosmsg.quaternion`
    values = np.concatenate((rows[..., :2], quaternions, rows[..., 3:]), axis=-1)  # x, y, qz, qw, v, omega
    tf = _Filled(_Template(partial(_tf, robots), 4 * len(robots)))
    path = tmp_path / "poses.mcap"
    with recorder.Recorder(path, trace=False) as log:
        signals = []
        times = np.array(stamps, dtype=np.int64)
        for r, robot in enumerate(robots):
            view = log.namespaced(f"n{r}")
            odom = view.fixed_channel("/odom", _layout(partial(_odometry, robot), 6))
            pose = view.fixed_channel("/pose", _layout(_pose_stamped, 4))
            signals += [
                (odom, 10 * times + 2 * r, times, values[:, r]),
                (pose, 10 * times + 2 * r + 1, times, values[:, r, :4]),
            ]
        log.hold_steps(signals)
    read: dict[str, list[bytes]] = {}
    with open(path, "rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
            read.setdefault(channel.topic, []).append(bytes(message.data))
    for r, robot in enumerate(robots):
        assert read[f"/n{r}/odom"] == [
            _odometry(robot, t_ns, values[k, r].tolist()) for k, t_ns in enumerate(stamps)
        ]
        assert read[f"/n{r}/pose"] == [
            rosmsg.pose_stamped_cdr(t_ns, *rows[k, r, :3].tolist()) for k, t_ns in enumerate(stamps)
        ]
    for k, t_ns in enumerate(stamps):
        assert tf.fill(t_ns, values[k, :, :4]) == _tf(robots, t_ns, values[k, :, :4].reshape(-1).tolist())


def _judge_step_by_step(each, ends, lengths, start):
    """The loop's judging before blocks: `_judge` for every step."""
    if not each.judged:
        return None
    before = start
    for i, (t, h) in enumerate(zip(ends, lengths, strict=True)):
        after = each.poses[i, :2]
        fleet_module._judge(each, t, h, before, after, i)
        before = after
        if not each.judged:
            return i
    return None


def _contacts_step_by_step(self, starts, lengths, positions):
    return [
        self.step(t, h, positions[k], positions[k + 1])
        for k, (t, h) in enumerate(zip(starts, lengths, strict=True))
    ]


@pytest.mark.slow
def test_a_fleet_run_is_that_of_the_step_by_step_loop(tmp_path, monkeypatch):
    """fleet_missions for 40 s: contacts at once, robots hitting racks (halted), goals reached and
    dwelt at; with on_collision = "continue" every shortcut is taken."""
    overrides = ["simulation.stop_time=40"]
    fleet = load_scenario(SCENARIOS / "fleet_missions.toml", overrides, fleet=True)
    made = []
    make = fleet_module._PythonSteps.make.__func__

    def recorded(cls, master, previous=None):
        made.append(make(cls, master, previous))
        return made[-1]

    monkeypatch.setattr(fleet_module._PythonSteps, "make", classmethod(recorded))
    tables = Master.kernel_tables
    scalar = []

    def kernel_tables(master, *args, **options):
        scalar.append(options.get("scalar_rows", False))
        return tables(master, *args, **options)

    monkeypatch.setattr(Master, "kernel_tables", kernel_tables)
    fast = fleet_module.run_fleet(fleet, log_path=tmp_path / "fast.mcap")
    assert scalar and all(scalar)  # rows without the plans' and scans' elements
    assert len(made) > 1 and None not in made  # stepped apart, also after robots were switched off
    assert all(each.snapshot is not None for each in made)  # lidars read the 10 vehicles' poses at once
    # the planners stepped by their C step (`_c_step`) where that needs no Python
    assert all(any(c_step is not None for *_, c_step in each.steps) for each in made)

    monkeypatch.setattr(fleet_module, "_judge_block", _judge_step_by_step)
    monkeypatch.setattr(fleet_module._FleetJudge, "make", classmethod(lambda *_: None))
    monkeypatch.setattr(fleet_module._PythonSteps, "make", classmethod(lambda *_: None))
    monkeypatch.setattr(FleetContacts, "steps", _contacts_step_by_step)
    monkeypatch.setattr(PlannerComponent, "kernel_step", lambda _self: None)  # every step in Python
    monkeypatch.setattr(  # whole rows: every input array's elements too
        Master,
        "kernel_tables",
        lambda master, *args, **options: tables(master, *args, **options | {"scalar_rows": False}),
    )
    fleet = load_scenario(SCENARIOS / "fleet_missions.toml", overrides, fleet=True)
    slow = fleet_module.run_fleet(fleet, log_path=tmp_path / "slow.mcap")

    assert fast.collisions and any(robot.collision for robot in fast.robots)
    assert any(robot.goals_reached for robot in fast.robots)
    assert outcome_record(fast) == outcome_record(slow)
    assert logged_messages(tmp_path / "fast.mcap") == logged_messages(tmp_path / "slow.mcap")
