"""Grid A* against a second implementation (scipy's csgraph Dijkstra on an explicitly built grid
graph), the thesis's switches, and every user error."""

import ctypes
import math

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

import planner
from planner import OccupancyGrid, PlannerError

MOVES = [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)]


def grid_graph(occupied, connectivity=8, corner_cutting=False, resolution=1.0, closed=None):
    """Sparse adjacency matrix of the free cells (edge cost in metres), built edge by edge.

    closed: cells no edge may enter (default: the occupied ones); corners are cut by occupied cells only."""
    closed = occupied if closed is None else closed
    rows, cols = occupied.shape
    sources, targets, weights = [], [], []
    for row in range(rows):
        for col in range(cols):
            if occupied[row, col]:
                continue
            for d_row, d_col in MOVES[:connectivity]:
                r, c = row + d_row, col + d_col
                if not (0 <= r < rows and 0 <= c < cols) or closed[r, c]:
                    continue
                diagonal = d_row != 0 and d_col != 0
                if (
                    diagonal
                    and not corner_cutting
                    and (occupied[row + d_row, col] or occupied[row, col + d_col])
                ):
                    continue
                sources.append(row * cols + col)
                targets.append(r * cols + c)
                weights.append(resolution * (np.sqrt(2.0) if diagonal else 1.0))
    return coo_matrix((weights, (sources, targets)), shape=(rows * cols, rows * cols)).tocsr()


def _random_map(seed, shape=(30, 40), density=0.3):
    return np.random.default_rng(seed).random(shape) < density


@pytest.mark.parametrize("connectivity, corner_cutting", [(8, False), (8, True), (4, False)])
@pytest.mark.parametrize("search", ["astar", "bidirectional"])
def test_lengths_agree_with_scipy_dijkstra(connectivity, corner_cutting, search):
    compared = 0
    for seed in range(4):
        occupied = _random_map(seed)
        grid = OccupancyGrid(occupied, resolution=0.5, origin=(2.0, -1.0))
        graph = grid_graph(occupied, connectivity, corner_cutting, 0.5)
        free = np.argwhere(~occupied)
        rng = np.random.default_rng(100 + seed)
        starts = free[rng.integers(len(free), size=6)]
        distances = dijkstra(graph, indices=starts[:, 0] * occupied.shape[1] + starts[:, 1])
        for start, row_distances in zip(starts, distances, strict=True):
            for goal in free[rng.integers(len(free), size=8)]:
                expected = row_distances[goal[0] * occupied.shape[1] + goal[1]]
                options = dict(connectivity=connectivity, corner_cutting=corner_cutting, planner=search)
                if np.isinf(expected):
                    with pytest.raises(PlannerError, match="no path"):
                        planner.plan(grid, grid.cell_to_world(start), grid.cell_to_world(goal), **options)
                    continue
                result = planner.plan(grid, grid.cell_to_world(start), grid.cell_to_world(goal), **options)
                assert result.length == pytest.approx(expected, rel=1e-9)
                steps = np.abs(np.diff(result.cells, axis=0))
                assert steps.max() == 1 and (steps.sum(1) <= (2 if connectivity == 8 else 1)).all()
                assert result.path_nodes == len(result.path) == len(result.cells)
                assert np.allclose(result.path, grid.cells_to_world(result.cells))
                compared += 1
    assert compared > 100


def test_distance_to_goal_matches_scipy():
    occupied = _random_map(9, (25, 31))
    grid = OccupancyGrid(occupied, resolution=0.1)
    goal = tuple(np.argwhere(~occupied)[17])
    expected = dijkstra(grid_graph(occupied, resolution=0.1), indices=goal[0] * 31 + goal[1]).reshape(25, 31)
    assert np.allclose(planner.distance_to_goal(grid, goal), expected, rtol=1e-12, atol=0)
    assert np.isinf(planner.distance_to_goal(grid, goal)[occupied]).all()


