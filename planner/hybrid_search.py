"""The compiled hybrid A* search loop (numba).

Nodes are continuous poses (x, y, theta); the closed set is keyed on (row, col, heading bin), so
two poses in one cell with different headings are both searched (MATLAB's plannerHybridAStar
closes a whole cell per driving direction). Each popped node is expanded with every motion
primitive; every few pops, and at every pop near the goal, an obstacle-checked Reeds-Shepp (or
Dubins) curve to the goal is tried and ends the search when it is free (analytic expansion).

Compile time matters here (the first call of a process without numba's cache compiles everything
a hybrid plan uses): OPEN and the closed-set index are small array structures written here rather
than heapq on a list of tuples and a typed Dict, buffers come from the caller, and no slice
assignment (whose shape-mismatch error message pulls in numba's string formatting) is used.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.misc.quicksort import make_py_quicksort
from numba.np.numpy_support import lt_floats

from planner import dubins, reeds_shepp
from planner.hybrid_geometry import TWO_PI, point_free, segments_free, wrap_angle

FOUND_AT_GOAL = 1  # a primitive ended within the goal tolerance
FOUND_ANALYTIC = 2  # an analytic curve reached the goal exactly
EXHAUSTED = 0  # OPEN became empty: no path for this vehicle
ITERATION_CAP = -1  # max_iterations expansions without reaching the goal
TIED = -2  # an exact cost tie among analytic curves beyond the given tie orders: order it, search again
# Poses farther than this many turning radii from the goal use the Euclidean distance in place
# of the Reeds-Shepp/Dubins length in the heuristic (both are lower bounds of the path length).
CURVE_HEURISTIC_RANGE = 6.0


# numba's np.argsort (quicksort) as plain Python: the order of candidates with equal costs is
# numba's, and it is computed only when a search meets such a tie (see _analytic_expansion).
_QUICKSORT = make_py_quicksort(lt=lt_floats, is_argsort=True, is_np_array=True)


def argsort_order(costs: np.ndarray) -> np.ndarray:
    """The permutation numba's np.argsort(costs) (quicksort) returns, without compiling it."""
    return np.asarray(_QUICKSORT.run_quicksort(np.array(costs, dtype=np.float64)), dtype=np.int64)


@njit(cache=True, inline="always")
def _cell(x, y, resolution, origin_x, origin_y, rows):
    col = int(math.floor((x - origin_x) / resolution))
    row = rows - 1 - int(math.floor((y - origin_y) / resolution))
    return row, col


@njit(cache=True, inline="always")
def _state_key(row, col, theta, cols, heading_bins):
    """Closed-set key of (row, col, heading bin); bins are centred on multiples of 2pi/bins."""
    heading_bin = int(round((theta % TWO_PI) / (TWO_PI / heading_bins))) % heading_bins
    return (row * cols + col) * heading_bins + heading_bin


@njit(cache=True)
def curve_length_to_goal(x, y, theta, goal, radius, forward_only, letters, lengths):
    """Obstacle-free Reeds-Shepp (forward_only None: reverse allowed) or Dubins (forward_only True)
    length [m] from a pose to the goal; letters, lengths: the candidate buffers of the scratch."""
    nx, ny, nphi = reeds_shepp.normalize(x, y, theta, goal[0], goal[1], goal[2], radius)
    if forward_only is None:
        return reeds_shepp.shortest_length_normalized(nx, ny, nphi, letters, lengths) * radius
    return dubins.shortest_length_normalized(nx, ny, nphi, letters, lengths) * radius


@njit(cache=True)
def _heuristic(
    x, y, theta, goal, distance_grid, resolution, origin_x, origin_y, radius, forward_only, scratch
):
    rows, cols = distance_grid.shape
    row, col = _cell(x, y, resolution, origin_x, origin_y, rows)
    if row < 0 or row >= rows or col < 0 or col >= cols:
        return np.inf
    distance = distance_grid[row, col]
    euclidean = math.hypot(goal[0] - x, goal[1] - y)
    if euclidean > CURVE_HEURISTIC_RANGE * radius:
        # Far from the goal the curve length is the Euclidean distance plus a few radii, which
        # the obstacle-aware distance almost always exceeds; the curve costs ~15 us, so skip it.
        return max(distance, euclidean)
    letters, lengths = scratch[0], scratch[1]
    return max(distance, curve_length_to_goal(x, y, theta, goal, radius, forward_only, letters, lengths))


