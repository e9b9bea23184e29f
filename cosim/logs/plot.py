"""Draw a run: the trajectory over the map, and time series of its signals.

Left: the map panel (`cosim.logs.plot_map`): map, inflated zone, unknown obstacles, every plan the
run had (older ones fainter, reverse segments marked), the driven trajectory with where the
avoider took over (the mixer's mode: 1 avoid, 2 recover), the start and each goal given. Right:
one panel per signal over time, with the avoid/recover intervals shaded; the distance to the goal
is to the goal in force at each time. Several runs (`cosim log plot A.mcap B.mcap`) overlay: the
first run's map, each run's trajectory, last plan, goal and signals in its own colour, named by
its file's stem.

Two sources give the same picture: a log (`plot_run`, `plot_log`: `cosim log plot`), or the
`cosim.record.recorder.RunTrace` a run kept in memory while writing that log (`plot_trace`: the PNG
`cosim run` draws, without reading the log back). Both are first reduced to a `PlotData` (the
arrays drawn) by the same code; then `draw` makes the figure: matplotlib's Agg canvas without
pyplot, fixed margins (no layout engine), and one artist per kind of thing (a single RGBA image for
the map and its inflated zone, one collection for the obstacles, their tracks, each mode's shading),
text boxes naming each panel's series (no legend per panel), ticks only inside the view, the
panels' grid lines and tick marks as two lines per axis (matplotlib's own pixels:
tests/logs/test_plot_render.py), each text's layout kept in the process by the canvas' renderer
(`_canvas_class`) and from one process to the next (`cosim.logs.kept_text`), the cyclic garbage
collector paused, and the PNG written straight from the canvas (`write_png`).
`cosim run` drafts its figure while the run goes (`Draft`: the map frame drawn from the scenario,
the panels' ticks made, the run drawn over it after), lays out its likely texts ahead
(`likely_texts`, `warm_text`) and draws the map and the panels in two processes: the same pixels.
matplotlib is imported when a plot is drawn, not with this module.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType, SimpleNamespace
from typing import TYPE_CHECKING

import numpy as np

from cosim.errors import CosimError
from cosim.logs.plot_data import MODE_AVOID, MODE_COLORS, ZONE_RGBA, PlotData, Series, mode_name
from cosim.logs.plot_map import draw_map, draw_map_frame, draw_map_run, draw_overlay_map, run_colour

if TYPE_CHECKING:
    from cosim.logs.reader import Log, Signals, Trajectory

# The avoider (the `vfh` role's FMU) by its model name: VFH by default, or the one that replaced it.
AVOIDERS = {"VectorFieldHistogram": "VFH", "ArtificialPotentialField": "APF"}
DPI = 110
GRID_ALPHA = 0.3  # the panels' grid lines
# The ticks a drafted panel's axis makes ahead (`Draft`: a tick is five artists, ~1 ms of CPU): its
# view holds 3 to 8, a panel's y axis mostly 3 to 5, the time axis mostly 6 to 8. Each y axis makes
# the first few with the draft, the rest while the run goes, when there is time (`Draft.more_ticks`).
TICKS_AHEAD = 8
Y_TICKS_DRAFTED = 4

# Where the default series come from, in order of preference (each must be in the trace's
# `TRACE_SIGNALS`, so that the plot of a run's trace is the plot of its log).
SPEED = [("vehicle", "v_actual"), ("mixer", "v"), ("vehicle", "v")]
STEERING = [("vehicle", "steering_angle_actual"), ("mixer", "steering_angle")]
TURNING = [("vehicle", "omega_actual"), ("mixer", "omega"), ("vehicle", "yaw_rate")]
DIRECTIONS = [
    ("pure_pursuit", "target_dir", "target direction (pure pursuit)"),
    ("vfh", "steering_dir", "{avoider} steering direction"),
]


def plot_run(log_path: str | Path, png_path: str | Path) -> Path:
    """Write the run's overview PNG (trajectory over the map and the default signals) from its log."""
    from cosim.logs.reader import open_log

    with open_log(log_path) as log:
        return plot_log(log, Path(png_path))


def plot_log(log: Log, png_path: Path, signals: list[str] | None = None, dpi: float = DPI, size=None) -> Path:
    """Draw `log` to `png_path`. `signals` are "component.variable" names; None = the defaults
    (speed, angular velocity or steering angle, VFH steering direction, minimum range, distance
    to the goal). `dpi` and `size` as `draw`'s. Returns the PNG path."""
    return draw(collect(log, signals), png_path, dpi, size)


def plot_logs(
    logs: list, png_path: Path, signals: list[str] | None = None, dpi: float = DPI, size=None
) -> Path:
    """Overlay the runs of `logs` in one picture (each in its own colour, named by its file's stem);
    otherwise as `plot_log`."""
    return draw([collect(log, signals) for log in logs], png_path, dpi, size)


def plot_trace(trace, png_path: str | Path) -> Path:
    """Draw the default plot of a run from its `RunTrace` (the same picture as `plot_run` of its log)."""
    return draw(collect(TraceSource(trace)), png_path)


def collect(source, signals: list[str] | None = None) -> PlotData:
    """The arrays the plot of `source` (a `Log`, or a `TraceSource`) shows."""
    data = collect_signals(source, signals)
    collect_map(data, source)
    return data


def collect_signals(source, signals: list[str] | None = None) -> PlotData:
    """`collect` without the map panel's arrays (`collect_map` adds them): the series, the mixer's
    modes, the title and names, which the panels need (`cosim.cli.plotter` sends them first)."""
    series = _chosen_series(source, signals) if signals else _default_series(source)
    return PlotData(
        _title(source),
        series=series,
        modes=_modes(source),
        label=source.path.stem,
        avoider=avoider_name(source.metadata),
    )


# --- a run's trace, read as a log -------------------------------------------------------------


class TraceSource:
    """A `cosim.record.recorder.RunTrace` behind the part of the `Log` interface the plot uses,
    each value decoded as `cosim.logs.reader` decodes the log's."""

    def __init__(self, trace) -> None:
        if trace.dropped:
            raise CosimError(f"{trace.path}: the run's trace was dropped (too long a run): plot its log")
        self.trace = trace
        self.path = trace.path
        self.metadata = trace.metadata
        self.is_complete = trace.complete
        self.components = list(trace.components)
        self._signals: dict[str, Signals] = {}

    @property
    def scenario_name(self) -> str | None:
        return self.metadata.get("navcosim", {}).get("scenario_name")

    @property
    def outcome(self) -> dict[str, bool | int | float | str] | None:
        from cosim.logs.reader import typed_value

        written = self.metadata.get("outcome")
        return None if written is None else {key: typed_value(text) for key, text in written.items()}

    def signals(self, component: str) -> Signals:
        from cosim.logs.reader import Signals

        if component not in self._signals:
            blocks = self.trace.signal_blocks.get(component, [])
            names = next((names for c, names, _ in self.trace.columns.values() if c == component), [])
            t_ns = np.concatenate([t for t, _ in blocks]) if blocks else np.zeros(0, dtype=np.int64)
            values = np.vstack([rows for _, rows in blocks]) if blocks else np.zeros((0, len(names)))
            self._signals[component] = Signals(component, t_ns / 1e9, t_ns, names, names, values, [])
        return self._signals[component]

    def map(self, topic: str = "/map"):
        from planner.grid import OccupancyGrid

        if topic not in self.trace.grids:
            return None
        occupied, resolution, origin = self.trace.grids[topic]
        return OccupancyGrid(occupied, resolution, origin)

    def plans(self) -> list[tuple[float, np.ndarray]]:
        from cosim.record.rosmsg import path_poses

        decoded = getattr(self.trace, "plan_poses", None)  # (`joined_trace`: decoded already)
        if decoded is not None:
            return [(t_ns / 1e9, poses) for t_ns, poses in decoded]
        return [(t_ns / 1e9, path_poses(message)) for t_ns, message in self.trace.plans]

    def goals(self) -> list[tuple[float, float, float]]:
        from cosim.logs.reader import metadata_goal

        if self.trace.goals:
            return [(t_ns / 1e9, m.pose.position.x, m.pose.position.y) for t_ns, m in self.trace.goals]
        goal = metadata_goal(self.metadata)  # (a log without /goal: its start time; never drawn)
        return [] if goal is None else [(0.0, *goal)]

    def obstacles(self) -> list:
        from cosim.logs.reader import _marker_shapes

        message = self.trace.obstacles_message()
        return [] if message is None else _marker_shapes(message)

    def obstacle_tracks(self) -> list[np.ndarray]:
        tracks: dict[int, list[tuple[float, float, float]]] = {}
        for t_ns, key, x, y in self.trace.obstacle_markers:
            tracks.setdefault(key, []).append((t_ns / 1e9, x, y))
        return [np.array(tracks[key], dtype=float) for key in sorted(tracks)]

    def trajectory(self) -> Trajectory | None:
        from cosim.logs.reader import Trajectory

        if "vehicle" in self.components:
            vehicle = self.signals("vehicle")
            if all(name in vehicle for name in ("x", "y", "theta")):
                return Trajectory(vehicle.t, vehicle["x"], vehicle["y"], vehicle["theta"])
        if not self.trace.poses:
            return None
        rows = np.vstack(self.trace.poses)
        # rosmsg.yaw_of of the logged quaternion (0, 0, qz, qw), as the reader takes it
        theta = np.array([np.arctan2(2.0 * (w * z), 1.0 - 2.0 * (z * z)) for z, w in rows[:, 3:5]])
        return Trajectory(rows[:, 0] / 1e9, rows[:, 1], rows[:, 2], theta)

    def goal(self) -> tuple[float, float] | None:
        from cosim.logs.reader import final_goal

        return final_goal(self.metadata, self.goals)

    def start(self) -> tuple[float, float, float] | None:
        from cosim.logs.reader import start_pose

        return start_pose(self.metadata, self.trajectory)

    def min_ranges(self) -> tuple[np.ndarray, np.ndarray] | None:
        if not self.trace.scan_t_ns:
            return None
        return np.array(self.trace.scan_t_ns) / 1e9, np.array(self.trace.scan_minima)


