"""An independent MAPF solution checker (Python, numpy and scipy; no code shared with planner.mapf), and an
exact reference solver for tiny instances; tested here on hand-made good and bad solutions.

`check(occupied, starts, goals, result)` raises AssertionError naming the first violation: paths of
equal length, 4-connected moves or waits on free cells, starts and goals, no vertex or swap conflict;
it recomputes the sum of costs, the makespan and the lower bound (scipy.sparse.csgraph distances).
`optimal_sum_of_costs(occupied, starts, goals)`: Dijkstra over joint states for 2-3 agents.
The benchmark (benchmarks/bench_mapf.py) applies `check` to every solution too.
"""

from __future__ import annotations

import heapq
import itertools
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path

MOVES = ((-1, 0), (1, 0), (0, -1), (0, 1))


def lower_bound(occupied, starts, goals, chunk: int = 64) -> int:
    """Sum over agents of the 4-connected shortest distance from start to goal over the free cells:
    scipy's breadth-first distances (csgraph, unweighted) on a graph built here, `chunk` goals at a time."""
    free = ~np.asarray(occupied, dtype=bool)
    rows, cols = free.shape
    index = np.full(free.shape, -1)
    index[free] = np.arange(int(free.sum()))
    edges = []
    for d_row, d_col in ((1, 0), (0, 1)):
        here = free[: rows - d_row, : cols - d_col] & free[d_row:, d_col:]
        a = index[: rows - d_row, : cols - d_col][here]
        b = index[d_row:, d_col:][here]
        edges.append((a, b))
    a = np.concatenate([edge[0] for edge in edges])
    b = np.concatenate([edge[1] for edge in edges])
    graph = csr_matrix((np.ones(len(a)), (a, b)), shape=(int(free.sum()),) * 2)
    starts = np.asarray(starts, dtype=int).reshape(-1, 2)
    goals = np.asarray(goals, dtype=int).reshape(-1, 2)
    total = 0.0
    for first in range(0, len(goals), chunk):
        sources = index[goals[first : first + chunk, 0], goals[first : first + chunk, 1]]
        targets = index[starts[first : first + chunk, 0], starts[first : first + chunk, 1]]
        table = shortest_path(graph, directed=False, unweighted=True, indices=sources)
        total += table[np.arange(len(sources)), targets].sum()
    assert np.isfinite(total), "an agent cannot reach its goal"
    return int(total)


def check(occupied, starts, goals, result) -> None:
    occupied = [[bool(value) for value in row] for row in occupied]
    starts = [tuple(int(v) for v in cell) for cell in starts]
    goals = [tuple(int(v) for v in cell) for cell in goals]
    assert result.solved
    paths = [[tuple(int(v) for v in cell) for cell in path] for path in result.paths]
    assert len(paths) == len(starts)
    length = len(paths[0])
    assert all(len(path) == length for path in paths), "paths of unequal length"
    rows, cols = len(occupied), len(occupied[0])
    for agent, path in enumerate(paths):
        assert path[0] == starts[agent], f"agent {agent} does not start at its start"
        assert path[-1] == goals[agent], f"agent {agent} does not end at its goal"
        for t, (row, col) in enumerate(path):
            assert 0 <= row < rows and 0 <= col < cols and not occupied[row][col], (
                f"agent {agent} off the free cells at {t}"
            )
            if t:
                step = abs(row - path[t - 1][0]) + abs(col - path[t - 1][1])
                assert step <= 1, f"agent {agent} jumps at {t}"
    for t in range(length):
        at = {}
        for agent, path in enumerate(paths):
            assert path[t] not in at, f"vertex conflict of agents {at.get(path[t])} and {agent} at {t}"
            at[path[t]] = agent
        if t:
            before = {path[t - 1]: agent for agent, path in enumerate(paths)}
            for agent, path in enumerate(paths):
                other = before.get(path[t])
                if other is not None and other != agent and paths[other][t] == path[t - 1]:
                    raise AssertionError(f"swap conflict of agents {agent} and {other} at {t}")
    cost = 0
    for agent, path in enumerate(paths):
        away = [t for t, cell in enumerate(path) if cell != goals[agent]]
        cost += away[-1] + 1 if away else 0
    assert result.sum_of_costs == cost
    makespan = max(
        (
            max((t + 1 for t, cell in enumerate(path) if cell != goals[agent]), default=0)
            for agent, path in enumerate(paths)
        ),
        default=0,
    )
    assert result.makespan == length - 1 == makespan, "the paths are padded beyond the makespan"
    assert result.lower_bound == lower_bound(occupied, starts, goals)
    assert result.sum_of_costs >= result.lower_bound


def _moves(occupied, cell):
    rows, cols = len(occupied), len(occupied[0])
    yield cell
    for d_row, d_col in MOVES:
        row, col = cell[0] + d_row, cell[1] + d_col
        if 0 <= row < rows and 0 <= col < cols and not occupied[row][col]:
            yield (row, col)