# Closed-set index: open addressing on int64 state keys (-1 = empty slot), grown at half load.
_INDEX_START = 1 << 12
_HASH = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: spreads consecutive keys


@njit(cache=True)
def _index_new(capacity):
    keys = np.empty(capacity, dtype=np.int64)
    for slot in range(capacity):
        keys[slot] = -1
    return keys, np.empty(capacity, dtype=np.int64)


@njit(cache=True, inline="always")
def _index_slot(keys, key):
    """The slot holding `key`, or the empty slot where it belongs."""
    mask = np.uint64(len(keys) - 1)
    slot = (np.uint64(key) * _HASH >> np.uint64(20)) & mask
    while keys[slot] != -1 and keys[slot] != key:
        slot = (slot + np.uint64(1)) & mask
    return slot


@njit(cache=True)
def _index_grown(keys, values):
    """The index rehashed into twice the slots."""
    new_keys, new_values = _index_new(2 * len(keys))
    for slot in range(len(keys)):
        if keys[slot] != -1:
            target = _index_slot(new_keys, keys[slot])
            new_keys[target] = keys[slot]
            new_values[target] = values[slot]
    return new_keys, new_values


@njit(cache=True, inline="always")
def _before(f_a, h_a, node_a, f_b, h_b, node_b):
    """(f, h, node) of a orders before that of b: by f, then h, then node (which is unique)."""
    if f_a != f_b:
        return f_a < f_b
    if h_a != h_b:
        return h_a < h_b
    return node_a < node_b


@njit(cache=True)
def _heap_push(heap_f, heap_h, heap_node, size, f, h, node):
    """Push onto the binary min-heap of (f, h, node); returns the new size. The order is total
    (nodes are unique), so the pops come in the same order as from any other priority queue."""
    index = size
    while index > 0:
        parent = (index - 1) >> 1
        if not _before(f, h, node, heap_f[parent], heap_h[parent], heap_node[parent]):
            break
        heap_f[index] = heap_f[parent]
        heap_h[index] = heap_h[parent]
        heap_node[index] = heap_node[parent]
        index = parent
    heap_f[index] = f
    heap_h[index] = h
    heap_node[index] = node
    return size + 1


@njit(cache=True)
def _heap_pop(heap_f, heap_h, heap_node, size):
    """Remove the smallest entry; returns (its node, the new size)."""
    top = heap_node[0]
    size -= 1
    f, h, node = heap_f[size], heap_h[size], heap_node[size]
    index = 0
    while True:
        child = 2 * index + 1
        if child >= size:
            break
        if child + 1 < size and _before(
            heap_f[child + 1],
            heap_h[child + 1],
            heap_node[child + 1],
            heap_f[child],
            heap_h[child],
            heap_node[child],
        ):
            child += 1
        if not _before(heap_f[child], heap_h[child], heap_node[child], f, h, node):
            break
        heap_f[index] = heap_f[child]
        heap_h[index] = heap_h[child]
        heap_node[index] = heap_node[child]
        index = child
    heap_f[index] = f
    heap_h[index] = h
    heap_node[index] = node
    return top, size


