"""Hybrid A*: drivable, collision-free paths on the warehouse map, clean errors, no-path cases.

Path checks are geometric and independent of the planner's code: every pose (sampled densely) lies
in a free cell of the inflated map; the curvature of the circle through any three consecutive
samples is at most 1/R_min; consecutive headings differ by no more than a circular arc of radius
R_min allows over the chord between them; and the chord points along the heading (forward) or
against it (reverse), i.e. the car never moves sideways. Cusps (direction flips) are exempt from
the three-point curvature check only.
"""

import math
import subprocess
import sys
import tomllib

import numpy as np
import pytest

import planner
from planner import OccupancyGrid, PlannerError, dubins, reeds_shepp
from planner.hybrid import plan_hybrid

# Tolerance of the geometric checks: the samples lie exactly on arcs and lines, so only rounding.
TOL = 1e-6
CAR = {"min_turning_radius": 3.5, "expansion_distance": 2.25}  # Table 4.4: 1.5 m radius + 0.75 m safety


@pytest.fixture(scope="module")
def warehouse(repo_root):
    return OccupancyGrid.from_file(repo_root / "scenarios/maps/warehouse.yaml")


@pytest.fixture(scope="module")
def queries(repo_root):
    with open(repo_root / "scenarios/maps/warehouse.queries.toml", "rb") as file:
        return tomllib.load(file)


def assert_drivable(
    result, grid, start, goal, radius, expansion, goal_tolerance=1e-6, heading_tolerance=1e-6
):
    path, directions = result.path, result.directions
    assert path.shape[1] == 3 and len(directions) == len(path) == result.path_nodes
    assert set(np.unique(directions)) <= {-1, 1}
    np.testing.assert_allclose(path[0], start, atol=1e-9)
    assert math.hypot(*(path[-1, :2] - np.asarray(goal[:2]))) <= goal_tolerance + 1e-9
    assert abs(math.remainder(path[-1, 2] - goal[2], 2 * math.pi)) <= heading_tolerance + 1e-9

    inflated = grid.inflate(expansion) if expansion > 0 else grid
    cells = grid.world_to_cells(path[:, :2])
    assert np.all((cells >= 0) & (cells < grid.shape)), "path leaves the map"
    assert not inflated.occupied[cells[:, 0], cells[:, 1]].any(), "path enters the inflated obstacles"

    chords = np.diff(path[:, :2], axis=0)
    chord = np.hypot(chords[:, 0], chords[:, 1])
    turn = np.abs(np.remainder(np.diff(path[:, 2]) + math.pi, 2 * math.pi) - math.pi)
    # heading continuity: an arc of radius >= R over chord c turns at most 2 asin(c / 2R)
    assert np.all(turn <= 2 * np.arcsin(np.minimum(1.0, chord / (2 * radius))) + TOL)
    # no sideways motion: the chord of an arc points along the mean heading (or against it)
    moving = chord > 1e-9
    motion = np.arctan2(chords[moving, 1], chords[moving, 0])
    mean_heading = path[:-1, 2][moving] + 0.5 * np.remainder(
        np.diff(path[:, 2])[moving] + math.pi, 2 * math.pi
    )
    mean_heading -= 0.5 * math.pi
    expected = np.where(directions[1:][moving] > 0, mean_heading, mean_heading + math.pi)
    assert np.all(np.abs(np.remainder(motion - expected + math.pi, 2 * math.pi) - math.pi) < 1e-5)
    # three-point (Menger) curvature 4 * area / (a b c) <= 1 / R, except across a cusp
    a, b, c = path[:-2, :2], path[1:-1, :2], path[2:, :2]
    ab, bc, ca = (np.hypot(*(q - p).T) for p, q in ((a, b), (b, c), (c, a)))
    area2 = np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    keep = (ab > 1e-6) & (bc > 1e-6) & (directions[1:-1] == directions[2:])
    curvature = 2 * area2[keep] / (ab[keep] * bc[keep] * ca[keep])
    assert np.all(curvature <= (1 + TOL) / radius)
    # the reported length is the arc length: each chord c turning by t spans an arc c (t/2) / sin(t/2)
    arcs = chord * np.where(turn > 1e-9, (turn / 2) / np.sin(np.maximum(turn, 1e-9) / 2), 1.0)
    assert result.length == pytest.approx(arcs.sum(), abs=1e-6)