def optimal_sum_of_costs(occupied, starts, goals) -> int | None:
    """Minimum sum of costs by Dijkstra over (cells, finished flags): an agent may finish only on its
    goal and then stays there; a step costs one per unfinished agent. None if unsolvable."""
    starts = tuple(tuple(cell) for cell in starts)
    goals = tuple(tuple(cell) for cell in goals)
    # an agent may finish at once on a goal it starts on (then it never moves and costs nothing)
    on_goal = [(False, True) if s == g else (False,) for s, g in zip(starts, goals, strict=True)]
    begins = [(starts, flags) for flags in itertools.product(*on_goal)]
    best = dict.fromkeys(begins, 0)
    queue = [(0, begin) for begin in begins]
    while queue:
        cost, (cells, finished) = heapq.heappop(queue)
        if cost > best[(cells, finished)]:
            continue
        if all(finished):
            return cost
        options = [
            [(cell, True)] if done else [(move, False) for move in _moves(occupied, cell)]
            for cell, done in zip(cells, finished, strict=True)
        ]
        for choice in itertools.product(*options):
            after = tuple(cell for cell, _ in choice)
            if len(set(after)) < len(after):
                continue
            if any(
                after[a] == cells[b] and after[b] == cells[a] for a in range(len(after)) for b in range(a)
            ):
                continue
            step = sum(not done for done in finished)
            for flags in itertools.product(*[
                (True,) if done else ((False, True) if cell == goals[agent] else (False,))
                for agent, ((cell, _), done) in enumerate(zip(choice, finished, strict=True))
            ]):  # fmt: skip
                state = (after, flags)
                if cost + step < best.get(state, 1 << 60):
                    best[state] = cost + step
                    heapq.heappush(queue, (cost + step, state))
    return None


# -- the checker and the reference solver on hand-made cases --------------------------------------
OPEN = [[False] * 3 for _ in range(3)]


def _result(paths, goals):
    cost = sum(
        max((t + 1 for t, cell in enumerate(path) if cell != goal), default=0)
        for path, goal in zip(paths, goals, strict=True)
    )
    return SimpleNamespace(
        solved=True, paths=paths, sum_of_costs=cost, makespan=len(paths[0]) - 1,
        lower_bound=lower_bound(OPEN, [path[0] for path in paths], goals),
    )  # fmt: skip


def test_checker_accepts_a_valid_plan():
    paths = [[(0, 0), (0, 1), (0, 2)], [(2, 2), (1, 2), (1, 1)]]
    check(OPEN, [(0, 0), (2, 2)], [(0, 2), (1, 1)], _result(paths, [(0, 2), (1, 1)]))


@pytest.mark.parametrize(
    "paths, message",
    [
        ([[(0, 0), (0, 1)], [(0, 2), (0, 1)]], "vertex conflict"),
        ([[(0, 0), (0, 1)], [(0, 1), (0, 0)]], "swap conflict"),
        ([[(0, 0), (1, 1)], [(2, 2), (2, 1)]], "jumps"),
        ([[(0, 0), (0, 1), (0, 1)], [(2, 2), (2, 1), (2, 1)]], "padded"),
    ],
)
def test_checker_rejects(paths, message):
    goals = [path[-1] for path in paths]
    with pytest.raises(AssertionError, match=message):
        check(OPEN, [path[0] for path in paths], goals, _result(paths, goals))


def test_checker_rejects_a_wrong_cost_or_bound():
    paths = [[(0, 0), (0, 1), (0, 2)], [(2, 2), (2, 2), (2, 2)]]
    goals = [(0, 2), (2, 2)]
    wrong = _result(paths, goals)
    wrong.sum_of_costs += 1
    with pytest.raises(AssertionError):
        check(OPEN, [(0, 0), (2, 2)], goals, wrong)


def test_reference_solver_on_known_optima():
    # two agents crossing the centre of a 3 x 3 room at once: one waits once
    assert optimal_sum_of_costs(OPEN, [(1, 0), (0, 1)], [(1, 2), (2, 1)]) == 2 + 3
    corridor = [[False, False, False]]
    assert optimal_sum_of_costs(corridor, [(0, 0), (0, 2)], [(0, 2), (0, 0)]) is None
    assert optimal_sum_of_costs(corridor, [(0, 0), (0, 1)], [(0, 1), (0, 2)]) == 2  # following is allowed
    # an agent on its goal from the start costs nothing when it need not move, and its last arrival
    # when it must step aside for another one (corridor: the agent at 1 must let the other pass)
    assert optimal_sum_of_costs(corridor, [(0, 1), (0, 0)], [(0, 1), (0, 0)]) == 0
    assert optimal_sum_of_costs(OPEN, [(1, 1), (1, 0)], [(1, 1), (1, 2)]) == 0 + 4
    assert optimal_sum_of_costs(OPEN, [(0, 1), (1, 0)], [(0, 1), (1, 2)]) == 0 + 2