# What of a `RunTrace` its plot reads: the panels' part (`collect_signals`: the signals, scans,
# poses and goals, the title's metadata) and the map's (`collect_map`: the grids, plans, obstacles).
TRACE_PANEL_PARTS = (
    "path", "metadata", "complete", "dropped", "components", "columns", "signal_blocks", "poses",
    "scan_t_ns", "scan_minima", "goals",
)  # fmt: skip
TRACE_MAP_PARTS = ("grids", "obstacle_markers")


def trace_parts(trace) -> tuple[SimpleNamespace, SimpleNamespace]:
    """The parts of `trace` (a `RunTrace`) the plot reads, as plain values that pickle without the
    trace's own modules: (the panels' part, the map's part, which holds the last /obstacles message
    as `obstacles`, and each plan's poses as `plan_poses`: (t [ns], N x 3 array) each, which pickle
    ten times faster than the messages). `cosim run` sends them to its plot process, which gathers
    the `PlotData` itself (`TraceSource` of `joined_trace`), so that this process need not import
    the log reader (~5 ms) once the run has ended."""
    from cosim.record.rosmsg import path_poses

    panels = SimpleNamespace(**{name: getattr(trace, name) for name in TRACE_PANEL_PARTS})
    mapped = SimpleNamespace(**{name: getattr(trace, name) for name in TRACE_MAP_PARTS})
    mapped.obstacles = trace.obstacles_message()
    mapped.plan_poses = [(t_ns, path_poses(message)) for t_ns, message in trace.plans]
    return panels, mapped


def joined_trace(panels: SimpleNamespace, mapped: SimpleNamespace | None = None) -> SimpleNamespace:
    """A trace `TraceSource` reads from the two parts of `trace_parts` (without the map's part:
    the panels' only, no obstacles, grids or plans)."""
    joined = SimpleNamespace(**vars(panels), grids={}, plans=[], obstacle_markers=[])
    obstacles = None
    if mapped is not None:
        vars(joined).update((name, value) for name, value in vars(mapped).items() if name != "obstacles")
        obstacles = mapped.obstacles
    joined.obstacles_message = lambda: obstacles
    return joined


# --- what is drawn ----------------------------------------------------------------------------


def outcome_text(outcome: dict | None, complete: bool) -> str:
    """How a run ended, in words: "goal reached at t = 74.2 s", "goal NOT reached (collision)"."""
    if outcome is None:
        return "no outcome recorded" + ("" if complete else " (log cut short)")
    if outcome.get("reached") is True:
        time = outcome.get("time")
        return f"goal reached at t = {float(time):.1f} s" if time else "goal reached"
    return f"goal NOT reached ({outcome.get('reason', 'unknown reason')})"


def _title(source) -> str:
    name = source.scenario_name or source.path.stem
    outcome = source.outcome
    result = outcome_text(outcome, source.is_complete)
    distance = outcome.get("distance") if outcome else None
    tail = f", driven {float(distance):.1f} m" if distance else ""
    return f"{name}: {result}{tail}\n{source.path.name}"


def map_image(grid, inflated) -> np.ndarray:
    """One 8-bit RGBA image of the map: occupied cells dark, free cells white, the inflated zone
    (inflated but not occupied) blended over the free cells; row 0 at the top, as `grid.occupied`.
    Bytes as matplotlib would make of the colours (x 255, truncated), so it draws them as they
    are instead of converting the whole image each time."""
    colours = np.array([(1.0, 1.0, 1.0, 1.0), (0.15, 0.15, 0.15, 1.0), (0.0, 0.0, 0.0, 1.0)])
    alpha = ZONE_RGBA[3]
    colours[2, :3] = alpha * np.array(ZONE_RGBA[:3]) + (1.0 - alpha)
    kind = np.where(grid.occupied, 1, 0)
    if inflated is not None and inflated.shape == grid.shape:
        kind[inflated.occupied & ~grid.occupied] = 2
    return (colours * 255).astype(np.uint8)[kind]


def draw_grid(axes, log) -> tuple[list, list[np.ndarray]]:
    """Draw the known map (occupied cells) and the planner's inflated zone as one image; returns the
    legend handles and the map's corners [m] (a bounds entry), both empty without a /map."""
    from matplotlib.patches import Patch

    grid, inflated = log.map("/map"), log.map("/map_inflated")
    if grid is None:
        return [], []
    extent = _extent(grid)
    axes.imshow(map_image(grid, inflated), extent=extent, origin="upper", interpolation="nearest", zorder=0)
    handles = [Patch(color="0.15", label="map: occupied")]
    if inflated is not None and inflated.shape == grid.shape:
        handles.insert(0, Patch(color=ZONE_RGBA[:3], label="inflated zone (planner)"))
    return handles, [np.array([[extent[0], extent[2]], [extent[1], extent[3]]])]


def _extent(grid) -> tuple[float, float, float, float]:
    rows, cols = grid.shape
    x0, y0 = grid.origin
    return (x0, x0 + cols * grid.resolution, y0, y0 + rows * grid.resolution)


def collect_map(data: PlotData, source) -> None:
    """Add the map panel's arrays of `source` to `data` (`collect_signals`' of it): the map, the
    obstacles, plans, trajectory, start and goals, and the view."""
    bounds: list[np.ndarray] = []  # points that must be inside the view [m]
    grid, inflated = source.map("/map"), source.map("/map_inflated")
    if grid is not None:
        data.image = map_image(grid, inflated)
        data.has_zone = inflated is not None and inflated.shape == grid.shape
        data.extent = _extent(grid)
        x0, x1, y0, y1 = data.extent
        bounds.append(np.array([[x0, y0], [x1, y1]]))
    data.obstacles = [np.asarray(obstacle.polygon(), dtype=float) for obstacle in source.obstacles()]
    data.tracks = [track[:, 1:3] for track in source.obstacle_tracks() if len(track) > 1]
    for t, poses in source.plans():
        if len(poses):
            data.plans.append((t, poses[:, :2]))
            data.reverse.append(reverse_segments(poses))
    trajectory = source.trajectory()
    if trajectory is not None and len(trajectory.t):
        data.trajectory = np.column_stack((trajectory.x, trajectory.y))
        bounds.append(data.trajectory)
        outcome = source.outcome or {}
        if outcome.get("reached") is not True:
            reason = outcome.get("reason", "log ends" if source.outcome is None else "end")
            data.end = (float(trajectory.x[-1]), float(trajectory.y[-1]), reason)
        if data.modes is not None:
            mode_t, mode_values = data.modes
            at = np.searchsorted(mode_t, trajectory.t, side="right") - 1
            mode_here = np.where(at >= 0, mode_values[np.clip(at, 0, len(mode_values) - 1)], 0)
            for mode in MODE_COLORS:
                where = mode_here == mode
                if np.any(where):
                    data.mode_points[mode] = data.trajectory[where]
    data.start, data.goal, data.goals = source.start(), source.goal(), source.goals()
    tolerance = source.metadata.get("navcosim", {}).get("goal_tolerance")
    data.tolerance = float(tolerance) if tolerance else None
    for point in (data.start, data.goal, *(goal[1:] for goal in data.goals)):
        if point is not None:
            bounds.append(np.array([point[:2]]))
    bounds += [points for _, points in data.plans]
    data.limits = view_limits(bounds)


