"""Multi-agent path finding on an occupancy grid: `solve(grid, starts, goals, time_limit=...)`.

Agents move synchronously on the free cells, 4-connected: each time step every agent moves to a
neighbour or waits; two agents never share a cell (vertex conflict) nor swap cells in one step
(swap conflict). The solver is C (planner/native/mapf.c, mapf_lns.h). The first solution comes from
LaCAM (Okumura, AAAI 2023): a depth-first search over configurations (one cell per agent) whose
successors PIBT (Okumura et al. 2022; with a swap of two agents meeting head-on at the mouth of a
dead end, after Okumura 2024) generates under constraints that a lazily grown tree adds agent by
agent, so every successor is eventually tried and the search is complete. PIBT here keeps one-cell
dead ends and corridors in order: an agent resting on its goal between another agent and that one's
goal further in steps out of the way (by the side the other comes from) until the other is home,
instead of being pushed in ahead of it for ever; and it breaks distance ties along a guide (a
shortest path per agent chosen against the flow of the others' guides, so that fewer agents meet
head-on in one-cell aisles). Once LaCAM no longer gets nearer the goals it takes turns, half the time
each, with prioritized planning (agents one after the other by SIPP, safe interval path planning,
Phillips and Likhachev 2011, against the ones before; an agent that finds no path evicts the planned
agents in its way, which are planned again after it), which is sometimes the quicker of the two in
one-cell warehouse aisles; and it repairs locally: from its configuration nearest the goals, the
agents not yet home (stuck in knots far apart, where PIBT locked them in one-cell aisles) get regions
(the cells near their shortest paths, merged where they overlap), and each region with the agents in
it is solved alone as a small instance (or, if not solved, brought nearer its goals) while every
other agent rests, in rounds until all are home; if that fails, restarts with other random choices
make their own repair. Then, until `time_limit` or a proof of optimality, two improvers share
the best solution: LaCAM* (Okumura, IJCAI 2023; configurations met again link the search nodes,
costs are rewired along the links, nodes that cannot beat the best sum of costs are pruned; an
exhausted search proves the best one optimal) and a large neighbourhood search (Li et al., IJCAI
2021: a few agents at a time replanned by SIPP against the others' paths, kept if the sum of costs
drops). Goal distances are one breadth-first search per agent.
"""

from __future__ import annotations

import ctypes
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from native.load import bind, load
from planner.errors import PlannerError
from planner.grid import OccupancyGrid

_INT_P = ctypes.POINTER(ctypes.c_int)
_KERNELS = bind(
    load(Path(__file__).parent / "native" / "mapf.c"),
    {
        "mapf_solve": (
            ctypes.c_void_p,
            [ctypes.c_int, _INT_P, ctypes.c_int, _INT_P, _INT_P, ctypes.c_double, ctypes.c_ulonglong,
             ctypes.c_double],
        ),
        "mapf_status": (ctypes.c_int, [ctypes.c_void_p]),
        "mapf_length": (ctypes.c_int, [ctypes.c_void_p]),
        "mapf_first_time": (ctypes.c_double, [ctypes.c_void_p]),
        "mapf_nodes": (ctypes.c_int, [ctypes.c_void_p]),
        "mapf_bytes": (ctypes.c_double, [ctypes.c_void_p]),
        "mapf_lns_iterations": (ctypes.c_longlong, [ctypes.c_void_p]),
        "mapf_lower": (ctypes.c_longlong, [ctypes.c_void_p]),
        "mapf_copy": (None, [ctypes.c_void_p, _INT_P]),
        "mapf_free": (None, [ctypes.c_void_p]),
        "mapf_single_path": (
            ctypes.c_int,
            [ctypes.c_int, _INT_P, ctypes.c_int, _INT_P, _INT_P, ctypes.c_int, ctypes.c_int, _INT_P,
             ctypes.c_int],
        ),
    },
)  # fmt: skip

# The kernel's status codes, and what MapfResult.status says for each.
STATUS = {1: "optimal", 2: "time limit", 0: "time limit", -1: "unsolvable", -3: "memory limit"}
DEFAULT_MEMORY = 1.0e9  # bytes: distance tables (4 per agent and cell), guides, search nodes (16 per agent)


