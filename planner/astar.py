"""The compiled grid A* of chapter 3 (C, planner/native/astar.c): heuristics 3.1-3.4 and 3.6, the
thesis's improvements.

Data layout (why it is fast): the map is flattened to 1-D with a one-cell blocked border, so a
neighbour is `node + offset` with no bounds test. `blocked` holds 0 = free, 1 = obstacle /
inflated / border, 2 = *untrusted point* (a free cell with an obstacle among its 8 neighbours).
g, parent and a per-cell `stamp` live in arrays that are reused from query to query:
`stamp[n] == generation` means n is in OPEN, `generation + 1` means CLOSED, anything else means
unseen, so a new query costs no clearing of grid-size arrays.

OPEN is a 4-ary heap of (int64 key, node) that keeps HEAP_SLACK spare slots after its last entry
(so a heap array of C entries holds C - HEAP_SLACK); the key packs f = g + h (rounded to 2^-24
cell) over h (quarter cells), so one integer comparison orders by f and, among equal f, by smaller
h (the "low_h" tie breaker, which keeps optimality; rounding f puts ties that octile costs make
equal in exact arithmetic on the same key). The thesis's second improvement, OPEN-list replacement, is a
decrease-key done lazily: a node reached again with a lower g gets the new g and parent and is
pushed again with its lower key; the stale entry is skipped when popped. Without it
(`decrease_key=False`) g, f and parent change but the key in OPEN does not, as in plannerAStarGrid.

Costs are in cells here (straight 1, diagonal sqrt 2); the caller multiplies by the resolution.
"""

from __future__ import annotations

import ctypes
import math
import struct
from pathlib import Path

import numpy as np

from native.load import bind, load
from planner.options import HEURISTICS as HEURISTICS  # the codes, re-exported
from planner.options import TIE_BREAKERS as TIE_BREAKERS

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

# The search's settings travel in one float64 array (set once per prepared search, read by the
# kernel); the index of each entry:
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

# Spare slots the kernel keeps after the heap's last entry (astar.c's HEAP_SLACK).
HEAP_SLACK = 3

# The cost argument of a search without a cost gradient (cost_weight 0: never read).
NO_COST = np.zeros(1)

# Status codes of astar_search / astar_plan. NO_GENERAL: settings that astar_general.c's library
# searches, before it was registered (`_register_general`, which every entry here calls first).
FOUND, NO_PATH, HEAP_FULL, ROUTE_FULL, BAD_START, BAD_GOAL, NO_GENERAL = 1, 0, -1, -2, -3, -4, -5


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


_NATIVE = Path(__file__).parent / "native"
_LIBRARY = load(_NATIVE / "astar.c")
# PyDLL: the kernels hold the GIL, as the compiled searches always did, so the shared work arrays
# (planner.searchspace.workspace) are never used by two threads at once.
_P = ctypes.c_void_p
_I = ctypes.c_int64
_D = ctypes.c_double
_SIGNATURES = {  # name (after navcosim_): restype, argtypes
    "heuristic_cells": (_D, (_I, _I, _I)),
    "heap_key_of": (_I, (_D, _D, _I)),
    "endpoint_node": (_I, (_P, _P, _D, _D)),
    "astar_search": (_I, (_P, _P, _P, _I, _I, _I, _P, _P, _I, _P, _I, _P)),
    "astar_plan": (_I, (_P, _D, _D, _D, _D)),  # (Query *, start_x, start_y, goal_x, goal_y)
    "astar_call": (None, ()),
    "astar_needs_general": (_I, (_P,)),
    "astar_set_general": (None, (_P,)),
}  # fmt: skip
_KERNELS = bind(_LIBRARY, {"navcosim_" + name: typed for name, typed in _SIGNATURES.items()}, hold_gil=True)
_heuristic_cells = _KERNELS.navcosim_heuristic_cells
_heap_key_of = _KERNELS.navcosim_heap_key_of
_endpoint_node = _KERNELS.navcosim_endpoint_node
_astar_search = _KERNELS.navcosim_astar_search
plan_kernel = _KERNELS.navcosim_astar_plan
# The thin call of planner.planning.GridSearch: call_in(call_io, 0, address of a Query, start_x,
# start_y, goal_x, goal_y); plan_call(); call_out(call_io, CALL_OUT) = (status, searched, count,
# length [m]). Five converted ctypes arguments cost about three times this.
plan_call = _KERNELS.navcosim_astar_call
call_io = (ctypes.c_char * 72).in_dll(_KERNELS, "navcosim_astar_io")
call_in = struct.Struct("=q4d").pack_into
call_out = struct.Struct("=qqqd").unpack_from
CALL_OUT = 40
# astar.c searches with the settings of a scenario's planner (the thesis's heuristic; any with a
# cost gradient) and planner.plan's defaults; astar_general.c with every other setting: a library of
# its own, built (~0.5 s of CPU) and loaded the first time a search needs it.
_general: ctypes.CDLL | None = None


