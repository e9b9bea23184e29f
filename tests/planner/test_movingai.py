"""Optimality on Moving AI benchmarks: the .scen optimal lengths are independent ground truth
(8-connected, octile costs, no corner cutting)."""

from pathlib import Path

import pytest

import planner

DATA = Path(__file__).resolve().parents[1] / "data" / "movingai"
MAPS = ["room-64-64-8", "random-64-64-10", "maze-128-128-2", "warehouse-10-20-10-2-1"]
QUERIES_PER_MAP = 60  # 240 queries in all, spread over every bucket of each file


def _queries(name: str):
    lines = (DATA / f"{name}-random-1.scen").read_text().splitlines()[1:]
    step = max(1, len(lines) // QUERIES_PER_MAP)
    for line in lines[::step][:QUERIES_PER_MAP]:
        fields = line.split("\t")
        start_col, start_row, goal_col, goal_row = (int(value) for value in fields[4:8])
        yield (start_row, start_col), (goal_row, goal_col), float(fields[8])


@pytest.mark.parametrize("name", MAPS)
@pytest.mark.parametrize("search", ["astar", "bidirectional"])
def test_scen_optimal_lengths(name, search):
    grid = planner.OccupancyGrid.from_file(DATA / f"{name}.map")
    assert grid.resolution == 1.0 and grid.origin == (0.0, 0.0)
    count = 0
    for start, goal, optimal in _queries(name):
        result = planner.plan(grid, grid.cell_to_world(start), grid.cell_to_world(goal), planner=search)
        assert result.length == pytest.approx(optimal, rel=1e-6, abs=1e-9), (start, goal)
        assert tuple(result.cells[0]) == start and tuple(result.cells[-1]) == goal
        assert not grid.occupied[result.cells[:, 0], result.cells[:, 1]].any()
        count += 1
    assert count == QUERIES_PER_MAP


def test_resolution_scales_lengths():
    """The same map at 0.25 m/cell gives a quarter of the cell-unit optimum."""
    base = planner.OccupancyGrid.from_file(DATA / "room-64-64-8.map")
    grid = planner.OccupancyGrid(base.occupied, resolution=0.25, origin=(-3.0, 7.0))
    for start, goal, optimal in list(_queries("room-64-64-8"))[:10]:
        result = planner.plan(grid, grid.cell_to_world(start), grid.cell_to_world(goal))
        assert result.length == pytest.approx(0.25 * optimal, rel=1e-6)
