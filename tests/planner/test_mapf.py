"""planner.mapf.solve: every solution passes the independent checker (test_mapf_checker); sums of costs
on small instances equal the exact joint-state optimum; bad input gives a one-line PlannerError."""

from __future__ import annotations

import numpy as np
import pytest
from test_mapf_checker import check, lower_bound, optimal_sum_of_costs

from planner import OccupancyGrid, PlannerError
from planner.mapf import solve

# "#" blocked, "." free; rows top to bottom.
POCKET = ["#.##", "...."]  # a corridor with a side pocket above its second cell
CROSS = ["##.##", "##.##", ".....", "##.##", "##.##"]
RING = ["....", ".##.", "...."]


def grid_of(rows: list[str]) -> OccupancyGrid:
    return OccupancyGrid(np.array([[char == "#" for char in row] for row in rows]))


def solve_checked(rows, starts, goals, **options):
    grid = grid_of(rows)
    result = solve(grid, starts, goals, **options)
    check(grid.occupied.tolist(), starts, goals, result)
    return result


@pytest.mark.parametrize(
    "rows, starts, goals",
    [
        (POCKET, [(1, 0), (1, 3)], [(1, 3), (1, 0)]),  # swap: one ducks into the pocket
        (CROSS, [(2, 0), (0, 2)], [(2, 4), (4, 2)]),  # crossing: one waits
        (RING, [(0, 0), (0, 3), (2, 0)], [(0, 3), (2, 3), (0, 0)]),  # three agents rotate on a ring
        (["....", "...."], [(0, 0), (0, 1), (0, 2)], [(0, 2), (0, 3), (1, 0)]),
    ],
)
def test_small_instances_reach_the_exact_optimum(rows, starts, goals):
    result = solve_checked(rows, starts, goals, time_limit=5.0)
    grid = grid_of(rows)
    assert result.sum_of_costs == optimal_sum_of_costs(grid.occupied.tolist(), starts, goals)
    assert result.optimal and result.status == "optimal"


def test_swap_through_the_pocket_and_crossing_costs():
    """Known by hand: the swap costs 3 + 5 (one agent steps into the pocket and out again while the
    other passes), the crossing 4 + 5 (one agent waits a step at the centre's neighbour)."""
    assert solve_checked(POCKET, [(1, 0), (1, 3)], [(1, 3), (1, 0)], time_limit=5.0).sum_of_costs == 8
    crossing = solve_checked(CROSS, [(2, 0), (0, 2)], [(2, 4), (4, 2)], time_limit=5.0)
    assert (crossing.sum_of_costs, crossing.lower_bound, crossing.makespan) == (9, 8, 5)


def test_agents_already_at_their_goals():
    cells = [(0, 0), (2, 3)]
    result = solve_checked(RING, cells, cells, time_limit=1.0)
    assert (result.sum_of_costs, result.makespan, result.lower_bound) == (0, 0, 0)
    assert [path.tolist() for path in result.paths] == [[[0, 0]], [[2, 3]]]
    assert result.optimal


def test_an_agent_passing_another_ones_goal():
    """The agent on its goal must step aside and come back: its cost counts until its last arrival."""
    starts, goals = [(1, 1), (1, 0)], [(1, 1), (1, 3)]
    result = solve_checked(POCKET, starts, goals, time_limit=5.0)
    assert (
        result.sum_of_costs == optimal_sum_of_costs(grid_of(POCKET).occupied.tolist(), starts, goals) == 2 + 3
    )


