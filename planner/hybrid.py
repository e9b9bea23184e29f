"""Hybrid A* for car-like vehicles: `plan_hybrid(grid, start, goal, **options) -> PlanResult`.

`planner.plan(grid, start, goal, planner="hybrid", **options)` lands here. Start and goal are
poses (x, y, theta) [m, m, rad]. The grid is the map; the vehicle's footprint is handled by
inflating it by `expansion_distance` [m], after which the vehicle is a point.

Options (units in brackets; defaults in parentheses):
    min_turning_radius      [m] (3.5, the bicycle car of the thesis's Table 4.4); or give
                            `wheelbase` [m] and `max_steering_angle` [rad] instead:
                            R = wheelbase / tan(max_steering_angle)
    reverse                 allow driving backwards (True); False makes the curves Dubins
    expansion_distance      [m] (0.0) inflation of the map for the vehicle radius + safety distance
    heading_bins            heading cells of the closed set (72, i.e. 5 degrees)
    primitive_length        [m] (1.5 sqrt(2) x resolution) arc length of a motion primitive; at
                            least sqrt(2) x resolution so every expansion leaves its cell
    num_curvatures          odd number of curvatures per direction, linspace(-1/R, 1/R, n) (3)
    reverse_cost            multiplier (>= 1) on the length driven backwards (2.0)
    direction_switch_cost   [m] added at every change between forward and reverse (4.0)
    steering_cost           relative extra cost per metre at full lock (0.05)
    analytic_interval       try a curve to the goal at the first and every this many expansions (5) ...
    analytic_distance       [m] ... and at every expansion closer than this to the goal (4 R);
                            analytic_interval 0 turns analytic expansion off (the goal is then
                            reached by primitives, within the goal tolerances)
    goal_tolerance          [m] position tolerance when a primitive reaches the goal (resolution)
    heading_tolerance       [rad] heading tolerance at the goal (one heading bin)
    interpolation_distance  [m] spacing of the returned poses (resolution)
    collision_step          [m] spacing of collision samples along curves (resolution / 2)
    max_iterations          node expansions before giving up (200000)
"""

from __future__ import annotations

import difflib
import math
import time
from pathlib import Path

import numpy as np

from native import load as native_load
from planner.endpoints import check_endpoint_cell
from planner.errors import PlannerError
from planner.goal_distance import distance_to_goal
from planner.grid import OccupancyGrid
from planner.hybrid_geometry import library, sample_segments
from planner.hybrid_primitives import build_primitives
from planner.hybrid_search import FOUND_ANALYTIC, ITERATION_CAP, hybrid_search
from planner.result import PlanResult

OPTIONS = (
    "min_turning_radius",
    "wheelbase",
    "max_steering_angle",
    "reverse",
    "expansion_distance",
    "heading_bins",
    "primitive_length",
    "num_curvatures",
    "reverse_cost",
    "direction_switch_cost",
    "steering_cost",
    "analytic_interval",
    "analytic_distance",
    "goal_tolerance",
    "heading_tolerance",
    "interpolation_distance",
    "collision_step",
    "max_iterations",
)
DEFAULT_TURNING_RADIUS = 3.5


def _number(name: str, value, minimum: float = 0.0, strict: bool = True, maximum: float = math.inf) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise PlannerError(f"hybrid option {name} must be a number, got {value!r}") from None
    low_ok = number > minimum if strict else number >= minimum
    if isinstance(value, bool) or not math.isfinite(number) or not low_ok or number > maximum:
        bound = ">" if strict else ">="
        upper = f" and <= {maximum:g}" if math.isfinite(maximum) else ""
        raise PlannerError(f"hybrid option {name} must be {bound} {minimum:g}{upper}, got {value!r}")
    return number


