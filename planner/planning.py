"""The front door: `plan(grid, start, goal, **options) -> PlanResult` and `distance_to_goal`.

Options (units in brackets; defaults in parentheses):
    planner            "astar" | "bidirectional" | "hybrid" ("astar"); `bidirectional=True` is
                       the same as planner="bidirectional". "hybrid" hands every option to
                       planner.hybrid.plan_hybrid.
    configuration      None | "basic" | "modified" (None): a preset; options given explicitly win.
    connectivity       4 | 8 (8)
    heuristic          "manhattan" (3.1) | "euclidean" (3.2) | "chebyshev" (3.3) | "octile" (3.4, the
                       diagonal distance) | "thesis" (3.6: Euclid + 2 Chebyshev) (octile with 8
                       neighbours, manhattan with 4: the exact distance on an empty map)
    heuristic_weight   h multiplier (1.0); > 1 trades optimality for speed
    corner_cutting     False: a diagonal step needs both orthogonally adjacent cells free (Moving
                       AI's rule); True: MATLAB plannerAStarGrid's rule (only the target must be free)
    expansion_distance [m] (0.0): the thesis's third improvement; cells whose centre lies within this
                       distance of an obstacle centre are closed to the search (planner.inflation)
    untrusted_points   the first improvement (False): every free cell with an obstacle (or inflated
                       cell) among its 8 neighbours is put in CLOSED before the search, so it is
                       never evaluated or expanded; start and goal are exempt. Unlike inflation it
                       is a fixed one-cell ring in cell units (independent of the resolution), it
                       makes no start/goal error, and it applies on top of the inflation.
    decrease_key       the second improvement (True): a node in OPEN reached with a lower g gets the
                       new g, parent and key (OPEN-list replacement). False: g, f and parent change
                       but the heap key does not (plannerAStarGrid), which can give longer paths.
    tie_breaker        "low_h" (among equal f prefer the smaller h; keeps optimality) | "none" |
                       "matlab" (h * 1.07 as plannerAStarGrid's TieBreaker "on": not optimal)
    cost_weight        (0.0) weight of the nav2-style cost gradient: a step's cost is its length times
                       (1 + cost_weight * cost of the entered cell), cost in [0, 1]
    cost_scaling_factor [1/m] (1.0) decay of that cost with the distance beyond expansion_distance
    smoothing          None | "line_of_sight" | "curvature" (planner.smoothing)

Presets:
    "basic"    plannerAStarGrid-like: connectivity 8, heuristic "euclidean", corner_cutting True,
               decrease_key False, untrusted_points False, tie_breaker "none".
    "modified" the thesis's Algorithm 3.1: connectivity 8, heuristic "thesis", corner_cutting False,
               decrease_key True, untrusted_points True, tie_breaker "low_h". The third improvement
               (expansion_distance) depends on the robot, so pass it too (Table 3.2's "inflated").

Costs are metres: a straight step costs `resolution`, a diagonal one sqrt(2) * resolution.
"""

from __future__ import annotations

import difflib
import math
from time import perf_counter

import numpy as np

from planner.astar import HEURISTICS, TIE_BREAKERS, astar_plan, astar_search, unpad_distances
from planner.errors import PlannerError
from planner.grid import OccupancyGrid
from planner.result import PlanResult
from planner.searchspace import SearchMap, search_map, workspace

DEFAULTS: dict[str, object] = {
    "planner": "astar",
    "configuration": None,
    "bidirectional": False,
    "connectivity": 8,
    "heuristic": None,
    "heuristic_weight": 1.0,
    "corner_cutting": False,
    "expansion_distance": 0.0,
    "untrusted_points": False,
    "decrease_key": True,
    "tie_breaker": "low_h",
    "cost_weight": 0.0,
    "cost_scaling_factor": 1.0,
    "smoothing": None,
}

PRESETS: dict[str, dict[str, object]] = {
    "basic": {
        "connectivity": 8,
        "heuristic": "euclidean",
        "corner_cutting": True,
        "decrease_key": False,
        "untrusted_points": False,
        "tie_breaker": "none",
    },
    "modified": {
        "connectivity": 8,
        "heuristic": "thesis",
        "corner_cutting": False,
        "decrease_key": True,
        "untrusted_points": True,
        "tie_breaker": "low_h",
    },
}

PLANNERS = ("astar", "bidirectional", "hybrid")
SMOOTHING = (None, "line_of_sight", "curvature")


def _choice(name: str, value, choices) -> None:
    if value not in choices:
        shown = ", ".join(repr(choice) for choice in choices)
        raise PlannerError(f"option {name}={value!r} is not valid (choose {shown})")


