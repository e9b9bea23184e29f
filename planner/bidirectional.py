"""Bidirectional A*: one search from the start towards the goal and one from the goal towards the
start, each with the heuristic to its own target, expanding the side whose OPEN list is smaller.

Every relaxed edge u -> v where v has been reached by the other side offers a path of cost
g_forward + step + g_backward; the best one is kept as mu. The search stops when either side's
smallest f in OPEN is >= mu: any path not yet seen must leave that side's OPEN through a node with
at least that f, so with an admissible, consistent heuristic (octile, Manhattan with 4 neighbours)
mu is the optimal cost. Options and costs are those of planner.astar; with the cost gradient the
cost of an edge is charged on the cell it enters in the start -> goal direction, on both sides.
The search is C (planner/native/bidirectional.c, navcosim_bidirectional_search).
"""

from __future__ import annotations

import ctypes
import time
from pathlib import Path

import numpy as np

from native.load import bind, load
from planner.astar import address, search_parameters
from planner.searchspace import SearchMap, workspace

# native/bidirectional.c: a library of its own (the one-way grid A* is astar.c's); PyDLL, as astar.c's
# kernels: they hold the GIL while they use the shared work arrays.
_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double
_KERNELS = bind(
    load(Path(__file__).parent / "native" / "bidirectional.c"),
    {
        "navcosim_bidirectional_search": (
            _I, (_P, _P, _P, _I, _I, _I, _P, _P, _I, _P, _P, _I, _P, _P, _I, _P, _P, _I, _P, _P),
        ),
        "navcosim_join_count": (_I, (_P, _P, _I, _I, _I, _I)),
        "navcosim_join_paths": (_D, (_P, _P, _I, _I, _I, _I, _P, _P, _P)),
    },
    hold_gil=True,
)  # fmt: skip
bidirectional_kernel = _KERNELS.navcosim_bidirectional_search
join_count_kernel = _KERNELS.navcosim_join_count
join_paths_kernel = _KERNELS.navcosim_join_paths


def bidirectional_search(
    moves,
    width,
    start,
    goal,
    heuristic,
    h_scale,
    tie_breaker,
    decrease_key,
    cost,
    cost_weight,
    g_forward,
    nodes_forward,
    generation_forward,
    heap_key_forward,
    heap_node_forward,
    g_backward,
    nodes_backward,
    generation_backward,
    heap_key_backward,
    heap_node_backward,
):
    """Returns (status, searched forward, searched backward, mu [cells], meet forward, meet backward).

    status 1 = path found, 0 = none, -1 = a heap is full (enlarge both and search again).
    heap_key_* and heap_node_* are the two rows of one int64 [2, capacity] array per side."""
    parameters = search_parameters(width, heuristic, tie_breaker, decrease_key, h_scale, cost_weight)
    return _bidirectional(
        moves, cost, parameters, start, goal,
        g_forward, nodes_forward, generation_forward, heap_key_forward, heap_node_forward,
        g_backward, nodes_backward, generation_backward, heap_key_backward, heap_node_backward,
    )  # fmt: skip