def _register_general(parameters: np.ndarray) -> None:
    """Load astar_general.c's library (building it the first time) and register its search with
    astar.c's, when `parameters` (a C-contiguous float64 PARAMETERS array) need it (astar.c's
    navcosim_astar_needs_general) and it is not loaded yet."""
    global _general
    if _general is None and _KERNELS.navcosim_astar_needs_general(
        address(parameters, np.float64, "parameters")
    ):
        library = load(_NATIVE / "astar_general.c")
        _KERNELS.navcosim_astar_set_general(ctypes.cast(library.navcosim_astar_general_search, _P))
        _general = library


class WorkState(ctypes.Structure):
    """The C view of a planner.searchspace.Workspace: its arrays' addresses and the generation."""

    _fields_ = [
        ("g", _P),
        ("nodes", _P),
        ("size", _I),
        ("heap", _P),
        ("capacity", _I),
        ("path", _P),
        ("cells", _P),
        ("path_rows", _I),
        ("generation", _I),
    ]


class Query(ctypes.Structure):
    """One prepared grid search for plan_kernel: the maps, the parameters, the workspace, and the
    answer of the last call (searched nodes, path nodes, length [m])."""

    _fields_ = [
        ("moves", _P),
        ("blocked", _P),
        ("cost", _P),
        ("parameters", _P),
        ("work", ctypes.POINTER(WorkState)),
        ("searched", _I),
        ("count", _I),
        ("length", _D),
    ]


def address(array: np.ndarray, dtype, name: str = "array") -> int:
    """The data address of `array`, which must be C-contiguous of `dtype` (the kernels take raw
    pointers: checked here, at the boundary)."""
    if not isinstance(array, np.ndarray) or array.dtype != dtype or not array.flags.c_contiguous:
        raise TypeError(f"{name} must be a C-contiguous {np.dtype(dtype).name} numpy array")
    return array.ctypes.data


def query(
    moves: np.ndarray, blocked: np.ndarray, cost: np.ndarray, parameters: np.ndarray, state: WorkState
) -> Query:
    """A Query over these arrays (the caller keeps them alive as long as the query)."""
    if len(moves) < int(parameters[P_ROWS] + 2) * int(parameters[P_WIDTH]) or len(blocked) != len(moves):
        raise ValueError("moves and blocked must cover the padded map of the parameters")
    _register_general(parameters)
    return Query(
        address(moves, np.uint8, "moves"),
        address(blocked, np.uint8, "blocked"),
        address(cost, np.float64, "cost"),
        address(parameters, np.float64, "parameters"),
        ctypes.pointer(state),
    )


def heuristic_cells(row_offset, col_offset, kind):
    """h in cells for a (row, col) offset to the goal: 3.1 Manhattan, 3.2 Euclid, 3.3 Chebyshev,
    3.4 octile (diagonal distance), 3.6 the thesis's Euclid + 2 Chebyshev, or 0."""
    return _heuristic_cells(int(row_offset), int(col_offset), int(kind))


def heap_key_of(f, h, tie_breaker):
    """One int64 key: f on a 2^-24 cell grid in the high bits, h (quarter cells) below for low_h ties."""
    return _heap_key_of(float(f), float(h), int(tie_breaker))


def neighbour_tables(width):
    """Offsets, row/col steps and lengths [cells] of the 8 moves, in the bit order of the move masks
    (planner.searchspace.MOVES): the 4 straight moves first."""
    row_steps = np.array(_ROW_STEPS, dtype=np.int64)
    col_steps = np.array(_COL_STEPS, dtype=np.int64)
    offsets = row_steps * int(width) + col_steps
    steps = np.where((row_steps != 0) & (col_steps != 0), SQRT2, 1.0)
    return offsets, row_steps, col_steps, steps


