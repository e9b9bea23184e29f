"""The compiled grid A* of chapter 3 (numba): heuristics 3.1-3.4 and 3.6, the thesis's improvements.

Data layout (why it is fast): the map is flattened to 1-D with a one-cell blocked border, so a
neighbour is `node + offset` with no bounds test. `blocked` holds 0 = free, 1 = obstacle /
inflated / border, 2 = *untrusted point* (a free cell with an obstacle among its 8 neighbours).
g, parent and a per-cell `stamp` live in arrays that are reused from query to query:
`stamp[n] == generation` means n is in OPEN, `generation + 1` means CLOSED, anything else means
unseen, so a new query costs no clearing of grid-size arrays.

OPEN is a 4-ary heap of (int64 key, node); the key packs f = g + h (rounded to 2^-24 cell) over h
(quarter cells), so one integer comparison orders by f and, among equal f, by smaller h (the
"low_h" tie breaker, which keeps optimality; rounding f puts ties that octile costs make equal in
exact arithmetic on the same key). The thesis's second improvement, OPEN-list replacement, is a
decrease-key done lazily: a node reached again with a lower g gets the new g and parent and is
pushed again with its lower key; the stale entry is skipped when popped. Without it
(`decrease_key=False`) g, f and parent change but the key in OPEN does not, as in plannerAStarGrid.

Costs are in cells here (straight 1, diagonal sqrt 2); the caller multiplies by the resolution.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

HEURISTICS = {"manhattan": 0, "euclidean": 1, "chebyshev": 2, "octile": 3, "thesis": 4, "zero": 5}
TIE_BREAKERS = {"none": 0, "matlab": 1, "low_h": 2}
FREE, BLOCKED, UNTRUSTED = 0, 1, 2

SQRT2 = math.sqrt(2.0)
# (row, col) steps of the 8 moves: planner.searchspace.MOVES, the bit order of the move masks.
_ROW_STEPS = (-1, 1, 0, 0, -1, -1, 1, 1)
_COL_STEPS = (0, 0, -1, 1, -1, 1, -1, 1)
# Heap keys pack f (2^-24 cell steps, up to 2^23 cells) over h (quarter cells, saturating at 2^14).
_H_BITS = 16
_F_SCALE = float(2**24)
_H_SCALE = 4.0
_H_MAX = 2**16 - 1


@njit(cache=True)
def heuristic_cells(row_offset, col_offset, kind):
    """h in cells for a (row, col) offset to the goal: 3.1 Manhattan, 3.2 Euclid, 3.3 Chebyshev,
    3.4 octile (diagonal distance), 3.6 the thesis's Euclid + 2 Chebyshev, or 0."""
    dr = abs(row_offset)
    dc = abs(col_offset)
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


@njit(cache=True)
def heap_push(heap_key, heap_node, size, key, node):
    """Push (key, node) on the 4-ary min-heap (the caller checks the capacity); returns the new size.

    Four children per entry: half the levels of a binary heap, and a node's children share a cache
    line, so a pop costs fewer dependent loads. Indices are cast to unsigned where they index: numba
    adds negative-index wraparound code to every signed index (~7 % of the search time)."""
    index = size
    while index > 0:
        parent = (index - 1) >> 2
        parent_slot = np.uint64(parent)
        if heap_key[parent_slot] <= key:
            break
        slot = np.uint64(index)
        heap_key[slot] = heap_key[parent_slot]
        heap_node[slot] = heap_node[parent_slot]
        index = parent
    slot = np.uint64(index)
    heap_key[slot] = key
    heap_node[slot] = node
    return size + 1


@njit(cache=True)
def heap_pop(heap_key, heap_node, size):
    """Remove the top of the heap; returns (node, new size)."""
    top = heap_node[0]
    size -= 1
    key = heap_key[np.uint64(size)]
    node = heap_node[np.uint64(size)]
    index = 0
    while True:
        first = 4 * index + 1
        if first >= size:
            break
        child = first
        smallest = heap_key[np.uint64(first)]
        last = min(first + 4, size)
        for other in range(first + 1, last):
            candidate = heap_key[np.uint64(other)]
            if candidate < smallest:
                smallest = candidate
                child = other
        if smallest >= key:
            break
        slot = np.uint64(index)
        child_slot = np.uint64(child)
        heap_key[slot] = smallest
        heap_node[slot] = heap_node[child_slot]
        index = child
    slot = np.uint64(index)
    heap_key[slot] = key
    heap_node[slot] = node
    return top, size