def _bidirectional(moves, cost, parameters, start, goal,
                   g_forward, nodes_forward, generation_forward, heap_key_forward, heap_node_forward,
                   g_backward, nodes_backward, generation_backward, heap_key_backward,
                   heap_node_backward):  # fmt: skip
    """bidirectional_search with the search's settings in a planner.astar.PARAMETERS array."""
    size = len(g_forward)
    for nodes, g in ((nodes_forward, g_forward), (nodes_backward, g_backward)):
        if nodes.shape != (3, size) or len(g) != size:
            raise ValueError("bidirectional_search needs g [size] and nodes [3, size] on both sides")
    if len(moves) != size or not (0 <= start < size and 0 <= goal < size):
        raise ValueError("moves, start and goal must fit the padded map")
    capacity_forward, capacity_backward = len(heap_key_forward), len(heap_key_backward)
    if len(heap_node_forward) != capacity_forward or len(heap_node_backward) != capacity_backward:
        raise ValueError("a side's heap keys and nodes must be of one length")
    out = np.empty(4, dtype=np.int64)
    mu = ctypes.c_double()
    sides = []
    for g, nodes, generation, heap_key, heap_node in (
        (g_forward, nodes_forward, generation_forward, heap_key_forward, heap_node_forward),
        (g_backward, nodes_backward, generation_backward, heap_key_backward, heap_node_backward),
    ):
        sides += [address(g, np.float64, "g"), address(nodes, np.int32, "nodes"), int(generation),
                  address(heap_key, np.int64, "heap keys"), address(heap_node, np.int64, "heap nodes"),
                  len(heap_key)]  # fmt: skip
    status = bidirectional_kernel(
        address(moves, np.uint8, "moves"), address(cost, np.float64, "cost"),
        address(parameters, np.float64, "parameters"), int(start), int(goal), size, *sides,
        out.ctypes.data, ctypes.byref(mu),
    )  # fmt: skip
    return status, int(out[0]), int(out[1]), mu.value, int(out[2]), int(out[3])


def join_paths(nodes_forward, nodes_backward, start, goal, meet_forward, meet_backward, width, rows,
               resolution, origin_x, origin_y):  # fmt: skip
    """Cells, path [m] and length [m] of the path through the meeting edge."""
    forward, backward = address(nodes_forward, np.int32, "nodes"), address(nodes_backward, np.int32, "nodes")
    count = join_count_kernel(forward, backward, int(start), int(goal), int(meet_forward), int(meet_backward))
    parameters = search_parameters(width, 0, 0, False, 1.0, 0.0, rows, 0, resolution, (origin_x, origin_y))
    cells = np.empty((count, 2), dtype=np.int64)
    path = np.empty((count, 2))
    length = join_paths_kernel(
        forward, backward, int(start), int(meet_forward), int(meet_backward), count, parameters.ctypes.data,
        cells.ctypes.data, path.ctypes.data,
    )  # fmt: skip
    return cells, path, length


def search_bidirectional(
    space: SearchMap, moves: np.ndarray, cost: np.ndarray, parameters: np.ndarray, start_node: int,
    goal_node: int,
):  # fmt: skip
    """Bidirectional A*; returns (found, cells, path [m], length [m], searched, elapsed [s], explored).

    moves: the move masks (SearchMap.moves, endpoints opened); cost: the padded cost gradient, or
    planner.astar.NO_COST when the cost weight is 0; parameters: planner.astar.PARAMETERS;
    explored: (expanded nodes, width, shape) as planner.result.PlanResult takes it."""
    size = len(space.blocked)
    forward, backward = workspace(size, 0), workspace(size, 1)
    while True:
        generation_forward, generation_backward = forward.next_generation(), backward.next_generation()
        began = time.perf_counter()
        status, searched_forward, searched_backward, _, meet_forward, meet_backward = _bidirectional(
            moves, cost, parameters, start_node, goal_node,
            forward.g, forward.nodes, generation_forward, forward.heap[0], forward.heap[1],
            backward.g, backward.nodes, generation_backward, backward.heap[0], backward.heap[1],
        )  # fmt: skip
        elapsed = time.perf_counter() - began
        if status >= 0:
            break
        forward.grow_heap()
        backward.grow_heap()
    grid = space.grid
    searched = searched_forward + searched_backward
    expanded = np.concatenate((forward.nodes[2, :searched_forward], backward.nodes[2, :searched_backward]))
    explored = (expanded, space.width, grid.shape)
    if status == 0:
        return False, None, None, 0.0, searched, elapsed, explored
    cells, path, length = join_paths(
        forward.nodes, backward.nodes, start_node, goal_node, meet_forward, meet_backward, space.width,
        space.rows, grid.resolution, grid.origin[0], grid.origin[1],
    )  # fmt: skip
    return True, cells, path, length, searched, elapsed, explored