def _flag(name: str, value) -> bool:
    if not isinstance(value, bool | np.bool_):
        raise PlannerError(f"option {name} must be True or False, got {value!r}")
    return bool(value)


def _number(name: str, value, minimum: float = 0.0, strict: bool = False) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise PlannerError(f"option {name} must be a number, got {value!r}") from None
    if (
        isinstance(value, bool)
        or not math.isfinite(number)
        or number < minimum
        or (strict and number == minimum)
    ):
        bound = ">" if strict else ">="
        raise PlannerError(f"option {name} must be a finite number {bound} {minimum}, got {value!r}")
    return number


_prepared_cache: dict[tuple, tuple[dict, tuple]] = {}


def resolve_options(options: dict) -> dict:
    """Defaults, then the preset, then explicit options; every name and value checked.

    The result is cached per option set (queries in a loop repeat them); do not modify it.
    """
    return _prepare(options)[0]


def _prepare(options: dict) -> tuple[dict, tuple]:
    """(resolved options, the compiled search's parameters), checked once per option set.

    The key holds each value's type, so True and 1 (which compare equal) stay apart: an option
    that must be a bool is rejected for 1 even after True has been cached.
    """
    values = tuple(options.values())
    try:
        key = (tuple(options), values, tuple(map(type, values)))
        cached = _prepared_cache.get(key)
    except TypeError:  # an unhashable value: check it the slow way
        key, cached = None, None
    if cached is not None:
        return cached
    resolved = _resolve(options)
    tie_breaker = TIE_BREAKERS[resolved["tie_breaker"]]
    parameters = (
        HEURISTICS[resolved["heuristic"]],
        resolved["heuristic_weight"] * (1.07 if resolved["tie_breaker"] == "matlab" else 1.0),
        tie_breaker,
        resolved["decrease_key"],
    )
    prepared = (resolved, parameters)
    if key is not None and len(_prepared_cache) < 256:
        _prepared_cache[key] = prepared
    return prepared


