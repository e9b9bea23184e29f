"""The shipped fleet scenarios with missions: fleet_missions (ten robots, shelves and a packing
station on the shipped map) and fleet_fifty (fifty robots on the generated map): their missions
against the map's layout (scenarios/maps/make_warehouse.py), and short runs."""

from __future__ import annotations

import importlib.util
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from cosim.navigation.fleet import run_fleet
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = REPO / "scenarios"


def _generator():
    spec = importlib.util.spec_from_file_location("make_warehouse", SCENARIOS / "maps" / "make_warehouse.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _in_aisle(layout, x: float, y: float) -> bool:
    """(x, y) between two rack rows and alongside a rack segment: in front of a shelf."""
    rows = sorted({(y0, y1) for _, _, y0, y1 in layout.racks})
    between = any(a[1] < y < b[0] for a, b in zip(rows, rows[1:], strict=False))
    return between and any(x0 <= x <= x1 for x0, x1, _, _ in layout.racks)


def test_ten_robots_shuttle_between_shelves_and_the_station_twice():
    fleet = load_scenario(SCENARIOS / "fleet_missions.toml", fleet=True)
    layout = _generator().shipped_layout()
    assert len(fleet.robots) == 10 and fleet.settings.coordination == "none"
    slots = set()
    for robot in fleet.robots:
        shelf, station = robot.mission
        assert robot.repeat == 2 and shelf.dwell > 0 and station.dwell > 0
        assert _in_aisle(layout, shelf.x, shelf.y)
        assert station.y < min(y0 for _, _, y0, _ in layout.racks)  # the bottom corridor
        slots.add((station.x, station.y))
    assert len(slots) == 10  # a drop slot each


def test_fifty_robots_on_the_generated_map_go_to_shelves_the_station_and_back():
    fleet = load_scenario(SCENARIOS / "fleet_fifty.toml", fleet=True)
    generator = _generator()
    layout = generator.regular_layout(150.0, 80.0, 5, 4, bottom_corridor=16.0, station=(30.0, 2.0))
    assert len(fleet.robots) == 50 and fleet.first.map_file.name == "warehouse_fifty.yaml"
    x0, x1, _, _ = layout.station
    for robot in fleet.robots:
        shelf, station, home = robot.mission
        assert _in_aisle(layout, shelf.x, shelf.y) and shelf.dwell > 0
        assert x0 <= station.x <= x1 and station.y == layout.station_front[1] and station.dwell > 0
        assert (home.x, home.y) == robot.scenario.start[:2]


@pytest.mark.slow
def test_a_short_run_of_the_ten_robots():
    fleet = load_scenario(SCENARIOS / "fleet_missions.toml", ["simulation.stop_time=0.5"], fleet=True)
    trace: list = []
    outcome = run_fleet(fleet, trace)
    assert outcome.reason == "stop_time" and outcome.time == pytest.approx(0.5)
    assert not outcome.collisions
    speed = tomllib.loads(fleet.first.text)["pure_pursuit"]["desired_linear_velocity"]  # [m/s]
    positions = np.array([p for _, p in trace])
    for k, robot in enumerate(outcome.robots):
        travelled = np.hypot(*np.diff(positions[:, k], axis=0).T).sum()
        assert robot.distance == pytest.approx(travelled, abs=1e-9)
        assert 0.0 < robot.distance <= speed * 0.5 + 1e-9
        assert robot.status == "stop_time" and robot.goals == 4


@pytest.mark.slow
def test_cosim_runs_fifty_robots_briefly(tmp_path):
    out = tmp_path / "fifty.mcap"
    done = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(SCENARIOS / "fleet_fifty.toml"), "--set",
         "simulation.stop_time=0.3", "--out", str(out), "--no-plot"],
        capture_output=True, text=True, cwd=REPO,
    )  # fmt: skip
    assert done.returncode == 1, done.stderr  # not every robot completed: exit 1
    rows = [line.split() for line in done.stdout.splitlines() if line.startswith("robot")]
    assert len(rows) == 51 and all(row[1] == "stop_time" for row in rows[1:])
    assert "fleet: stop_time at t = 0.30 s" in done.stdout and out.exists()
    assert math.isfinite(float(rows[1][4]))