def view_limits(bounds: list[np.ndarray]) -> tuple[float, float, float, float] | None:
    """The map view (x0, x1, y0, y1) [m] that shows every point of `bounds` (N x 2 arrays [m]),
    with a margin; None for no points."""
    if not bounds:
        return None
    low, high = np.min(np.vstack(bounds), axis=0), np.max(np.vstack(bounds), axis=0)
    margin = 0.03 * max(float(np.max(high - low)), 1.0)
    return (low[0] - margin, high[0] + margin, low[1] - margin, high[1] + margin)


def reverse_segments(poses: np.ndarray) -> np.ndarray:
    """Per segment of a path of N poses (x, y [m], heading [rad]), whether it is driven in reverse:
    it leads backwards from the heading at its first pose. A run logs a grid planner's pose facing
    the next one (never reverse), a Hybrid A* pose with the car's heading, which is the tangent of
    the curve forwards and its opposite in reverse (a sampled arc's chord is within half its
    angle, well under 90 degrees, of the tangent); at a cusp the heading is the same before and
    after while the direction of travel turns round."""
    if len(poses) < 2:
        return np.zeros(0, dtype=bool)
    step = np.diff(poses[:, :2], axis=0)
    along = step[:, 0] * np.cos(poses[:-1, 2]) + step[:, 1] * np.sin(poses[:-1, 2])
    return along < 0.0


