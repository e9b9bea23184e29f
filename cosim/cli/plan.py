"""`cosim plan`: plan a path on a map and print the thesis's metrics; `cosim plan compare` for Tables 3.1-3.4.

    cosim plan MAP --start X,Y --goal X,Y [options] [--png OUT]
    cosim plan MAP --query NAME [options]          (named start/goal from MAP's <stem>.queries.toml)
    cosim plan compare MAP --start X,Y --goal X,Y [--expansion-distance M] [--png OUT]
    cosim plan mapf MAP --scen FILE --agents N [--time-limit S] [--seed K] [--png OUT]   (see plan_mapf)

Metrics: path length [m], path nodes, searched nodes (expanded cells), elapsed time [s]. The search is a
C kernel built on first use and loaded once per process, so every configuration runs once untimed and
the elapsed time printed is the median of --repeat timed runs of the search as the planner measures it.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import statistics
import tomllib
from dataclasses import dataclass
from pathlib import Path

from cosim.cli import plan_mapf
from cosim.errors import CosimError
from planner.options import CONFIGURATIONS, PLANNERS, USER_HEURISTICS

SMOOTHING = ("none", "line_of_sight", "curvature")
DEFAULT_COMPARE_EXPANSION = 0.8  # m: the thesis's differential-drive robot (radius 0.5 + safety 0.3)

USAGE = (
    "cosim plan [compare] MAP (--start X,Y --goal X,Y | --query NAME) [options] [--png OUT]\n"
    "       cosim plan mapf MAP --scen FILE --agents N [--time-limit S] [--seed K] [--png OUT]\n"
    "       X,Y in metres; X,Y,THETA (THETA in rad) for --planner hybrid; negative values as --start=-5,6"
)


@dataclass(frozen=True)
class Configuration:
    """One column of the comparison: a label and the planner options that define it."""

    label: str
    options: dict


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "plan",
        help="plan a path on a map; 'plan compare': the thesis's Tables 3.1-3.4; 'plan mapf': many agents",
        description=__doc__,
        usage=USAGE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "words", nargs="+", metavar="[compare|mapf] MAP", help="map file (.yaml, .map, .png, .pgm, .npy)"
    )
    parser.add_argument("--start", metavar="X,Y[,THETA]", help="start [m] (and heading [rad] for hybrid)")
    parser.add_argument("--goal", metavar="X,Y[,THETA]", help="goal [m] (and heading [rad] for hybrid)")
    parser.add_argument("--query", metavar="NAME", help="named start/goal from the map's <stem>.queries.toml")
    parser.add_argument("--connectivity", type=int, choices=(4, 8), help="neighbours per cell (8)")
    parser.add_argument(
        "--heuristic", choices=USER_HEURISTICS, help="h: eqs 3.1, 3.2, 3.3, 3.4 (octile), 3.6 (thesis)"
    )
    parser.add_argument("--heuristic-weight", type=float, metavar="W", help="h multiplier (1.0)")
    parser.add_argument("--configuration", choices=CONFIGURATIONS, help="preset (see planner.plan)")
    parser.add_argument(
        "--expansion-distance", type=float, metavar="M", help="inflation radius [m] (plan: 0; compare: 0.8)"
    )
    parser.add_argument(
        "--corner-cutting", action="store_true", default=None, help="allow MATLAB-style diagonals"
    )
    parser.add_argument("--untrusted-points", action="store_true", default=None, help="first improvement")
    parser.add_argument("--planner", choices=PLANNERS, default="astar")
    parser.add_argument("--min-turning-radius", type=float, metavar="M", help="hybrid: vehicle's [m]")
    parser.add_argument(
        "--reverse", action=argparse.BooleanOptionalAction, help="hybrid: allow reversing (planner's default)"
    )
    parser.add_argument("--smoothing", choices=SMOOTHING, help="path smoothing (none)")
    parser.add_argument("--resolution", type=float, metavar="M", help="cell size [m] for .png/.npy maps")
    parser.add_argument("--repeat", type=int, default=5, metavar="N", help="timed runs per plan (5)")
    parser.add_argument(
        "--png", type=Path, metavar="OUT", help="draw map, inflation, explored cells, path(s)"
    )
    plan_mapf.add_arguments(parser)
    parser.set_defaults(handler=_handler)


def _handler(args: argparse.Namespace) -> int:
    words = args.words
    _prepare_kernels(words, args.planner)
    if len(words) == 2 and words[0] == "compare":
        return _compare(args, Path(words[1]))
    if len(words) == 2 and words[0] == "mapf":
        return plan_mapf.run(args, Path(words[1]))
    if len(words) != 1:
        raise CosimError(
            "expected 'cosim plan MAP', 'cosim plan compare MAP' or 'cosim plan mapf MAP', "
            f"got {' '.join(words)!r}"
        )
    return _plan_one(args, Path(words[0]))


def _prepare_kernels(words: list[str], planner_name: str) -> None:
    """Start compiling the planner kernels this command loads, side by side, with one line on stderr
    when a first use compiles any (as `cosim run` says what it builds); they load as they finish."""
    import sys

    import planner
    from cosim.fmi.builtin import prepare

    native = Path(planner.__file__).parent / "native"
    if words[:1] == ["mapf"]:
        names = ["mapf.c"]
    elif words[:1] == ["compare"] or planner_name == "hybrid":
        # the longest to compile first; astar_general.c: hybrid's Dijkstra (the zero heuristic) and
        # the comparison's basic configuration (Euclidean) search with settings astar.c leaves to it
        names = ["hybrid.c", "astar_general.c", "astar.c", "distance.c"]
    else:
        names = ["astar.c", "distance.c"]
    prepare((), kernels=[native / name for name in names], announce=lambda line: print(line, file=sys.stderr))


# -- input ---------------------------------------------------------------------------------------
def parse_point(text: str, option: str, with_heading: bool) -> tuple[float, ...]:
    """Parse "X,Y" or "X,Y,THETA" [m, m, rad]; CosimError naming the option otherwise."""
    expected = "X,Y,THETA (metres, radians)" if with_heading else "X,Y (metres)"
    try:
        values = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise CosimError(f"{option} must be {expected}, got {text!r}") from None
    if len(values) not in (2, 3) or (with_heading and len(values) != 3):
        raise CosimError(f"{option} must be {expected}, got {text!r}")
    if not all(math.isfinite(value) for value in values):
        raise CosimError(f"{option} must be finite numbers, got {text!r}")
    return values


def queries_file(map_path: Path) -> Path:
    """Where the named start/goal queries of a map live: <map folder>/<map stem>.queries.toml."""
    return map_path.with_name(f"{map_path.stem}.queries.toml")


def load_query(map_path: Path, name: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(start, goal) of a named query, each (x, y, theta) [m, m, rad]."""
    path = queries_file(map_path)
    try:
        queries = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise CosimError(f"--query {name}: {path} not found (no named queries for this map)") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise CosimError(f"{path}: cannot read queries ({error})") from None
    if name not in queries:
        raise CosimError(f"--query {name!r} not in {path} (known: {', '.join(sorted(queries)) or 'none'})")
    points = []
    for key in ("start", "goal"):
        value = queries[name].get(key)
        if (
            not isinstance(value, list)
            or len(value) not in (2, 3)
            or not all(isinstance(item, int | float) for item in value)
        ):
            raise CosimError(f"{path}: [{name}].{key} must be [x, y] or [x, y, theta]")
        points.append(tuple(float(item) for item in value) + ((0.0,) if len(value) == 2 else ()))
    return points[0], points[1]