@dataclass(frozen=True)
class MapfResult:
    """A MAPF solution (or its absence).

    paths: one int array (makespan + 1, 2) of (row, col) per agent, padded with its goal; empty
        if not solved.
    sum_of_costs: sum over agents of the time step at which each reaches its goal for the last
        time (None if not solved).
    makespan: time steps until every agent rests on its goal (None if not solved).
    lower_bound: sum of the single-agent shortest distances (time steps).
    elapsed: wall time of the solve [s]; first_solution: wall time to the first solution [s]
        (None if none).
    solved: a solution was found; optimal: its sum of costs is proven minimal.
    status: why the search stopped: "optimal", "time limit", "memory limit" (the byte budget was
        spent before a solution) or "unsolvable" (proven: some agent cannot reach its goal, or the
        complete search ran out of configurations).
    nodes: configurations LaCAM created; neighbourhoods: large-neighbourhood iterations made;
    memory: bytes charged to the budget (distance tables and LaCAM's search).
    """

    paths: list
    sum_of_costs: int | None
    makespan: int | None
    lower_bound: int
    elapsed: float
    solved: bool
    optimal: bool
    first_solution: float | None
    status: str
    nodes: int
    neighbourhoods: int
    memory: float


def _cells(name: str, cells, grid: OccupancyGrid) -> np.ndarray:
    try:
        array = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    except (TypeError, ValueError):
        raise PlannerError(f"{name} must be (row, col) cells, got {cells!r}") from None
    rows, cols = grid.shape
    for index, (row, col) in enumerate(array):
        if not (0 <= row < rows and 0 <= col < cols):
            raise PlannerError(
                f"{name[:-1]} {index} {(int(row), int(col))} is outside the {rows}x{cols} grid"
            )
        if grid.occupied[row, col]:
            raise PlannerError(f"{name[:-1]} {index} {(int(row), int(col))} is on an obstacle")
    seen: dict[tuple[int, int], int] = {}
    for index, cell in enumerate(map(tuple, array.tolist())):
        if cell in seen:
            raise PlannerError(f"{name[:-1]}s {seen[cell]} and {index} are the same cell {cell}")
        seen[cell] = index
    return array


def graph(grid: OccupancyGrid) -> tuple[np.ndarray, np.ndarray]:
    """(vertex of each cell, -1 if blocked; (V, 4) neighbour vertices, -1 = none) of the free cells."""
    cached = grid._cache.get("mapf_graph")
    if cached is not None:
        return cached
    free = ~grid.occupied
    vertex = np.full(free.shape, -1, dtype=np.int32)
    vertex[free] = np.arange(int(free.sum()), dtype=np.int32)
    padded = np.pad(vertex, 1, constant_values=-1)
    rows, cols = np.nonzero(free)
    rows, cols = rows + 1, cols + 1
    neighbours = np.stack(
        [padded[rows - 1, cols], padded[rows + 1, cols], padded[rows, cols - 1], padded[rows, cols + 1]],
        axis=1,
    ).astype(np.int32)
    grid._cache["mapf_graph"] = (vertex, np.ascontiguousarray(neighbours))
    return grid._cache["mapf_graph"]


def sum_of_costs(paths: list[np.ndarray], goals: np.ndarray) -> int:
    """Sum over agents of the last time step at which an agent is not on its goal, plus one."""
    total = 0
    for path, goal in zip(paths, goals, strict=True):
        away = np.nonzero(np.any(path != goal, axis=1))[0]
        total += int(away[-1]) + 1 if away.size else 0
    return total


def single_agent_path(grid: OccupancyGrid, others, start, goal) -> np.ndarray | None:
    """The solver's single-agent search (SIPP) on its own: a shortest path (cells per time step,
    ending when the agent reaches `goal` for good) from `start` that meets no vertex or swap conflict
    with the `others`, (T_k, 2) arrays of cells per time step that each rest on their last cell
    afterwards; None if there is none. For tests and diagnostics: `solve` does not call it."""
    vertex, neighbours = graph(grid)
    cells = [np.asarray(path, dtype=np.int64).reshape(-1, 2) for path in others]
    (start_v,), (goal_v,) = (
        vertex[tuple(_cells(name, [cell], grid).T)] for name, cell in (("starts", start), ("goals", goal))
    )
    flat = np.ascontiguousarray(
        np.concatenate([vertex[path[:, 0], path[:, 1]] for path in cells]) if cells else np.zeros(0),
        dtype=np.int32,
    )
    if (flat < 0).any():
        raise PlannerError("others: a path passes an obstacle")
    offset = np.ascontiguousarray(np.cumsum([0] + [len(path) for path in cells]), dtype=np.int32)
    room = len(neighbours) + sum(len(path) for path in cells) + 1  # a path never needs more steps
    out = np.zeros(room, dtype=np.int32)
    cost = _KERNELS.mapf_single_path(
        len(neighbours), neighbours.ctypes.data_as(_INT_P), len(cells), flat.ctypes.data_as(_INT_P),
        offset.ctypes.data_as(_INT_P), int(start_v), int(goal_v), out.ctypes.data_as(_INT_P), room,
    )  # fmt: skip
    if cost == -2:
        raise MemoryError("mapf: cannot allocate the single-agent search")
    if cost < 0:
        return None
    rows, cols = np.nonzero(~grid.occupied)
    return np.stack([rows, cols], axis=1).astype(np.int64)[out[: cost + 1]]