def goal_distance(goals, t: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Distance [m] from (x, y) at times t [s] to the goal in force at each time: the last of `goals`
    ((t, x, y) each, in time order) given at or before it (the first before any was given)."""
    goal_t = np.array([goal[0] for goal in goals])
    points = np.array([goal[1:] for goal in goals], dtype=float).reshape(-1, 2)
    at = np.clip(np.searchsorted(goal_t, t, side="right") - 1, 0, len(goals) - 1)
    return np.hypot(x - points[at, 0], y - points[at, 1])


def avoider_name(metadata: dict) -> str:
    """The avoider a run used, from its `fmu/vfh` metadata: "VFH", "APF", or the FMU's model name."""
    model = metadata.get("fmu/vfh", {}).get("model_name", "")
    return AVOIDERS.get(model, model or "VFH")


def _modes(source) -> tuple[np.ndarray, np.ndarray] | None:
    if "mixer" not in source.components:
        return None
    mixer = source.signals("mixer")
    return (mixer.t, np.rint(mixer["mode"]).astype(int)) if "mode" in mixer else None


def _first(source, candidates: list[tuple[str, str]]):
    for component, name in candidates:
        if component in source.components:
            signals = source.signals(component)
            if name in signals:
                return component, name, signals
    return None


def _default_series(source) -> list[Series]:
    series = []
    speed = _first(source, SPEED)
    if speed:
        component, name, signals = speed
        series.append(Series(f"{component}.{name}", "m/s", signals.t, signals[name], "speed"))
    steering = _first(source, STEERING)
    is_bicycle = source.metadata.get("navcosim", {}).get("vehicle_type", "") == "bicycle" or (
        "vehicle" in source.components and "steering_angle_actual" in source.signals("vehicle")
    )
    turning = steering if is_bicycle and steering else _first(source, TURNING)
    if turning:
        component, name, signals = turning
        unit = "rad" if "steering" in name else "rad/s"
        series.append(Series(f"{component}.{name}", unit, signals.t, signals[name], "turning"))
    avoider = avoider_name(source.metadata)
    for component, name, label in DIRECTIONS:
        found = _first(source, [(component, name)])
        if found:
            series.append(
                Series(label.format(avoider=avoider), "rad", found[2].t, found[2][name], "direction")
            )
    ranges = source.min_ranges() if isinstance(source, TraceSource) else _min_range(source)
    if ranges is not None:
        series.append(Series("minimum lidar range (/scan)", "m", *ranges, "range"))
    trajectory, goals = source.trajectory(), source.goals()
    if trajectory is not None and goals:
        distance = goal_distance(goals, trajectory.t, trajectory.x, trajectory.y)
        label = "distance to the goal" + (" in force" if len(goals) > 1 else "")
        series.append(Series(label, "m", trajectory.t, distance, "goal"))
    return series


def _chosen_series(log: Log, names: list[str]) -> list[Series]:
    series = []
    for text in names:
        component, _, name = text.partition(".")
        if not name:
            raise CosimError(f"--signals {text!r}: expected COMPONENT.VARIABLE, e.g. vehicle.v_actual")
        signals = log.signals(component)
        values = signals[name]  # (an unknown name: the error that lists the known ones)
        series.append(Series(text, signals.unit(name), signals.t, values, text))
    return series


def _min_range(log: Log) -> tuple[np.ndarray, np.ndarray] | None:
    """Per scan the shortest finite range [m] within the scan's limits (NaN when every beam missed)."""
    if not log.has_topic("/scan"):
        return None
    times, minima = [], []
    for item in log.messages("/scan"):
        ranges = np.asarray(item.message.ranges, dtype=float)
        valid = ranges[
            np.isfinite(ranges) & (ranges >= item.message.range_min) & (ranges <= item.message.range_max)
        ]
        times.append(item.t)
        minima.append(valid.min() if len(valid) else np.nan)
    return np.array(times), np.array(minima)


# --- drawing ----------------------------------------------------------------------------------


@contextmanager
def collector_paused():
    """Pause Python's cyclic garbage collector for the block, then restore it as it was. Importing
    matplotlib and drawing one figure make ~100k objects: in a process that holds many (a run's),
    the collector would walk them all a few times over (0.1-0.2 s here). The figure is freed by
    reference counting, its cycles when the collector runs again."""
    import gc

    collecting = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if collecting:
            gc.enable()


def skip_matplotlib_docstrings() -> None:
    """For a process that draws and exits (`cosim run`): before matplotlib is imported, have it skip
    writing the property list into each artist class's `set()` docstring (matplotlib builds them
    at import for `help()`: about 0.15 s of the plot's time), and the keyword signature of each
    artist class's `set()` (for `help()` and `inspect.signature`; made from the names of the
    class's setters at import, ~20 ms of CPU): each class's `set()` then is its parent's, which
    takes the same keywords the same way (`Artist.set`). Drawing is unaffected; a no-op when
    matplotlib is already imported or has no such step."""
    import sys

    if "matplotlib.figure" in sys.modules:
        return
    with collector_paused():
        import matplotlib.artist

    if callable(getattr(matplotlib.artist, "kwdoc", None)):
        matplotlib.artist.kwdoc = lambda artist: ""
    artist = getattr(matplotlib.artist, "Artist", None)
    if callable(getattr(artist, "_update_set_signature_and_docstring", None)):
        artist._update_set_signature_and_docstring = classmethod(lambda cls: None)


def prepare_drawing() -> None:
    """Import what `draw` uses and load the font its texts are set in: the work of a plot that
    does not depend on the data (`cosim.cli.plotter` does it while the run goes). For a process
    that draws the run's figures and exits (`skip_matplotlib_docstrings`), and draws no 3-D axes:
    matplotlib's projections are registered without the 3-D one (`_without_3d_axes`); nor, most
    likely, usetex text: the glyph names only it reads run when first used (`_glyph_names_when_used`)."""
    import importlib

    skip_matplotlib_docstrings()
    _glyph_names_when_used()
    with collector_paused(), _without_3d_axes():
        for module in ("backends.backend_agg", "figure", "collections", "lines", "patches", "ticker"):
            importlib.import_module(f"matplotlib.{module}")
        from matplotlib.font_manager import FontProperties, findfont, get_font

        get_font(findfont(FontProperties()))


def _glyph_names_when_used() -> None:
    """Before matplotlib's text modules are first imported: `fontTools.agl` (Adobe's glyph names,
    which `matplotlib.dviread` imports and reads only for text drawn with usetex; importing it
    builds its tables, ~10 ms of CPU) is put in place as a module that runs when first used."""
    runs_when_used("fontTools.agl")


def runs_when_used(name: str) -> ModuleType | None:
    """Put the module `name` (of a package: "package.module") in place without running its code,
    which runs when a name it does not hold yet is first looked up in it (`_RunsWhenUsed`); it is
    bound in its package as an import binds it. The module, or None (and nothing done) when it
    is imported already or cannot be found."""
    import importlib.util
    import sys

    if name in sys.modules:
        return None
    try:
        spec = importlib.util.find_spec(name)
    except ImportError:  # (no such package: its importer then says so)
        return None
    if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
        return None
    module = importlib.util.module_from_spec(spec)
    module.__class__ = _RunsWhenUsed
    sys.modules[name] = module
    package, _, child = name.rpartition(".")
    if package:
        setattr(sys.modules[package], child, module)
    return module


class _RunsWhenUsed(ModuleType):
    """A module whose code has not run yet: it runs (its loader's `exec_module`) when a name it does
    not hold yet is looked up, which is then looked up in the module as it is made. Its import
    attributes (`__spec__`, `__name__`, ...) are there before: an import of it, which reads them,
    does not run it."""

    def __getattr__(self, name: str):
        import sys

        self.__class__ = ModuleType
        try:
            self.__spec__.loader.exec_module(self)
        except BaseException:
            sys.modules.pop(self.__name__, None)  # as a failed import leaves it: imported anew next time
            raise
        return getattr(self, name)


@contextmanager
def _without_3d_axes():
    """While matplotlib's projections are first imported (`matplotlib.projections`, which every
    figure imports): `mpl_toolkits.mplot3d` is a module without `Axes3D`, as matplotlib takes it
    where that cannot be imported, so the 3-D projection (~5-10 ms of CPU to import) is not
    registered. The real package is imported if anything asks for it afterwards. A no-op when the
    projections or the 3-D toolkit are imported already."""
    import sys

    name = "mpl_toolkits.mplot3d"
    if "matplotlib.projections" in sys.modules or name in sys.modules:
        yield
        return
    placeholder = ModuleType(name, "A stand-in without Axes3D: no 3-D projection (cosim.logs.plot).")
    placeholder.Axes3D = None
    sys.modules[name] = placeholder
    try:
        yield
    finally:
        if sys.modules.get(name) is placeholder:
            del sys.modules[name]


# Text set in the same font, size and pixel density is laid out the same wherever it is drawn:
# its size (`RendererAgg.get_text_width_height_descent`) and its glyphs and their offsets (the
# layout `draw_text` makes) are kept here per (text, font, dpi, hinting), for every figure of the
# process. Laying a text out is most of the time matplotlib spends on it (shaping, with fallback
# fonts: ~15 us per character, twice per text: for its size and to draw it); a process that knows
# which texts it will draw lays them out ahead (`warm_text`: the plot process, while the run goes).
# What an earlier process laid out is read from the file `cosim.logs.kept_text` keeps, before a
# text is laid out here (a run's ~300 texts: most of them the same from run to run).
_TEXT_SIZES: dict = {}
_TEXT_GLYPHS: dict = {}
_FONT_HEIGHTS: dict = {}
_CANVAS: list = []
if hasattr(os, "register_at_fork"):
    # The glyphs' fonts (FT2Font) must not be used in a forked process, which would read their
    # files through the parent's file offsets: dropped there, as matplotlib drops its own fonts.
    os.register_at_fork(after_in_child=_TEXT_GLYPHS.clear)


def _canvas_class():
    """The Agg canvas of the run's figure: matplotlib's, whose renderer keeps each text's layout
    (`_TEXT_SIZES`, `_TEXT_GLYPHS`) and each font's height metrics (`_FONT_HEIGHTS`), and draws a
    text glyph by glyph as matplotlib's own `draw_text` does (the same pixels). These follow
    matplotlib 3.11's private code (it draws text so since 3.11); with another version only the
    sizes are kept, the rest is matplotlib's own."""
    if _CANVAS:
        return _CANVAS[0]
    import math

    import matplotlib
    from matplotlib import ft2font
    from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg, get_hinting_flag

    from cosim.logs import kept_text

    RenderMode = getattr(ft2font, "RenderMode", None)
    NORMAL, MONO = (RenderMode.NORMAL, RenderMode.MONO) if RenderMode is not None else (None, None)
    known = matplotlib.__version__.split(".")[:2] == ["3", "11"]  # the version this follows

    class Renderer(RendererAgg):
        glyph_by_glyph = (
            known and RenderMode is not None and hasattr(RendererAgg, "_draw_text_glyphs_and_boxes")
        )

        def get_text_width_height_descent(self, s, prop, ismath):
            if ismath:
                return super().get_text_width_height_descent(s, prop, ismath)
            flags = get_hinting_flag()
            key = (s, hash(prop), self.dpi, flags)  # FontProperties are equal by hash
            size = _TEXT_SIZES.get(key)
            if size is None:
                size = kept_text.size_of(s, prop, self.dpi, flags)  # laid out by an earlier process
                if size is None:
                    size = super().get_text_width_height_descent(s, prop, ismath)
                    kept_text.remember_size(s, prop, self.dpi, flags, size)
                _TEXT_SIZES[key] = size
            return size

        def _get_font_height_metrics(self, prop):
            # matplotlib's Text asks its renderer for this first (else it reads the font's tables
            # itself for every text it lays out): the same numbers, kept per font and dpi
            key = (hash(prop), self.dpi)
            heights = _FONT_HEIGHTS.get(key)
            if heights is None:
                heights = _FONT_HEIGHTS[key] = _font_height_metrics(prop, self.dpi)
            return heights

        def draw_text(self, gc, x, y, s, prop, angle, ismath=False, mtext=None):
            if (
                ismath
                or not self.glyph_by_glyph
                or (mtext is not None and (mtext.get_fontfeatures() or mtext.get_language()))
            ):
                return super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
            # matplotlib's `_draw_text_glyphs_and_boxes` for a text without boxes, but each font's
            # size set once, not before each glyph (that doubled the time of each glyph's bitmap)
            cos, sin = math.cos(math.radians(angle)), math.sin(math.radians(angle))
            matrix = (0x10000 * np.array([[cos, -sin], [sin, cos]])).round().astype(int).tolist()
            flags = get_hinting_flag()
            mono = not gc.get_antialiased()
            mode = MONO if mono else NORMAL
            size = prop.get_size_in_points()
            sized = set()
            height = self.height
            top = int(height)
            blend = self._renderer.draw_text_image
            for font, glyph, dx, dy in self.text_glyphs(s, prop, flags):  # dy is upwards
                if font not in sized:
                    font.set_size(size, self.dpi)
                    sized.add(font)
                font._set_transform(
                    matrix,
                    (
                        round(0x40 * (x + dx * cos - dy * sin)),
                        round(0x40 * (height - y + dx * sin + dy * cos)),
                    ),
                )
                bitmap = font._render_glyph(glyph, flags, mode)
                buffer = bitmap.buffer
                if mono:
                    buffer *= 0xFF
                blend(buffer, bitmap.left, top - bitmap.top + buffer.shape[0], 0, gc)

        def text_glyphs(self, s, prop, flags=None) -> list:
            """(font, glyph index, x, y) of each glyph of `s` set in `prop`, as `draw_text` lays
            it out (`flags`: the hinting flags, by default rcParams')."""
            if flags is None:
                flags = get_hinting_flag()
            key = (s, hash(prop), self.dpi, flags)
            glyphs = _TEXT_GLYPHS.get(key)
            if glyphs is None:
                font = self._prepare_font(prop)
                kept = kept_text.glyphs_of(s, prop, self.dpi, flags)  # laid out by an earlier process
                if kept is not None:
                    glyphs = [(font, glyph, x, y) for glyph, x, y in kept]
                else:
                    items = font._layout(s, flags=flags, features=None, language=None)
                    glyphs = [(item.ft_object, item.glyph_index, item.x, item.y) for item in items]
                    if all(item.ft_object is font for item in items):  # (no fallback font: kept)
                        kept_text.remember_glyphs(s, prop, self.dpi, flags, [glyph[1:] for glyph in glyphs])
                _TEXT_GLYPHS[key] = glyphs
            return glyphs

    class Canvas(FigureCanvasAgg):
        def get_renderer(self):
            w, h = self.get_width_height(physical=True)
            key = w, h, self.figure.dpi
            if self._lastKey != key:
                self.renderer = Renderer(w, h, self.figure.dpi)
                self._lastKey = key
            return self.renderer

    if not known:  # (Text uses this when its renderer has it)
        del Renderer._get_font_height_metrics
    Canvas.renderer_class = Renderer
    _CANVAS.append(Canvas)
    return Canvas


canvas_class = _canvas_class  # public: the canvas other figures (sweep.png) draw with too


def _font_height_metrics(prop, dpi: float) -> tuple:
    """(ascent, descent, line gap) [px] of the font of `prop`, the numbers matplotlib's `Text` lays a
    line out with when its renderer does not give them: the font's typographic metrics of its OS/2
    table, or where it has none its hhea table's, in font units scaled to pixels by
    size [pt] * dpi / 72 / units per em (in that order of operations, so the floats are the same);
    (None, None, None) without either table (it then measures the text "lp" instead)."""
    from matplotlib.font_manager import fontManager, get_font

    font = get_font(fontManager._find_fonts_by_props(prop))
    os2 = font.get_sfnt_table("OS/2")
    if os2 is not None:
        units = os2["sTypoAscender"], os2["sTypoDescender"], os2["sTypoLineGap"]
    else:
        hhea = font.get_sfnt_table("hhea")
        if hhea is None:
            return None, None, None
        units = hhea["ascent"], hhea["descent"], hhea["lineGap"]
    pixels = 1 / font.get_sfnt_table("head")["unitsPerEm"] * prop.get_size_in_points() * dpi / 72
    ascent, descent, gap = units
    return ascent * pixels, -descent * pixels, gap * pixels


def warm_text(texts, stop=lambda: False, dpi: float = DPI) -> None:
    """Lay out ahead each (text, font size [pt]) of `texts` (in the default font) as the run's
    figure would (its size, and its glyphs where they are kept), until `stop()` is true (asked
    before each)."""
    from matplotlib.font_manager import FontProperties

    renderer = _canvas_class().renderer_class(1, 1, dpi)
    fonts: dict = {}
    for text, size in texts:
        if stop():
            return
        prop = fonts.get(size) or fonts.setdefault(size, FontProperties(size=size))
        renderer.get_text_width_height_descent(text, prop, False)
        if renderer.glyph_by_glyph:
            renderer.text_glyphs(text, prop)


def likely_texts(map_part: bool, numbers: bool = True) -> list[tuple[str, float]]:
    """The texts (text, font size [pt]) the part of a run's figure drawn after the run (`Draft`:
    with `map_part` the map's legend, else the panels) most likely holds, the likeliest first, for
    `warm_text`: the map's legend entries; the panels' units, names and (with `numbers`) tick
    labels as matplotlib's default formatter writes them (~250: the whole numbers, halves,
    quarters, tenths and twentieths the panels' views most often step by). In the order the runs
    of the shipped scenarios use them: with the first 45 laid out, 2 of their ~30 panel texts per
    run are not (12 with the names first and the numbers by step). A text not among them is laid
    out when drawn, as any other."""
    if map_part:
        legend = [  # what the runs of the shipped scenarios show first (one replan, VFH), then the rest
            "inflated zone (planner)", "map: occupied", "unknown obstacles (lidar only)",
            "plan in force at the end (of 2)", "earlier plans (older: fainter)", "replanned here", "plan",
            "driven trajectory", mode_name(MODE_AVOID, next(iter(AVOIDERS.values()))),
            "start (and heading)", "goal (tolerance circle)",
            "moving obstacles: tracks (last pose drawn)", "plan: reverse segments",
            "goal at the end (tolerance circle)", "earlier goal", "earlier goals",
            *(f"end: {reason}" for reason in ("collision", "stop_time", "no_path", "interrupted")),
            *(mode_name(mode, avoider) for avoider in AVOIDERS.values() for mode in MODE_COLORS),
            *(f"plan in force at the end (of {count})" for count in range(3, 13)),
        ]  # fmt: skip
        return list(dict.fromkeys([("lp", 8.0)] + [(text, 8.0) for text in legend]))
    # The likeliest first (what the runs of the shipped scenarios show): the units, the default
    # names of a vehicle with pure pursuit and VFH, the tick labels their views step by (whole
    # numbers, tens, halves); then the other names, and the other numbers.
    avoider = next(iter(AVOIDERS.values()))
    names = [f"{component}.{name}" for component, name in (SPEED[0], TURNING[0])]
    names += [label.format(avoider=avoider) for _, _, label in DIRECTIONS]
    names += ["minimum lidar range (/scan)", "distance to the goal", mode_name(MODE_AVOID, avoider)]
    more_names = [f"{component}.{name}" for component, name in SPEED + STEERING + TURNING]
    more_names += [label.format(avoider=name) for _, _, label in DIRECTIONS for name in AVOIDERS.values()]
    more_names += ["distance to the goal in force"]
    more_names += [mode_name(mode, name) for name in AVOIDERS.values() for mode in MODE_COLORS]
    labels = ["lp", "time [s]", "[m/s]", "[rad]", "[m]", "[rad/s]"]

    def number(value: float, decimals: int) -> str:
        return f"{value:.{decimals}f}".replace("-", "\N{MINUS SIGN}")

    ticks, rest = [], []
    if numbers:  # as the panels' views most often step (seconds, metres, m/s, radians)
        ticks += [number(value, 0) for value in (*range(-2, 11), *range(20, 101, 10))]
        ticks += [number(k / 2, 1) for k in range(-3, 4)]
        rest += [number(value, 0) for value in range(-10, 31)]
        rest += [number(value, 0) for value in range(30, 101) if value % 5 == 0 or value % 2 == 0]
        rest += [number(k / 2, 1) for k in range(-10, 11)] + [number(k / 4, 2) for k in range(-20, 21)]
        rest += [number(k / 10, 1) for k in range(-30, 31)] + [number(k / 20, 2) for k in range(-20, 21)]
        rest += [number(value, 0) for value in range(100, 301, 5) if value % 10 == 0 or value % 25 == 0]
    texts = [("lp", 8.0)] + [(text, 10.0) for text in labels] + [(name, 8.0) for name in names]
    texts += [(text, 10.0) for text in ticks] + [(name, 8.0) for name in more_names]
    texts += [(text, 10.0) for text in rest]
    return list(dict.fromkeys(texts))


def draw(data: PlotData | list[PlotData], png_path: str | Path, dpi: float = DPI, size=None) -> Path:
    """Render `data` (one run, or a list of runs to overlay) to a PNG (Agg, no pyplot, no display);
    `dpi` [pixels per inch]; `size` (width, height) [px], by default 15 in wide and as high as the
    panels need. Returns its path."""
    with collector_paused():
        figure = build_figure(data, dpi, size)
        png_path = Path(png_path)
        png_path.parent.mkdir(parents=True, exist_ok=True)
        write_png(png_path, np.asarray(figure.canvas.buffer_rgba()), dpi)  # the figure is opaque
        return png_path


def figure_size(rows: int, size=None, dpi: float = DPI) -> tuple[float, float]:
    """The figure's (width, height) [in]: `size` [px] at `dpi`, else 15 in by 1.9 in per panel row
    (at least 7.5 in)."""
    if size is not None:
        return size[0] / dpi, size[1] / dpi
    return 15.0, max(7.5, 1.9 * rows)


def build_figure(data: PlotData | list[PlotData], dpi: float = DPI, size=None, title: str | None = None):
    """The drawn figure of `data` (its canvas drawn): `draw` writes its pixels; the map is
    `figure.axes[0]`, then the panels top to bottom. `title` replaces the picture's own."""
    runs = data if isinstance(data, list) else [data]
    if not runs:
        raise CosimError("no run to plot")
    panels = _panels(runs)
    if title is None:
        title = runs[0].title if len(runs) == 1 else _overlay_title(runs)
    figure, grid = _new_figure(len(panels), title.count("\n") + 1, dpi, size)
    map_axes = figure.add_subplot(grid[:, 0])
    if len(runs) == 1:
        draw_map(map_axes, runs[0])
    else:
        draw_overlay_map(map_axes, runs)
    _ticks_in_view(map_axes)
    _draw_panels(figure, grid, panels, runs)
    figure.suptitle(title, fontsize=13)
    figure.canvas.draw()
    return figure


def _panels(runs: list[PlotData]) -> dict[str, list[tuple[int, Series]]]:
    """The series of `runs` by panel, in order: (run index, series) each."""
    panels: dict[str, list[tuple[int, Series]]] = {}
    for index, run in enumerate(runs):
        for item in run.series:
            panels.setdefault(item.panel, []).append((index, item))
    return panels


def _new_figure(panels: int, title_lines: int, dpi: float, size):
    """An empty figure on an Agg canvas for a map and `panels` rows of panels, under a title of
    `title_lines` lines: (figure, grid spec: the map spans column 0, the panels column 1)."""
    from matplotlib.figure import Figure

    rows = max(panels, 1)
    width, height = figure_size(rows, size, dpi)
    figure = Figure(figsize=(width, height), dpi=dpi)
    _canvas_class()(figure)
    # Fixed margins [inches] instead of a layout engine: room for the title above, the map's
    # legend below it, and the panels' tick labels.
    grid = figure.add_gridspec(
        rows,
        2,
        width_ratios=(1.15, 1.0),
        left=0.825 / width,
        right=1.0 - 0.225 / width,
        top=1.0 - (0.75 + 0.22 * max(title_lines - 2, 0)) / height,
        bottom=0.55 / height,
        wspace=0.14,
        hspace=0.12,
    )
    return figure, grid


def _draw_panels(figure, grid, panels, runs: list[PlotData], made=None) -> list:
    """The panels (`_draw_series`), their ticks fixed; returns the panels' axes."""
    panel_axes = _draw_series(figure, grid, panels, runs, made)
    for axes in panel_axes:
        _ticks_in_view(axes)
    _panel_ticks(panel_axes)
    return panel_axes


class Draft:
    """The figure of a run drawn ahead, while the run goes, from what is known before it (`cosim
    run`'s plot process: `cosim.cli.plotter`): the layout for the panels `preview` has (only how
    many matters) and the map frame of `preview` (`draw_map_frame`: the map image, the view's
    limits, ticks, labels; the view is the map and the start and goal with a margin, which a run
    inside the map does not widen). When the run's data has the same frame (`fits`), `finish` draws
    only the rest over those pixels: the run over the map and its legend, the panels, the title,
    each artist as `build_figure` draws it and in the same order (what the frame holds lies under
    all of it), so the picture is `draw`'s. Otherwise it is drawn afresh by `draw`."""

    def __init__(self, preview: PlotData, dpi: float = DPI) -> None:
        self.preview = preview
        self.dpi = dpi
        self.rows = len(_panels([preview]))
        with collector_paused():
            self.figure, self.grid = _new_figure(self.rows, preview.title.count("\n") + 1, dpi, None)
            self.map_axes = self.figure.add_subplot(self.grid[:, 0])
            draw_map_frame(self.map_axes, preview)
            _ticks_in_view(self.map_axes)
            self.panel_axes = _panel_axes(self.figure, self.grid, self.rows)  # drawn by `finish`
            for axes in self.panel_axes:
                axes.set_visible(False)
            canvas = self.figure.canvas
            canvas.draw()  # (its pixels are drawn over once: `draw_run`; no copy of them is kept)
            self._drawn = False
            for axes in self.panel_axes:
                axes.set_visible(True)
                if axes.get_facecolor() == self.figure.get_facecolor() and axes.get_facecolor()[3] == 1.0:
                    # its opaque background would cover the same colour of the frame: not drawn
                    axes.patch.set_visible(False)
            for axis in [axes.yaxis for axes in self.panel_axes] + [self.panel_axes[-1].xaxis]:
                _tick_marks_off(axis)  # as `_panel_ticks` has them, before the ticks are made
                # made here, not after the run; a y axis' likely further ones by `more_ticks`
                axis.get_major_ticks(TICKS_AHEAD if axis is self.panel_axes[-1].xaxis else Y_TICKS_DRAFTED)
                axis.get_minor_ticks(1)  # (an axis makes one even with none to draw)

    def more_ticks(self, stop=lambda: False) -> None:
        """Make the panels' y axes' ticks up to `TICKS_AHEAD` each, one round of one more tick per
        axis at a time, until `stop()` is true (asked before each tick, ~1 ms, not each round of
        them: the run's data waits no longer than a tick): the ticks a panel is less likely to
        draw, made while the run goes when there is time for them (a tick made ahead or when
        drawn: the same)."""
        axes = [panel.yaxis for panel in self.panel_axes]
        for count in range(Y_TICKS_DRAFTED + 1, TICKS_AHEAD + 1):
            for axis in axes:
                if stop():
                    return
                with collector_paused():
                    axis.get_major_ticks(count)

    def fits(self, data: PlotData) -> bool:
        """Whether `data` has the drafted frame: the same map image and view, panel rows and title lines."""
        preview = self.preview
        return (
            len(_panels([data])) == self.rows
            and data.title.count("\n") == preview.title.count("\n")
            and data.limits is not None
            and data.limits == preview.limits
            and data.extent == preview.extent
            and data.has_zone == preview.has_zone
            and data.image is not None
            and preview.image is not None
            and data.image.shape == preview.image.shape
            and bool(np.array_equal(data.image, preview.image))
        )

    def finish(self, data: PlotData, png_path: str | Path) -> Path:
        """Draw `data` to a PNG at `png_path` (as `draw` does), over the draft when it fits."""
        if not self.fits(data):
            return draw(data, png_path, self.dpi)
        self.draw_run(data)
        return self.write(png_path)

    def draw_run(self, data: PlotData, map_part: bool = True, panels: slice = slice(None)) -> None:
        """Draw `data` (which `fits`) over the drafted frame: with `map_part` the run over the map,
        its legend and the title, and the panels `panels` (top to bottom; `slice(0)`: none). Parts
        can be drawn by copies of the draft in two processes (`cosim.cli.plotter`) and their
        pixels put together (`map_boxes`, `panels_box`). Once per draft: it draws over the frame's
        pixels, of which no copy is kept (a copy of the whole canvas, ~5 ms of the draft's time)."""
        with collector_paused():
            figure, axes = self.figure, self.map_axes
            canvas = figure.canvas
            renderer = canvas.get_renderer()
            if self._drawn:  # (the canvas holds the frame only until then)
                raise RuntimeError("a draft is drawn over once: make another for another picture")
            self._drawn = True
            if map_part:
                drafted = set(axes.get_children())
                draw_map_run(axes, data)
                figure.suptitle(data.title, fontsize=13)
                added = [artist for artist in axes.get_children() if artist not in drafted]
                for artist in sorted(added, key=lambda artist: artist.get_zorder()):  # as Axes.draw sorts
                    artist.draw(renderer)
            if range(self.rows)[panels]:  # every panel's artists: they share the time axis's limits
                made = self.panel_axes or None
                self.panel_axes = _draw_panels(figure, self.grid, _panels([data]), [data], made)
                for panel in self.panel_axes[panels]:
                    panel.draw(renderer)
            if map_part:
                for text in figure.texts:  # drawn after every axes, as a figure draws them
                    text.draw(renderer)

    def pixels(self) -> np.ndarray:
        """The canvas' RGBA pixels (rows x columns x 4, row 0 at the top), writable."""
        return np.asarray(self.figure.canvas.buffer_rgba())

    def map_boxes(self) -> list[tuple[int, int, int, int]]:
        """(top, bottom, left, right) [pixel rows and columns, end excluded] around what the map
        part of `draw_run` drew over the frame: the map's axes (its artists are clipped to them)
        with the legend and the texts written on the map (which may reach out of it), and the
        title. From these few boxes: a tight box of every artist costs a seventh of the part's time."""
        renderer = self.figure.canvas.get_renderer()
        axes = self.map_axes
        boxes = [axes.bbox] + [text.get_window_extent(renderer) for text in axes.texts]
        if axes.get_legend() is not None:
            boxes.append(axes.get_legend().get_window_extent(renderer))
        titles = [self._pixel_box([text.get_window_extent(renderer)]) for text in self.figure.texts]
        return [self._pixel_box(boxes), *titles]

    def panels_box(self, panels: slice = slice(None)) -> tuple[int, int, int, int]:
        """As `map_boxes`, one box around the panels `panels` (top to bottom), to the right edge
        of the figure: their axes, their y labels (left of their tick labels), the
        y tick labels in view (which may stand out above or below an axes), the tick marks under
        an upper panel, the bottom one's time tick labels and label. From these few texts: a tight
        box of every artist costs a tenth of the panels' time."""
        import matplotlib as mpl
        from matplotlib.transforms import Bbox

        renderer = self.figure.canvas.get_renderer()
        every = self.figure.axes[1:]
        chosen = every[panels]
        marks = mpl.rcParams["xtick.major.size"] * self.dpi / 72.0 + 1.0  # [px] under an upper panel
        boxes = []
        for axes in chosen:
            boxes += [axes.bbox, axes.yaxis.label.get_window_extent(renderer)]
            boxes += _tick_label_boxes(axes.yaxis, axes.get_ylim(), renderer)
            if axes is every[-1]:
                boxes.append(axes.xaxis.label.get_window_extent(renderer))
                boxes += _tick_label_boxes(axes.xaxis, axes.get_xlim(), renderer)
            else:
                x0, y0, x1, _ = axes.bbox.extents
                boxes.append(Bbox.from_extents(x0, y0 - marks, x1, y0))
        top, bottom, left, _ = self._pixel_box(boxes)
        return top, bottom, left, self.pixels().shape[1]

    def _pixel_box(self, boxes, margin: int = 2) -> tuple[int, int, int, int]:
        from matplotlib.transforms import Bbox

        box = Bbox.union([box for box in boxes if box is not None])
        height, width = self.pixels().shape[:2]
        top = max(int(np.floor(height - box.y1)) - margin, 0)
        bottom = min(int(np.ceil(height - box.y0)) + margin, height)
        left = max(int(np.floor(box.x0)) - margin, 0)
        right = min(int(np.ceil(box.x1)) + margin, width)
        return top, bottom, left, right

    def write(self, png_path: str | Path, rows: np.ndarray | None = None, last_half=None) -> Path:
        """Write the canvas to a PNG at `png_path` (`rows`: its `png_rows`, made before;
        `last_half`: the second half of them compressed: `write_png`); returns its path."""
        png_path = Path(png_path)
        png_path.parent.mkdir(parents=True, exist_ok=True)
        write_png(png_path, self.pixels(), self.dpi, rows, last_half)
        return png_path


def _tick_label_boxes(axis, limits, renderer) -> list:
    """The window boxes of the tick labels `axis` draws for a view of `limits`: as its last draw
    measured them (`_label_boxes_once`: the same boxes, ~70 us a label less), else measured here."""
    drawn = getattr(axis, "_drawn_label_boxes", None)
    if drawn is not None:
        return drawn
    low, high = sorted(limits)
    return [
        tick.label1.get_window_extent(renderer)
        for tick in axis.get_major_ticks()
        if tick.label1.get_visible() and low <= tick.get_loc() <= high
    ]


def _overlay_title(runs: list[PlotData]) -> str:
    lines = [f"{len(runs)} runs overlaid"]
    for run in runs:
        result, _, _ = run.title.partition("\n")
        lines.append(f"{run.label}: {result.partition(': ')[2] or result}")
    return "\n".join(lines)


def png_rows(pixels: np.ndarray, into: np.ndarray | None = None) -> np.ndarray:
    """The rows of a PNG of `pixels` (as `write_png` takes them) before compression: per row a
    filter byte (0: none) and the RGB bytes (rows x (1 + 3 x columns)); written `into` that
    array when given (e.g. memory shared with another process)."""
    height, width = pixels.shape[:2]
    rows = np.empty((height, 1 + 3 * width), dtype=np.uint8) if into is None else into
    rows[:, 0] = 0
    copy_rgb(rows[:, 1:], pixels)
    return rows


def copy_rgb(rows: np.ndarray, pixels: np.ndarray) -> None:
    """Copy the RGB bytes of `pixels` (rows x columns x 3 or 4) into `rows` (rows x 3 columns), one
    colour at a time: numpy copies 3 bytes of each pixel at once several times slower (~13 ms for
    a run's picture here, ~2 ms so)."""
    into = rows.reshape(pixels.shape[0], pixels.shape[1], 3)
    for colour in range(3):
        into[:, :, colour] = pixels[:, :, colour]


def png_halves(height: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """The two halves of a PNG's rows (`write_png`) as (first row, end row) each."""
    return (0, height // 2), (height // 2, height)


def deflate_half(part: np.ndarray, last: bool) -> tuple[bytes, int]:
    """A half of a PNG's rows (`png_halves`) compressed as `write_png` does it: a raw deflate
    stream at level 1, the first half ended on a byte boundary (a sync flush), the `last` one
    closed; and the half's Adler-32 checksum."""
    import zlib

    stream = zlib.compressobj(1, zlib.DEFLATED, -15)  # raw: no zlib header or checksum
    body = stream.compress(part) + stream.flush(zlib.Z_FINISH if last else zlib.Z_SYNC_FLUSH)
    return body, zlib.adler32(part)


def write_png(
    path: Path, pixels: np.ndarray, dpi: float, rows: np.ndarray | None = None, last_half=None
) -> None:
    """Write an 8-bit RGB image (rows x columns x 3, or x 4 whose 4th byte is left out; row 0 at
    the top) as a PNG: no filter on the rows and zlib level 1. A plot is mostly flat colour, so this
    is a quarter larger than Pillow's default (adaptive filters, level 6) in a tenth of its time,
    and a third of Pillow's time at level 1. The rows are compressed in two halves side by side
    (zlib lets other threads run): each half a raw deflate stream, the first ended on a byte
    boundary without closing the stream (a sync flush), so the two are one stream, as pigz does;
    the stream's checksum is put together from the halves' (`_adler32_combine`). `rows`: the
    image's `png_rows`, made before (then `pixels` only gives the size); `last_half`: a function
    that gives their second half compressed (`deflate_half`: another process compresses it, and
    is asked once the first half is done here), or None where it could not (then it is done
    here). The pixel density (`dpi`) is recorded as Pillow and matplotlib record it."""
    import struct
    import threading
    import zlib

    height, width = pixels.shape[:2]
    copy = rows is None
    if copy:
        rows = np.empty((height, 1 + 3 * width), dtype=np.uint8)  # a filter byte (0: none) per row
    halves = png_halves(height)
    done: list = [None, None]

    def deflate(index: int) -> None:
        low, high = halves[index]
        part = rows[low:high]
        if copy:
            part[:, 0] = 0
            copy_rgb(part[:, 1:], pixels[low:high])
        done[index] = deflate_half(part, index == 1)

    if last_half is None:
        second = threading.Thread(target=deflate, args=(1,))
        second.start()
        deflate(0)
        second.join()
    else:
        deflate(0)
        done[1] = last_half()
    if done[1] is None:  # (the thread or the other process failed: its half again, here)
        deflate(1)
    (first, first_sum), (last, last_sum) = done
    checksum = _adler32_combine(first_sum, last_sum, rows[halves[1][0] :].nbytes)
    compressed = b"\x78\x01" + first + last + struct.pack(">I", checksum)

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    per_metre = int(dpi / 0.0254 + 0.5)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))  # 8-bit RGB
        + chunk(b"pHYs", struct.pack(">IIB", per_metre, per_metre, 1))
        + chunk(b"IDAT", compressed)
        + chunk(b"IEND", b"")
    )


