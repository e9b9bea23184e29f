"""The options of the grid planners (`planner.plan`): names, units, defaults, presets, checks.

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

import math

import numpy as np

from planner.errors import PlannerError

# The compiled search's codes (`planner.astar`, which uses them from here: importing this module,
# as validating a scenario does, neither loads nor compiles astar.c).
HEURISTICS = {"manhattan": 0, "euclidean": 1, "chebyshev": 2, "octile": 3, "thesis": 4, "zero": 5}
TIE_BREAKERS = {"none": 0, "matlab": 1, "low_h": 2}

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
CONFIGURATIONS = tuple(PRESETS)
# The heuristics a user names (planner.astar's "zero" is internal: Dijkstra's goal distances).
USER_HEURISTICS = tuple(name for name in HEURISTICS if name != "zero")
SMOOTHING = (None, "line_of_sight", "curvature")


def choice(name: str, value, choices) -> None:
    if value not in choices:
        shown = ", ".join(repr(choice) for choice in choices)
        raise PlannerError(f"option {name}={value!r} is not valid (choose {shown})")


def flag(name: str, value) -> bool:
    if not isinstance(value, bool | np.bool_):
        raise PlannerError(f"option {name} must be True or False, got {value!r}")
    return bool(value)


def number(name: str, value, minimum: float = 0.0, strict: bool = False) -> float:
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


def resolve(options: dict) -> dict:
    """Defaults, then the preset, then explicit options; every name and value checked (PlannerError
    names the first bad one)."""
    unknown = [name for name in options if name not in DEFAULTS]
    if unknown:
        import difflib  # only for this message: a run that names its options right never loads it

        name = unknown[0]
        close = difflib.get_close_matches(name, DEFAULTS, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else f" (valid: {', '.join(sorted(DEFAULTS))})"
        raise PlannerError(f"unknown planner option {name!r}{hint}")
    resolved = dict(DEFAULTS)
    configuration = options.get("configuration")
    if configuration is not None:
        choice("configuration", configuration, (None, *PRESETS))
        resolved.update(PRESETS[configuration])
    resolved.update(options)
    choice("planner", resolved["planner"], PLANNERS)
    if flag("bidirectional", resolved["bidirectional"]):
        resolved["planner"] = "bidirectional"
    choice("connectivity", resolved["connectivity"], (4, 8))
    resolved["connectivity"] = int(resolved["connectivity"])  # 8.0 is 8 (it indexes the move table)
    if resolved["heuristic"] is None:
        resolved["heuristic"] = "octile" if resolved["connectivity"] == 8 else "manhattan"
    choice("heuristic", resolved["heuristic"], USER_HEURISTICS)
    resolved["heuristic_weight"] = number("heuristic_weight", resolved["heuristic_weight"])
    for name in ("corner_cutting", "untrusted_points", "decrease_key"):
        resolved[name] = flag(name, resolved[name])
    resolved["expansion_distance"] = number("expansion_distance", resolved["expansion_distance"])
    choice("tie_breaker", resolved["tie_breaker"], tuple(TIE_BREAKERS))
    resolved["cost_weight"] = number("cost_weight", resolved["cost_weight"])
    resolved["cost_scaling_factor"] = number("cost_scaling_factor", resolved["cost_scaling_factor"])
    choice("smoothing", resolved["smoothing"], SMOOTHING)
    return resolved
