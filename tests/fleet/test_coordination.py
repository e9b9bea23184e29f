"""Fleet coordination without simulation: the action dependency graph, the coarse grid, the keys.

The graph is checked against hand-made plans (which action waits for which) and by executing MAPF
plans in random orders, delayed agents included, with an independent check of every state: no
two agents in one cell, no two swapping, and every agent at its goal at the end (no deadlock).
"""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from cosim.errors import CosimError
from cosim.navigation.coordination import (
    TURN_OFFSET,
    ActionGraph,
    Agent,
    CoordinationError,
    CoordinationGrid,
    Coordinator,
    turn_round,
)
from cosim.scenario.fleet_compose import describe_fleet
from cosim.scenario.load import load_scenario
from planner import mapf
from planner.grid import OccupancyGrid
from tests.fleet.test_fleet_scenario import HEAD_ON, TWO, _parse, _with_robots


def _line(*cols: int, row: int = 0) -> list[tuple[int, int]]:
    return [(row, col) for col in cols]


def test_a_follower_enters_each_cell_after_the_leader_has_left_it():
    # Leader A: (0,1) -> (0,2) -> (0,3); follower B one cell behind: (0,0) -> (0,1) -> (0,2).
    graph = ActionGraph([_line(1, 2, 3), _line(0, 1, 2)])
    a, b = graph.actions
    assert [(x.source, x.target, x.time) for x in a] == [
        ((0, 1), (0, 1), 0),
        ((0, 1), (0, 2), 1),
        ((0, 2), (0, 3), 2),
    ]
    # B's move into (0,1) at t = 1 waits for A's move out of it at t = 1 (following is allowed in
    # the plan, so the same time step counts), B's move into (0,2) for A's move out at t = 2.
    assert b[1].needs == [(0, 1)] and b[2].needs == [(0, 2)]
    assert all(not x.needs for x in a)
    # A is released to its end; B only its settle.
    assert graph.released == [3, 1]
    graph.finish(1)  # B settles: nothing new for B
    assert graph.release() == [] and graph.released == [3, 1]
    graph.finish(0)  # A settles
    graph.finish(0)  # A has left (0,1)
    assert graph.release() == [1] and graph.released[1] == 2
    graph.finish(1)  # B is in (0,1); (0,2) still A's
    assert not graph.ready(1, 2)
    graph.finish(0)
    graph.release()
    graph.finish(1)
    assert graph.complete


def test_only_the_latest_move_out_before_the_entry_counts_and_waits_are_no_actions():
    # A passes (0,2) twice before B enters it at t = 6; A waits (repeats a cell) on the way.
    path_a = [(0, 2), (0, 3), (0, 3), (0, 2), (1, 2), (1, 3), (1, 3)]
    path_b = [(0, 0), (0, 0), (0, 0), (0, 0), (0, 0), (0, 1), (0, 2)]
    graph = ActionGraph([path_a, path_b])
    a, b = graph.actions
    assert [x.time for x in a] == [0, 1, 3, 4, 5]  # the wait at t = 2 and the rest are no actions
    # A leaves (0,2) at t = 1 (action 1) and again at t = 4 (action 3): B needs the later one.
    assert b[-1].target == (0, 2) and b[-1].needs == [(0, 3)]


def test_a_move_into_a_cell_the_other_robot_overlaps_at_the_start_waits_for_its_settle():
    # B stands between (0,1) and (0,2) (start cell (0,2), footprint over (0,1) too); A enters (0,1).
    graph = ActionGraph([_line(0, 1), [(0, 2), (0, 2)]], held=[set(), {(0, 1)}])
    a, b = graph.actions
    assert a[1].needs == [(1, 0)]
    assert graph.released == [1, 1]
    graph.finish(0)
    graph.finish(1)  # B has settled wholly into (0,2)
    graph.release()
    assert graph.released == [2, 1]


def test_settles_in_each_others_footprint_go_by_index():
    graph = ActionGraph([[(0, 0)], [(0, 1)]], held=[{(0, 1)}, {(0, 0)}])
    assert graph.actions[0][0].needs == [] and graph.actions[1][0].needs == [(0, 0)]
    graph.check_acyclic()


def test_horizon_limits_the_released_run():
    graph = ActionGraph([_line(0, 1, 2, 3, 4)], horizon=2)
    assert graph.released == [2]
    graph.finish(0)
    graph.release()
    assert graph.released == [3]