@pytest.mark.parametrize("name", ["thesis_table_3_1", "thesis_table_3_3"])
def test_warehouse_queries_for_the_table_4_4_car(warehouse, queries, name):
    start, goal = queries[name]["start"], queries[name]["goal"]
    result = planner.plan(warehouse, start, goal, planner="hybrid", interpolation_distance=0.05, **CAR)
    assert result.planner == "hybrid"
    assert_drivable(result, warehouse, start, goal, 3.5, 2.25)
    # a car path is never shorter than the obstacle-free Reeds-Shepp curve, and it cannot beat
    # the grid's shortest path by more than the grid's 8-connected detour (< 8.3 %)
    assert result.length >= reeds_shepp.path_length(start, goal, 3.5) - 1e-9
    grid_length = planner.plan(warehouse, start[:2], goal[:2], expansion_distance=2.25).length
    assert grid_length / 1.083 <= result.length <= 1.3 * grid_length
    assert result.searched_nodes > 0 and result.explored.shape == warehouse.shape and result.explored.any()


def test_turning_around_in_an_aisle_needs_reverse_and_cusps(warehouse):
    # Facing east in an 8 m aisle (3.5 m free after inflation) with the goal to the west: a
    # 7 m wide U-turn does not fit, so the car reverses.
    start, goal = (64.0, 41.0, 0.0), (20.0, 30.0, math.pi / 2)
    result = plan_hybrid(warehouse, start, goal, interpolation_distance=0.1, **CAR)
    assert_drivable(result, warehouse, start, goal, 3.5, 2.25)
    assert (result.directions < 0).any() and result.info["cusps"] >= 1


def test_forward_only_paths_are_dubins_and_never_reverse(warehouse):
    start, goal = (6.0, 6.0, 0.0), (64.0, 41.0, math.pi)
    result = plan_hybrid(warehouse, start, goal, reverse=False, interpolation_distance=0.1, **CAR)
    assert_drivable(result, warehouse, start, goal, 3.5, 2.25)
    assert np.all(result.directions == 1)
    assert result.length >= dubins.path_length(start, goal, 3.5) - 1e-9


def test_wheelbase_and_steering_angle_give_the_turning_radius(warehouse):
    wheelbase, steering = 2.0, -math.pi / 6  # R = 2 / tan(30 deg) = 3.46 m; the sign (side) is ignored
    start, goal = (6.0, 6.0, 0.0), (20.0, 52.0, math.pi)
    result = plan_hybrid(
        warehouse, start, goal, wheelbase=wheelbase, max_steering_angle=steering, expansion_distance=1.0
    )
    assert_drivable(result, warehouse, start, goal, wheelbase / math.tan(abs(steering)), 1.0)


def test_empty_map_gives_the_optimal_curve():
    grid = OccupancyGrid(np.zeros((60, 60), dtype=bool), resolution=0.5)
    for start, goal in [((5.0, 5.0, 0.0), (25.0, 5.0, 0.0)), ((10.0, 10.0, 0.0), (12.0, 14.0, math.pi))]:
        result = plan_hybrid(
            grid,
            start,
            goal,
            min_turning_radius=2.0,
            direction_switch_cost=0.0,
            reverse_cost=1.0,
            steering_cost=0.0,
        )
        # the analytic curve from the start is free: the shortest Reeds-Shepp path
        assert result.length == pytest.approx(reeds_shepp.path_length(start, goal, 2.0), abs=1e-6)
        assert_drivable(result, grid, start, goal, 2.0, 0.0)
    straight = plan_hybrid(grid, (2.0, 15.0, 0.0), (28.0, 15.0, 0.0), min_turning_radius=2.0)
    assert straight.length == pytest.approx(26.0, abs=1e-9) and straight.info["cusps"] == 0