def _resolve(options: dict) -> dict:
    unknown = [name for name in options if name not in DEFAULTS]
    if unknown:
        name = unknown[0]
        close = difflib.get_close_matches(name, DEFAULTS, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else f" (valid: {', '.join(sorted(DEFAULTS))})"
        raise PlannerError(f"unknown planner option {name!r}{hint}")
    resolved = dict(DEFAULTS)
    configuration = options.get("configuration")
    if configuration is not None:
        _choice("configuration", configuration, (None, *PRESETS))
        resolved.update(PRESETS[configuration])
    resolved.update(options)
    _choice("planner", resolved["planner"], PLANNERS)
    if _flag("bidirectional", resolved["bidirectional"]):
        resolved["planner"] = "bidirectional"
    _choice("connectivity", resolved["connectivity"], (4, 8))
    if resolved["heuristic"] is None:
        resolved["heuristic"] = "octile" if resolved["connectivity"] == 8 else "manhattan"
    _choice("heuristic", resolved["heuristic"], tuple(name for name in HEURISTICS if name != "zero"))
    resolved["heuristic_weight"] = _number("heuristic_weight", resolved["heuristic_weight"])
    for name in ("corner_cutting", "untrusted_points", "decrease_key"):
        resolved[name] = _flag(name, resolved[name])
    resolved["expansion_distance"] = _number("expansion_distance", resolved["expansion_distance"])
    _choice("tie_breaker", resolved["tie_breaker"], tuple(TIE_BREAKERS))
    resolved["cost_weight"] = _number("cost_weight", resolved["cost_weight"])
    resolved["cost_scaling_factor"] = _number("cost_scaling_factor", resolved["cost_scaling_factor"])
    _choice("smoothing", resolved["smoothing"], SMOOTHING)
    return resolved


def _describe(grid: OccupancyGrid, point, cell) -> str:
    return f"({point[0]:g}, {point[1]:g}) m = cell (row {cell[0]}, col {cell[1]})"


def endpoint_node(space: SearchMap, point, role: str) -> int:
    """Padded node of a start/goal point [m]; PlannerError when it is outside, on an obstacle or inflated."""
    grid = space.grid
    try:
        x, y = float(point[0]), float(point[1])
        col = math.floor((x - grid.origin[0]) / grid.resolution)
        row = space.rows - 1 - math.floor((y - grid.origin[1]) / grid.resolution)
    except (TypeError, ValueError, IndexError, OverflowError):
        col = row = -1  # the checks below name the problem
    else:
        if 0 <= row < space.rows and 0 <= col < space.cols:
            node = (row + 1) * space.width + col + 1
            if space.blocked[node] != 1:  # the common case: a free cell, one test
                return node
    return _endpoint_error(space, point, role)


def check_endpoint_cell(
    grid: OccupancyGrid, inflated: np.ndarray, expansion_distance: float, point, role: str
) -> tuple[int, int]:
    """The (row, col) of a start/goal point (x, y) [m]; PlannerError when it is outside the map, on
    an obstacle, or inside the inflation (`inflated`, bool [row, col], by `expansion_distance` m)."""
    row, col = grid.world_to_cell((point[0], point[1]))
    where = f"{role} {_describe(grid, point, (row, col))}"
    if not grid.contains_cell((row, col)):
        width, height = grid.size_m
        raise PlannerError(
            f"{where} is outside the map (x in [{grid.origin[0]:g}, {grid.origin[0] + width:g}), "
            f"y in [{grid.origin[1]:g}, {grid.origin[1] + height:g}) m)"
        )
    if grid.occupied[row, col]:
        raise PlannerError(f"{where} is on an obstacle")
    if inflated[row, col]:
        raise PlannerError(
            f"{where} is inside the inflation (expansion_distance {expansion_distance:g} m) "
            "around an obstacle"
        )
    return row, col


def _endpoint_error(space: SearchMap, point, role: str) -> int:
    """Raise the PlannerError that says why `point` cannot be an endpoint."""
    grid = space.grid
    try:
        x, y = float(point[0]), float(point[1])
    except (TypeError, ValueError, IndexError):
        raise PlannerError(f"{role} must be (x, y) in metres, got {point!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise PlannerError(f"{role} must be finite (x, y) in metres, got {point!r}")
    row, col = check_endpoint_cell(grid, space.inflated, space.expansion_distance, (x, y), role)
    return space.node(row, col)


def _check_grid(grid) -> OccupancyGrid:
    if not isinstance(grid, OccupancyGrid):
        raise PlannerError(f"plan() needs an OccupancyGrid, got {type(grid).__name__}")
    return grid


def plan(grid: OccupancyGrid, start, goal, **options) -> PlanResult:
    """Plan from `start` to `goal` (x, y) [m] on `grid`; see the module docstring for the options.

    Raises PlannerError (one line) for bad options, a start/goal outside the map, on an obstacle
    or inside the inflation, and when no path exists.
    """
    if options.get("planner") == "hybrid":
        from planner.hybrid import plan_hybrid

        hybrid_options = {name: value for name, value in options.items() if name != "planner"}
        return plan_hybrid(_check_grid(grid), start, goal, **hybrid_options)
    settings, parameters = _prepare(options)
    space = search_map(_check_grid(grid), settings["expansion_distance"])
    start_node = endpoint_node(space, start, "start")
    goal_node = endpoint_node(space, goal, "goal")
    moves = space.moves(settings["connectivity"], settings["corner_cutting"], settings["untrusted_points"])
    # Start and goal are exempt from the untrusted points: let the moves into them for this query.
    saved = (
        space.open_endpoints(
            moves, (start_node, goal_node), settings["connectivity"], settings["corner_cutting"]
        )
        if settings["untrusted_points"]
        else None
    )
    try:
        if settings["planner"] == "bidirectional":
            from planner.bidirectional import search_bidirectional

            found, cells, path, length, searched, elapsed, explored = search_bidirectional(
                space, moves, start_node, goal_node, settings, parameters
            )
        else:
            found, cells, path, length, searched, elapsed, explored = _search_astar(
                space, moves, start_node, goal_node, settings, parameters
            )
    finally:
        if saved is not None:
            space.restore(moves, saved)
    if not found:
        raise PlannerError(
            f"no path from start {tuple(start[:2])} m to goal {tuple(goal[:2])} m "
            f"({searched} cells searched{_settings_note(settings)})"
        )
    info = {"configuration": settings["configuration"] or "default", "options": dict(settings)}
    if settings["smoothing"] is not None:
        from planner.smoothing import smooth_path

        info["raw_length"] = length
        info["raw_path_nodes"] = len(cells)
        path = smooth_path(space, path, settings["smoothing"])
        length = float(np.hypot(*np.diff(path, axis=0).T).sum())
        cells = grid.world_to_cells(path)
    # Positional, in the field order of PlanResult (path, cells, length, path_nodes, searched_nodes,
    # elapsed, explored, directions, planner, info): keywords cost ~1 us more per plan.
    planner_name = settings["planner"]
    return PlanResult(path, cells, length, len(path), searched, elapsed, explored, None, planner_name, info)


def _settings_note(settings: dict) -> str:
    notes = []
    if settings["expansion_distance"] > 0:
        notes.append(f"expansion_distance {settings['expansion_distance']:g} m")
    if settings["untrusted_points"]:
        notes.append("untrusted points closed")
    if settings["connectivity"] == 4:
        notes.append("4-connected")
    return "; " + ", ".join(notes) if notes else ""


def _cost(space: SearchMap, settings: dict) -> tuple[np.ndarray, float]:
    cost_weight = settings["cost_weight"]
    if cost_weight > 0.0:
        return space.costs(settings["cost_scaling_factor"]), cost_weight
    return None, 0.0


def run_astar(
    space: SearchMap, moves: np.ndarray, start_node: int, goal_node: int, settings: dict, parameters: tuple
):
    """Run the compiled A* into the shared workspace; returns (status, searched, elapsed [s])."""
    work = workspace(len(space.blocked))
    cost, cost_weight = _cost(space, settings)
    while True:
        generation = work.next_generation()
        compiled = len(astar_search.overloads)
        began = perf_counter()
        status, searched = astar_search(
            moves, space.width, start_node, goal_node, *parameters, cost, cost_weight,
            work.g, work.nodes, generation, work.heap_key, work.heap_node,
        )  # fmt: skip
        elapsed = perf_counter() - began
        if len(astar_search.overloads) != compiled:
            continue  # that call compiled the kernel (or loaded it from the cache): time a clean run
        if status >= 0:
            return status, searched, elapsed
        work.grow_heap()


def _search_astar(
    space: SearchMap, moves: np.ndarray, start_node: int, goal_node: int, settings: dict, parameters: tuple
):
    """A* and its path; returns (found, cells, path [m], length [m], searched, elapsed [s], explored).

    elapsed covers the search and the path reconstruction (Algorithm 3.1, lines 3-15), which run
    in one compiled call. The compiled call writes into arrays made here and in the workspace
    (returning new arrays from it costs more than the search of a short query)."""
    work = workspace(len(space.blocked))
    integers, reals, cost = space.kernel_arguments(
        parameters, settings["cost_weight"], settings["cost_scaling_factor"]
    )
    explored = np.zeros((space.rows, space.cols), dtype=bool)
    while True:
        generation = work.next_generation()
        compiled = len(astar_plan.overloads)
        began = perf_counter()
        status, searched, count, length = astar_plan(
            moves, cost, integers, reals, start_node, goal_node, generation, work.g, work.nodes,
            work.heap_key, work.heap_node, explored, work.cells, work.path,
        )  # fmt: skip
        elapsed = perf_counter() - began
        if len(astar_plan.overloads) != compiled:
            explored[:] = False  # that call compiled the kernel (or loaded it from the cache):
            continue  # elapsed excludes JIT compilation, so time a clean run
        if status >= 0:
            cells, path = work.cells[:count].copy(), work.path[:count].copy()
            return status == 1, cells, path, length, searched, elapsed, explored
        if status == -1:
            work.grow_heap()
        else:
            work.grow_path(count)


_DIJKSTRA = {
    "connectivity": 8,
    "corner_cutting": False,
    "cost_weight": 0.0,
    "cost_scaling_factor": 1.0,
}


def distance_to_goal(
    grid: OccupancyGrid, goal_cell: tuple[int, int], connectivity: int = 8, corner_cutting: bool = False
) -> np.ndarray:
    """Shortest grid distance [m] from every cell to `goal_cell` (row, col): a compiled Dijkstra.

    Steps cost resolution (straight) and sqrt(2) * resolution (diagonal); inf on obstacles and
    where the goal cannot be reached. Used as an obstacle-aware heuristic by hybrid A*.
    """
    _check_grid(grid)
    _choice("connectivity", connectivity, (4, 8))
    corner_cutting = _flag("corner_cutting", corner_cutting)
    space = search_map(grid, 0.0)
    row, col = int(goal_cell[0]), int(goal_cell[1])
    if not grid.contains_cell((row, col)):
        raise PlannerError(f"goal cell (row {row}, col {col}) is outside the {space.rows}x{space.cols} map")
    if grid.occupied[row, col]:
        return np.full(grid.shape, np.inf)
    settings = dict(_DIJKSTRA, connectivity=connectivity, corner_cutting=corner_cutting)
    parameters = (HEURISTICS["zero"], 1.0, TIE_BREAKERS["none"], True)
    moves = space.moves(connectivity, corner_cutting, False)
    run_astar(space, moves, space.node(row, col), -1, settings, parameters)
    work = workspace(len(space.blocked))
    return unpad_distances(
        work.g, work.nodes[1], work.generation + 1, space.rows, space.cols, grid.resolution
    )
