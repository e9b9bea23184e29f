"""The compiled grid A* of chapter 3 (numba): heuristics 3.1-3.4 and 3.6, the thesis's improvements.

Data layout (why it is fast): the map is flattened to 1-D with a one-cell blocked border, so a
neighbour is `node + offset` with no bounds test. `blocked` holds 0 = free, 1 = obstacle /
inflated / border, 2 = *untrusted point* (a free cell with an obstacle among its 8 neighbours).
g, parent, heap position and a per-cell `stamp` live in arrays that are reused from query to
query: `stamp[n] == generation` means n is in OPEN, `generation + 1` means CLOSED, anything else
means unseen, so a new query costs no clearing of grid-size arrays.

OPEN is an indexed binary heap (node, key, secondary key, and each node's heap position) with
keys f = g + h. The thesis's second improvement ("OPEN-list replacement") is a decrease-key: a
node reached again with a lower g gets the new g, parent and key in place. Without it the node
keeps its old key, as in plannerAStarGrid (g, f and parent change, the heap does not).

Costs are in cells here (straight 1, diagonal sqrt 2); the caller multiplies by the resolution.
f is rounded to 2^-30 cell before comparison so that equal-f ties (frequent with octile costs, but
split by rounding noise) are broken by the secondary key; the rounding costs at most ~1e-9 cell per
node of optimality.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

HEURISTICS = {"manhattan": 0, "euclidean": 1, "chebyshev": 2, "octile": 3, "thesis": 4, "zero": 5}
TIE_BREAKERS = {"none": 0, "matlab": 1, "low_h": 2}
FREE, BLOCKED, UNTRUSTED = 0, 1, 2

SQRT2 = math.sqrt(2.0)
_QUANTUM = 1073741824.0  # 2^30: f is compared on a 2^-30 cell grid


@njit(cache=True, inline="always")
def heuristic_cells(node, goal_row, goal_col, width, kind):
    """h in cells between padded node and goal: 3.1 Manhattan, 3.2 Euclid, 3.3 Chebyshev,
    3.4 octile (diagonal), 3.6 the thesis's Euclid + 2 Chebyshev, or 0."""
    dr = abs(node // width - goal_row)
    dc = abs(node % width - goal_col)
    if kind == 3:
        if dr > dc:
            return dr + (SQRT2 - 1.0) * dc
        return dc + (SQRT2 - 1.0) * dr
    if kind == 0:
        return float(dr + dc)
    if kind == 1:
        return math.sqrt(dr * dr + dc * dc)
    if kind == 2:
        return float(max(dr, dc))
    if kind == 4:
        return math.sqrt(dr * dr + dc * dc) + 2.0 * max(dr, dc)
    return 0.0


@njit(cache=True, inline="always")
def _less(key_a, second_a, key_b, second_b):
    return key_a < key_b or (key_a == key_b and second_a < second_b)


@njit(cache=True)
def heap_sift_up(heap_node, heap_key, heap_second, heap_pos, index):
    node = heap_node[index]
    key = heap_key[index]
    second = heap_second[index]
    while index > 0:
        parent = (index - 1) >> 1
        if not _less(key, second, heap_key[parent], heap_second[parent]):
            break
        heap_node[index] = heap_node[parent]
        heap_key[index] = heap_key[parent]
        heap_second[index] = heap_second[parent]
        heap_pos[heap_node[index]] = index
        index = parent
    heap_node[index] = node
    heap_key[index] = key
    heap_second[index] = second
    heap_pos[node] = index


@njit(cache=True)
def heap_push(heap_node, heap_key, heap_second, heap_pos, size, node, key, second):
    heap_node[size] = node
    heap_key[size] = key
    heap_second[size] = second
    heap_sift_up(heap_node, heap_key, heap_second, heap_pos, size)
    return size + 1


@njit(cache=True)
def heap_pop(heap_node, heap_key, heap_second, heap_pos, size):
    """Remove the top; returns (node, new size)."""
    top = heap_node[0]
    size -= 1
    if size == 0:
        return top, size
    node = heap_node[size]
    key = heap_key[size]
    second = heap_second[size]
    index = 0
    while True:
        child = 2 * index + 1
        if child >= size:
            break
        right = child + 1
        if right < size and _less(heap_key[right], heap_second[right], heap_key[child], heap_second[child]):
            child = right
        if not _less(heap_key[child], heap_second[child], key, second):
            break
        heap_node[index] = heap_node[child]
        heap_key[index] = heap_key[child]
        heap_second[index] = heap_second[child]
        heap_pos[heap_node[index]] = index
        index = child
    heap_node[index] = node
    heap_key[index] = key
    heap_second[index] = second
    heap_pos[node] = index
    return top, size


@njit(cache=True)
def neighbour_tables(width):
    """Offsets, step lengths [cells] and the two orthogonal offsets of each diagonal move.

    Order: the 4 straight moves first, so 4-connectivity uses the first 4 entries."""
    offsets = np.array([-width, width, -1, 1, -width - 1, -width + 1, width - 1, width + 1], dtype=np.int64)
    steps = np.array([1.0, 1.0, 1.0, 1.0, SQRT2, SQRT2, SQRT2, SQRT2])
    side_a = np.array([0, 0, 0, 0, -width, -width, width, width], dtype=np.int64)
    side_b = np.array([0, 0, 0, 0, -1, 1, -1, 1], dtype=np.int64)
    return offsets, steps, side_a, side_b


@njit(cache=True)
def astar_search(
    blocked,
    width,
    start,
    goal,
    connectivity,
    corner_cutting,
    heuristic,
    heuristic_weight,
    tie_breaker,
    decrease_key,
    untrusted,
    cost,
    cost_weight,
    g,
    parent,
    stamp,
    generation,
    heap_node,
    heap_key,
    heap_second,
    heap_pos,
    expanded,
):
    """A* (or Dijkstra with heuristic 5 and goal -1) on a padded flat grid.

    Fills g [cells], parent, stamp and `expanded` (nodes in the order they were closed). Returns
    (goal reached, number of expanded nodes). With goal == -1 the search runs until OPEN is empty.
    """
    offsets, steps, side_a, side_b = neighbour_tables(width)
    directions = 8 if connectivity == 8 else 4
    goal_row = goal // width if goal >= 0 else 0
    goal_col = goal % width if goal >= 0 else 0
    h_scale = heuristic_weight * (1.07 if tie_breaker == 1 else 1.0)
    closed = generation + 1
    use_cost = cost_weight > 0.0

    g[start] = 0.0
    parent[start] = start
    stamp[start] = generation
    h0 = heuristic_cells(start, goal_row, goal_col, width, heuristic) * h_scale
    size = heap_push(heap_node, heap_key, heap_second, heap_pos, 0, start, math.floor(h0 * _QUANTUM + 0.5), 0.0)
    searched = 0
    while size > 0:
        node, size = heap_pop(heap_node, heap_key, heap_second, heap_pos, size)
        stamp[node] = closed
        expanded[searched] = node
        searched += 1
        if node == goal:
            return True, searched
        g_node = g[node]
        for k in range(directions):
            neighbour = node + offsets[k]
            state = blocked[neighbour]
            if state == 1:
                continue
            if state == 2 and untrusted and neighbour != goal:
                continue
            seen = stamp[neighbour]
            if seen == closed:
                continue
            if k >= 4 and not corner_cutting:
                if blocked[node + side_a[k]] == 1 or blocked[node + side_b[k]] == 1:
                    continue
            step = steps[k]
            if use_cost:
                step *= 1.0 + cost_weight * cost[neighbour]
            g_new = g_node + step
            if seen == generation:
                if g_new < g[neighbour]:
                    g[neighbour] = g_new
                    parent[neighbour] = node
                    if decrease_key:
                        h = heuristic_cells(neighbour, goal_row, goal_col, width, heuristic) * h_scale
                        index = heap_pos[neighbour]
                        heap_key[index] = math.floor((g_new + h) * _QUANTUM + 0.5)
                        heap_second[index] = h if tie_breaker == 2 else 0.0
                        heap_sift_up(heap_node, heap_key, heap_second, heap_pos, index)
            else:
                stamp[neighbour] = generation
                g[neighbour] = g_new
                parent[neighbour] = node
                h = heuristic_cells(neighbour, goal_row, goal_col, width, heuristic) * h_scale
                size = heap_push(
                    heap_node,
                    heap_key,
                    heap_second,
                    heap_pos,
                    size,
                    neighbour,
                    math.floor((g_new + h) * _QUANTUM + 0.5),
                    h if tie_breaker == 2 else 0.0,
                )
    return False, searched


@njit(cache=True)
def trace_path(parent, start, goal, width, cols):
    """Cells (row, col) from start to goal by following parents, and their length [cells]."""
    count = 1
    node = goal
    while node != start:
        node = parent[node]
        count += 1
    cells = np.empty((count, 2), dtype=np.int64)
    node = goal
    length = 0.0
    for index in range(count - 1, -1, -1):
        cells[index, 0] = node // width - 1
        cells[index, 1] = node % width - 1
        previous = parent[node]
        if node != start:
            difference = abs(previous - node)
            length += 1.0 if difference == 1 or difference == width else SQRT2
        node = previous
    return cells, length


@njit(cache=True)
def mark_explored(expanded, count, width, cols, explored_flat):
    """Set explored_flat[row * cols + col] for the first `count` padded nodes of `expanded`."""
    for index in range(count):
        node = expanded[index]
        explored_flat[(node // width - 1) * cols + node % width - 1] = True


@njit(cache=True)
def unpad_distances(g, stamp, closed, rows, cols, resolution):
    """g [cells] of closed padded nodes as an unpadded [rows, cols] array in metres, inf elsewhere."""
    width = cols + 2
    result = np.full((rows, cols), np.inf)
    for row in range(rows):
        base = (row + 1) * width + 1
        for col in range(cols):
            if stamp[base + col] == closed:
                result[row, col] = g[base + col] * resolution
    return result