@njit(cache=True)
def heap_key_of(f, h, tie_breaker):
    """One int64 key: f on a 2^-24 cell grid in the high bits, h (quarter cells) below for low_h ties."""
    key = np.int64(f * _F_SCALE + 0.5) << _H_BITS
    if tie_breaker == 2:
        key += min(np.int64(h * _H_SCALE + 0.5), _H_MAX)
    return key


@njit(cache=True)
def neighbour_tables(width):
    """Offsets, row/col steps and lengths [cells] of the 8 moves, in the bit order of the move masks
    (planner.searchspace.MOVES): the 4 straight moves first. Filled element by element: np.array of
    a list costs about a second more to compile, and tuples index slower in the loop."""
    offsets = np.empty(8, dtype=np.int64)
    row_steps = np.empty(8, dtype=np.int64)
    col_steps = np.empty(8, dtype=np.int64)
    steps = np.empty(8, dtype=np.float64)
    for k in range(8):
        row_step = _ROW_STEPS[k]
        col_step = _COL_STEPS[k]
        row_steps[k] = row_step
        col_steps[k] = col_step
        offsets[k] = row_step * width + col_step
        steps[k] = SQRT2 if row_step != 0 and col_step != 0 else 1.0
    return offsets, row_steps, col_steps, steps


@njit(cache=True)
def astar_search(
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
    g,
    nodes,
    generation,
    heap_key,
    heap_node,
):
    """A* (or Dijkstra with heuristic 5 and goal -1) on a padded flat grid.

    moves: uint8 per padded cell, bit k set when move k (neighbour_tables order) leaves the cell
    (planner.searchspace.SearchMap.moves: connectivity, corner rule and untrusted points are in it,
    so the loop tests one bit per neighbour). h_scale multiplies h (weight, MATLAB's 1.07).
    nodes: int32 [3, size] = parent, stamp, and the expanded nodes in the order they were closed.
    Returns (status, number of expanded nodes): status 1 = goal reached, 0 = OPEN ran empty (no
    path; with goal == -1, the Dijkstra mode, this is the normal end), -1 = the heap arrays are
    full: give larger ones and search again (growing them here would slow every push down).

    The best child of an expansion skips the heap when its key is <= every key in OPEN (it would
    be popped next anyway): on open ground, where f stays constant along a straight run towards the
    goal, most nodes never enter the heap. The pop order stays that of the keys, so the search is
    the same A*.
    """
    parent = nodes[0]
    stamp = nodes[1]
    expanded = nodes[2]
    offsets, row_steps, col_steps, steps = neighbour_tables(width)
    goal_row = goal // width if goal >= 0 else 0
    goal_col = goal % width if goal >= 0 else 0
    closed = generation + 1
    capacity = len(heap_key)

    g[start] = 0.0
    parent[start] = start
    stamp[start] = generation
    size = np.int64(0)  # not the literal 0: heap_pop would compile once more for Literal[int](0)
    next_node = start  # the candidate that skips the heap; -1 = none
    next_key = np.int64(0)
    searched = 0
    while True:
        if next_node >= 0:
            node = next_node
            next_node = -1
        elif size > 0:
            node, size = heap_pop(heap_key, heap_node, size)
            if stamp[np.uint64(node)] == closed:
                continue  # a stale entry left behind by a decrease-key
        else:
            return 0, searched
        here = np.uint64(node)
        stamp[here] = closed
        expanded[np.uint64(searched)] = node
        searched += 1
        if node == goal:
            return 1, searched
        g_node = g[here]
        row_offset = node // width - goal_row
        col_offset = node % width - goal_col
        allowed = moves[here]
        for k in range(8):
            if not (allowed >> k) & 1:
                continue
            neighbour = node + offsets[k]
            slot = np.uint64(neighbour)  # an unsigned index: no negative-index wraparound code
            seen = stamp[slot]
            if seen == closed:
                continue
            step = steps[k]
            if cost is not None:  # decided at compile time: None and an array compile apart
                step *= 1.0 + cost_weight * cost[slot]
            g_new = g_node + step
            if seen == generation:
                if g_new >= g[slot]:
                    continue
                g[slot] = g_new
                parent[slot] = node
                if not decrease_key:
                    continue  # plannerAStarGrid: g, f and parent change, the key in OPEN does not
            else:
                stamp[slot] = generation
                g[slot] = g_new
                parent[slot] = node
            h = heuristic_cells(row_offset + row_steps[k], col_offset + col_steps[k], heuristic) * h_scale
            key = heap_key_of(g_new + h, h, tie_breaker)
            if next_node < 0:
                if size == 0 or key <= heap_key[0]:
                    next_node = neighbour
                    next_key = key
                    continue
            elif key < next_key:
                key, next_key = next_key, key
                neighbour, next_node = next_node, neighbour
            if size == capacity:
                return -1, searched
            size = heap_push(heap_key, heap_node, size, key, neighbour)


