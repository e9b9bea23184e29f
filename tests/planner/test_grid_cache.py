"""What `plan()` keeps in a grid's cache (the prepared search, its search map, hybrid A*'s maps) does
not refer back to the grid strongly: a grid dropped after planning is freed by reference counting
alone, with the cyclic collector off (a replanning run makes a one-off grid per replan, and a
cycle would keep each until a collection: memory growing with simulated time)."""

from __future__ import annotations

import gc
import weakref

import numpy as np
import pytest

from planner import OccupancyGrid, plan

OPTIONS = {
    "grid A*": ({}, (1.0, 1.0), (30.0, 20.0)),
    "grid A*, cost gradient, smoothing": (
        {
            "cost_weight": 1.0,
            "cost_scaling_factor": 1.0,
            "untrusted_points": True,
            "smoothing": "line_of_sight",
        },
        (1.0, 1.0),
        (30.0, 20.0),
    ),
    "bidirectional, inflated": (
        {"planner": "bidirectional", "expansion_distance": 1.0},
        (2.0, 2.0),
        (30.0, 20.0),
    ),
    "hybrid A*, inflated": (
        {"planner": "hybrid", "min_turning_radius": 1.0, "expansion_distance": 0.5},
        (2.0, 2.0, 0.0),
        (30.0, 20.0, 0.0),
    ),
}


@pytest.fixture
def collector_off():
    enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    yield
    if enabled:
        gc.enable()


@pytest.mark.parametrize("name", list(OPTIONS))
def test_a_planned_grid_is_freed_without_the_cyclic_collector(name, collector_off):
    options, start, goal = OPTIONS[name]
    occupied = np.zeros((60, 80), bool)
    occupied[10:40, 30] = True  # a wall to go round
    grid = OccupancyGrid(occupied, 0.5)
    result = plan(grid, start, goal, **options)
    again = plan(grid, start, goal, **options)  # from the cache
    assert len(result.path) > 1 and np.array_equal(result.path, again.path)
    assert any(not isinstance(key, str) for key in grid._cache)  # something was kept
    alive = weakref.ref(grid)
    del grid
    assert alive() is None