def _adler32_combine(first: int, second: int, second_length: int) -> int:
    """The Adler-32 checksum of two byte strings one after the other, from each one's (`second`
    of `second_length` bytes), as zlib's adler32_combine: the first sum (1 + the bytes, mod 65521)
    adds up; the second (the sum of the first sums after each byte) gains the first string's
    first sum minus 1 once per byte of the second."""
    base = 65521
    low = ((first & 0xFFFF) + (second & 0xFFFF) - 1) % base
    high = ((first >> 16) + (second >> 16) + second_length * ((first & 0xFFFF) - 1)) % base
    return (high << 16) | low


def _ticks_in_view(axes) -> None:
    """Fix each axis' major ticks to the locations its default locator gives inside the view.
    That locator also returns a location beyond each end, never drawn, but matplotlib builds a
    tick (five artists) for each: a quarter of the figure's ticks. The ticks drawn are the same.
    An axis with fewer than two ticks in view keeps its locator: the tick labels' number format
    then depends on the ticks outside the view too."""
    from matplotlib.ticker import FixedLocator

    for axis, limits in ((axes.xaxis, axes.get_xlim()), (axes.yaxis, axes.get_ylim())):
        locations = _in_view(axis.get_majorticklocs(), limits)
        if len(locations) >= 2:
            axis.set_major_locator(FixedLocator(locations))
        _label_boxes_once(axis)