def test_agents_reorder_in_a_dead_end():
    """Three agents in a one-cell dead end in the wrong order for their goals: greedy steps (PIBT)
    deadlock here; all three must come out to the open cells so that the deepest goal's agent goes in
    first. The solution is valid and costs the exact optimum of the joint-state search."""
    rows = ["...######", "........."]
    starts, goals = [(1, 6), (1, 7), (1, 8)], [(1, 7), (1, 3), (1, 5)]
    result = solve_checked(rows, starts, goals, time_limit=5.0)
    optimum = optimal_sum_of_costs(grid_of(rows).occupied.tolist(), starts, goals)
    assert optimum is not None and optimum > result.lower_bound
    assert result.sum_of_costs == optimum


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_agents_resting_in_a_dead_end_let_a_deeper_goal_pass(seed):
    """Two agents rest on their goals in a one-cell dead end; a third's goal lies deeper. Both must
    come out to the open cells and go back in after it (the case of the maze's border corridors,
    where PIBT pushed the resting agents deeper, ahead of the third, for ever). Valid, and the exact
    optimum of the joint-state search."""
    rows = ["...#####", "........"]
    starts, goals = [(1, 4), (1, 5), (0, 0)], [(1, 4), (1, 5), (1, 7)]
    result = solve_checked(rows, starts, goals, time_limit=5.0, seed=seed)
    optimum = optimal_sum_of_costs(grid_of(rows).occupied.tolist(), starts, goals)
    assert optimum is not None and optimum > result.lower_bound
    assert result.sum_of_costs == optimum


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_agents_resting_in_a_corridor_let_a_deeper_goal_pass(seed):
    """A one-cell corridor open at both ends (a warehouse aisle): two agents rest on their goals in
    it, a third's goal lies beyond them from the side it comes by. Valid, and the exact optimum of the
    joint-state search (here the resting agents step out and back rather than the third going round)."""
    rows = [".........", ".#######.", ".........", ".#######.", "........."]
    starts, goals = [(2, 3), (2, 4), (0, 0)], [(2, 3), (2, 4), (2, 5)]
    result = solve_checked(rows, starts, goals, time_limit=5.0, seed=seed)
    optimum = optimal_sum_of_costs(grid_of(rows).occupied.tolist(), starts, goals)
    assert optimum is not None and optimum > result.lower_bound
    assert result.sum_of_costs == optimum


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_warehouse_of_one_cell_aisles(seed):
    """Shelves 6 x 1 with one-cell aisles all round (corridors, crossings, dead ends at the wall
    pockets), a third of the free cells taken by agents with random starts and goals: solved and valid
    by the independent checker, and no better than the bound."""
    rows = ["." * 17]
    for _ in range(4):
        rows += [".######.######.##", "." * 17]
    rows[1] = "#" + rows[1][1:]  # a dead end at the wall: row 2's left end reaches only down
    grid = grid_of(rows)
    free = np.argwhere(~grid.occupied)
    rng = np.random.default_rng(seed)
    agents = len(free) // 3
    starts = free[rng.choice(len(free), agents, replace=False)]
    goals = free[rng.choice(len(free), agents, replace=False)]
    result = solve(grid, starts, goals, time_limit=1.0, seed=seed)
    assert result.solved
    check(grid.occupied.tolist(), starts, goals, result)
    assert result.sum_of_costs >= result.lower_bound


def warehouse_of_long_aisles() -> OccupancyGrid:
    """Four rows of six shelves 10 x 2 between one-cell aisles (the Moving AI warehouse-10-20-10-2-1
    in small), open margins three cells wide left and right."""
    aisle = "." * 73
    shelves = "..." + "".join("." + "#" * 10 for _ in range(6)) + "...."
    return grid_of([aisle] + [shelves, shelves, aisle] * 4)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_dense_warehouse_of_long_aisles(seed):
    """140 agents on 469 cells of one-cell aisles: PIBT locks knots of agents that must pass each
    other in the aisles, where LaCAM's search stalls (the solver before the local repair found no
    solution in 5 s for any of these seeds); the knots are untied region by region. Solved, and valid
    by the independent checker."""
    grid = warehouse_of_long_aisles()
    free = np.argwhere(~grid.occupied)
    rng = np.random.default_rng(seed)
    agents = int(0.3 * len(free))
    starts = free[rng.choice(len(free), agents, replace=False)]
    goals = free[rng.choice(len(free), agents, replace=False)]
    # The first solutions come at ~0.25, ~3.6 and ~0.65 s on an idle core of the 2-core machine; the
    # search's slices are timed, so a core shared with the rest of the suite stretches that (seed 1
    # once took over 5 s there): 10 s, which the solver then spends improving.
    result = solve(grid, starts, goals, time_limit=10.0, seed=seed)
    assert result.solved
    check(grid.occupied.tolist(), starts, goals, result)
    assert result.sum_of_costs >= result.lower_bound == lower_bound(grid.occupied.tolist(), starts, goals)


@pytest.mark.slow
def test_random_instances_on_an_obstacle_grid():
    """Many agents on a 24 x 24 grid with 15 % obstacles: valid paths, and the improvement phase."""
    rng = np.random.default_rng(7)
    occupied = rng.random((24, 24)) < 0.15
    grid = OccupancyGrid(occupied)
    free = np.argwhere(~occupied)
    # the largest 4-connected component, so every pair is reachable
    from scipy.ndimage import label

    labels, _ = label(~occupied)
    largest = np.bincount(labels[labels > 0]).argmax()
    free = free[labels[free[:, 0], free[:, 1]] == largest]
    for agents in (5, 40, 120):
        picks = rng.choice(len(free), size=2 * agents, replace=False)
        starts, goals = free[picks[:agents]], free[picks[agents:]]
        result = solve(grid, starts, goals, time_limit=0.5, seed=agents)
        check(occupied.tolist(), starts, goals, result)
        assert result.first_solution <= result.elapsed