def solve(
    grid: OccupancyGrid,
    starts,
    goals,
    time_limit: float = 10.0,
    seed: int = 0,
    memory: float = DEFAULT_MEMORY,
) -> MapfResult:
    """Collision-free paths from `starts` to `goals` ((row, col) cells, one per agent).

    time_limit [s]: wall time of the whole solve, first solution included; the improvement runs
    until then unless the optimum is proven earlier. seed: the random choices (PIBT's ties, the
    neighbourhoods). memory [bytes]: budget of the distance tables and LaCAM's search nodes.
    """
    if not isinstance(grid, OccupancyGrid):
        raise PlannerError(f"grid must be a planner.OccupancyGrid, got {type(grid).__name__}")
    starts = _cells("starts", starts, grid)
    goals = _cells("goals", goals, grid)
    if len(starts) != len(goals):
        raise PlannerError(f"{len(starts)} starts but {len(goals)} goals: one of each per agent")
    if len(starts) == 0:
        raise PlannerError("no agents: give at least one start and goal")
    if (
        isinstance(time_limit, bool)
        or not isinstance(time_limit, (int, float))
        or not 0 <= time_limit < float("inf")
    ):
        raise PlannerError(f"time_limit must be a finite number of seconds >= 0, got {time_limit}")
    if isinstance(memory, bool) or not isinstance(memory, (int, float)) or not memory > 0:
        raise PlannerError(f"memory must be a number of bytes > 0, got {memory}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise PlannerError(f"seed must be an integer >= 0, got {seed!r}")
    began = time.perf_counter()
    vertex, neighbours = graph(grid)
    n = len(starts)
    start_v = np.ascontiguousarray(vertex[starts[:, 0], starts[:, 1]], dtype=np.int32)
    goal_v = np.ascontiguousarray(vertex[goals[:, 0], goals[:, 1]], dtype=np.int32)
    handle = _KERNELS.mapf_solve(
        len(neighbours), neighbours.ctypes.data_as(_INT_P), n, start_v.ctypes.data_as(_INT_P),
        goal_v.ctypes.data_as(_INT_P), float(time_limit), seed, float(memory),
    )  # fmt: skip
    if not handle:
        raise MemoryError("mapf: cannot allocate the solver's state")
    try:
        status = _KERNELS.mapf_status(handle)
        length = _KERNELS.mapf_length(handle)
        path = np.zeros((max(length, 1), n), dtype=np.int32)
        _KERNELS.mapf_copy(handle, path.ctypes.data_as(_INT_P))
        lower = _KERNELS.mapf_lower(handle)
        first = _KERNELS.mapf_first_time(handle)
        nodes = _KERNELS.mapf_nodes(handle)
        neighbourhoods = _KERNELS.mapf_lns_iterations(handle)
        used = _KERNELS.mapf_bytes(handle)
    finally:
        _KERNELS.mapf_free(handle)
    solved = length > 0
    paths: list[np.ndarray] = []
    if solved:
        rows, cols = np.nonzero(~grid.occupied)
        cells = np.stack([rows, cols], axis=1).astype(np.int64)  # vertex -> (row, col)
        paths = [cells[path[:length, agent]] for agent in range(n)]
    return MapfResult(
        paths=paths,
        sum_of_costs=sum_of_costs(paths, goals) if solved else None,
        makespan=length - 1 if solved else None,
        lower_bound=int(lower),
        elapsed=time.perf_counter() - began,
        solved=solved,
        optimal=status == 1,
        first_solution=first if solved else None,
        status=STATUS[status],
        nodes=nodes,
        neighbourhoods=neighbourhoods,
        memory=used,
    )