def _execute(graph: ActionGraph, rng: random.Random, slow: int | None = None, slow_odds: float = 0.05):
    """Finish released actions in a random order (agent `slow` rarely) and check every state
    independently of the graph: distinct cells, no swap. Returns the final cells."""
    n = len(graph)
    cells = [actions[0].target for actions in graph.actions]
    assert len(set(cells)) == n
    slow_behind = 0
    while True:
        movable = [i for i in range(n) if graph.done[i] < graph.released[i]]
        if not movable:
            break
        if slow is not None and slow in movable and len(movable) > 1 and rng.random() > slow_odds:
            movable.remove(slow)
            slow_behind += 1
        i = rng.choice(movable)
        action = graph.actions[i][graph.done[i]]
        assert cells[i] == action.source
        graph.finish(i)
        graph.release()
        target = action.target
        assert target not in [cells[j] for j in range(n) if j != i], (
            f"agent {i} entered {target}, another agent's cell"
        )
        cells[i] = target
    return cells, slow_behind


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(6))
def test_mapf_plans_executed_in_any_order_never_collide_nor_deadlock(seed):
    # A 6 x 8 room with a wall: agents to random distinct cells, planned by planner.mapf.
    occupied = np.zeros((6, 8), dtype=bool)
    occupied[1:5, 4] = True
    grid = OccupancyGrid(occupied, 1.0, (0.0, 0.0))
    free = [tuple(map(int, cell)) for cell in np.argwhere(~occupied)]
    rng = random.Random(seed)
    picks = rng.sample(free, 16)
    starts, goals = picks[:8], picks[8:]
    result = mapf.solve(grid, starts, goals, time_limit=1.0)
    assert result.solved
    graph = ActionGraph(result.paths)
    graph.check_acyclic()
    # Agent 0 is delayed: it finishes an action only now and then while the others run ahead.
    cells, slow_behind = _execute(graph, rng, slow=0)
    assert graph.complete, "a deadlock: released actions ran out before the goals"
    assert cells == [tuple(goal) for goal in goals]
    assert slow_behind > 0


def test_a_stopped_agent_never_lets_a_later_one_into_its_cell():
    # B crosses the cell A is in, after A has moved on in the plan; A never moves (a breakdown).
    path_a = [(1, 1), (1, 2), (1, 3)]
    path_b = [(0, 1), (0, 1), (1, 1), (2, 1)]
    graph = ActionGraph([path_a, path_b])
    graph.finish(0)  # A settles, then stops for good
    graph.finish(1)  # B settles
    graph.release()
    assert graph.released[1] == 1 and not graph.ready(1, 1)  # B waits before (1,1)
    assert graph.actions[1][1].needs == [(0, 1)]
    for _ in range(3):
        assert graph.release() == []
    graph.finish(0)  # A leaves (1,1) at last
    assert graph.release() == [1]


# -- the coarse grid ---------------------------------------------------------------------------------


def test_the_coarse_cell_fits_the_robot_with_clearance_and_is_free_only_when_all_its_cells_are():
    occupied = np.zeros((9, 13), dtype=bool)  # 4.5 m x 6.5 m at 0.5 m
    occupied[8, 1] = True  # bottom row, second column
    grid = OccupancyGrid(occupied, 0.5, (10.0, 20.0))
    cells = CoordinationGrid(grid, radius=0.5, clearance=0.5)
    assert cells.size == 2.0 and cells.k == 4
    assert (cells.rows, cells.cols) == (2, 3)  # the top row and the right column are left over
    assert cells.grid.occupied.tolist() == [[False, False, False], [True, False, False]]
    # The coarse grid is a planner OccupancyGrid: its own cell centres agree with ours.
    for cell in [(0, 0), (1, 2), (0, 1)]:
        assert cells.centre(cell) == pytest.approx(cells.grid.cell_to_world(cell))
        assert cells.cell_of(*cells.centre(cell)) == cell
    assert cells.centre((1, 0)) == (11.0, 21.0)
    # A 0.6 m disc at the corner of four cells overlaps all four; at a centre only its own.
    assert cells.overlapped(12.0, 22.0, 0.6) == {(0, 0), (0, 1), (1, 0), (1, 1)}
    assert cells.overlapped(13.0, 21.0, 0.6) == {(1, 1)}
    # A radius of 0.6 m needs 2 (0.6 + 0.5) = 2.2 m: 5 cells of 0.5 m.
    assert CoordinationGrid(grid, radius=0.6, clearance=0.5).size == 2.5


def _coordinator(starts, goals, radius=0.5):
    grid = OccupancyGrid.from_file(str(HEAD_ON.parent / "maps" / "warehouse.yaml"))
    agents = [Agent(f"r{k}", radius, 1.0) for k in range(len(starts))]
    coordinator = Coordinator("mapf", grid, agents)
    coordinator.check([(*start, 0.0) for start in starts], [[goal] for goal in goals])
    return coordinator


