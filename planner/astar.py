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

# The search's settings travel in one float64 array (every argument of a compiled call costs
# dispatch time); the index of each entry:
PARAMETERS = (
    "width",  # padded columns, cols + 2
    "heuristic",  # HEURISTICS code
    "tie_breaker",  # TIE_BREAKERS code
    "decrease_key",  # 1.0 or 0.0
    "h_scale",  # multiplier of h: heuristic_weight (x 1.07 for the "matlab" tie breaker)
    "cost_weight",  # weight of the cost gradient
    "rows",
    "cols",
    "resolution",  # [m/cell]
    "origin_x",  # [m]
    "origin_y",  # [m]
)
P_WIDTH, P_HEURISTIC, P_TIE, P_DECREASE, P_H_SCALE, P_COST_WEIGHT = range(6)
P_ROWS, P_COLS, P_RESOLUTION, P_ORIGIN_X, P_ORIGIN_Y = range(6, 11)

# The cost argument of a search without a cost gradient (cost_weight 0: never read). An array rather
# than None so that every search is one compiled specialisation: None and an array compiled apart,
# and a run that replans with the cost gradient compiled the whole search twice on a cold cache.
NO_COST = np.zeros(1)

# Status codes of astar_search / astar_plan.
FOUND, NO_PATH, HEAP_FULL, ROUTE_FULL, BAD_START, BAD_GOAL = 1, 0, -1, -2, -3, -4