@njit(cache=True)
def _analytic_expansion(
    x, y, theta, direction, goal, radius, forward_only, reverse_cost, steering_cost, switch_cost,
    occupied, resolution, origin_x, origin_y, collision_step, exact_ties, scratch, out_curvature, out_length,
):  # fmt: skip
    """Cheapest collision-free curve to the goal; writes its segments, returns (count, cost).

    Candidates are tried cheapest first, in the order numba's np.argsort gives: mirror-image curves
    (a goal right behind, facing back) cost exactly the same, and the order decides which of them
    is taken. exact_ties None: distinct costs have one order, found here by insertion; an exact tie
    takes the caller's order (tie_orders[t] for the t-th tie of this search, t < ties[0]; ties[1]
    counts them) or, beyond those, returns -count (TIED: the caller orders costs[:count] as
    np.argsort does and searches again, which meets the same ties in the same order). np.argsort
    is compiled only with exact_ties True (for a search that meets many ties): its quicksort costs
    about as much compile time as the rest of this function.
    scratch: (letters int64 [K, 5], lengths [K, 5], costs [K], order int64 [K], curvatures [5],
    signed lengths [5], tie_orders int64 [T, K], ties int64 [2]) with K >= reeds_shepp.MAX_CANDIDATES;
    the letter and length buffers start zeroed (a Dubins word fills 3 of the 5 columns)."""
    letters, lengths, costs, order, curvatures, signed, tie_orders, ties = scratch
    nx, ny, nphi = reeds_shepp.normalize(x, y, theta, goal[0], goal[1], goal[2], radius)
    if forward_only is None:
        count = reeds_shepp.enumerate_normalized(nx, ny, nphi, letters, lengths)
    else:
        count = dubins.enumerate_normalized(nx, ny, nphi, letters, lengths)
    for k in range(count):
        cost = 0.0
        previous = direction
        for j in range(5):
            length = lengths[k, j] * radius
            if length == 0.0:
                continue
            sign = 1 if length > 0.0 else -1
            multiplier = reverse_cost if sign < 0 else 1.0
            if letters[k, j] != 0:
                multiplier *= 1.0 + steering_cost
            cost += abs(length) * multiplier
            if previous != 0 and sign != previous:
                cost += switch_cost
            previous = sign
        costs[k] = cost
    if exact_ties is None:
        # Cheapest first by insertion (a few dozen candidates).
        for k in range(count):
            position = k
            while position > 0 and costs[order[position - 1]] > costs[k]:
                order[position] = order[position - 1]
                position -= 1
            if position > 0 and costs[order[position - 1]] == costs[k]:
                tie = ties[1]
                ties[1] = tie + 1
                if tie >= ties[0]:
                    return -count, 0.0
                for rank in range(count):
                    order[rank] = tie_orders[tie, rank]
                break
            order[position] = k
    else:
        sorted_order = np.argsort(costs[:count])
        for rank in range(count):
            order[rank] = sorted_order[rank]
    for rank in range(count):
        k = order[rank]
        for j in range(5):
            curvatures[j] = letters[k, j] / radius
            signed[j] = lengths[k, j] * radius
        if segments_free(
            occupied, resolution, origin_x, origin_y, x, y, theta, curvatures, signed, 5, collision_step
        ):
            for j in range(5):
                out_curvature[j] = curvatures[j]
                out_length[j] = signed[j]
            return 5, costs[k]
    return 0, np.inf