def test_starts_and_goals_the_coarse_grid_cannot_take_are_refused_in_one_line():
    with pytest.raises(CoordinationError, match=r"^r1 and r0 start in one coordination cell \(9, 6\)"):
        _coordinator([(12.5, 41.0), (13.5, 41.0)], [(30.0, 19.0), (30.0, 41.0)])
    with pytest.raises(CoordinationError, match=r"^r1's goal \(30, 24\) m lies in a coordination cell"):
        _coordinator([(12.0, 41.0), (20.0, 41.0)], [(30.0, 19.0), (30.0, 24.0)])
    with pytest.raises(CoordinationError, match=r"^r1 and r0 end in one coordination cell"):
        _coordinator([(12.0, 41.0), (20.0, 41.0)], [(30.0, 19.0), (30.5, 19.5)])


def test_waypoints_end_beyond_the_last_released_centre_by_the_goal_tolerance():
    coordinator = _coordinator([(13.0, 19.0)], [(35.0, 19.0)])
    coordinator.agents[0].goal = (35.0, 19.0)
    coordinator.start(0.0, [(13.0, 19.0, 0.0)])
    waypoints = coordinator.waypoints(0, (13.0, 19.0, 0.0))
    # Released: the settle and two moves east along y = 19 (2 m cells); then the extension.
    assert waypoints[:-1].tolist() == [[13.0, 19.0], [15.0, 19.0], [17.0, 19.0]]
    assert waypoints[-1] == pytest.approx([17.0 + 1.0 - 0.02, 19.0])


# -- scenario keys ---------------------------------------------------------------------------------


def test_coordination_speed_factor_and_stop_keys():
    fleet = _parse(
        _with_robots(
            TWO.replace('name = "a"', 'name = "a"\nspeed_factor = 0.5\nstop = { at = 3.0, duration = 5.0 }'),
            '\n[fleet]\ncoordination = "prioritized"\n',
        )
    )
    assert fleet.settings.coordination == "prioritized"
    a, b = fleet.robots
    assert (a.speed_factor, a.stop, b.speed_factor, b.stop) == (0.5, (3.0, 5.0), 1.0, None)
    # speed_factor scales what feeds the vehicle's v and omega, nothing else.
    described = describe_fleet(fleet)
    scales = {c.target: c.scale for c in described.robots["a"].connections if c.target.startswith("vehicle.")}
    assert scales == {"vehicle.v": 0.5, "vehicle.omega": 0.5}
    assert {c.scale for c in described.robots["b"].connections} == {1.0}
    # A coordinated robot's lidar is not linked to the others (the coordinator keeps them apart).
    assert described.links == ()


R0 = r"^f\.toml: \[\[robots\]\]\[0\]\."


@pytest.mark.parametrize(
    ("robot_keys", "fleet_keys", "message"),
    [
        ("speed_factor = 0.0", "", R0 + r"speed_factor: must be > 0"),
        ("speed_factor = 1.5", "", R0 + r"speed_factor: must be <= 1"),
        ("stop = { at = 1.0 }", "", R0 + r"stop\.duration: missing required key"),
        (
            "stop = { at = 1.0, duration = 0.0 }",
            "",
            R0 + r"stop\.duration: must be > 0",
        ),
        (
            "stop = { at = 1.0, duration = 2, for = 3 }",
            "",
            R0 + r"stop\.for: unknown key",
        ),
        (
            "planner = { replan = false }",
            '\n[fleet]\ncoordination = "mapf"\n',
            R0 + r"planner\.replan: \[fleet\] coordination = 'mapf' hands the planner",
        ),
    ],
)
def test_bad_coordination_keys_are_one_line_errors(robot_keys, fleet_keys, message):
    text = _with_robots(TWO.replace('name = "a"', f'name = "a"\n{robot_keys}'), fleet_keys)
    with pytest.raises(CosimError, match=message) as error:
        _parse(text)
    assert "\n" not in str(error.value)


def test_shipped_coordinated_scenarios_load():
    for name in ("fleet_head_on_mapf.toml", "fleet_intersection_mapf.toml"):
        fleet = load_scenario(HEAD_ON.parent / name, fleet=True)
        assert fleet.settings.coordination == "mapf"


def test_waypoints_stop_before_the_path_turns_back():
    # Pure Pursuit stops within its tolerance of the last waypoint: a released run that goes to a
    # cell and back would end next to where it starts, and the robot would never leave.
    coordinator = _coordinator([(13.0, 19.0)], [(35.0, 19.0)])
    there_and_back = [(20, 6), (20, 7), (20, 6), (20, 5)]
    coordinator.graph = ActionGraph([there_and_back])
    waypoints = coordinator.waypoints(0, (13.0, 19.0, 0.0))
    assert waypoints[:-1].tolist() == [[13.0, 19.0], [15.0, 19.0]]
    assert waypoints[-1] == pytest.approx([15.98, 19.0])
    # At (20, 7) with the move into it done, the rest is released as the next run.
    coordinator.graph.finish(0)
    coordinator.graph.finish(0)
    waypoints = coordinator.waypoints(0, (15.0, 19.0, 0.0))
    assert waypoints[:-1].tolist() == [[15.0, 19.0], [13.0, 19.0], [11.0, 19.0]]


