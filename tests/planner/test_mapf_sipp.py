"""The MAPF solver's single-agent search (SIPP over safe intervals, planner.mapf.single_agent_path)
against a plain space-time breadth-first search written here: on small random grids with other
agents moving along fixed paths, both find a path of the same cost (or both none), and SIPP's path
is a legal walk that meets no one (vertex or swap conflict)."""

from __future__ import annotations

import numpy as np
import pytest

from planner import OccupancyGrid
from planner.mapf import single_agent_path

MOVES = ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1))


def at(path, t):
    return tuple(path[min(t, len(path) - 1)])


def reference_cost(free, others, start, goal):
    """Earliest time from which the agent can rest on `goal` for good: breadth first over (cell, t)."""
    rows, cols = free.shape
    horizon = max((len(path) for path in others), default=1) + free.sum() + 2
    last_visit = max((t for path in others for t in range(len(path)) if at(path, t) == goal), default=-1)
    if any(tuple(path[-1]) == goal for path in others):
        return None  # someone rests on it for ever
    frontier = {start} if all(at(path, 0) != start for path in others) else set()
    for t in range(horizon):
        if goal in frontier and t > last_visit:
            return t
        taken = {at(path, t + 1) for path in others}
        following = set()
        for r, c in frontier:
            for dr, dc in MOVES:
                cell = (r + dr, c + dc)
                if not (0 <= cell[0] < rows and 0 <= cell[1] < cols) or not free[cell] or cell in taken:
                    continue
                if any(at(path, t) == cell and at(path, t + 1) == (r, c) for path in others):
                    continue  # swap
                following.add(cell)
        frontier = following
    return None


def random_others(rng, free, count, length, avoid):
    """Random walks (waits included) without vertex or swap conflicts among themselves."""
    cells = [tuple(cell) for cell in np.argwhere(free) if tuple(cell) not in avoid]
    picks = rng.choice(len(cells), size=count, replace=False)
    paths = [[cells[k]] for k in picks]
    for _ in range(length):
        taken = set()
        moved = []
        for path in paths:
            here = path[-1]
            options = []
            for dr, dc in MOVES:
                cell = (here[0] + dr, here[1] + dc)
                if 0 <= cell[0] < free.shape[0] and 0 <= cell[1] < free.shape[1] and free[cell]:
                    options.append(cell)
            rng.shuffle(options)
            choice = here
            for cell in options:
                swap = any(other[-1] == cell and new == here for other, new in moved)
                if (
                    cell not in taken
                    and not swap
                    and all(other[-1] != cell for other in paths if other is not path)
                ):
                    choice = cell
                    break
            taken.add(choice)
            moved.append((path, choice))
        for path, choice in moved:
            path.append(choice)
    return [np.array(path) for path in paths]


def assert_legal(path, free, others, start, goal):
    assert tuple(path[0]) == start and tuple(path[-1]) == goal
    for t in range(len(path) - 1):
        step = np.abs(path[t + 1] - path[t]).sum()
        assert step <= 1 and free[tuple(path[t + 1])]
    horizon = max([len(path)] + [len(other) for other in others]) + 1
    for other in others:
        for t in range(horizon):
            assert at(path, t) != at(other, t), f"vertex conflict at t={t}"
            assert not (at(path, t) == at(other, t + 1) and at(path, t + 1) == at(other, t)), f"swap at t={t}"


@pytest.mark.parametrize("seed", range(60))
def test_sipp_cost_equals_space_time_search(seed):
    rng = np.random.default_rng(seed)
    size = int(rng.integers(4, 9))
    free = rng.random((size, size)) > 0.2
    cells = [tuple(cell) for cell in np.argwhere(free)]
    if len(cells) < 6:
        pytest.skip("too few free cells")
    start, goal = (cells[k] for k in rng.choice(len(cells), size=2, replace=False))
    others = random_others(
        rng, free, int(rng.integers(1, min(6, len(cells) - 2))), int(rng.integers(0, 12)), {start}
    )
    others = [path for path in others if tuple(path[-1]) != goal] or others[:0]
    grid = OccupancyGrid(~free)
    path = single_agent_path(grid, others, start, goal)
    expected = reference_cost(free, others, start, goal)
    if expected is None:
        assert path is None
    else:
        assert path is not None and len(path) - 1 == expected
        assert_legal(path, free, others, start, goal)


def test_ducks_into_the_pocket_of_a_head_on_agent():
    """By hand: in a corridor with a side pocket above its second cell, an agent coming head-on (and
    then resting on our start) makes us step into the pocket at t = 2 and out at t = 3: cost 5."""
    free = np.array([[False, True, False, False], [True, True, True, True]])
    other = np.array([(1, 3), (1, 2), (1, 1), (1, 0)])
    path = single_agent_path(OccupancyGrid(~free), [other], (1, 0), (1, 3))
    assert path.tolist() == [[1, 0], [1, 1], [0, 1], [1, 1], [1, 2], [1, 3]]
    assert (
        single_agent_path(OccupancyGrid(~free), [other[::-1]], (1, 2), (1, 0)) is None
    )  # walled in: no pass
