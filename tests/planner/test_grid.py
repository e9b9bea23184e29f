"""OccupancyGrid: world <-> cell conventions (row 0 on top, origin at the lower-left corner)."""

import numpy as np
import pytest

from planner import OccupancyGrid, PlannerError


def test_cell_centres_follow_ros_convention():
    grid = OccupancyGrid(np.zeros((4, 6), bool), resolution=0.5, origin=(10.0, -2.0))
    assert grid.shape == (4, 6)
    # Bottom-left cell is the last row, first column; its centre is half a cell from the origin.
    assert grid.cell_to_world((3, 0)) == pytest.approx((10.25, -1.75))
    # Top-right cell.
    assert grid.cell_to_world((0, 5)) == pytest.approx((12.75, -0.25))
    for row in range(4):
        for col in range(6):
            assert grid.world_to_cell(grid.cell_to_world((row, col))) == (row, col)
    cells = np.array([[0, 0], [3, 5], [2, 1]])
    assert np.array_equal(grid.world_to_cells(grid.cells_to_world(cells)), cells)


def test_world_to_cell_on_edges_and_outside():
    grid = OccupancyGrid(np.zeros((2, 3), bool), resolution=1.0)
    assert grid.world_to_cell((0.0, 0.0)) == (1, 0)  # lower-left corner belongs to the bottom row
    assert grid.world_to_cell((2.999, 1.999)) == (0, 2)
    assert not grid.contains_cell(grid.world_to_cell((3.0, 0.5)))
    assert not grid.contains_cell(grid.world_to_cell((-0.01, 0.5)))


def test_occupied_is_read_only_copy():
    source = np.zeros((3, 3), bool)
    grid = OccupancyGrid(source)
    source[1, 1] = True
    assert not grid.occupied[1, 1]
    with pytest.raises(ValueError):
        grid.occupied[0, 0] = True


@pytest.mark.parametrize("resolution", [0.0, -1.0, float("nan"), "abc"])
def test_bad_resolution(resolution):
    with pytest.raises(PlannerError, match="resolution"):
        OccupancyGrid(np.zeros((2, 2), bool), resolution=resolution)


@pytest.mark.parametrize(
    "array, match",
    [
        (np.zeros(4, bool), "2-D"),
        (np.zeros((0, 3), bool), "non-empty"),
        (np.full((2, 2), 0.5), "0 \\(free\\)"),
    ],
)
def test_bad_arrays(array, match):
    with pytest.raises(PlannerError, match=match):
        OccupancyGrid(array)


def test_numeric_zero_one_array():
    grid = OccupancyGrid(np.array([[0, 1], [1, 0]]))
    assert grid.occupied.dtype == bool and grid.occupied.tolist() == [[False, True], [True, False]]