def _pursue(path, pose, steps=400, v=0.7, lookahead=0.3, omega_max=5.0, h=0.01):
    # A plain Pure Pursuit (lookahead point `lookahead` along the path beyond the robot's nearest
    # point, never going back; omega = v 2 sin(alpha) / L, clipped) on a unicycle: the robot's
    # positions.
    path = np.asarray(path, dtype=float)
    dense = np.concatenate(
        [
            np.linspace(a, b, max(2, int(np.hypot(*(b - a)) / 0.01)), endpoint=False)
            for a, b in zip(path, path[1:], strict=False)
        ]
        + [path[-1:]]
    )
    x, y, theta = pose
    done, trail = 0, []
    for _ in range(steps):
        window = dense[done : done + 100]
        done += int(np.argmin(np.hypot(window[:, 0] - x, window[:, 1] - y)))
        ahead = dense[min(done + int(lookahead / 0.01), len(dense) - 1)]
        alpha = math.atan2(ahead[1] - y, ahead[0] - x) - theta
        omega = float(np.clip(v * 2.0 * math.sin(alpha) / lookahead, -omega_max, omega_max))
        x, y, theta = x + v * math.cos(theta) * h, y + v * math.sin(theta) * h, theta + omega * h
        trail.append((x, y))
    return np.array(trail)


def test_a_robot_that_must_turn_round_turns_where_it_stands():
    # Facing +x at its cell's centre with the released cells behind it (-x): the waypoints as they
    # are put the lookahead point straight behind the robot, sin(alpha) ~ 0, and it drives on
    # ahead, out of its 2 m cell (seen: robot5 drove 1.2 m into robot6's cell at the station).
    pose = (0.0, 1e-4, 0.0)
    behind = np.array([[0.0, 0.0], [-2.0, 0.0], [-2.98, 0.0]])
    assert _pursue(behind, pose)[:, 0].max() > 1.0
    turned = turn_round(pose, behind)
    # From the robot, by a point TURN_OFFSET to its side (the path's side: the robot stands 0.1 mm
    # to its left, so right, -y), then on from the first waypoint beyond TURN_NEAR.
    np.testing.assert_allclose(turned[:2], [[0.0, 1e-4], [0.0, 1e-4 - TURN_OFFSET]])
    np.testing.assert_allclose(turned[2:], behind[1:])
    trail = _pursue(turned, pose)
    assert trail[:, 0].max() < 0.3 and np.abs(trail[:, 1]).max() < 0.5  # inside its cell (1 m each way)
    assert trail[-1, 0] < -1.5  # and on its way
    # Behind and to the right: it turns right.
    assert turn_round((0.0, 0.0, 0.0), np.array([[0.0, 0.0], [-2.0, -1.0]]))[1, 1] == pytest.approx(
        -TURN_OFFSET
    )
    # Waypoints ahead, or to the side, stay as they are; so do cells already passed before them
    # (the lead-in of a re-solve: seen sending a robot back 8 m).
    for ahead in (
        [[0.0, 0.0], [2.0, 0.0]],
        [[0.0, 0.0], [0.0, 2.0]],
        [[0.1, 0.0], [-0.9, 1.9]],
        [[-8.0, 0.0], [-6.0, 0.0], [-4.0, 0.0], [-2.0, 0.0], [0.0, 0.0], [2.0, 0.0]],
        [[-0.8, 0.1], [1.2, 0.0], [3.2, 0.0]],
    ):
        np.testing.assert_array_equal(turn_round((0.0, 0.0, 0.0), np.array(ahead)), ahead)


def test_a_robot_on_its_way_to_a_shared_goal_cell_keeps_it():
    # r1 heads for a drop slot; then r0 (first in fleet order) needs the same slot: r0 waits, r1
    # goes on (by fleet order alone r0 took the cell and r1 waited, again at every such request).
    poses = [(12.0, 41.0, 0.0), (20.0, 41.0, 0.0)]
    coordinator = _coordinator([p[:2] for p in poses], [(14.0, 41.0), (30.0, 19.0)])
    slot = (30.0, 19.0)
    coordinator.agents[0].goal, coordinator.agents[1].goal = (14.0, 41.0), slot
    coordinator.start(0.0, poses)
    assert not coordinator.agents[1].waiting
    coordinator.new_goal(0, slot)
    coordinator.update(0.1, poses)
    graph, cell = coordinator.graph, coordinator.cells.cell_of(*slot)
    assert coordinator.agents[0].waiting and not coordinator.agents[1].waiting
    assert graph.actions[1][-1].target == cell and graph.actions[0][-1].target != cell
