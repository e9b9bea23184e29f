"""scenarios/maps/make_warehouse.py's regular layouts: the grid's size, racks and station occupied,
aisles and corridors free, every free cell reachable from every other (scipy's connected-component
labelling, and the planner's A* between aisles of the far corners), the same bytes for the same
arguments, and the committed fleet_fifty map equal to the command its scenario records."""

from __future__ import annotations

import importlib.util
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import label

import planner

REPO = Path(__file__).resolve().parents[2]
MAPS = REPO / "scenarios" / "maps"


@pytest.fixture(scope="module")
def generator():
    spec = importlib.util.spec_from_file_location("make_warehouse", MAPS / "make_warehouse.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


LARGE = {"rack_rows": 5, "rack_columns": 4, "bottom_corridor": 16.0, "station": (30.0, 2.0)}


def _centre_cells(layout, box):
    """(rows, cols) of the cells whose centres lie inside box = (x0, x1, y0, y1), row 0 at the top."""
    res = layout.resolution
    rows, cols = round(layout.height / res), round(layout.width / res)
    x = (np.arange(cols) + 0.5) * res
    y = (rows - np.arange(rows) - 0.5) * res
    x0, x1, y0, y1 = box
    return np.ix_((y > y0) & (y < y1), (x > x0) & (x < x1))


def test_size_racks_station_and_free_aisles(generator):
    layout = generator.regular_layout(150.0, 80.0, **LARGE)
    occupied = generator.build_warehouse(layout)
    assert occupied.shape == (160, 300)  # 80 m x 150 m at 0.5 m/cell
    assert occupied[0].all() and occupied[-1].all() and occupied[:, 0].all() and occupied[:, -1].all()
    assert len(layout.racks) == 20
    for box in [*layout.racks, layout.station]:
        cells = occupied[_centre_cells(layout, box)]
        assert cells.size > 0 and cells.all(), box
    # Rack depth 3 m, aisles 8 m, cross corridors 10 m (to the half cell the edges are snapped to).
    for _, _, y0, y1 in layout.racks:
        assert y1 - y0 == pytest.approx(3.0)
    rows = sorted({(y0, y1) for _, _, y0, y1 in layout.racks})
    assert [b[0] - a[1] for a, b in zip(rows, rows[1:], strict=False)] == pytest.approx([8.0] * 4)
    columns = sorted({(x0, x1) for x0, x1, _, _ in layout.racks})
    gaps = [b[0] - a[1] for a, b in zip(columns, columns[1:], strict=False)]
    assert all(abs(gap - 10.0) <= 0.5 for gap in gaps)
    # Everything that is not a rack, the station or the wall is free: the aisles and corridors.
    expected = np.zeros_like(occupied)
    expected[0, :] = expected[-1, :] = expected[:, 0] = expected[:, -1] = True
    for box in [*layout.racks, layout.station]:
        expected[_centre_cells(layout, box)] = True
    assert np.array_equal(occupied, expected)
    for y in layout.aisles_y:  # each aisle's centre line free from wall to wall
        row = round((layout.height - y) / layout.resolution - 0.5)
        assert not occupied[row, 1:-1].any(), y


def test_every_free_cell_is_connected_and_a_star_crosses_the_warehouse(generator, tmp_path):
    layout = generator.regular_layout(150.0, 80.0, **LARGE)
    occupied = generator.build_warehouse(layout)
    _, parts = label(~occupied)  # 4-connected components of the free cells
    assert parts == 1
    generator.main(tmp_path, layout, "big")
    grid = planner.OccupancyGrid.from_file(tmp_path / "big.yaml")
    assert grid.occupied.shape == occupied.shape and np.array_equal(grid.occupied, occupied)
    first_x = (layout.racks[0][0] + layout.racks[0][1]) / 2
    last_x = (layout.racks[-1][0] + layout.racks[-1][1]) / 2
    start, goal = (first_x, layout.aisles_y[0]), (last_x, layout.aisles_y[-1])
    result = planner.plan(grid, start, goal, expansion_distance=3.0)
    # Racks stand between the aisles: the path detours through a cross corridor.
    assert result.length > np.hypot(goal[0] - start[0], goal[1] - start[1]) + 1.0
    path = np.asarray(result.path)
    rows = np.round((layout.height - path[:, 1]) / layout.resolution - 0.5).astype(int)
    cols = np.round(path[:, 0] / layout.resolution - 0.5).astype(int)
    assert not occupied[rows, cols].any()
    front = layout.station_front  # the station's front reachable from an aisle
    assert planner.plan(grid, start, front, expansion_distance=3.0).length > 0


def test_same_arguments_same_bytes_and_the_default_is_the_shipped_map(generator, tmp_path):
    layout = generator.regular_layout(120.0, 70.0, 4, 3, aisle_width=7.0, station=(10.0, 1.5))
    one = generator.pgm_bytes(generator.build_warehouse(layout))
    two = generator.pgm_bytes(
        generator.build_warehouse(
            generator.regular_layout(120.0, 70.0, 4, 3, aisle_width=7.0, station=(10.0, 1.5))
        )
    )
    assert one == two
    assert one != generator.pgm_bytes(generator.build_warehouse(generator.regular_layout(120.0, 70.0, 4, 3)))
    assert generator.layout_from_options(generator.parse([])) == generator.shipped_layout()


def test_the_committed_fifty_robot_map_is_the_command_its_scenario_records(generator, tmp_path):
    text = (REPO / "scenarios" / "fleet_fifty.toml").read_text()
    (command,) = re.findall(
        r"#\s+(python3 scenarios/maps/make_warehouse\.py .*?)(?<!\\)\n", text.replace("\\\n#", "")
    )
    arguments = shlex.split(command)[2:]
    assert arguments[0] == "scenarios/maps"
    options = generator.parse([str(tmp_path), *arguments[1:]])
    generator.main(tmp_path, generator.layout_from_options(options), options.name)
    for suffix in ("pgm", "yaml"):
        assert (tmp_path / f"warehouse_fifty.{suffix}").read_bytes() == (
            MAPS / f"warehouse_fifty.{suffix}"
        ).read_bytes()


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ((100.0, 60.0, 9, 3), "leave no corridor"),
        ((100.0, 60.0, 4, 9), "do not fit"),
        ((100.0, 60.0, 4, 3, 8.0, 10.0, 3.0, None, (20.0, 6.0)), "must fit in the bottom corridor"),
    ],
)
def test_layouts_that_do_not_fit_are_refused(generator, arguments, message):
    with pytest.raises(ValueError, match=message):
        generator.regular_layout(*arguments)
