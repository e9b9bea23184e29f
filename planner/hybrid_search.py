"""The compiled hybrid A* search loop (numba).

Nodes are continuous poses (x, y, theta); the closed set is keyed on (row, col, heading bin), so
two poses in one cell with different headings are both searched (MATLAB's plannerHybridAStar
closes a whole cell per driving direction). Each popped node is expanded with every motion
primitive; every few pops, and at every pop near the goal, an obstacle-checked Reeds-Shepp (or
Dubins) curve to the goal is tried and ends the search when it is free (analytic expansion).
"""

from __future__ import annotations

import heapq
import math

import numpy as np
from numba import njit, types
from numba.typed import Dict

from planner import dubins, reeds_shepp
from planner.hybrid_geometry import TWO_PI, point_free, segments_free, wrap_angle

FOUND_AT_GOAL = 1  # a primitive ended within the goal tolerance
FOUND_ANALYTIC = 2  # an analytic curve reached the goal exactly
EXHAUSTED = 0  # OPEN became empty: no path for this vehicle
ITERATION_CAP = -1  # max_iterations expansions without reaching the goal
# Poses farther than this many turning radii from the goal use the Euclidean distance in place
# of the Reeds-Shepp/Dubins length in the heuristic (both are lower bounds of the path length).
CURVE_HEURISTIC_RANGE = 6.0


@njit(cache=True)
def _cell(x, y, resolution, origin_x, origin_y, rows):
    col = int(math.floor((x - origin_x) / resolution))
    row = rows - 1 - int(math.floor((y - origin_y) / resolution))
    return row, col


@njit(cache=True)
def _state_key(row, col, theta, cols, heading_bins):
    """Closed-set key of (row, col, heading bin); bins are centred on multiples of 2pi/bins."""
    heading_bin = int(round((theta % TWO_PI) / (TWO_PI / heading_bins))) % heading_bins
    return (row * cols + col) * heading_bins + heading_bin


@njit(cache=True)
def curve_length_to_goal(x, y, theta, goal, radius, reverse):
    """Obstacle-free Reeds-Shepp (reverse allowed) or Dubins length [m] from a pose to the goal."""
    nx, ny, nphi = reeds_shepp.normalize(x, y, theta, goal[0], goal[1], goal[2], radius)
    if reverse:
        return reeds_shepp.shortest_length_normalized(nx, ny, nphi) * radius
    return dubins.shortest_length_normalized(nx, ny, nphi) * radius


@njit(cache=True)
def _heuristic(x, y, theta, goal, distance_grid, resolution, origin_x, origin_y, radius, reverse):
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
    return max(distance, curve_length_to_goal(x, y, theta, goal, radius, reverse))


@njit(cache=True)
def _analytic_expansion(
    x, y, theta, direction, goal, radius, reverse, reverse_cost, steering_cost, switch_cost,
    occupied, resolution, origin_x, origin_y, collision_step, out_curvature, out_length,
):  # fmt: skip
    """Cheapest collision-free curve to the goal; writes its segments, returns (count, cost)."""
    nx, ny, nphi = reeds_shepp.normalize(x, y, theta, goal[0], goal[1], goal[2], radius)
    letters = np.zeros((reeds_shepp.MAX_CANDIDATES, 5), dtype=np.int64)
    lengths = np.zeros((reeds_shepp.MAX_CANDIDATES, 5))
    if reverse:
        count = reeds_shepp.enumerate_normalized(nx, ny, nphi, letters, lengths)
    else:
        count = dubins.enumerate_normalized(nx, ny, nphi, letters[:, :3], lengths[:, :3])
    costs = np.empty(count)
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
    curvatures = np.empty(5)
    signed = np.empty(5)
    for k in np.argsort(costs):
        for j in range(5):
            curvatures[j] = letters[k, j] / radius
            signed[j] = lengths[k, j] * radius
        if segments_free(
            occupied, resolution, origin_x, origin_y, x, y, theta, curvatures, signed, 5, collision_step
        ):
            out_curvature[:] = curvatures
            out_length[:] = signed
            return 5, costs[k]
    return 0, np.inf


@njit(cache=True)
def hybrid_search(
    occupied, resolution, origin_x, origin_y, distance_grid, start, goal,
    prim_curvature, prim_cost, prim_direction, prim_samples, prim_sample_count,
    heading_bins, radius, reverse, reverse_cost, steering_cost, switch_cost,
    analytic_interval, analytic_distance, goal_tolerance, heading_tolerance, collision_step,
    max_iterations, node_x, node_y, node_theta, node_g, node_parent, node_primitive, node_direction,
    explored, analytic_curvature, analytic_length,
):  # fmt: skip
    """Run hybrid A* from `start` to `goal` (x, y, theta).

    Node arrays are preallocated with room for max_iterations x P + 1 nodes. Returns
    (status, final node, expanded nodes, analytic segment count, analytic cost); the path is
    the parent chain of the final node followed by the analytic segments (if any).
    """
    rows, cols = occupied.shape
    primitives = len(prim_cost)
    best_node = Dict.empty(key_type=types.int64, value_type=types.int64)
    closed = np.zeros(len(node_g), dtype=np.bool_)

    node_x[0], node_y[0], node_theta[0] = start[0], start[1], start[2]
    node_g[0] = 0.0
    node_parent[0] = -1
    node_primitive[0] = -1
    node_direction[0] = 0
    nodes = 1
    h = _heuristic(
        start[0], start[1], start[2], goal, distance_grid, resolution, origin_x, origin_y, radius, reverse
    )
    heap = [(h, h, 0)]
    row, col = _cell(start[0], start[1], resolution, origin_x, origin_y, rows)
    best_node[_state_key(row, col, start[2], cols, heading_bins)] = 0
    expanded = 0
    while len(heap) > 0:
        _, _, node = heapq.heappop(heap)
        if closed[node]:
            continue
        x, y, theta = node_x[node], node_y[node], node_theta[node]
        row, col = _cell(x, y, resolution, origin_x, origin_y, rows)
        key = _state_key(row, col, theta, cols, heading_bins)
        if best_node[key] != node:
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
                x, y, theta, node_direction[node], goal, radius, reverse, reverse_cost, steering_cost,
                switch_cost, occupied, resolution, origin_x, origin_y, collision_step,
                analytic_curvature, analytic_length,
            )  # fmt: skip
            if count > 0:
                return FOUND_ANALYTIC, node, expanded, count, node_g[node] + cost
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
            if new_key in best_node:
                other = best_node[new_key]
                if closed[other] or node_g[other] <= new_g:
                    continue
            h = _heuristic(
                new_x, new_y, new_theta, goal, distance_grid, resolution, origin_x, origin_y, radius, reverse
            )
            if h == np.inf:
                continue
            node_x[nodes], node_y[nodes], node_theta[nodes] = new_x, new_y, new_theta
            node_g[nodes] = new_g
            node_parent[nodes] = node
            node_primitive[nodes] = p
            node_direction[nodes] = prim_direction[p]
            best_node[new_key] = nodes
            heapq.heappush(heap, (new_g + h, h, nodes))
            nodes += 1
    return EXHAUSTED, -1, expanded, 0, 0.0