@njit(cache=True)
def hybrid_search(
    occupied, resolution, origin_x, origin_y, distance_grid, start, goal,
    prim_curvature, prim_cost, prim_direction, prim_samples, prim_sample_count,
    heading_bins, radius, forward_only, reverse_cost, steering_cost, switch_cost,
    analytic_interval, analytic_distance, goal_tolerance, heading_tolerance, collision_step, exact_ties,
    max_iterations, node_x, node_y, node_theta, node_g, node_parent, node_primitive, node_direction,
    closed, heap_f, heap_h, heap_node, scratch, explored, analytic_curvature, analytic_length,
):  # fmt: skip
    """Run hybrid A* from `start` to `goal` (x, y, theta).

    forward_only: None when the car may reverse (Reeds-Shepp curves), True when it may not
    (Dubins); exact_ties: see _analytic_expansion. None rather than False in both: numba drops an
    `is None` branch at compile time, so a search compiles only the curves and the sort it uses.
    Node arrays (node_*, closed (False), heap_*) have room for max_iterations x P + 1 nodes;
    scratch: see _analytic_expansion. Returns (status, final node, expanded nodes, analytic segment
    count (TIED: the number of candidates, whose costs are in scratch[2]), analytic cost); the path
    is the parent chain of the final node followed by the analytic segments (if any).
    """
    rows, cols = occupied.shape
    primitives = len(prim_cost)
    # (cell, heading bin) -> best node. np.int64 here and below, not literals: a Literal[int]
    # argument compiles a function once more.
    index_keys, index_nodes = _index_new(np.int64(_INDEX_START))

    node_x[0], node_y[0], node_theta[0] = start[0], start[1], start[2]
    node_g[0] = 0.0
    node_parent[0] = -1
    node_primitive[0] = -1
    node_direction[0] = 0
    nodes = np.int64(1)
    h = _heuristic(
        start[0],
        start[1],
        start[2],
        goal,
        distance_grid,
        resolution,
        origin_x,
        origin_y,
        radius,
        forward_only,
        scratch,
    )
    size = _heap_push(heap_f, heap_h, heap_node, np.int64(0), h, h, np.int64(0))
    row, col = _cell(start[0], start[1], resolution, origin_x, origin_y, rows)
    key = _state_key(row, col, start[2], cols, heading_bins)
    slot = _index_slot(index_keys, key)
    index_keys[slot] = key
    index_nodes[slot] = 0
    indexed = 1
    expanded = 0
    while size > 0:
        node, size = _heap_pop(heap_f, heap_h, heap_node, size)
        if closed[node]:
            continue
        x, y, theta = node_x[node], node_y[node], node_theta[node]
        row, col = _cell(x, y, resolution, origin_x, origin_y, rows)
        key = _state_key(row, col, theta, cols, heading_bins)
        if index_nodes[_index_slot(index_keys, key)] != node:
            continue  # a cheaper pose took over this (cell, heading bin) after this one was pushed
        closed[node] = True
        explored[row, col] = True
        expanded += 1
        distance = math.hypot(x - goal[0], y - goal[1])
        if distance <= goal_tolerance and abs(wrap_angle(theta - goal[2])) <= heading_tolerance:
            return FOUND_AT_GOAL, node, expanded, 0, 0.0
        if analytic_interval > 0 and (
            expanded == 1 or expanded % analytic_interval == 0 or distance <= analytic_distance
        ):
            count, cost = _analytic_expansion(
                x, y, theta, node_direction[node], goal, radius, forward_only, reverse_cost, steering_cost,
                switch_cost, occupied, resolution, origin_x, origin_y, collision_step, exact_ties, scratch,
                analytic_curvature, analytic_length,
            )  # fmt: skip
            if count > 0:
                return FOUND_ANALYTIC, node, expanded, count, node_g[node] + cost
            if count < 0:
                return TIED, node, expanded, -count, 0.0
        if expanded >= max_iterations:
            return ITERATION_CAP, node, expanded, 0, 0.0
        cos_t, sin_t = math.cos(theta), math.sin(theta)
        for p in range(primitives):
            free = True
            for s in range(prim_sample_count[p]):
                sx = x + cos_t * prim_samples[p, s, 0] - sin_t * prim_samples[p, s, 1]
                sy = y + sin_t * prim_samples[p, s, 0] + cos_t * prim_samples[p, s, 1]
                if not point_free(occupied, resolution, origin_x, origin_y, sx, sy):
                    free = False
                    break
            if not free:
                continue
            last = prim_sample_count[p] - 1
            new_x = x + cos_t * prim_samples[p, last, 0] - sin_t * prim_samples[p, last, 1]
            new_y = y + sin_t * prim_samples[p, last, 0] + cos_t * prim_samples[p, last, 1]
            new_theta = wrap_angle(theta + prim_samples[p, last, 2])
            new_row, new_col = _cell(new_x, new_y, resolution, origin_x, origin_y, rows)
            new_key = _state_key(new_row, new_col, new_theta, cols, heading_bins)
            new_g = node_g[node] + prim_cost[p]
            if node_direction[node] != 0 and prim_direction[p] != node_direction[node]:
                new_g += switch_cost
            slot = _index_slot(index_keys, new_key)
            if index_keys[slot] == new_key:
                other = index_nodes[slot]
                if closed[other] or node_g[other] <= new_g:
                    continue
            h = _heuristic(
                new_x,
                new_y,
                new_theta,
                goal,
                distance_grid,
                resolution,
                origin_x,
                origin_y,
                radius,
                forward_only,
                scratch,
            )
            if h == np.inf:
                continue
            node_x[nodes], node_y[nodes], node_theta[nodes] = new_x, new_y, new_theta
            node_g[nodes] = new_g
            node_parent[nodes] = node
            node_primitive[nodes] = p
            node_direction[nodes] = prim_direction[p]
            if index_keys[slot] != new_key:
                index_keys[slot] = new_key
                indexed += 1
            index_nodes[slot] = nodes
            if 2 * indexed > len(index_keys):
                index_keys, index_nodes = _index_grown(index_keys, index_nodes)
            size = _heap_push(heap_f, heap_h, heap_node, size, new_g + h, h, nodes)
            nodes += 1
    return EXHAUSTED, -1, expanded, 0, 0.0
