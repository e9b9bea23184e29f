"""The hybrid A* search loop, in C (`planner/native/hybrid.c`, hy_search), and its Python entry.

Nodes are continuous poses (x, y, theta); the closed set is keyed on (row, col, heading bin), so
two poses in one cell with different headings are both searched (MATLAB's plannerHybridAStar
closes a whole cell per driving direction). Each popped node is expanded with every motion
primitive; every few pops, and at every pop near the goal, an obstacle-checked Reeds-Shepp (or
Dubins) curve to the goal is tried and ends the search when it is free (analytic expansion).

Candidate curves are tried cheapest first; curves of exactly equal cost (mirror images: a goal
right behind, facing back) in the order they were enumerated (hy_argsort is a stable sort).
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np

from planner.hybrid_geometry import library
from planner.hybrid_primitives import Primitives

FOUND_AT_GOAL = 1  # a primitive ended within the goal tolerance
FOUND_ANALYTIC = 2  # an analytic curve reached the goal exactly
EXHAUSTED = 0  # OPEN became empty: no path for this vehicle
ITERATION_CAP = -1  # max_iterations expansions without reaching the goal
NO_MEMORY = -3  # the closed-set index could not grow (malloc failed)

_P = ctypes.c_void_p
_I = ctypes.c_int64
_D = ctypes.c_double


class _Search(ctypes.Structure):
    """HySearch of hybrid.c: the inputs, buffers and results of one search."""

    _fields_ = [
        ("occupied", _P), ("rows", _I), ("cols", _I),
        ("resolution", _D), ("origin_x", _D), ("origin_y", _D),
        ("distance", _P), ("start", _D * 3), ("goal", _D * 3),
        ("prim_cost", _P), ("prim_direction", _P), ("prim_samples", _P), ("prim_sample_count", _P),
        ("primitives", _I), ("max_samples", _I),
        ("heading_bins", _I), ("radius", _D), ("forward_only", _I),
        ("reverse_cost", _D), ("steering_cost", _D), ("switch_cost", _D),
        ("analytic_interval", _I),
        ("analytic_distance", _D), ("goal_tolerance", _D), ("heading_tolerance", _D), ("collision_step", _D),
        ("max_iterations", _I),
        ("node_x", _P), ("node_y", _P), ("node_theta", _P), ("node_g", _P),
        ("node_parent", _P), ("node_primitive", _P), ("node_direction", _P),
        ("closed", _P), ("heap_f", _P), ("heap_h", _P), ("heap_node", _P),
        ("explored", _P),
        ("status", _I), ("final_node", _I), ("expanded", _I), ("analytic_count", _I),
        ("analytic_cost", _D), ("analytic_curvature", _D * 5), ("analytic_length", _D * 5),
    ]  # fmt: skip


@dataclass(frozen=True)
class SearchOutcome:
    """What hybrid_search found.

    status: FOUND_AT_GOAL, FOUND_ANALYTIC, EXHAUSTED or ITERATION_CAP.
    final: the last node (-1 when EXHAUSTED); the path is its parent chain (node_parent,
        node_primitive: the primitive that reached each node), then the analytic segments.
    expanded: nodes expanded. explored: rows x cols bool, the cells of expanded nodes.
    analytic_count: segments of the analytic curve (0 or 5), analytic_curvature [1/m] and
        analytic_length [m, signed] (5 each), analytic_cost: the path's cost g + curve cost.
    """

    status: int
    final: int
    expanded: int
    node_parent: np.ndarray
    node_primitive: np.ndarray
    explored: np.ndarray
    analytic_count: int
    analytic_curvature: np.ndarray
    analytic_length: np.ndarray
    analytic_cost: float


def argsort_order(costs: np.ndarray) -> np.ndarray:
    """The order in which candidates of these costs are tried: increasing cost, exact ties in index
    order (a stable sort)."""
    values = np.ascontiguousarray(costs, dtype=np.float64).ravel()
    order = np.empty(len(values), dtype=np.int64)
    library().hy_argsort(values.ctypes.data, len(values), order.ctypes.data)
    return order


def _array(values, dtype, shape=None) -> np.ndarray:
    array = np.ascontiguousarray(values, dtype=dtype)
    if shape is not None and array.shape != shape:
        raise ValueError(f"hybrid_search: an array of shape {array.shape} where {shape} is needed")
    return array


def hybrid_search(
    occupied, resolution, origin_x, origin_y, distance_grid, start, goal, primitives: Primitives,
    heading_bins, radius, forward_only, reverse_cost, steering_cost, switch_cost,
    analytic_interval, analytic_distance, goal_tolerance, heading_tolerance, collision_step, max_iterations,
) -> SearchOutcome:  # fmt: skip
    """Run hybrid A* from `start` to `goal` (x, y, theta) on the (inflated) grid `occupied`, with the
    obstacle-aware heuristic `distance_grid` [m] (same shape) and the motion `primitives`.

    forward_only: False when the car may reverse (Reeds-Shepp curves), True when it may not (Dubins).
    The node arrays have room for max_iterations x P + 1 nodes: np.empty and np.zeros only reserve
    memory, pages are touched as the search reaches them.
    """
    occupied = _array(occupied, bool)
    if occupied.ndim != 2:
        raise ValueError("hybrid_search needs a 2-D occupancy grid")
    distances = _array(distance_grid, np.float64, occupied.shape)
    cost = _array(primitives.cost, np.float64)
    count = len(cost)
    direction = _array(primitives.direction, np.int64, (count,))
    samples = _array(primitives.samples, np.float64)
    sample_count = _array(primitives.sample_count, np.int64, (count,))
    if samples.ndim != 3 or samples.shape[0] != count or samples.shape[2] != 3:
        raise ValueError("hybrid_search: primitive samples must be P x M x 3")
    if count and not (1 <= sample_count.min() and sample_count.max() <= samples.shape[1]):
        raise ValueError("hybrid_search: primitive sample counts must lie in 1..M")
    max_iterations = int(max_iterations)
    capacity = max_iterations * count + 1
    node_x, node_y, node_theta, node_g, heap_f, heap_h = (np.empty(capacity) for _ in range(6))
    node_parent, node_primitive, node_direction, heap_node = (
        np.empty(capacity, dtype=np.int64) for _ in range(4)
    )
    closed = np.zeros(capacity, dtype=bool)
    explored = np.zeros(occupied.shape, dtype=bool)
    rows, cols = occupied.shape
    search = _Search(
        occupied.ctypes.data, rows, cols, float(resolution), float(origin_x), float(origin_y),
        distances.ctypes.data, (_D * 3)(*map(float, start)), (_D * 3)(*map(float, goal)),
        cost.ctypes.data, direction.ctypes.data, samples.ctypes.data, sample_count.ctypes.data,
        count, samples.shape[1],
        int(heading_bins), float(radius), 1 if forward_only else 0,
        float(reverse_cost), float(steering_cost), float(switch_cost),
        int(analytic_interval),
        float(analytic_distance), float(goal_tolerance), float(heading_tolerance), float(collision_step),
        max_iterations,
        node_x.ctypes.data, node_y.ctypes.data, node_theta.ctypes.data, node_g.ctypes.data,
        node_parent.ctypes.data, node_primitive.ctypes.data, node_direction.ctypes.data,
        closed.ctypes.data, heap_f.ctypes.data, heap_h.ctypes.data, heap_node.ctypes.data,
        explored.ctypes.data,
    )  # fmt: skip
    status = library().hy_search(ctypes.byref(search))
    if status == NO_MEMORY:
        raise MemoryError("hybrid A*: out of memory for the closed-set index")
    return SearchOutcome(
        status=int(status),
        final=int(search.final_node),
        expanded=int(search.expanded),
        node_parent=node_parent,
        node_primitive=node_primitive,
        explored=explored,
        analytic_count=int(search.analytic_count),
        analytic_curvature=np.array(search.analytic_curvature[:], dtype=np.float64),
        analytic_length=np.array(search.analytic_length[:], dtype=np.float64),
        analytic_cost=float(search.analytic_cost),
    )