def test_decrease_key_never_longer():
    compared = 0
    for seed in range(6):
        occupied = _random_map(seed, (40, 40), 0.25)
        grid = OccupancyGrid(occupied)
        free = np.argwhere(~occupied)
        rng = np.random.default_rng(seed)
        for _ in range(25):
            start, goal = (grid.cell_to_world(cell) for cell in free[rng.integers(len(free), size=2)])
            try:
                with_key = planner.plan(grid, start, goal, configuration="basic", decrease_key=True)
            except PlannerError:
                continue
            without = planner.plan(grid, start, goal, configuration="basic")
            assert with_key.length <= without.length + 1e-9
            compared += 1
    assert compared > 100


def test_presets_set_documented_options():
    grid = OccupancyGrid(np.zeros((5, 5), bool))
    basic = planner.plan(grid, (0.5, 0.5), (4.5, 4.5), configuration="basic").info["options"]
    assert (basic["heuristic"], basic["corner_cutting"], basic["decrease_key"], basic["tie_breaker"]) == (
        "euclidean", True, False, "none")  # fmt: skip
    modified = planner.plan(grid, (0.5, 0.5), (4.5, 4.5), configuration="modified").info["options"]
    assert modified["heuristic"] == "thesis" and modified["untrusted_points"] and modified["decrease_key"]
    overridden = planner.plan(grid, (0.5, 0.5), (4.5, 4.5), configuration="modified", heuristic="octile")
    assert overridden.info["options"]["heuristic"] == "octile"


def test_corner_cutting_rule():
    # Two blocked cells touching at a corner: only MATLAB's rule squeezes through diagonally.
    occupied = np.ones((3, 3), bool)
    occupied[0, 0] = occupied[1, 1] = occupied[2, 2] = False
    grid = OccupancyGrid(occupied)
    result = planner.plan(grid, grid.cell_to_world((0, 0)), grid.cell_to_world((2, 2)), corner_cutting=True)
    assert result.length == pytest.approx(2 * np.sqrt(2))
    with pytest.raises(PlannerError, match="no path"):
        planner.plan(grid, grid.cell_to_world((0, 0)), grid.cell_to_world((2, 2)))


def test_untrusted_points_are_closed_but_start_goal_exempt():
    occupied = np.zeros((11, 16), bool)
    occupied[5, 3:13] = True  # a wall with 3-cell gaps at both ends
    grid = OccupancyGrid(occupied)
    start, goal = grid.cell_to_world((4, 7)), grid.cell_to_world((6, 7))  # both next to the wall
    plain = planner.plan(grid, start, goal)
    untrusted = planner.plan(grid, start, goal, untrusted_points=True)
    assert untrusted.length > plain.length
    # No cell of the path other than start and goal has an obstacle among its 8 neighbours.
    padded = np.pad(occupied, 1)
    for row, col in untrusted.cells[1:-1]:
        assert not padded[row : row + 3, col : col + 3].any()
    assert (untrusted.explored <= ~occupied).all()


@pytest.mark.parametrize("search", ["astar", "bidirectional"])
def test_untrusted_points_lengths_agree_with_scipy_dijkstra(search):
    """Untrusted points (free cells with an obstacle among their 8 neighbours) closed except at the
    query's own start and goal; the exemption of one query must not leak into the next."""
    occupied = _random_map(21, (24, 30), 0.04)
    grid = OccupancyGrid(occupied)
    padded = np.pad(occupied, 1)
    near = np.zeros_like(occupied)
    for d_row in range(3):
        for d_col in range(3):
            near |= padded[d_row : d_row + 24, d_col : d_col + 30]
    untrusted = near & ~occupied
    free = np.argwhere(~occupied)
    rng = np.random.default_rng(5)
    compared = 0
    for _ in range(40):
        start, goal = free[rng.integers(len(free), size=2)]
        closed = occupied | untrusted
        closed[tuple(start)] = closed[tuple(goal)] = False
        graph = grid_graph(occupied, closed=closed)
        expected = dijkstra(graph, indices=start[0] * 30 + start[1])[goal[0] * 30 + goal[1]]
        points = grid.cell_to_world(start), grid.cell_to_world(goal)
        if np.isinf(expected):
            with pytest.raises(PlannerError, match="no path"):
                planner.plan(grid, *points, untrusted_points=True, planner=search)
            continue
        result = planner.plan(grid, *points, untrusted_points=True, planner=search)
        assert result.length == pytest.approx(expected, rel=1e-9)
        compared += 1
    assert compared > 10