@njit(cache=True)
def finish(
    nodes, start, goal, found, searched, width, rows, resolution, origin_x, origin_y, explored, cells, path
):
    """Write the path of a finished search and the explored mask into the caller's arrays.

    cells (int64) and path (float64) are C x 2 buffers: rows 0..N-1 get the N path cells
    (row, col) and the cell centres (x, y) [m]; explored, bool [rows, cols], gets True where a cell
    was expanded. Returns (N, length [m]); N = 0 with found False. When N > C nothing is written
    (give buffers of N rows and call again). The arrays come from the caller because returning new
    arrays from a compiled function costs ~3 us each (numba boxes them through a pickled dtype).
    """
    parent = nodes[0]
    expanded = nodes[2]
    count = 0
    if found:
        count = 1
        node = goal
        while node != start:
            node = parent[node]
            count += 1
    if count > len(cells):
        return count, 0.0
    for index in range(searched):
        node = expanded[index]
        explored[node // width - 1, node % width - 1] = True
    length = 0.0
    node = goal
    for index in range(count - 1, -1, -1):
        row = node // width - 1
        col = node % width - 1
        cells[index, 0] = row
        cells[index, 1] = col
        path[index, 0] = origin_x + (col + 0.5) * resolution
        path[index, 1] = origin_y + (rows - 1 - row + 0.5) * resolution
        previous = parent[node]
        if node != start:
            difference = abs(previous - node)
            length += resolution if difference == 1 or difference == width else SQRT2 * resolution
        node = previous
    return count, length


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


@njit(cache=True)
def astar_plan(moves, cost, integers, reals, start, goal, generation, g, nodes, heap_key, heap_node, explored,
               cells, path):  # fmt: skip
    """astar_search then finish in one compiled call (one dispatch: small maps answer in microseconds).

    integers: int64 [width, heuristic, tie breaker, decrease_key, rows]; reals: float64 [h_scale,
    cost_weight, resolution [m], origin x, origin y [m]] (kept per map and option set by the caller:
    every argument of a compiled call costs dispatch time). explored, cells, path: see finish.
    Returns (status, searched, N, length [m]): status as astar_search's, or -2 when the path has
    more than len(cells) = C cells (nothing written: search again with buffers of N rows).
    """
    width = integers[0]
    status, searched = astar_search(
        moves, width, start, goal, integers[1], reals[0], integers[2], integers[3] != 0, cost, reals[1],
        g, nodes, generation, heap_key, heap_node,
    )  # fmt: skip
    if status < 0:
        return status, searched, 0, 0.0
    count, length = finish(
        nodes, start, goal, status == 1, searched, width, integers[4], reals[2], reals[3], reals[4],
        explored, cells, path,
    )  # fmt: skip
    if count > len(cells):
        return -2, searched, count, 0.0
    return status, searched, count, length