def _endpoints(args: argparse.Namespace, map_path: Path, with_heading: bool):
    start = goal = None
    if args.query:
        start, goal = load_query(map_path, args.query)
    if args.start is not None:
        start = parse_point(args.start, "--start", with_heading)
    if args.goal is not None:
        goal = parse_point(args.goal, "--goal", with_heading)
    if start is None or goal is None:
        raise CosimError("give --start X,Y and --goal X,Y (or --query NAME)")
    return start, goal


def _load_grid(args: argparse.Namespace, map_path: Path):
    import planner

    options = {} if args.resolution is None else {"resolution": args.resolution}
    return planner.OccupancyGrid.from_file(map_path, **options)


def _single_options(args: argparse.Namespace) -> dict:
    """planner.plan options from the command line; unset ones keep the planner's defaults.

    Every option given is passed on, so one the chosen planner does not take (say --heuristic with
    --planner hybrid) is reported by the planner as an error rather than silently ignored.
    """
    names = {
        "connectivity": args.connectivity,
        "heuristic": args.heuristic,
        "heuristic_weight": args.heuristic_weight,
        "configuration": args.configuration,
        "expansion_distance": args.expansion_distance,
        "corner_cutting": args.corner_cutting,
        "untrusted_points": args.untrusted_points,
        "smoothing": None if args.smoothing in (None, "none") else args.smoothing,
        "min_turning_radius": args.min_turning_radius,
        "reverse": args.reverse,
    }
    options = {name: value for name, value in names.items() if value is not None}
    options["planner"] = args.planner
    return options