def endpoint_node(blocked, parameters, x, y):
    """Padded node of the cell that contains (x, y) [m], or -1 when that is outside the map, not a
    number, or a blocked cell (obstacle, inflated, border). Same arithmetic as
    OccupancyGrid.world_to_cell, so both agree on every point."""
    blocked_address = address(blocked, np.uint8, "blocked")
    return _endpoint_node(blocked_address, address(parameters, np.float64, "parameters"), float(x), float(y))


def astar_search(moves, cost, parameters, start, goal, generation, g, nodes, heap):
    """A* (or Dijkstra with heuristic 5 and goal -1) on a padded flat grid.

    moves: uint8 per padded cell, bit k set when move k (neighbour_tables order) leaves the cell
    (planner.searchspace.SearchMap.moves: connectivity, corner rule and untrusted points are in it,
    so the loop tests one bit per neighbour). cost: the padded cost gradient, or NO_COST when the
    cost weight is 0 (then it is never read).
    parameters: PARAMETERS. g: float64 [size]. nodes: int32 [3, size] = parent, stamp, and the
    expanded nodes in the order they were closed. heap: int64 [2, capacity], keys and nodes of OPEN
    (at most capacity - HEAP_SLACK entries).
    Returns (status, number of expanded nodes): FOUND, NO_PATH (OPEN ran empty; with goal == -1,
    the Dijkstra mode, this is the normal end) or HEAP_FULL (give larger heap arrays and search
    again: growing them here would slow every push down).

    The best child of an expansion skips the heap when its key is <= every key in OPEN (it would
    be popped next anyway): on open ground, where f stays constant along a straight run towards the
    goal, most nodes never enter the heap. The pop order stays that of the keys, so the search is
    the same A*.
    """
    size = len(g)
    if nodes.shape != (3, size) or len(moves) != size or heap.ndim != 2 or heap.shape[0] != 2:
        raise ValueError("astar_search needs moves [size], g [size], nodes [3, size] and heap [2, capacity]")
    if not (0 <= start < size and -1 <= goal < size):
        raise ValueError(f"start {start} or goal {goal} is not a node of the padded map")
    _register_general(parameters)
    searched = ctypes.c_int64()
    status = _astar_search(
        address(moves, np.uint8, "moves"), address(cost, np.float64, "cost"),
        address(parameters, np.float64, "parameters"), int(start), int(goal), int(generation),
        address(g, np.float64, "g"), address(nodes, np.int32, "nodes"), size,
        address(heap, np.int64, "heap"), heap.shape[1], ctypes.byref(searched),
    )  # fmt: skip
    return status, searched.value


def astar_plan(moves, blocked, cost, parameters, start_x, start_y, goal_x, goal_y, generation, g, nodes, heap,
               path, cells):  # fmt: skip
    """A query in one compiled call: the endpoint cells of (start_x, start_y) and (goal_x, goal_y)
    [m], astar_search, and the path.

    path (float64) and cells (int64): C x 2 buffers; rows 0..N-1 get the path's cell centres (x, y)
    [m] and its cells (row, col). Returns (status, searched, N, length [m]): status as
    astar_search's, or ROUTE_FULL when the path has more than C cells (search again with buffers of
    N rows), BAD_START / BAD_GOAL when that endpoint is outside the map or blocked (the caller says
    which and why). planner.planning.GridSearch calls the kernel (plan_kernel) directly with a Query
    set up once.
    """
    size = len(g)
    if nodes.shape != (3, size) or heap.ndim != 2 or heap.shape[0] != 2 or path.shape != cells.shape:
        raise ValueError("astar_plan needs g [size], nodes [3, size], heap [2, capacity], path, cells [C, 2]")
    state = WorkState(
        address(g, np.float64, "g"), address(nodes, np.int32, "nodes"), size, address(heap, np.int64, "heap"),
        heap.shape[1], address(path, np.float64, "path"), address(cells, np.int64, "cells"), len(path),
        int(generation) - 2,  # the kernel takes the next generation, as Workspace.next_generation does
    )  # fmt: skip
    prepared = query(moves, blocked, cost, parameters, state)
    endpoints = float(start_x), float(start_y), float(goal_x), float(goal_y)
    status = plan_kernel(ctypes.addressof(prepared), *endpoints)
    return status, prepared.searched, prepared.count, prepared.length