def _label_boxes_once(axis) -> None:
    """Have `axis` place its label, when drawn, from the boxes of the tick labels it has just
    measured for itself. matplotlib 3.11's `Axis.draw` updates its ticks and measures their labels
    (`_get_ticklabel_bboxes`), draws the ticks, then places the axis label from the boxes of the
    tick labels of the axis and of the axes it is aligned with (`_get_tick_boxes_siblings`), which
    updates and measures the same ticks again when it is aligned with none (nothing changed
    them in between: the same boxes, the same label position). With another version, or a figure
    that aligns labels, matplotlib's own steps. A no-op for an axis so already."""
    import matplotlib

    if "_get_tick_boxes_siblings" in vars(axis) or matplotlib.__version__.split(".")[:2] != ["3", "11"]:
        return
    measured: list = []
    measure, siblings = axis._get_ticklabel_bboxes, axis._get_tick_boxes_siblings

    def get_ticklabel_bboxes(ticks, renderer=None):
        boxes = measure(ticks, renderer)
        measured[:] = [boxes]
        return boxes

    def get_tick_boxes_siblings(renderer):
        name = axis._get_axis_name()
        groups = axis.get_figure(root=False)._align_label_groups
        if measured and name in groups and groups[name].get_siblings(axis.axes) == [axis.axes]:
            return measured[0]
        return siblings(renderer)

    def draw(renderer):
        measured.clear()  # (only what this draw measures)
        try:
            return type(axis).draw(axis, renderer)
        finally:
            # the boxes of the tick labels it drew, for `Draft.panels_box` (`_tick_label_boxes`)
            axis._drawn_label_boxes = measured[0][0] if measured else None
            measured.clear()

    axis._get_ticklabel_bboxes = get_ticklabel_bboxes
    axis._get_tick_boxes_siblings = get_tick_boxes_siblings
    axis.draw = draw