def search_parameters(
    width: int,
    heuristic: int,
    tie_breaker: int,
    decrease_key: bool,
    h_scale: float,
    cost_weight: float,
    rows: int = 0,
    cols: int = 0,
    resolution: float = 1.0,
    origin: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """The PARAMETERS array of astar_search / astar_plan."""
    return np.array(
        [width, heuristic, tie_breaker, float(decrease_key), h_scale, cost_weight, rows, cols, resolution,
         origin[0], origin[1]],
        dtype=np.float64,
    )  # fmt: skip


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
def heap_pop(heap_key, heap_node, size):
    """Remove the top of the heap; returns (node, new size).

    The hole left at the root sinks to the bottom along the smallest children, then the last entry
    rises into it from there while its parent's key is >= its own: the same place as sifting the
    last entry down from the root would give (the keys along that path only grow), with one test
    per level fewer. Of four children the first smallest is chosen by a branch-free tournament
    (pairs, then the pair winners, the earlier on ties): which child wins is data-dependent, so
    branches there were mispredicted at about every level (~12 % of the search time).
    Inlined (numba IR) into the search: as a called function it cost ~5 % more."""
    top = heap_node[0]
    size -= 1
    key = heap_key[np.uint64(size)]
    node = heap_node[np.uint64(size)]
    index = 0
    while True:
        first = 4 * index + 1
        if first + 3 < size:
            slot = np.uint64(first)
            key0 = heap_key[slot]
            key1 = heap_key[slot + np.uint64(1)]
            key2 = heap_key[slot + np.uint64(2)]
            key3 = heap_key[slot + np.uint64(3)]
            child_a = first + 1 if key1 < key0 else first
            key_a = key1 if key1 < key0 else key0
            child_b = first + 3 if key3 < key2 else first + 2
            key_b = key3 if key3 < key2 else key2
            child = child_b if key_b < key_a else child_a
            smallest = key_b if key_b < key_a else key_a
        elif first < size:
            child = first
            smallest = heap_key[np.uint64(first)]
            for other in range(first + 1, size):
                candidate = heap_key[np.uint64(other)]
                if candidate < smallest:
                    smallest = candidate
                    child = other
        else:
            break
        slot = np.uint64(index)
        heap_key[slot] = smallest
        heap_node[slot] = heap_node[np.uint64(child)]
        index = child
    while index > 0:
        parent = (index - 1) >> 2
        parent_key = heap_key[np.uint64(parent)]
        if parent_key < key:
            break
        slot = np.uint64(index)
        heap_key[slot] = parent_key
        heap_node[slot] = heap_node[np.uint64(parent)]
        index = parent
    slot = np.uint64(index)
    heap_key[slot] = key
    heap_node[slot] = node
    return top, size


@njit(cache=True, inline="always")
def heap_key_of(f, h, tie_breaker):
    """One int64 key: f on a 2^-24 cell grid in the high bits, h (quarter cells) below for low_h ties."""
    key = np.int64(f * _F_SCALE + 0.5) << _H_BITS
    if tie_breaker == 2:
        key += min(np.int64(h * _H_SCALE + 0.5), _H_MAX)
    return key


@njit(cache=True, inline="always")
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
def astar_search(moves, cost, parameters, start, goal, generation, g, nodes, heap):
    """A* (or Dijkstra with heuristic 5 and goal -1) on a padded flat grid.

    moves: uint8 per padded cell, bit k set when move k (neighbour_tables order) leaves the cell
    (planner.searchspace.SearchMap.moves: connectivity, corner rule and untrusted points are in it,
    so the loop tests one bit per neighbour). cost: the padded cost gradient, or NO_COST when the
    cost weight is 0 (then it is never read).
    parameters: PARAMETERS. nodes: int32 [3, size] = parent, stamp, and the expanded nodes in the
    order they were closed. heap: int64 [2, capacity], keys and nodes of OPEN.
    Returns (status, number of expanded nodes): FOUND, NO_PATH (OPEN ran empty; with goal == -1,
    the Dijkstra mode, this is the normal end) or HEAP_FULL (give larger heap arrays and search
    again: growing them here would slow every push down).

    The best child of an expansion skips the heap when its key is <= every key in OPEN (it would
    be popped next anyway): on open ground, where f stays constant along a straight run towards the
    goal, most nodes never enter the heap. The pop order stays that of the keys, so the search is
    the same A*.
    """
    width = np.int64(parameters[P_WIDTH])
    heuristic = np.int64(parameters[P_HEURISTIC])
    tie_breaker = np.int64(parameters[P_TIE])
    decrease_key = parameters[P_DECREASE] != 0.0
    h_scale = parameters[P_H_SCALE]
    cost_weight = parameters[P_COST_WEIGHT]
    weighted = cost_weight != 0.0
    parent = nodes[0]
    stamp = nodes[1]
    expanded = nodes[2]
    heap_key = heap[0]
    heap_node = heap[1]
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
            return NO_PATH, searched
        here = np.uint64(node)
        stamp[here] = closed
        expanded[np.uint64(searched)] = node
        searched += 1
        if node == goal:
            return FOUND, searched
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
            if weighted:
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
                return HEAP_FULL, searched
            size = heap_push(heap_key, heap_node, size, key, neighbour)


@njit(cache=True, inline="always")
def endpoint_node(blocked, parameters, x, y):
    """Padded node of the cell that contains (x, y) [m], or -1 when that is outside the map, not a
    number, or a blocked cell (obstacle, inflated, border). Same arithmetic as
    OccupancyGrid.world_to_cell, so both agree on every point."""
    resolution = parameters[P_RESOLUTION]
    # np.floor keeps a float, so a huge or NaN coordinate fails the range test below instead of
    # overflowing an integer conversion.
    column = np.floor((x - parameters[P_ORIGIN_X]) / resolution)
    row_from_bottom = np.floor((y - parameters[P_ORIGIN_Y]) / resolution)
    rows = parameters[P_ROWS]
    if not (0.0 <= column < parameters[P_COLS] and 0.0 <= row_from_bottom < rows):
        return -1  # also NaN, which fails every comparison
    node = (np.int64(rows) - np.int64(row_from_bottom)) * np.int64(parameters[P_WIDTH]) + np.int64(column) + 1
    if blocked[node] == BLOCKED:
        return -1
    return node


@njit(cache=True)
def astar_plan(moves, blocked, cost, parameters, start_x, start_y, goal_x, goal_y, generation, g, nodes, heap,
               path, cells):  # fmt: skip
    """A query in one compiled call (one dispatch: small maps answer in microseconds): the endpoint
    cells of (start_x, start_y) and (goal_x, goal_y) [m], astar_search, and the path.

    path (float64) and cells (int64): C x 2 buffers; rows 0..N-1 get the path's cell centres (x, y)
    [m] and its cells (row, col). Returns (status, searched, N, length [m]): status as
    astar_search's, or ROUTE_FULL when the path has more than C cells (search again with buffers of
    N rows), BAD_START / BAD_GOAL when that endpoint is outside the map or blocked (the caller says
    which and why). The buffers come from the caller because returning new arrays from a compiled
    function costs ~3 us each (numba boxes them through a pickled dtype).
    """
    start = endpoint_node(blocked, parameters, start_x, start_y)
    if start < 0:
        return BAD_START, 0, 0, 0.0
    goal = endpoint_node(blocked, parameters, goal_x, goal_y)
    if goal < 0:
        return BAD_GOAL, 0, 0, 0.0
    status, searched = astar_search(moves, cost, parameters, start, goal, generation, g, nodes, heap)
    if status != FOUND:
        return status, searched, 0, 0.0
    parent = nodes[0]
    count = 1
    node = goal
    while node != start:
        node = parent[node]
        count += 1
    if count > len(path):
        return ROUTE_FULL, searched, count, 0.0
    width = np.int64(parameters[P_WIDTH])
    rows = parameters[P_ROWS]
    resolution = parameters[P_RESOLUTION]
    origin_x = parameters[P_ORIGIN_X]
    origin_y = parameters[P_ORIGIN_Y]
    length = 0.0
    node = goal
    for index in range(count - 1, -1, -1):
        row = node // width - 1
        col = node % width - 1
        path[index, 0] = origin_x + (col + 0.5) * resolution
        path[index, 1] = origin_y + (rows - 1 - row + 0.5) * resolution
        cells[index, 0] = row
        cells[index, 1] = col
        previous = parent[node]
        if node != start:
            difference = abs(previous - node)
            length += resolution if difference == 1 or difference == width else SQRT2 * resolution
        node = previous
    return FOUND, searched, count, length