def test_thesis_heuristic_searches_fewer_nodes_on_open_map():
    occupied = np.zeros((60, 80), bool)
    occupied[10:50, 40] = True
    grid = OccupancyGrid(occupied, resolution=0.5)
    start, goal = grid.cell_to_world((30, 5)), grid.cell_to_world((28, 75))
    euclid = planner.plan(grid, start, goal, heuristic="euclidean", tie_breaker="none")
    thesis = planner.plan(grid, start, goal, heuristic="thesis", tie_breaker="none")
    assert thesis.searched_nodes < euclid.searched_nodes
    assert thesis.length >= euclid.length - 1e-9  # inadmissible: never shorter than the optimum
    assert euclid.explored.sum() == euclid.searched_nodes


def test_cost_gradient_keeps_away_from_walls():
    occupied = np.zeros((21, 40), bool)
    occupied[0, :] = occupied[-1, :] = True
    occupied[1:8, 10:30] = True
    grid = OccupancyGrid(occupied, resolution=0.5)
    start, goal = grid.cell_to_world((8, 2)), grid.cell_to_world((8, 37))
    plain = planner.plan(grid, start, goal)
    weighted = planner.plan(grid, start, goal, cost_weight=5.0, cost_scaling_factor=1.0)
    distance = planner.inflation.obstacle_distance(grid)
    assert distance[tuple(weighted.cells.T)].min() > distance[tuple(plain.cells.T)].min()
    assert weighted.length >= plain.length - 1e-9


@pytest.mark.parametrize(
    "start, goal, options, match",
    [
        ((-1.0, 1.0), (5.5, 5.5), {}, r"start \(-1, 1\) m = cell \(row 8, col -1\) is outside the map"),
        ((1.5, 1.5), (5.5, 50.0), {}, "goal .* is outside the map"),
        ((4.5, 4.5), (1.5, 1.5), {}, r"start \(4.5, 4.5\) m = cell \(row 5, col 4\) is on an obstacle"),
        ((1.5, 1.5), (4.5, 4.5), {}, "goal .* is on an obstacle"),
        ((3.5, 4.5), (1.5, 1.5), {"expansion_distance": 1.0}, "start .* inside the inflation"),
        (
            (1.5, 1.5),
            (8.5, 8.5),
            {"conectivity": 4},
            "unknown planner option 'conectivity'.*did you mean 'connectivity'",
        ),
        ((1.5, 1.5), (8.5, 8.5), {"connectivity": 6}, "connectivity=6"),
        ((1.5, 1.5), (8.5, 8.5), {"heuristic": "cosine"}, "heuristic='cosine'"),
        ((1.5, 1.5), (8.5, 8.5), {"tie_breaker": "yes"}, "tie_breaker"),
        ((1.5, 1.5), (8.5, 8.5), {"configuration": "fast"}, "configuration"),
        ((1.5, 1.5), (8.5, 8.5), {"expansion_distance": -1}, "expansion_distance"),
        ((1.5, 1.5), (8.5, 8.5), {"heuristic_weight": float("nan")}, "heuristic_weight"),
        ((1.5, 1.5), (8.5, 8.5), {"decrease_key": "no"}, "decrease_key must be True or False"),
        ((1.5, 1.5), (8.5, 8.5), {"smoothing": "spline"}, "smoothing"),
        (("a", 1), (8.5, 8.5), {}, "start must be"),
    ],
)
def test_user_errors_are_one_line(start, goal, options, match):
    occupied = np.zeros((10, 10), bool)
    occupied[5, 4] = True
    grid = OccupancyGrid(occupied)
    with pytest.raises(PlannerError, match=match) as error:
        planner.plan(grid, start, goal, **options)
    assert "\n" not in str(error.value)


def test_no_path_and_bad_grid():
    occupied = np.zeros((5, 5), bool)
    occupied[:, 2] = True
    grid = OccupancyGrid(occupied)
    with pytest.raises(PlannerError, match=r"no path .* \(\d+ cells searched"):
        planner.plan(grid, (0.5, 0.5), (4.5, 4.5))
    with pytest.raises(PlannerError, match="needs an OccupancyGrid"):
        planner.plan(occupied, (0.5, 0.5), (4.5, 4.5))
    assert isinstance(PlannerError("x"), planner.NavcosimError)


