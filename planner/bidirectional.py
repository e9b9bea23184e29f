"""Bidirectional A*: one search from the start towards the goal and one from the goal towards the
start, each with the heuristic to its own target, expanding the side whose OPEN list is smaller.

Every relaxed edge u -> v where v has been reached by the other side offers a path of cost
g_forward + step + g_backward; the best one is kept as mu. The search stops when either side's
smallest f in OPEN is >= mu: any path not yet seen must leave that side's OPEN through a node with
at least that f, so with an admissible, consistent heuristic (octile, Manhattan with 4 neighbours)
mu is the optimal cost. Options and costs are those of planner.astar; with the cost gradient the
cost of an edge is charged on the cell it enters in the start -> goal direction, on both sides.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from planner.astar import (
    _F_SCALE,
    _H_BITS,
    P_COST_WEIGHT,
    P_DECREASE,
    P_H_SCALE,
    P_HEURISTIC,
    P_TIE,
    heap_key_of,
    heap_pop,
    heap_push,
    heuristic_cells,
    neighbour_tables,
)
from planner.searchspace import SearchMap, workspace


@njit(cache=True)
def _expand(
    moves,
    width,
    target,
    backward,
    heuristic,
    h_scale,
    tie_breaker,
    decrease_key,
    cost,
    cost_weight,
    g,
    nodes,
    generation,
    heap_key,
    heap_node,
    size,
    searched,
    other_g,
    other_stamp,
    other_generation,
    best,
    mine,
):
    """Pop and expand one node of one side. best = [mu, forward meet node, backward meet node];
    mine is this side's index in best (1 forward, 2 backward). The move masks are symmetric (a move
    and its reverse need the same cells free), so the backward side uses them as they are.

    Returns (new heap size, new searched count, status): status -1 = heap full, 0 = popped a stale
    entry or expanded, 1 = heap empty."""
    parent = nodes[0]
    stamp = nodes[1]
    expanded = nodes[2]
    offsets, row_steps, col_steps, steps = neighbour_tables(width)
    closed = generation + 1
    capacity = len(heap_key)
    if size == 0:
        return size, searched, 1
    node, size = heap_pop(heap_key, heap_node, size)
    here = np.uint64(node)  # unsigned indices: numba adds wraparound code to signed ones
    if stamp[here] == closed:
        return size, searched, 0
    stamp[here] = closed
    expanded[np.uint64(searched)] = node
    searched += 1
    g_node = g[here]
    row_offset = node // width - target // width
    col_offset = node % width - target % width
    allowed = moves[here]
    for k in range(8):
        if not (allowed >> k) & 1:
            continue
        neighbour = node + offsets[k]
        slot = np.uint64(neighbour)
        seen = stamp[slot]
        if seen == closed:
            continue
        step = steps[k]
        if cost_weight != 0.0:  # cost is NO_COST (never read) when the weight is 0
            step *= 1.0 + cost_weight * cost[here if backward else slot]
        g_new = g_node + step
        other = other_stamp[slot]
        reached_by_other = other == other_generation or other == other_generation + 1
        if reached_by_other and g_new + other_g[slot] < best[0]:
            best[0] = g_new + other_g[slot]
            best[mine] = node
            best[3 - mine] = neighbour
        if seen == generation:
            if g_new >= g[slot]:
                continue
            g[slot] = g_new
            parent[slot] = node
            if not decrease_key:
                continue
        else:
            stamp[slot] = generation
            g[slot] = g_new
            parent[slot] = node
        if size == capacity:
            return size, searched, -1
        h = heuristic_cells(row_offset + row_steps[k], col_offset + col_steps[k], heuristic) * h_scale
        size = heap_push(heap_key, heap_node, size, heap_key_of(g_new + h, h, tie_breaker), neighbour)
    return size, searched, 0


@njit(cache=True)
def _root(width, root, target, heuristic, h_scale, tie_breaker, g, nodes, generation, heap_key, heap_node):
    """Put `root` in OPEN of one side."""
    g[root] = 0.0
    nodes[0, root] = root
    nodes[1, root] = generation
    h = heuristic_cells(root // width - target // width, root % width - target % width, heuristic) * h_scale
    heap_push(heap_key, heap_node, np.int64(0), heap_key_of(h, h, tie_breaker), root)


@njit(cache=True)
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

    status 1 = path found, 0 = none, -1 = a heap is full (enlarge both and search again)."""
    best = np.array([np.inf, -1.0, -1.0])
    searched_forward = np.int64(0)
    searched_backward = np.int64(0)
    _root(width, start, goal, heuristic, h_scale, tie_breaker,
          g_forward, nodes_forward, generation_forward, heap_key_forward, heap_node_forward)  # fmt: skip
    _root(width, goal, start, heuristic, h_scale, tie_breaker,
          g_backward, nodes_backward, generation_backward, heap_key_backward, heap_node_backward)  # fmt: skip
    if start == goal:
        nodes_forward[2, 0] = start
        return 1, 1, 0, 0.0, start, -1
    # np.int64, not literals: a Literal[int] argument would compile _expand and heap_pop once more.
    size_forward = np.int64(1)
    size_backward = np.int64(1)
    while size_forward > 0 and size_backward > 0:
        top_forward = (heap_key_forward[0] >> _H_BITS) / _F_SCALE
        top_backward = (heap_key_backward[0] >> _H_BITS) / _F_SCALE
        if top_forward >= best[0] or top_backward >= best[0]:
            break
        # The side is a runtime value, not a literal True/False/1/2, so _expand compiles once.
        backward = size_forward > size_backward
        side = np.int64(2) if backward else np.int64(1)
        if backward:
            size_backward, searched_backward, status = _expand(
                moves, width, start, backward, heuristic, h_scale, tie_breaker, decrease_key,
                cost, cost_weight,
                g_backward, nodes_backward, generation_backward, heap_key_backward, heap_node_backward,
                size_backward, searched_backward,
                g_forward, nodes_forward[1], generation_forward, best, side,
            )  # fmt: skip
        else:
            size_forward, searched_forward, status = _expand(
                moves, width, goal, backward, heuristic, h_scale, tie_breaker, decrease_key,
                cost, cost_weight,
                g_forward, nodes_forward, generation_forward, heap_key_forward, heap_node_forward,
                size_forward, searched_forward,
                g_backward, nodes_backward[1], generation_backward, best, side,
            )  # fmt: skip
        if status < 0:
            return -1, searched_forward, searched_backward, 0.0, -1, -1
    if best[0] == np.inf:
        return 0, searched_forward, searched_backward, 0.0, -1, -1
    return 1, searched_forward, searched_backward, best[0], np.int64(best[1]), np.int64(best[2])