def _in_view(locations, limits) -> list[float]:
    """The tick `locations` matplotlib draws for an axis showing `limits`."""
    low, high = sorted(limits)
    slack = 1e-10 * (high - low)  # as matplotlib's own test of which ticks to draw
    return [float(loc) for loc in locations if low - slack <= loc <= high + slack]


def _panel_ticks(panel_axes: list) -> None:
    """The panels' grid (on, at `GRID_ALPHA`) and tick marks, drawn as two line artists per axis
    (`_tick_lines`) instead of by their axes, which keep only their tick labels: the time axis of
    the bottom panel, which labels the time axis they share, and every y axis; the other panels'
    time axes are hidden (they would draw texts that are not shown). An axis builds five artists
    per tick and draws two lines per tick: these were most of the panels' ticks' time. The same
    lines, styles, clipping and drawing order (an axis draws at zorder 1.5; a panel's time axis
    before its y axis), so the same pixels (tests/logs/test_plot_render.py)."""
    for axes in panel_axes:
        _tick_lines(axes, axes.xaxis)
        _tick_lines(axes, axes.yaxis)
        if axes is panel_axes[-1]:
            _tick_marks_off(axes.xaxis)
        else:
            axes.xaxis.set_visible(False)
        _tick_marks_off(axes.yaxis)


