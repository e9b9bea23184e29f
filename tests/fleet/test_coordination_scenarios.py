"""The shipped coordinated ten- and fifty-robot scenarios: every start and goal in its own free
2 m coordination cell, found from the map's pixels directly (not through the coordinator's grid)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.scenario.load import load_scenario
from planner.grid import OccupancyGrid

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
COORDINATED = ("fleet_missions_mapf.toml", "fleet_fifty_mapf.toml")


def _cell(grid: OccupancyGrid, size: float, x: float, y: float) -> tuple[int, int]:
    # Cells counted from the map's lower-left corner: (column, row from the bottom).
    return (math.floor((x - grid.origin[0]) / size), math.floor((y - grid.origin[1]) / size))


def _free(grid: OccupancyGrid, size: float, cell: tuple[int, int]) -> bool:
    # All map pixels whose centres lie in the cell are free; the cell lies wholly on the map.
    col, row = cell
    rows, cols = grid.occupied.shape
    x0, y0 = grid.origin[0] + col * size, grid.origin[1] + row * size
    if x0 < grid.origin[0] or y0 < grid.origin[1]:
        return False
    if x0 + size > grid.origin[0] + cols * grid.resolution + 1e-9:
        return False
    if y0 + size > grid.origin[1] + rows * grid.resolution + 1e-9:
        return False
    xs = grid.origin[0] + (np.arange(cols) + 0.5) * grid.resolution
    ys = grid.origin[1] + (rows - 1 - np.arange(rows) + 0.5) * grid.resolution
    inside = ((ys >= y0) & (ys < y0 + size))[:, None] & ((xs >= x0) & (xs < x0 + size))[None, :]
    return not bool(np.asarray(grid.occupied)[inside].any())


@pytest.mark.parametrize("name", COORDINATED)
def test_coordinated_fleet_starts_and_goals_lie_in_distinct_free_cells(name):
    fleet = load_scenario(SCENARIOS / name, fleet=True)
    assert fleet.settings.coordination == "mapf"
    grid = OccupancyGrid.from_file(fleet.first.map_file)
    radius = max(robot.radius for robot in fleet.robots)
    # The smallest multiple of the map's resolution at least 2 (r + 0.5 m): 2 m for r = 0.5 m.
    size = math.ceil(2 * (radius + 0.5) / grid.resolution - 1e-9) * grid.resolution
    assert size == pytest.approx(2.0)
    starts = [_cell(grid, size, *robot.scenario.start[:2]) for robot in fleet.robots]
    assert len(set(starts)) == len(starts), "two robots start in one cell"
    lasts = [_cell(grid, size, robot.mission[-1].x, robot.mission[-1].y) for robot in fleet.robots]
    assert len(set(lasts)) == len(lasts), "two robots end in one cell"
    for robot, start in zip(fleet.robots, starts, strict=True):
        assert _free(grid, size, start), f"{robot.name} starts in a cell that is not free"
        for goal in robot.mission:
            assert _free(grid, size, _cell(grid, size, goal.x, goal.y)), f"{robot.name}: goal {goal}"
    assert len(fleet.robots) == {"fleet_missions_mapf.toml": 10, "fleet_fifty_mapf.toml": 50}[name]


@pytest.mark.slow
def test_fifty_coordinated_robots_leave_their_parking_rows_without_contact():
    # The busiest part of the fifty-robot run: all leave the parking rows at once (10 s simulated).
    from tests.fleet.test_coordination_run import _check_trace, _run

    fleet, outcome, trace = _run("fleet_fifty_mapf.toml", "simulation.stop_time=10")
    assert outcome.collisions == [] and outcome.deadlocks == []
    _check_trace(fleet, trace)
    # They do drive: most robots have left their start cells (some wait for others to pass).
    first, last = trace[0][1], trace[-1][1]
    moved = np.hypot(*(last - first).T)
    assert (moved > 2.0).sum() >= 25, moved