def test_start_equals_goal():
    grid = OccupancyGrid(np.zeros((3, 3), bool))
    for search in ("astar", "bidirectional"):
        result = planner.plan(grid, (1.5, 1.5), (1.5, 1.4), planner=search)
        assert result.length == 0.0 and result.path_nodes == 1 and result.searched_nodes == 1


@pytest.mark.slow
def test_first_call_elapsed_excludes_building_the_kernels(tmp_path):
    """PlanResult.elapsed is the search's time: the first call in a process, which builds the C
    kernels into an empty cache (a compiler run: hundreds of ms at least) or loads them, is not
    counted. Each planner in a fresh process with a fresh kernel cache, so its call builds."""
    import os
    import subprocess
    import sys

    calls = {
        "astar": "planner.plan(grid, (6.0, 6.0), (84.0, 53.0), planner='astar')",
        "bidirectional": "planner.plan(grid, (6.0, 6.0), (84.0, 53.0), planner='bidirectional')",
        "hybrid": "planner.plan(grid, (6.0, 6.0, 0.0), (84.0, 53.0, 0.0), planner='hybrid', "
        "expansion_distance=2.25)",
    }
    repo = __import__("pathlib").Path(__file__).resolve().parents[2]
    for kind, call in calls.items():
        script = (
            "import time, planner\n"
            "grid = planner.OccupancyGrid.from_file('scenarios/maps/warehouse.yaml')\n"
            "began = time.perf_counter()\n"
            f"result = {call}\n"
            "print(result.elapsed, time.perf_counter() - began)\n"
        )
        env = dict(os.environ, NAVCOSIM_NATIVE_CACHE=str(tmp_path / kind))
        run = subprocess.run(
            [sys.executable, "-c", script], cwd=repo, capture_output=True, text=True, check=True, env=env
        )
        elapsed, wall = (float(value) for value in run.stdout.split())
        assert wall > 0.05, f"{kind}: the process's first plan() should include building its kernels"
        # Against the call's own wall time, not a fixed limit: on a loaded machine a 5 ms search can
        # take 30 ms, but never a large part of a call that built its kernels.
        assert elapsed < 0.25 * wall, f"{kind}: elapsed {elapsed} s of {wall} s includes the build"


def test_a_repeated_query_checks_its_options_and_endpoints_as_the_first_did():
    """plan() keeps a prepared search per grid and option set; a later call must not slip past the
    checks: 0 is not a bool even after False was accepted, and bad endpoints still name the problem."""
    grid = OccupancyGrid(np.zeros((10, 10), bool))
    for _ in range(2):
        planner.plan(grid, (1.5, 1.5), (8.5, 8.5), corner_cutting=False)
        with pytest.raises(PlannerError, match="corner_cutting must be True or False"):
            planner.plan(grid, (1.5, 1.5), (8.5, 8.5), corner_cutting=0)
    for point, match in [
        ((float("nan"), 1.5), "start must be finite"),
        ((1e300, 1.5), "start .* is outside the map"),
        ((1.5,), "start must be"),
    ]:
        with pytest.raises(PlannerError, match=match):
            planner.plan(grid, point, (8.5, 8.5), corner_cutting=False)
    with pytest.raises(PlannerError, match="connectivity="):
        planner.plan(grid, (1.5, 1.5), (8.5, 8.5), connectivity=[8])  # unhashable: not cached
    assert planner.plan(grid, (1.5, 1.5), (8.5, 8.5), connectivity=8.0).length == pytest.approx(
        7 * math.sqrt(2)
    )


def test_explored_is_the_expanded_cells_of_its_own_query():
    """The explored mask is built on first access from the nodes the search expanded; a later query,
    which reuses the search's work arrays, must not change an earlier result's mask."""
    occupied = np.zeros((20, 30), bool)
    occupied[3:17, 12] = True
    grid = OccupancyGrid(occupied)
    first = planner.plan(grid, (1.5, 10.5), (28.5, 10.5))
    second = planner.plan(grid, (28.5, 1.5), (1.5, 18.5))
    for result in (second, first):
        explored = result.explored
        assert explored.shape == grid.shape and explored.sum() == result.searched_nodes
        assert not (explored & occupied).any()
        assert explored[tuple(result.cells.T)].all()  # every path cell was expanded (closed)
    assert not np.array_equal(first.explored, second.explored)


