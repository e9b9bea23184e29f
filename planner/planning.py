"""The front door: `plan(grid, start, goal, **options) -> PlanResult` (options: planner.options).

plan() keeps one prepared search per grid and option set (`GridSearch`: the checked options, the
move masks, the C kernel's parameters and its reusable work arrays, their addresses in one
planner.astar.Query), so a repeated query costs a dictionary look-up, one ctypes call without
arguments (planner.astar.plan_call) and the result object: a few microseconds on any map size,
with no array of the map's size allocated or cleared per call.
"""

from __future__ import annotations

import ctypes
import struct
import weakref
from time import perf_counter

import numpy as np

from planner.astar import (
    BAD_GOAL,
    BAD_START,
    CALL_OUT,
    FOUND,
    HEAP_FULL,
    HEURISTICS,
    NO_COST,
    NO_PATH,
    ROUTE_FULL,
    TIE_BREAKERS,
    call_in,
    call_io,
    call_out,
    plan_call,
    query,
    search_parameters,
)
from planner.endpoints import check_grid, endpoint_error, endpoint_node
from planner.errors import PlannerError
from planner.grid import OccupancyGrid
from planner.options import resolve
from planner.result import PlanResult
from planner.searchspace import search_map, workspace

# Prepared searches kept per grid: enough for every option set a program uses, bounded for one
# that generates option sets in a loop.
_SEARCHES_PER_GRID = 64


def plan(grid: OccupancyGrid, start, goal, **options) -> PlanResult:
    """Plan from `start` to `goal` (x, y) [m] on `grid`; options as planner.options documents them.

    Raises PlannerError (one line) for bad options, a start/goal outside the map, on an obstacle
    or inside the inflation, and when no path exists.
    """
    # The key holds each value's type, so True and 1 (which compare equal) stay apart: an option
    # that must be a bool is rejected for 1 even after True has been cached. The key's shape (the
    # (name, value) pairs, then the types: one flat tuple, built faster than a pair of tuples)
    # cannot collide with the grid's other cache entries (names, tuples that start with a name).
    key = (*options.items(), *map(type, options.values()))
    try:
        search = grid._cache[key]
    except KeyError:
        search = _prepare(check_grid(grid), options, key)
    except (AttributeError, TypeError):  # not an OccupancyGrid, or an unhashable option value
        search = _prepare(check_grid(grid), options, None)
    return search(start, goal)


def _is_search_key(name) -> bool:
    """Whether `name` in a grid's cache is the key of a prepared search: a tuple of (option, value)
    pairs and types (empty for no options); the other entries are names or tuples led by a name."""
    return isinstance(name, tuple) and (not name or isinstance(name[0], tuple))


def _prepare(grid: OccupancyGrid, options: dict, key: tuple | None):
    """The prepared search of `options` on `grid`, a callable (start, goal) -> PlanResult; kept in
    the grid's cache under `key` (None: not kept)."""
    if options.get("planner") == "hybrid":
        # planning -> hybrid, never back: hybrid A* checks its own options on every call.
        from planner.hybrid import plan_hybrid

        hybrid_options = {name: value for name, value in options.items() if name != "planner"}
        held = weakref.ref(grid)  # the grid's cache holds this search: no strong reference back

        def search(start, goal) -> PlanResult:
            return plan_hybrid(held(), start, goal, **hybrid_options)

    else:
        search = GridSearch(grid, resolve(options))
    if key is not None:
        searches = [name for name in grid._cache if _is_search_key(name)]
        if len(searches) >= _SEARCHES_PER_GRID:
            del grid._cache[searches[0]]
        grid._cache[key] = search
    return search