def _integer(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise PlannerError(f"hybrid option {name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _turning_radius(options: dict) -> float:
    given = [name for name in ("wheelbase", "max_steering_angle") if options.get(name) is not None]
    if options.get("min_turning_radius") is not None:
        if given:
            raise PlannerError("give either min_turning_radius or wheelbase and max_steering_angle, not both")
        return _number("min_turning_radius", options["min_turning_radius"])
    if len(given) == 1:
        raise PlannerError(f"hybrid option {given[0]} needs its partner (wheelbase and max_steering_angle)")
    if given:
        wheelbase = _number("wheelbase", options["wheelbase"])
        steering = abs(_number("max_steering_angle", options["max_steering_angle"], minimum=-math.inf))
        if not 0.0 < steering < math.pi / 2:
            raise PlannerError(
                f"hybrid option max_steering_angle must be non-zero, |angle| < pi/2 rad, got {steering:g}"
            )
        return wheelbase / math.tan(steering)
    return DEFAULT_TURNING_RADIUS


def resolve_hybrid_options(grid: OccupancyGrid, options: dict) -> dict:
    """Every option checked and filled with its default; PlannerError names a bad one."""
    unknown = [name for name in options if name not in OPTIONS]
    if unknown:
        close = difflib.get_close_matches(unknown[0], OPTIONS, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else f" (valid: {', '.join(OPTIONS)})"
        raise PlannerError(f"unknown hybrid option {unknown[0]!r}{hint}")
    resolution = grid.resolution
    radius = _turning_radius(options)
    settings = {"min_turning_radius": radius}
    reverse = options.get("reverse", True)
    if not isinstance(reverse, bool | np.bool_):
        raise PlannerError(f"hybrid option reverse must be True or False, got {reverse!r}")
    settings["reverse"] = bool(reverse)
    settings["expansion_distance"] = _number(
        "expansion_distance", options.get("expansion_distance", 0.0), strict=False
    )
    settings["heading_bins"] = _integer("heading_bins", options.get("heading_bins", 72), 8)
    minimum_length = math.sqrt(2.0) * resolution
    length = _number("primitive_length", options.get("primitive_length", 1.5 * minimum_length))
    if length < minimum_length - 1e-12:
        raise PlannerError(
            f"hybrid option primitive_length must be >= sqrt(2) x resolution = {minimum_length:g} m "
            f"so every expansion leaves its cell, got {length:g}"
        )
    settings["primitive_length"] = length
    curvatures = _integer("num_curvatures", options.get("num_curvatures", 3), 3)
    if curvatures % 2 == 0:
        raise PlannerError(
            f"hybrid option num_curvatures must be odd (straight in the middle), got {curvatures}"
        )
    settings["num_curvatures"] = curvatures
    settings["reverse_cost"] = _number(
        "reverse_cost", options.get("reverse_cost", 2.0), minimum=1.0, strict=False
    )
    settings["direction_switch_cost"] = _number(
        "direction_switch_cost", options.get("direction_switch_cost", 4.0), strict=False
    )
    settings["steering_cost"] = _number("steering_cost", options.get("steering_cost", 0.05), strict=False)
    settings["analytic_interval"] = _integer("analytic_interval", options.get("analytic_interval", 5), 0)
    settings["analytic_distance"] = _number(
        "analytic_distance", options.get("analytic_distance", 4.0 * radius), strict=False
    )
    settings["goal_tolerance"] = _number(
        "goal_tolerance", options.get("goal_tolerance", resolution), strict=False
    )
    settings["heading_tolerance"] = _number(
        "heading_tolerance",
        options.get("heading_tolerance", 2.0 * math.pi / settings["heading_bins"]),
        strict=False,
        maximum=math.pi,
    )
    settings["interpolation_distance"] = _number(
        "interpolation_distance", options.get("interpolation_distance", resolution)
    )
    settings["collision_step"] = _number(
        "collision_step", options.get("collision_step", 0.5 * resolution), maximum=0.5 * resolution
    )
    settings["max_iterations"] = _integer("max_iterations", options.get("max_iterations", 200_000), 1)
    return settings


def _pose(value, role: str) -> tuple[float, float, float]:
    try:
        x, y, theta = (float(v) for v in value)
    except (TypeError, ValueError):
        raise PlannerError(
            f"hybrid A* needs the {role} as (x, y, theta) [m, m, rad], got {value!r}"
        ) from None
    if not all(math.isfinite(v) for v in (x, y, theta)):
        raise PlannerError(f"{role} must be finite (x, y, theta), got {value!r}")
    return x, y, theta


def _loaded_kernels() -> int:
    """C libraries loaded so far (the heuristic grid comes from grid A*'s search, another library)."""
    return len(native_load._loaded)


def _start_heuristic_build() -> None:
    """Start compiling astar_general.c, whose search of the zero heuristic the heuristic grid's
    Dijkstra loads, on a thread when no cache holds it: a first call then compiles it beside
    hybrid.c (~0.5 s of CPU each) instead of after it."""
    sources = native_load.missing([Path(__file__).resolve().parent / "native" / "astar_general.c"])
    if sources:
        from concurrent.futures import ThreadPoolExecutor

        builder = ThreadPoolExecutor(1, thread_name_prefix="navcosim-build")
        native_load.start_builds(sources, builder)
        builder.shutdown(wait=False)  # its thread ends with the build


def plan_hybrid(grid: OccupancyGrid, start, goal, **options) -> PlanResult:
    """See `_plan_hybrid`. The hybrid A* kernels are loaded first (built on a fresh install); a call
    that still loaded kernels (grid A*'s, for the heuristic), as the first one in a process does, is
    run again so that `elapsed` excludes building and loading them."""
    _start_heuristic_build()
    library()
    loaded = _loaded_kernels()
    result = _plan_hybrid(grid, start, goal, **options)
    if _loaded_kernels() != loaded:
        result = _plan_hybrid(grid, start, goal, **options)
    return result


def _plan_hybrid(grid: OccupancyGrid, start, goal, **options) -> PlanResult:
    """Plan a drivable path for a car from pose `start` to pose `goal` (x, y, theta).

    Returns PlanResult with `path` N x 3 poses every `interpolation_distance`, `directions`
    (+1 forward, -1 reverse per pose), `length` [m] (arc length of the curve), `path_nodes`,
    `searched_nodes` (expansions), `elapsed` [s] (heuristic grid + search + path sampling) and
    `info` (timings [s], the settings, whether the last piece is an analytic curve).
    Raises PlannerError for bad options, start/goal outside the map or in collision, and no path.
    """
    if not isinstance(grid, OccupancyGrid):
        raise PlannerError(f"plan_hybrid() needs an OccupancyGrid, got {type(grid).__name__}")
    settings = resolve_hybrid_options(grid, options)
    start, goal = _pose(start, "start"), _pose(goal, "goal")
    began = time.perf_counter()
    expansion = settings["expansion_distance"]
    inflated = grid.inflate(expansion) if expansion > 0.0 else grid
    check_endpoint_cell(grid, inflated.occupied, expansion, start, "start")
    goal_cell = check_endpoint_cell(grid, inflated.occupied, expansion, goal, "goal")
    inflated_at = time.perf_counter()

    distances = distance_to_goal(inflated, goal_cell, connectivity=8, corner_cutting=False)
    start_cell = grid.world_to_cell(start[:2])
    if not math.isfinite(distances[start_cell]):
        raise PlannerError(
            f"no path from start {start[:2]} m to goal {goal[:2]} m: the goal is enclosed "
            f"(not reachable on the map inflated by {expansion:g} m)"
        )
    heuristic_at = time.perf_counter()

    radius = settings["min_turning_radius"]
    primitives = build_primitives(
        radius,
        settings["primitive_length"],
        settings["num_curvatures"],
        settings["reverse"],
        settings["reverse_cost"],
        settings["steering_cost"],
        settings["collision_step"],
    )
    search_began = time.perf_counter()
    search = hybrid_search(
        inflated.occupied, grid.resolution, float(grid.origin[0]), float(grid.origin[1]), distances,
        start, goal, primitives,
        settings["heading_bins"], radius, not settings["reverse"], settings["reverse_cost"],
        settings["steering_cost"], settings["direction_switch_cost"], settings["analytic_interval"],
        settings["analytic_distance"], settings["goal_tolerance"], settings["heading_tolerance"],
        settings["collision_step"], settings["max_iterations"],
    )  # fmt: skip
    status, searched = search.status, search.expanded
    searched_at = time.perf_counter()
    if status <= 0:
        reason = (
            f"iteration cap max_iterations={settings['max_iterations']} reached"
            if status == ITERATION_CAP
            else "search exhausted"
        )
        raise PlannerError(
            f"no path from start {start} to goal {goal} for a car with min turning radius {radius:g} m "
            f"({reason} after {searched} expansions; expansion_distance {expansion:g} m)"
        )

    chain = []
    node = search.final
    while search.node_parent[node] >= 0:
        chain.append(search.node_primitive[node])
        node = search.node_parent[node]
    chain.reverse()
    curvatures = [primitives.curvature[p] for p in chain]
    lengths = [primitives.signed_length[p] for p in chain]
    if status == FOUND_ANALYTIC:
        curvatures.extend(search.analytic_curvature[: search.analytic_count])
        lengths.extend(search.analytic_length[: search.analytic_count])
    path, directions = sample_segments(
        start,
        np.array(curvatures, dtype=float),
        np.array(lengths, dtype=float),
        settings["interpolation_distance"],
    )
    path[:, 2] = np.remainder(path[:, 2] + math.pi, 2.0 * math.pi) - math.pi
    finished = time.perf_counter()
    length = float(np.abs(lengths).sum())
    info = {
        "settings": settings,
        "analytic_expansion": status == FOUND_ANALYTIC,
        "cusps": int(np.count_nonzero(np.diff(directions) != 0)),
        "primitives": len(chain),
        "time_inflation": inflated_at - began,
        "time_heuristic": heuristic_at - inflated_at,
        "time_search": searched_at - search_began,
        "time_path": finished - searched_at,
    }
    return PlanResult(
        path=path,
        cells=grid.world_to_cells(path[:, :2]),
        length=length,
        path_nodes=len(path),
        searched_nodes=int(searched),
        elapsed=finished - began,
        explored=search.explored,
        directions=directions.astype(np.int8),
        planner="hybrid",
        info=info,
    )