def test_paths_longer_than_the_first_path_buffer():
    """A 1 x 3000 corridor: the path (3000 cells) outgrows the reused path buffers, which grow."""
    grid = OccupancyGrid(np.zeros((1, 3000), bool))
    result = planner.plan(grid, (0.5, 0.5), (2999.5, 0.5))
    assert result.path_nodes == 3000 and result.length == 2999.0
    assert np.array_equal(result.cells[:, 1], np.arange(3000)) and (result.cells[:, 0] == 0).all()
    assert np.array_equal(result.path[:, 0], np.arange(3000) + 0.5)


@pytest.mark.parametrize("search", ["astar", "bidirectional"])
def test_an_open_list_that_outgrows_the_heap_grows_it(search):
    """A heap with room for 2 entries (plus the kernel's spare slots): the search reports a full heap,
    the workspace doubles it until OPEN fits, and the plan is the one a roomy heap gives."""
    from planner.astar import HEAP_SLACK
    from planner.searchspace import workspace

    grid = OccupancyGrid(_random_map(5))
    free = np.argwhere(~grid.occupied)
    start, goal = grid.cell_to_world(tuple(free[0])), grid.cell_to_world(tuple(free[-1]))
    options = {"bidirectional": search == "bidirectional"}
    roomy = planner.plan(grid, start, goal, **options)
    size = (grid.shape[0] + 2) * (grid.shape[1] + 2)
    for direction in (0, 1):
        work = workspace(size, direction)
        work.heap = np.empty((2, 2 + HEAP_SLACK), dtype=np.int64)
        work.state.heap, work.state.capacity = work.heap.ctypes.data, work.heap.shape[1]
    tight = planner.plan(grid, start, goal, **options)
    assert workspace(size).heap.shape[1] >= 16 + HEAP_SLACK  # grown at least three times
    assert np.array_equal(tight.cells, roomy.cells) and tight.length == roomy.length
    assert tight.searched_nodes == roomy.searched_nodes
    assert np.array_equal(tight.explored, roomy.explored)


def test_settings_other_than_the_defaults_search_with_the_general_library():
    """astar.c searches the default settings only; any other one is searched by astar_general.c's
    library, which planner.astar registers before the first such search. Without it registered the
    kernel answers NO_GENERAL instead of searching. Its plans keep the optimal length (scipy's)."""
    from planner import astar
    from planner.searchspace import search_map, workspace

    occupied = _random_map(7)
    grid = OccupancyGrid(occupied)
    free = np.argwhere(~occupied)
    start, goal = tuple(free[0]), tuple(free[-1])
    lengths = dijkstra(grid_graph(occupied), indices=start[0] * occupied.shape[1] + start[1])
    optimal = lengths[goal[0] * occupied.shape[1] + goal[1]]
    for options in ({"heuristic": "euclidean"}, {"tie_breaker": "none"}, {"heuristic": "chebyshev"}):
        result = planner.plan(grid, grid.cell_to_world(start), grid.cell_to_world(goal), **options)
        assert result.length == pytest.approx(optimal, rel=1e-12), options
    assert astar._general is not None
    space = search_map(grid, 0.0)
    moves = space.moves(8, False, False)
    parameters = astar.search_parameters(space.width, astar.HEURISTICS["euclidean"], 2, True, 1.0, 0.0)
    work = workspace(len(space.blocked))
    arguments = (moves, astar.NO_COST, parameters, space.node(*start), space.node(*goal))
    astar._KERNELS.navcosim_astar_set_general(None)
    try:
        status, searched = astar.astar_search(
            *arguments, work.next_generation(), work.g, work.nodes, work.heap
        )
        assert (status, searched) == (astar.NO_GENERAL, 0)
    finally:
        astar._KERNELS.navcosim_astar_set_general(
            ctypes.cast(astar._general.navcosim_astar_general_search, ctypes.c_void_p)
        )
    status, searched = astar.astar_search(*arguments, work.next_generation(), work.g, work.nodes, work.heap)
    assert status == astar.FOUND and searched > 0