class GridSearch:
    """Grid A* or bidirectional A* with one resolved option set on one grid; call it with (start, goal).

    The kernel's library is built (first use after an install or an edit) or loaded when
    planner.astar is imported, so `elapsed` never includes it.
    """

    __slots__ = (
        "space",
        "settings",
        "moves",
        "cost",
        "parameters",
        "work",
        "name",
        "configuration",
        "untrusted",
        "connectivity",
        "corner_cutting",
        "general",
        "query",
        "address",
        "expanded",
        "shape",
    )

    def __init__(self, grid: OccupancyGrid, settings: dict) -> None:
        # No reference to the grid (its cache holds this search): `space.grid` is a weak one.
        space = search_map(grid, settings["expansion_distance"])
        self.space = space
        self.settings = settings
        self.name = settings["planner"]
        self.configuration = settings["configuration"] or "default"
        self.untrusted = settings["untrusted_points"]
        self.connectivity = settings["connectivity"]
        self.corner_cutting = settings["corner_cutting"]
        # The options that need more than one compiled call per query.
        self.general = self.untrusted or self.name == "bidirectional" or settings["smoothing"] is not None
        self.moves = space.moves(self.connectivity, self.corner_cutting, self.untrusted)
        cost_weight = settings["cost_weight"]
        self.cost = space.costs(settings["cost_scaling_factor"]) if cost_weight > 0.0 else NO_COST
        matlab = settings["tie_breaker"] == "matlab"
        self.parameters = search_parameters(
            space.width,
            HEURISTICS[settings["heuristic"]],
            TIE_BREAKERS[settings["tie_breaker"]],
            settings["decrease_key"],
            settings["heuristic_weight"] * (1.07 if matlab else 1.0),
            cost_weight,
            space.rows,
            space.cols,
            grid.resolution,
            grid.origin,
        )
        self.work = workspace(len(space.blocked))
        # The kernel's one argument besides the endpoints; the arrays it points to live as long as self.
        self.query = query(self.moves, space.blocked, self.cost, self.parameters, self.work.state)
        self.address = ctypes.addressof(self.query)
        self.expanded = self.work.nodes[2]  # the expanded nodes of the last search (never reallocated)
        self.shape = grid.shape

    def _search(self, start_x: float, start_y: float, goal_x: float, goal_y: float) -> tuple:
        """astar_plan into the workspace, growing its buffers until they suffice;
        returns (status, searched, path nodes, length [m], elapsed [s])."""
        while True:
            call_in(call_io, 0, self.address, start_x, start_y, goal_x, goal_y)
            began = perf_counter()
            plan_call()
            elapsed = perf_counter() - began
            status, searched, count, length = call_out(call_io, CALL_OUT)
            if status == HEAP_FULL:
                self.work.grow_heap()
            elif status == ROUTE_FULL:
                self.work.grow_path(count)
            else:
                return status, searched, count, length, elapsed

    def __call__(self, start, goal) -> PlanResult:
        if self.general:
            return self._plan_general(start, goal)
        # The common case inline (each Python call and conversion costs a tenth of a query): the
        # struct packing converts the endpoints as float() does and raises where float() would.
        try:
            call_in(call_io, 0, self.address, start[0], start[1], goal[0], goal[1])
        except (TypeError, ValueError, IndexError, OverflowError, struct.error):
            return self._plan_general(start, goal)  # which names the bad endpoint
        began = perf_counter()
        plan_call()
        elapsed = perf_counter() - began
        status, searched, count, length = call_out(call_io, CALL_OUT)
        if status != FOUND:
            if status == HEAP_FULL or status == ROUTE_FULL:
                status, searched, count, length, elapsed = self._search(
                    float(start[0]), float(start[1]), float(goal[0]), float(goal[1])
                )
            if status != FOUND:
                self._fail(status, start, goal, searched)
        work = self.work
        # Positional, in the order of PlanResult's parameters: keywords cost ~1 us more per plan.
        return PlanResult(
            work.path[:count].copy(), work.cells[:count].copy(), length, count, searched, elapsed,
            (self.expanded[:searched].copy(), self.space.width, self.shape),
            None, "astar", {"configuration": self.configuration, "options": self.settings.copy()},
        )  # fmt: skip

    def _fail(self, status: int, start, goal, searched: int) -> None:
        """Raise the PlannerError of a search that ended with `status` (not FOUND)."""
        if status == BAD_START:
            endpoint_error(self.space, start, "start")
        if status == BAD_GOAL:
            endpoint_error(self.space, goal, "goal")
        if status == NO_PATH:
            raise PlannerError(
                f"no path from start {tuple(start[:2])} m to goal {tuple(goal[:2])} m "
                f"({searched} cells searched{self._settings_note()})"
            )
        raise AssertionError(f"search status {status}")  # pragma: no cover (every status is handled)

    def _plan_general(self, start, goal) -> PlanResult:
        """Every option: untrusted points (start and goal exempt), bidirectional search, smoothing."""
        space, settings = self.space, self.settings
        start_node = endpoint_node(space, start, "start")
        goal_node = endpoint_node(space, goal, "goal")
        # Start and goal are exempt from the untrusted points: let the moves into them for this query.
        saved = (
            space.open_endpoints(self.moves, (start_node, goal_node), self.connectivity, self.corner_cutting)
            if self.untrusted
            else None
        )
        try:
            if self.name == "bidirectional":
                from planner.bidirectional import search_bidirectional

                found, cells, path, length, searched, elapsed, explored = search_bidirectional(
                    space, self.moves, self.cost, self.parameters, start_node, goal_node
                )
                status = FOUND if found else NO_PATH
            else:
                status, searched, count, length, elapsed = self._search(
                    float(start[0]), float(start[1]), float(goal[0]), float(goal[1])
                )
                if status == FOUND:
                    path, cells = self.work.path[:count].copy(), self.work.cells[:count].copy()
                    nodes = self.work.nodes[2, :searched].copy()
                    explored = (nodes, space.width, self.shape)
        finally:
            if saved is not None:
                space.restore(self.moves, saved)
        if status != FOUND:
            self._fail(status, start, goal, searched)
        info = {"configuration": self.configuration, "options": settings.copy()}
        if settings["smoothing"] is not None:
            from planner.smoothing import smooth_path

            info["raw_length"] = length
            info["raw_path_nodes"] = len(cells)
            path = smooth_path(space, path, settings["smoothing"])
            length = float(np.hypot(*np.diff(path, axis=0).T).sum())
            cells = space.grid.world_to_cells(path)
        return PlanResult(path, cells, length, len(path), searched, elapsed, explored, None, self.name, info)

    def _settings_note(self) -> str:
        settings = self.settings
        notes = []
        if settings["expansion_distance"] > 0:
            notes.append(f"expansion_distance {settings['expansion_distance']:g} m")
        if settings["untrusted_points"]:
            notes.append("untrusted points closed")
        if settings["connectivity"] == 4:
            notes.append("4-connected")
        return "; " + ", ".join(notes) if notes else ""