def test_mirror_image_curves_of_equal_cost():
    """A goal right behind the car, facing back: the turn to the left and the turn to the right
    cost exactly the same (the search then tries them in the order they were enumerated);
    either is a shortest Reeds-Shepp path, pi R long."""
    grid = OccupancyGrid(np.zeros((60, 60), dtype=bool), resolution=0.5)
    start, goal = (15.0, 15.0, 0.0), (11.0, 15.0, math.pi)
    result = plan_hybrid(grid, start, goal, min_turning_radius=2.0)
    assert result.length == pytest.approx(math.pi * 2.0, abs=1e-9)
    assert result.length == pytest.approx(reeds_shepp.path_length(start, goal, 2.0), abs=1e-9)
    assert_drivable(result, grid, start, goal, 2.0, 0.0)


def test_exact_ties_are_tried_in_enumeration_order():
    """Candidate curves are tried by increasing cost, exact ties in the order they were enumerated:
    the same permutation as NumPy's stable sort."""
    from planner.hybrid_search import argsort_order

    rng = np.random.default_rng(3)
    for _ in range(300):
        size = int(rng.integers(1, reeds_shepp.MAX_CANDIDATES + 1))
        costs = rng.integers(0, int(rng.integers(1, 8)), size) * 0.25 + 3.0  # many exact ties
        assert np.array_equal(argsort_order(costs), np.argsort(costs, kind="stable"))