@njit(cache=True)
def join_paths(nodes_forward, nodes_backward, start, goal, meet_forward, meet_backward, width, rows,
               resolution, origin_x, origin_y):  # fmt: skip
    """Cells, path [m] and length [m] of the path through the meeting edge."""
    forward_count = 1
    node = meet_forward
    while node != start:
        node = nodes_forward[0, node]
        forward_count += 1
    backward_count = 0
    if meet_backward >= 0:
        backward_count = 1
        node = meet_backward
        while node != goal:
            node = nodes_backward[0, node]
            backward_count += 1
    count = forward_count + backward_count
    sequence = np.empty(count, dtype=np.int64)
    node = meet_forward
    for index in range(forward_count - 1, -1, -1):
        sequence[index] = node
        node = nodes_forward[0, node]
    node = meet_backward
    for index in range(forward_count, count):
        sequence[index] = node
        node = nodes_backward[0, node]
    cells = np.empty((count, 2), dtype=np.int64)
    path = np.empty((count, 2))
    length = 0.0
    for index in range(count):
        node = sequence[index]
        row = node // width - 1
        col = node % width - 1
        cells[index, 0] = row
        cells[index, 1] = col
        path[index, 0] = origin_x + (col + 0.5) * resolution
        path[index, 1] = origin_y + (rows - 1 - row + 0.5) * resolution
        if index > 0:
            difference = abs(node - sequence[index - 1])
            length += (
                resolution if difference == 1 or difference == width else 1.4142135623730951 * resolution
            )
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
    heuristic = int(parameters[P_HEURISTIC])
    h_scale = float(parameters[P_H_SCALE])
    tie_breaker = int(parameters[P_TIE])
    decrease_key = bool(parameters[P_DECREASE])
    cost_weight = float(parameters[P_COST_WEIGHT])
    while True:
        generation_forward, generation_backward = forward.next_generation(), backward.next_generation()
        compiled = len(bidirectional_search.overloads)
        began = time.perf_counter()
        status, searched_forward, searched_backward, _, meet_forward, meet_backward = bidirectional_search(
            moves, space.width, start_node, goal_node, heuristic, h_scale, tie_breaker, decrease_key,
            cost, cost_weight,
            forward.g, forward.nodes, generation_forward, forward.heap[0], forward.heap[1],
            backward.g, backward.nodes, generation_backward, backward.heap[0], backward.heap[1],
        )  # fmt: skip
        elapsed = time.perf_counter() - began
        if len(bidirectional_search.overloads) != compiled:
            continue  # that call compiled the kernel (or loaded it from the cache): time a clean run
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
