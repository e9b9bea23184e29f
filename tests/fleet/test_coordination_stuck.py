"""The coordinator's "blocked" trigger (`cosim.navigation.coordination`): a robot with released
moves that has not moved `STUCK_DISTANCE` for `BLOCKED_AFTER` seconds (something on its way that
VFH could not pass and no lidar mark explains) has the cell it could not enter closed for the next
plan, and all robots are planned again; a robot halted by a `stop`, or one that moves, never
triggers it.

Truths: the coarse grid's own cells (`CoordinationGrid`), the plan re-checked by the project's
independent path checker (`valid_paths`), and the timing stated by the module's constants.
"""

from __future__ import annotations

import numpy as np

from cosim.navigation.coordination import BLOCKED_AFTER, STUCK_DISTANCE, valid_paths
from tests.fleet.test_coordination import _coordinator

START, GOAL = (13.0, 19.0), (35.0, 19.0)
H = 0.1  # [s] a block


def _started():
    coordinator = _coordinator([START], [GOAL])
    coordinator.agents[0].goal = GOAL
    coordinator.start(0.0, [(*START, 0.0)])
    return coordinator


def _targets(coordinator) -> list:
    return [action.target for action in coordinator.graph.actions[0] if not action.settle]


def _stand(coordinator, poses, until: float, t: float = 0.0) -> float:
    """update() every block while the robots stand at `poses` from t to `until` [s]; the last t."""
    while t < until - 1e-9:
        t = round(t + H, 9)
        coordinator.update(t, poses)
    return t


def test_a_robot_that_stands_with_released_moves_closes_its_next_cell_and_is_planned_around():
    coordinator = _started()
    first = _targets(coordinator)
    blocked = coordinator.graph.next_action(0)
    # the settle first: mark it done by standing in the start cell, then the first move is next
    coordinator.update(H, [(*START, 0.0)])
    nxt = coordinator.graph.next_action(0)
    assert nxt is not None and not nxt.settle
    blocked = nxt.target
    assert blocked in first
    solves = coordinator.solves
    t = _stand(coordinator, [(*START, 0.0)], BLOCKED_AFTER - H, t=H)
    assert coordinator.solves == solves  # not yet: 10 s have not passed since it last moved
    _stand(coordinator, [(*START, 0.0)], BLOCKED_AFTER + H, t=t)
    assert coordinator.solves == solves + 1
    after = _targets(coordinator)
    assert blocked not in after  # planned around the cell it could not enter
    assert after[-1] == first[-1] == coordinator.cells.cell_of(*GOAL)
    start = coordinator.cells.cell_of(*START)
    path = np.array([start, *after])
    steps = np.abs(np.diff(path, axis=0)).sum(axis=1)
    assert set(steps.tolist()) <= {0, 1}  # 4-connected unit moves
    assert all(coordinator.cells.free(tuple(cell)) for cell in path.tolist())
    assert valid_paths([[tuple(c) for c in path.tolist()]], [start], [after[-1]])
    # closed for that one plan only: a later re-solve may use it again
    assert coordinator.avoid == set()


def test_a_robot_that_moves_or_is_halted_is_never_taken_for_blocked():
    coordinator = _started()
    coordinator.update(H, [(*START, 0.0)])
    solves = coordinator.solves
    # creeping forward STUCK_DISTANCE every 5 s: moving, however slowly
    t, x = H, START[0]
    while t < 3 * BLOCKED_AFTER:
        t = round(t + H, 9)
        if round(t / H) % 50 == 0:
            x += STUCK_DISTANCE
        coordinator.update(t, [(x, START[1], 0.0)])
    assert coordinator.solves == solves
    # halted (a scenario's stop): standing still for longer is no blockage
    halted = _started()
    halted.update(H, [(*START, 0.0)])
    halted.halted.add(0)
    solves = halted.solves
    _stand(halted, [(*START, 0.0)], 3 * BLOCKED_AFTER, t=H)
    assert halted.solves == solves


def test_waiting_for_a_release_is_not_standing_still():
    """A follower that waited more than `BLOCKED_AFTER` for its leader to leave a cell (nothing
    released to it: the dependency graph holds it) is not taken for blocked the moment its move is
    released: the clock starts at the release (it triggered at once, and the re-solve sent robots
    round cells that were free)."""
    from cosim.navigation.coordination import RELEASE_AHEAD, ActionGraph

    coordinator = _coordinator([(15.0, 19.0), (13.0, 19.0)], [(19.0, 19.0), (17.0, 19.0)])
    row = coordinator.cells.cell_of(13.0, 19.0)[0]
    # Leader 0 from the cell east of 1, both driving east along the row, 1 one cell behind.
    leader = [(row, 7), (row, 8), (row, 9)]
    follower = [(row, 6), (row, 7), (row, 8)]
    assert [coordinator.cells.cell_of(*p) for p in ((15.0, 19.0), (13.0, 19.0))] == [leader[0], follower[0]]
    coordinator.graph = ActionGraph([leader, follower], None, None, RELEASE_AHEAD)
    for agent, pose in zip(coordinator.agents, ((15.0, 19.0), (13.0, 19.0)), strict=True):
        agent.moved_at, agent.moved_from = 0.0, pose
    coordinator.halted.add(0)  # the leader stands (halted, so never blocked itself)
    poses = [(15.0, 19.0, 0.0), (13.0, 19.0, 0.0)]
    t = 0.0
    while t < 1.5 * BLOCKED_AFTER:
        t = round(t + H, 9)
        coordinator.update(t, poses)
    graph = coordinator.graph
    assert graph.done[1] == graph.released[1] == 1  # settled, its move into the leader's cell held
    solves = coordinator.solves
    released_at = round(t + H, 9)
    poses[0] = (17.0, 19.0, 0.0)  # the leader has left its first cell: the follower's move is released
    coordinator.update(released_at, poses)
    assert graph.released[1] > graph.done[1] and coordinator.solves == solves
    t = _stand(coordinator, poses, released_at + BLOCKED_AFTER - 2 * H, t=released_at)
    assert coordinator.solves == solves and coordinator.graph is graph  # not blocked: 10 s not yet gone
    _stand(coordinator, poses, released_at + BLOCKED_AFTER + H, t=t)
    assert coordinator.solves == solves + 1  # standing 10 s with its move released: blocked