def _tick_marks_off(axis) -> None:
    """No tick marks drawn by `axis` (its labels stay): `_tick_lines` draws them. A no-op for an
    axis whose ticks are so already (`Draft` makes its panels' ticks so)."""
    if axis.majorTicks[0].tick1line.get_visible():
        axis.set_tick_params(which="major", tick1On=False)


def _tick_lines(axes, axis) -> None:
    """Draw the grid lines and tick marks of `axis` (of `axes`: its x or y axis) at its ticks in
    view as one line artist each, as the axis would draw them with its grid on (`GRID_ALPHA`)."""
    import matplotlib as mpl
    from matplotlib.lines import TICKDOWN, TICKLEFT, TICKRIGHT, TICKUP, Line2D

    rc = mpl.rcParams
    along_x = axis is axes.xaxis
    locations = np.array(_in_view(axis.get_majorticklocs(), axes.get_xlim() if along_x else axes.get_ylim()))
    if not len(locations):
        return
    ends = np.tile([0.0, 1.0, np.nan], len(locations))  # one path: a grid line, then NaN, per tick
    at = np.repeat(locations, 3)
    at[2::3] = np.nan
    transform = axes.get_xaxis_transform if along_x else axes.get_yaxis_transform
    axes.add_artist(
        Line2D(
            *((at, ends) if along_x else (ends, at)),
            transform=transform("grid"),
            color=rc["grid.color"],
            alpha=GRID_ALPHA,
            linestyle=rc["grid.linestyle"],
            linewidth=rc["grid.linewidth"],
            zorder=1.5,
        )
    )
    name = "xtick" if along_x else "ytick"
    marks = {"out": (TICKDOWN, TICKLEFT), "in": (TICKUP, TICKRIGHT), "inout": ("|", "_")}
    zeros = np.zeros(len(locations))
    axes.add_artist(
        Line2D(
            *((locations, zeros) if along_x else (zeros, locations)),
            transform=transform("tick1"),
            linestyle="none",
            marker=marks[rc[f"{name}.direction"]][0 if along_x else 1],
            color=rc[f"{name}.color"],
            markeredgecolor=rc[f"{name}.color"],
            markersize=rc[f"{name}.major.size"],
            markeredgewidth=rc[f"{name}.major.width"],
            clip_on=False,
            zorder=1.5,
        )
    )


LINE_STYLES = ("-", "--", ":", "-.")  # the series of one run that share a panel, in an overlay


def _panel_axes(figure, grid, rows: int) -> list:
    """The panels' axes, top to bottom in the grid's column 1, sharing the time axis."""
    made: list = []
    for row in range(rows):
        made.append(figure.add_subplot(grid[row, 1], sharex=made[0] if made else None))
    return made


def _draw_series(
    figure, grid, panels: dict[str, list[tuple[int, Series]]], runs: list[PlotData], made=None
) -> list:
    """One panel (axes) per entry of `panels` ((run index, series) each), top to bottom, sharing the
    time axis (`made`: those axes, made before: `_panel_axes`); returns them. One run: each series
    in the next default colour, the mixer's modes shaded; an overlay: each run in its colour, a
    panel's series told apart by line style."""
    overlay = len(runs) > 1
    if made is None:
        made = _panel_axes(figure, grid, len(panels))
    drawn = []
    for row, (items, axes) in enumerate(zip(panels.values(), made, strict=False)):
        drawn.append(axes)
        if overlay:
            # the k-th series of each run in this panel gets the k-th style, named as the first run names it
            labels: list[str] = []
            position = dict.fromkeys(range(len(runs)), 0)
            for index, item in items:
                k = position[index]
                position[index] += 1
                if k == len(labels):
                    labels.append(item.label)
                axes.plot(
                    item.t, item.values, LINE_STYLES[k % len(LINE_STYLES)], color=run_colour(index), lw=1.2
                )
            entries = [(f"{label} ({LINE_STYLES[k % len(LINE_STYLES)]})" if len(labels) > 1 else label,
                        "black", None) for k, label in enumerate(labels)]  # fmt: skip
            if row == 0:
                entries += [(run.label, run_colour(index), None) for index, run in enumerate(runs)]
        else:
            lines = [axes.plot(item.t, item.values, lw=1.2)[0] for _, item in items]
            shaded = _shade_modes(axes, runs[0].modes)
            entries = [
                (item.label, line.get_color(), None) for (_, item), line in zip(items, lines, strict=True)
            ]
            if row == 0:  # explain the shading once
                entries += [(mode_name(mode, runs[0].avoider), "black", MODE_COLORS[mode]) for mode in shaded]
        unit = items[0][1].unit
        axes.set_ylabel(f"[{unit}]" if unit else "value")
        _label_panel(axes, entries)  # (its grid: `_panel_ticks`)
        if row == len(panels) - 1:  # the others' time axes are hidden: `_panel_ticks`
            axes.set_xlabel("time [s]")
    if not panels:
        axes = figure.add_subplot(grid[0, 1])
        axes.text(
            0.5, 0.5, "no navcosim signals in this log", ha="center", va="center", transform=axes.transAxes
        )
        axes.set_axis_off()
    return drawn


def _label_panel(axes, entries: list[tuple[str, str, str | None]]) -> None:
    """Name a panel's series in the upper right corner, one box per (text, text colour, shading
    colour or None) entry, stacked: each series in its line's colour, each kind of shading on a
    box of its colour. A text box costs a fifth of what a legend does (a tree of boxes, a handle
    artist per entry) and says the same."""
    from matplotlib.colors import to_rgb

    for index, (text, colour, shading) in enumerate(entries):
        # a shading's colour as the legend drew it, alpha 0.3 over white, but opaque
        face = (1.0, 1.0, 1.0, 0.85) if shading is None else (*(0.3 * np.array(to_rgb(shading)) + 0.7),)
        axes.annotate(
            text,
            (1.0, 1.0),
            xycoords="axes fraction",
            xytext=(-5.0, -5.0 - 14.0 * index),
            textcoords="offset points",
            ha="right",
            va="top",
            fontsize=8,
            color=colour,
            bbox={"boxstyle": "round,pad=0.25", "fc": face, "ec": (0.8, 0.8, 0.8, 0.85)},
            zorder=6,
        )


def mode_intervals(modes, mode: int) -> list[tuple[float, float]]:
    """The (start, end) times [s] in which the mixer was in `mode`."""
    mode_t, mode_values = modes
    active = np.concatenate(([False], mode_values == mode, [False])).astype(int)
    starts = np.flatnonzero(np.diff(active) == 1)
    ends = np.flatnonzero(np.diff(active) == -1)
    return [
        (float(mode_t[start]), float(mode_t[end] if end < len(mode_t) else mode_t[-1]))
        for start, end in zip(starts, ends, strict=True)
    ]


def _shade_modes(axes, modes) -> list[int]:
    """Shade the time intervals in which the mixer avoided (orange) or recovered (red), one
    collection per mode; returns the modes that occur."""
    if modes is None:
        return []
    from matplotlib.collections import PolyCollection

    shaded = []
    for mode, colour in MODE_COLORS.items():
        intervals = mode_intervals(modes, mode)
        if not intervals:
            continue
        shaded.append(mode)
        boxes = [[(a, 0.0), (b, 0.0), (b, 1.0), (a, 1.0)] for a, b in intervals]
        axes.add_collection(
            PolyCollection(boxes, color=colour, alpha=0.15, lw=0, transform=axes.get_xaxis_transform()),
            autolim=False,
        )
    return shaded