@pytest.mark.slow
def test_curves_and_search_run_without_numba():
    """The hybrid search and the curves are C kernels: importing and running them loads no numba."""
    code = (
        "import sys, math\n"
        "from planner import dubins, reeds_shepp, hybrid_search\n"
        "assert reeds_shepp.path_length((0, 0, 0), (3, 1, 1), 1.0) > 0\n"
        "assert dubins.path_length((0, 0, 0), (3, 1, 1), 1.0) > 0\n"
        "assert list(hybrid_search.argsort_order([2.0, 1.0])) == [1, 0]\n"
        "print('numba' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"


def test_curve_buffers_are_checked():
    """The curve kernels write into the caller's buffers: a wrong dtype or size is a ValueError, not
    a write out of bounds."""
    with pytest.raises(ValueError, match="letters must be .* int64 .* 64 x 5"):
        reeds_shepp.enumerate_normalized(1.0, 1.0, 0.0, np.zeros((64, 5)), np.zeros((64, 5)))
    with pytest.raises(ValueError, match="lengths must be .* float64 .* 8 x 3"):
        dubins.enumerate_normalized(1.0, 1.0, 0.0, np.zeros((8, 3), dtype=np.int64), np.zeros((7, 3)))
    letters, lengths = np.zeros((8, 5), dtype=np.int64), np.zeros((8, 5))
    count = dubins.enumerate_normalized(3.0, 1.0, 1.0, letters, lengths)  # wider rows: stride 5
    assert 1 <= count <= dubins.MAX_CANDIDATES and not lengths[:, 3:].any()
    best = min(lengths[k, :3].sum() for k in range(count))
    assert best == dubins.path_length((0, 0, 0), (3.0, 1.0, 1.0), 1.0)


def test_goal_tolerance_without_analytic_expansion():
    # With analytic expansion off, the search must end on a primitive within
    # the goal tolerances.
    grid = OccupancyGrid(np.zeros((40, 40), dtype=bool), resolution=1.0)
    start, goal = (5.5, 5.5, 0.0), (30.5, 20.5, math.pi / 2)
    result = plan_hybrid(
        grid,
        start,
        goal,
        min_turning_radius=3.0,
        analytic_interval=0,
        goal_tolerance=1.0,
        heading_tolerance=0.2,
    )
    assert not result.info["analytic_expansion"]
    assert_drivable(result, grid, start, goal, 3.0, 0.0, goal_tolerance=1.0, heading_tolerance=0.2)


def test_enclosed_goal_is_a_clean_planner_error():
    occupied = np.zeros((40, 60), dtype=bool)
    occupied[10:20, 30] = occupied[10:20, 45] = occupied[10, 30:46] = occupied[19, 30:46] = True
    grid = OccupancyGrid(occupied, resolution=0.5)
    goal = grid.cell_to_world((15, 38)) + (0.0,)
    with pytest.raises(PlannerError, match="no path.*enclosed"):
        plan_hybrid(grid, (3.0, 3.0, 0.0), goal, min_turning_radius=1.0)


def test_unreachable_for_the_car_exhausts_the_search():
    # A corridor 2 m wide ending in a dead end: reachable for a point, but a car with R = 3 m
    # facing away can neither turn into it nor reverse in (reverse disabled).
    occupied = np.ones((30, 40), dtype=bool)
    occupied[1:-1, 1:10] = False  # a 4.5 m x 14 m room
    occupied[13:17, 10:39] = False  # a 2 m corridor to the east
    grid = OccupancyGrid(occupied, resolution=0.5)
    with pytest.raises(PlannerError, match="no path.*(exhausted|iteration cap)"):
        plan_hybrid(grid, (2.5, 7.5, math.pi), (18.0, 7.5, 0.0), min_turning_radius=3.0, reverse=False)


@pytest.mark.parametrize(
    ("start", "goal", "options", "message"),
    [
        ((-1.0, 5.0, 0.0), (20.0, 5.0, 0.0), {}, "start .* outside the map"),
        ((5.0, 5.0, 0.0), (20.0, 5.0), {}, "goal as \\(x, y, theta\\)"),
        ((5.0, 5.0, 0.0), (15.2, 10.2, 0.0), {}, "goal .* on an obstacle"),
        ((5.0, 5.0, 0.0), (15.2, 8.0, 0.0), {"expansion_distance": 2.5}, "goal .* inside the inflation"),
        ((5.0, 5.0, 0.0), (20.0, 5.0, 0.0), {"min_turning_radius": -1}, "min_turning_radius must be > 0"),
        ((5.0, 5.0, 0.0), (20.0, 5.0, 0.0), {"primitive_length": 0.3}, "primitive_length must be >="),
        ((5.0, 5.0, 0.0), (20.0, 5.0, 0.0), {"num_curvatures": 4}, "num_curvatures must be odd"),
        ((5.0, 5.0, 0.0), (20.0, 5.0, 0.0), {"reverse_cost": 0.5}, "reverse_cost must be >= 1"),
        ((5.0, 5.0, 0.0), (20.0, 5.0, 0.0), {"turning_radius": 3}, "unknown hybrid option"),
        ((5.0, 5.0, 0.0), (20.0, 5.0, 0.0), {"wheelbase": 2.0}, "needs its partner"),
        ((5.0, 5.0, 0.0), (20.0, 5.0, 0.0), {"wheelbase": 2.0, "max_steering_angle": 0}, "non-zero"),
        (
            (5.0, 5.0, 0.0),
            (20.0, 5.0, 0.0),
            {"wheelbase": 2.0, "max_steering_angle": "a"},
            "must be a number",
        ),
        ((5.0, 5.0, 0.0), (20.0, 5.0, 3.0), {"max_iterations": 3, "analytic_interval": 0}, "iteration cap"),
        (
            (5.0, 5.0, 0.0),
            (20.0, 5.0, 3.0),
            {"analytic_interval": -1},
            "analytic_interval must be an integer",
        ),
    ],
)
def test_bad_input_raises_one_line_planner_error(start, goal, options, message):
    occupied = np.zeros((40, 60), dtype=bool)
    occupied[18:22, 28:32] = True  # a 2 m block around (15, 10) m
    grid = OccupancyGrid(occupied, resolution=0.5)
    with pytest.raises(PlannerError, match=message) as error:
        plan_hybrid(grid, start, goal, **{"analytic_distance": 0.0, **options})
    assert "\n" not in str(error.value)
