"""Coordinated fleets simulated: head-on and intersection with "mapf" (and delayed robots) and
"prioritized" complete without contact or deadlock.

Besides the run's outcome, every step's positions (the run's trace) are checked independently:
no two footprints closer than the sum of their radii, and no coordination cell overlapped by two
footprints at once (what the action dependency graph promises).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.navigation.coordination import CoordinationGrid
from cosim.navigation.fleet import format_fleet, run_fleet
from cosim.scenario.load import load_scenario
from planner.grid import OccupancyGrid

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"


def _run(name: str, *overrides: str):
    fleet = load_scenario(SCENARIOS / name, list(overrides), fleet=True)
    trace: list = []
    outcome = run_fleet(fleet, trace=trace)
    print(format_fleet(fleet, outcome))
    return fleet, outcome, trace


def _check_trace(fleet, trace) -> None:
    radii = np.array([robot.radius for robot in fleet.robots])
    grid = OccupancyGrid.from_file(fleet.first.map_file)
    cells = CoordinationGrid(grid, float(radii.max()))
    n = len(radii)
    closest = np.inf
    for _t, positions in trace:
        gaps = np.hypot(*(positions[:, None, :] - positions[None, :, :]).transpose(2, 0, 1))
        gaps -= radii[:, None] + radii[None, :]
        gaps[np.arange(n), np.arange(n)] = np.inf
        closest = min(closest, float(gaps.min()))
    assert closest > 0.0, f"footprints touched (gap {closest:.3f} m)"
    for t, positions in trace[::5]:
        owners: dict = {}
        for k, (x, y) in enumerate(positions):
            for cell in cells.overlapped(float(x), float(y), float(radii[k])):
                assert cell not in owners, f"t = {t:.2f} s: robots {owners[cell]} and {k} both in cell {cell}"
                owners[cell] = k


def _assert_all_completed(outcome) -> None:
    assert outcome.collisions == []
    assert outcome.deadlocks == []
    assert [robot.status for robot in outcome.robots] == ["completed"] * len(outcome.robots)
    assert outcome.reason == "completed" and outcome.exit_code == 0


@pytest.mark.slow
def test_head_on_with_mapf_passes_without_contact_and_a_delayed_robot_only_takes_longer():
    fleet, outcome, trace = _run("fleet_head_on_mapf.toml")
    _assert_all_completed(outcome)
    _check_trace(fleet, trace)
    # robot1 at half speed, robot2 halted for 5 s on its way: the others wait as the graph says.
    fleet, delayed, trace = _run(
        "fleet_head_on_mapf.toml",
        "robots.robot1.speed_factor=0.5",
        "robots.robot2.stop={ at = 3.0, duration = 5.0 }",
        "simulation.stop_time=120",
    )
    _assert_all_completed(delayed)
    _check_trace(fleet, trace)
    slow, stopped = delayed.robots
    # Half speed: the straight 22 m take about twice as long as at full speed.
    assert slow.completion_time > 1.8 * outcome.robots[0].completion_time
    assert stopped.stopped_time >= 5.0
    assert delayed.makespan > outcome.makespan


@pytest.mark.slow
def test_intersection_with_mapf_and_with_delays_has_no_contact_and_no_deadlock():
    fleet, outcome, trace = _run("fleet_intersection_mapf.toml")
    _assert_all_completed(outcome)
    _check_trace(fleet, trace)
    fleet, delayed, trace = _run(
        "fleet_intersection_mapf.toml",
        "robots.robot1.speed_factor=0.5",
        "robots.robot3.stop={ at = 3.0, duration = 5.0 }",
        "simulation.stop_time=120",
    )
    _assert_all_completed(delayed)
    _check_trace(fleet, trace)
    assert delayed.robots[2].stopped_time >= 5.0


@pytest.mark.slow
def test_prioritized_runs_through_the_same_execution():
    fleet, outcome, trace = _run("fleet_intersection_mapf.toml", "fleet.coordination=prioritized")
    _assert_all_completed(outcome)
    _check_trace(fleet, trace)


def test_a_stop_halts_an_uncoordinated_robot_too():
    fleet, outcome, _ = _run(
        "fleet_head_on.toml", "robots.robot2.stop={ at = 1.0, duration = 3.0 }", "simulation.stop_time=6"
    )
    robot1, robot2 = outcome.robots
    # robot2 is halted from 1 s to 4 s, so drives 3 s of the 6 at 1.5 m/s; robot1 drives all 6 s.
    assert robot2.stopped_time == pytest.approx(3.0, abs=0.15)
    assert robot2.distance == pytest.approx(1.5 * 3.0, abs=0.3)
    assert robot1.distance == pytest.approx(1.5 * 6.0, abs=0.3)


@pytest.mark.slow
def test_cosim_run_prints_a_coordinated_fleet_without_collisions(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    result = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(SCENARIOS / "fleet_head_on_mapf.toml"),
         "--out", str(tmp_path / "f.mcap"), "--no-plot"],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "collisions 0; deadlocks 0" in result.stdout
    # the planning's line, and its counts in the log's fleet_outcome (read by the mcap package)
    line = next(line for line in result.stdout.splitlines() if line.startswith("coordination: "))
    match = re.fullmatch(
        r"coordination: mapf: (\d+) solves \(0 without a plan\), [0-9.]+ s of wall time planning", line
    )
    assert match, line
    from mcap.reader import make_reader

    with open(tmp_path / "f.mcap", "rb") as stream:
        metadata = {m.name: m.metadata for m in make_reader(stream).iter_metadata()}
    planning = json.loads(metadata["fleet_outcome"]["coordination"])
    # 2 robots, one goal each: the first plan, then a re-solve when each completes
    assert planning == {"method": "mapf", "solves": int(match.group(1)), "failures": 0}
    assert planning["solves"] >= 1


def test_an_unknown_obstacle_on_the_plan_is_seen_and_planned_around():
    from cosim.scenario.load import parse_scenario

    # A 1 m box on the aisle's centre line, where the plan of fleet_head_on_mapf runs.
    text = (SCENARIOS / "fleet_head_on_mapf.toml").read_text()
    box = '[[obstacles]]\ntype = "rectangle"\ncenter = [20.0, 19.0]\nsize = [1.0, 1.0]\n\n[[robots]]'
    fleet = parse_scenario(text.replace("[[robots]]", box, 1), "box.toml", SCENARIOS)
    trace: list = []
    outcome = run_fleet(fleet, trace=trace)
    print(format_fleet(fleet, outcome))
    _assert_all_completed(outcome)  # a robot that hit the box would have status "collision"
    _check_trace(fleet, trace)
    # The robots' distance to the box's nearest side stayed above their radius.
    for robot in outcome.robots:
        assert robot.min_clearance_walls > 0.3