def test_unsolvable_instances():
    walled = grid_of(["..#.."])
    result = solve(walled, [(0, 0)], [(0, 4)], time_limit=1.0)
    assert (result.solved, result.status, result.paths, result.sum_of_costs) == (
        False,
        "unsolvable",
        [],
        None,
    )
    # reachable goals, but two agents cannot pass each other in a corridor: the complete search proves it
    result = solve(grid_of(["...."]), [(0, 0), (0, 3)], [(0, 3), (0, 0)], time_limit=5.0)
    assert (result.solved, result.status, result.lower_bound) == (False, "unsolvable", 6)
    # on a ring agents keep their cyclic order: these goals ask for another one
    starts, goals = [(0, 0), (0, 3), (2, 0)], [(0, 3), (0, 0), (2, 3)]
    assert optimal_sum_of_costs(grid_of(RING).occupied.tolist(), starts, goals) is None
    assert solve(grid_of(RING), starts, goals, time_limit=5.0).status == "unsolvable"


def test_memory_budget_is_honoured():
    grid = grid_of(["." * 30] * 30)
    starts = [(row, 0) for row in range(30)]
    goals = [(29 - row, 29) for row in range(30)]
    # below the distance tables (30 agents x 900 cells x 4 bytes): no search, but the bound is known
    tiny = solve(grid, starts, goals, time_limit=1.0, memory=50_000)
    assert (tiny.solved, tiny.status) == (False, "memory limit") and tiny.memory <= 50_000
    assert tiny.lower_bound == lower_bound(grid.occupied.tolist(), starts, goals)
    for budget in (200_000, 2_000_000):
        result = solve(grid, starts, goals, time_limit=0.3, memory=budget)
        assert result.memory <= budget
        if result.solved:
            check(grid.occupied.tolist(), starts, goals, result)
        else:
            assert result.status == "memory limit"


def test_planning_goes_on_when_the_search_budget_is_spent():
    """A budget that pays for the distance tables and a handful of LaCAM's nodes, fewer than the
    crossing's makespan: LaCAM stops for memory, and prioritized planning (no nodes charged) solves."""
    grid = grid_of(["." * 30] * 30)
    starts = [(row, 0) for row in range(30)]
    goals = [(29 - row, 29) for row in range(30)]
    tables = 30 * 900 * 4 + 1024 * 4  # distance tables and LaCAM's first hash table, bytes
    result = solve(grid, starts, goals, time_limit=10.0, memory=tables + 8_000)
    check(grid.occupied.tolist(), starts, goals, result)
    assert result.nodes < result.makespan and result.memory <= tables + 8_000


def test_time_limit_ends_the_improvement():
    """An instance whose optimum is not proven quickly: the solve uses its time limit and says so."""
    rng = np.random.default_rng(3)
    grid = OccupancyGrid(np.zeros((16, 16), bool))
    cells = np.argwhere(~grid.occupied)
    picks = rng.choice(len(cells), size=160, replace=False)
    result = solve(grid, cells[picks[:80]], cells[picks[80:]], time_limit=0.3)
    check(grid.occupied.tolist(), cells[picks[:80]], cells[picks[80:]], result)
    assert result.status == "time limit" and not result.optimal
    assert result.elapsed >= 0.3
    assert result.neighbourhoods > 0


@pytest.mark.parametrize(
    "starts, goals, message",
    [
        ([(0, 0)], [(1, 0)], "start 0 (0, 0) is on an obstacle"),
        ([(1, 0)], [(0, 2)], "goal 0 (0, 2) is on an obstacle"),
        ([(1, 0), (1, 0)], [(1, 1), (1, 2)], "starts 0 and 1 are the same cell (1, 0)"),
        ([(1, 0), (1, 1)], [(1, 2), (1, 2)], "goals 0 and 1 are the same cell (1, 2)"),
        ([(1, 0)], [(2, 0)], "goal 0 (2, 0) is outside the 2x4 grid"),
        ([(-1, 0)], [(1, 0)], "start 0 (-1, 0) is outside the 2x4 grid"),
        ([(1, 0), (1, 1)], [(1, 2)], "2 starts but 1 goals"),
        ([], [], "no agents"),
        ("somewhere", [(1, 0)], "starts must be (row, col) cells"),
    ],
)
def test_bad_input_is_one_line_planner_error(starts, goals, message):
    with pytest.raises(PlannerError, match=message.replace("(", r"\(").replace(")", r"\)")) as error:
        solve(grid_of(POCKET), starts, goals)
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"time_limit": -1.0}, "time_limit"),
        ({"time_limit": float("nan")}, "time_limit"),
        ({"time_limit": "10"}, "time_limit"),
        ({"memory": 0}, "memory"),
        ({"seed": -1}, "seed"),
        ({"seed": 1.5}, "seed"),
    ],
)
def test_bad_options(options, message):
    with pytest.raises(PlannerError, match=message):
        solve(grid_of(POCKET), [(1, 0)], [(1, 3)], **options)
    with pytest.raises(PlannerError, match="OccupancyGrid"):
        solve(np.zeros((2, 2), bool), [(0, 0)], [(1, 1)])