# -- running and timing ----------------------------------------------------------------------------
def timed_plan(grid, start, goal, options: dict, repeat: int):
    """One untimed run (compiles the search), then `repeat` runs; (result, median elapsed [s])."""
    import planner

    if repeat < 1:
        raise CosimError(f"--repeat must be >= 1, got {repeat}")
    endpoints = (start, goal) if options.get("planner") == "hybrid" else (start[:2], goal[:2])
    result = planner.plan(grid, *endpoints, **options)
    elapsed = []
    for _ in range(repeat):
        result = planner.plan(grid, *endpoints, **options)
        elapsed.append(result.elapsed)
    return result, statistics.median(elapsed)


def plan_panel(title: str, grid, result, options: dict):
    """A plot panel with the cells the search could not enter: inflated zone and untrusted points.

    Uses the options the planner resolved (result.info["options"]) when it reports them, so presets
    such as configuration="modified" show what they switched on.
    """
    from cosim.cli.plan_plot import PlanPanel
    from planner.inflation import dilate_square, inflation_mask

    settings = result.info.get("options", options) if isinstance(result.info, dict) else options
    expansion = settings.get("expansion_distance") or 0.0
    inflated = inflation_mask(grid, expansion) if expansion else None
    untrusted = None
    if settings.get("untrusted_points"):
        # The planner's rule: a free cell with an obstacle or inflated cell among its 8 neighbours.
        closed = grid.occupied if inflated is None else grid.occupied | inflated
        untrusted = dilate_square(closed) & ~closed
    return PlanPanel(title, result, inflated, untrusted)


def format_table(row_labels: list[str], columns: dict[str, list[str]]) -> str:
    """A plain-text table: one row per metric, one right-aligned column per configuration."""
    label_width = max(len(label) for label in row_labels)
    widths = {name: max(len(name), *(len(cell) for cell in cells)) for name, cells in columns.items()}
    lines = [" " * label_width + "".join(f"  {name:>{widths[name]}}" for name in columns)]
    for index, label in enumerate(row_labels):
        cells = "".join(f"  {columns[name][index]:>{widths[name]}}" for name in columns)
        lines.append(f"{label:<{label_width}}{cells}")
    return "\n".join(lines)


METRICS = ("path length [m]", "path nodes", "searched nodes", "elapsed time [s]")


def _metric_cells(result, elapsed: float) -> list[str]:
    return [f"{result.length:.2f}", str(result.path_nodes), str(result.searched_nodes), f"{elapsed:.6f}"]


def _header(map_path: Path, grid, start, goal) -> str:
    rows, cols = grid.shape
    start_text, goal_text = (", ".join(f"{value:g}" for value in point) for point in (start, goal))
    return (
        f"map {map_path} ({cols} x {rows} cells, {grid.resolution:g} m/cell)\n"
        f"start ({start_text})  goal ({goal_text})"
    )


def effective_options(grid, options: dict) -> str:
    """Every option the search ran with, as `planner.plan` resolves them (defaults, then the preset,
    then the given ones), the given ones marked with *."""
    if options.get("planner") == "hybrid":
        from planner.hybrid import resolve_hybrid_options

        hybrid = {name: value for name, value in options.items() if name != "planner"}
        resolved = {"planner": "hybrid", **resolve_hybrid_options(grid, hybrid)}
    else:
        from planner.options import resolve

        resolved = resolve(options)
        resolved.pop("bidirectional")  # said by planner
    given = set(options)

    def shown(value) -> str:
        if isinstance(value, float):
            return f"{value:g}"
        return "none" if value is None else str(value)

    return ", ".join(
        f"{name} {shown(value)}{'*' if name in given else ''}" for name, value in resolved.items()
    )


# The `cosim plan` options that give a comparison column's planner options.
_FLAGS = {
    "planner": "--planner",
    "configuration": "--configuration",
    "heuristic": "--heuristic",
    "expansion_distance": "--expansion-distance",
    "min_turning_radius": "--min-turning-radius",
}


def reproducing_command(map_path: Path, start, goal, options: dict) -> str:
    """The `cosim plan` command that plans one comparison column alone, with the same result."""
    import shlex

    hybrid = options.get("planner") == "hybrid"
    points = [point if len(point) == 3 or not hybrid else (*point, 0.0) for point in (start, goal)]
    if not hybrid:
        points = [point[:2] for point in points]
    words = ["cosim", "plan", str(map_path)]
    for option, point in zip(("--start", "--goal"), points, strict=True):
        words.append(f"{option}={','.join(f'{value:g}' for value in point)}")
    for name, value in options.items():
        if not (name == "planner" and value == "astar"):
            words += [_FLAGS[name], f"{value:g}" if isinstance(value, float) else str(value)]
    return shlex.join(words)


def _timing_note(repeat: int) -> str:
    return (
        f"elapsed time: search only, median of {repeat} runs after one untimed run that loads "
        "the search's C kernel"
    )


def _plan_one(args: argparse.Namespace, map_path: Path) -> int:
    hybrid = args.planner == "hybrid"
    grid = _load_grid(args, map_path)
    start, goal = _endpoints(args, map_path, with_heading=hybrid)
    options = _single_options(args)
    result, elapsed = timed_plan(grid, start, goal, options, args.repeat)
    print(_header(map_path, grid, start, goal))
    print(f"options (* given, the rest the planner's defaults): {effective_options(grid, options)}")
    print(format_table(list(METRICS), {"value": _metric_cells(result, elapsed)}))
    print(_timing_note(args.repeat))
    if args.png is not None:
        from cosim.cli import plan_plot

        panel = plan_panel(
            f"{args.planner} ({args.configuration or 'default'} configuration)", grid, result, options
        )
        plan_plot.save_plan_png(args.png, grid, panel, start, goal, suptitle=f"{map_path.name}: planned path")
        print(f"wrote {args.png}")
    return 0


def compare_configurations(expansion_distance: float) -> list[Configuration]:
    """The columns of Tables 3.1-3.4: MATLAB-like basic A*, the thesis's improvements, inflation, eq 3.6.

    "modified" keeps basic's Euclidean h so that its column shows the improvements alone
    (untrusted points, OPEN-list replacement); "inflated + new h" switches to eq 3.6.
    """
    modified = {"configuration": "modified", "heuristic": "euclidean"}
    return [
        Configuration("basic", {"configuration": "basic"}),
        Configuration("modified", modified),
        Configuration("inflated", {**modified, "expansion_distance": expansion_distance}),
        Configuration(
            "inflated + new h", {**modified, "expansion_distance": expansion_distance, "heuristic": "thesis"}
        ),
    ]


def hybrid_available() -> bool:
    """True when planner/hybrid.py exists (imported lazily: the grid planner never needs it)."""
    return importlib.util.find_spec("planner.hybrid") is not None


def _compare(args: argparse.Namespace, map_path: Path) -> int:
    from cosim.cli import plan_plot

    grid = _load_grid(args, map_path)
    start, goal = _endpoints(args, map_path, with_heading=False)
    expansion = DEFAULT_COMPARE_EXPANSION if args.expansion_distance is None else args.expansion_distance
    configurations = compare_configurations(expansion)
    notes = []
    if hybrid_available():
        hybrid_options = {"planner": "hybrid", "expansion_distance": expansion}
        if args.min_turning_radius is not None:
            hybrid_options["min_turning_radius"] = args.min_turning_radius
        configurations.append(Configuration("hybrid", hybrid_options))
        if len(start) == 2 or len(goal) == 2:
            notes.append("hybrid: no heading given, start and goal heading 0 rad assumed")
    else:
        notes.append("hybrid column omitted: planner.hybrid is not available in this installation")
    with_heading = [point if len(point) == 3 else (*point, 0.0) for point in (start, goal)]
    columns, panels = {}, []
    for configuration in configurations:
        result, elapsed = timed_plan(grid, *with_heading, configuration.options, args.repeat)
        columns[configuration.label] = _metric_cells(result, elapsed)
        panels.append(plan_panel(configuration.label, grid, result, configuration.options))
    print(_header(map_path, grid, start, goal))
    print(format_table(list(METRICS), columns))
    print(_timing_note(args.repeat))
    print(
        f"basic: plannerAStarGrid-like (Euclidean h, no decrease-key, corner cutting); modified: untrusted "
        f"points + OPEN-list replacement, no corner cutting; inflated: expansion distance {expansion:g} m; "
        "new h: eq 3.6"
    )
    print("each column alone (the same search as its column):")
    for configuration in configurations:
        print(f"  {configuration.label}: {reproducing_command(map_path, start, goal, configuration.options)}")
    for note in notes:
        print(f"note: {note}")
    if args.png is not None:
        plan_plot.save_comparison_png(
            args.png, grid, panels, start, goal, suptitle=f"{map_path.name}: planner comparison"
        )
        print(f"wrote {args.png}")
    return 0
