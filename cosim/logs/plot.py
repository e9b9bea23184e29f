"""Draw a run from its log alone: the trajectory over the map, and time series of its signals.

Left: map (occupied cells), inflated zone, unknown obstacles, planned path, driven trajectory,
start and goal, and where VFH took over (the mixer's mode: 1 avoid, 2 recover). Right: one panel
per signal over time, with the avoid/recover intervals shaded.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import patches  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from cosim.errors import CosimError  # noqa: E402
from cosim.logs.reader import Log, open_log  # noqa: E402

MODE_AVOID, MODE_RECOVER = 1, 2
MODE_COLORS = {MODE_AVOID: "#ff9f1c", MODE_RECOVER: "#d62828"}
MODE_NAMES = {MODE_AVOID: "VFH avoiding (mode 1)", MODE_RECOVER: "recovering (mode 2)"}


@dataclass
class Series:
    label: str  # legend text
    unit: str  # y axis unit
    t: np.ndarray  # [s]
    values: np.ndarray
    panel: str  # series with the same panel share an axis


def plot_run(log_path: str | Path, png_path: str | Path) -> Path:
    """Write the run's overview PNG (trajectory over the map and the default signals)."""
    with open_log(log_path) as log:
        return plot_log(log, Path(png_path))


def plot_log(log: Log, png_path: Path, signals: list[str] | None = None) -> Path:
    """Draw `log` to `png_path`. `signals` are "component.variable" names; None = the defaults
    (speed, angular velocity or steering angle, VFH steering direction, minimum range, distance
    to the goal). Returns the PNG path."""
    series = _chosen_series(log, signals) if signals else _default_series(log)
    modes = _modes(log)
    rows = max(len({item.panel for item in series}), 1)
    figure = plt.figure(figsize=(15, max(7.5, 1.9 * rows)), layout="constrained")
    grid = figure.add_gridspec(rows, 2, width_ratios=(1.15, 1.0))
    _draw_map(figure.add_subplot(grid[:, 0]), log, modes)
    _draw_series(figure, grid, series, modes)
    figure.suptitle(_title(log), fontsize=13)
    png_path = Path(png_path)
    png_path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(png_path, dpi=110)
    plt.close(figure)
    return png_path


def _title(log: Log) -> str:
    name = log.scenario_name or log.path.stem
    outcome = log.outcome
    if outcome is None:
        result = "no outcome recorded" + ("" if log.is_complete else " (log cut short)")
    elif outcome.get("reached") == "true":
        time = outcome.get("time")
        result = f"goal reached at t = {float(time):.1f} s" if time else "goal reached"
    else:
        result = f"goal NOT reached ({outcome.get('reason', 'unknown reason')})"
    distance = outcome.get("distance") if outcome else None
    tail = f", driven {float(distance):.1f} m" if distance else ""
    return f"{name}: {result}{tail}\n{log.path.name}"


# --- the map panel ---------------------------------------------------------------------------


def _draw_map(axes, log: Log, modes: tuple[np.ndarray, np.ndarray] | None) -> None:
    handles, bounds = draw_grid(axes, log)
    has_map = bool(bounds)
    obstacles = log.obstacles()
    for obstacle in obstacles:
        axes.add_patch(
            patches.Polygon(obstacle.polygon(), closed=True, color="#c1121f", alpha=0.75, zorder=3)
        )
    if obstacles:
        handles.append(patches.Patch(color="#c1121f", alpha=0.75, label="unknown obstacles (lidar only)"))
    moved = [track for track in log.obstacle_tracks() if len(track) > 1]
    for number, track in enumerate(moved):
        (line,) = axes.plot(
            track[:, 1], track[:, 2], ":", color="#c1121f", lw=1.4, zorder=3,
            label="moving obstacles: tracks (last pose drawn)" if number == 0 else None,
        )  # fmt: skip
        if number == 0:
            handles.append(line)
    plan = log.plan()
    if plan is not None and len(plan):
        (line,) = axes.plot(
            plan[:, 0], plan[:, 1], "--", color="#1d4ed8", lw=1.6, label="planned path (A*)", zorder=4
        )
        handles.append(line)
    trajectory = log.trajectory()
    if trajectory is not None and len(trajectory.t):
        (line,) = axes.plot(
            trajectory.x, trajectory.y, "-", color="#111111", lw=1.4, label="driven trajectory", zorder=5
        )
        handles.append(line)
        bounds.append(np.column_stack((trajectory.x, trajectory.y)))
        reason = (log.outcome or {}).get("reason", "log ends" if log.outcome is None else "end")
        if (log.outcome or {}).get("reached") != "true":
            axes.plot(
                trajectory.x[-1], trajectory.y[-1], marker="X", color="#7b2cbf", ms=11, ls="none", zorder=8
            )
            handles.append(
                Line2D([], [], marker="X", color="#7b2cbf", ls="none", ms=9, label=f"end: {reason}")
            )
        handles += _mark_interventions(axes, trajectory, modes)
    start, goal = log.start(), log.goal()
    if start is not None:
        axes.plot(*start[:2], marker="o", color="#2a9d8f", ms=10, ls="none", zorder=7)
        axes.annotate(
            "",
            xy=(start[0] + np.cos(start[2]), start[1] + np.sin(start[2])),
            xytext=start[:2],
            arrowprops={"arrowstyle": "->", "color": "#2a9d8f", "lw": 2},
            zorder=7,
        )
        handles.append(
            Line2D([], [], marker="o", color="#2a9d8f", ls="none", ms=9, label="start (and heading)")
        )
    if goal is not None:
        axes.plot(*goal, marker="*", color="#e76f51", ms=16, ls="none", zorder=7)
        tolerance = log.metadata.get("navcosim", {}).get("goal_tolerance")
        if tolerance:
            axes.add_patch(
                patches.Circle(goal, float(tolerance), fill=False, ls=":", color="#e76f51", zorder=6)
            )
        handles.append(
            Line2D([], [], marker="*", color="#e76f51", ls="none", ms=13, label="goal (tolerance circle)")
        )
    for point in (start, goal):
        if point is not None:
            bounds.append(np.array([point[:2]]))
    if plan is not None and len(plan):
        bounds.append(plan)
    if bounds:
        low, high = np.min(np.vstack(bounds), axis=0), np.max(np.vstack(bounds), axis=0)
        margin = 0.03 * max(float(np.max(high - low)), 1.0)
        axes.set_xlim(low[0] - margin, high[0] + margin)
        axes.set_ylim(low[1] - margin, high[1] + margin)
    if not has_map and trajectory is None:
        axes.text(
            0.5,
            0.5,
            "no map and no trajectory in this log",
            ha="center",
            va="center",
            transform=axes.transAxes,
        )
    axes.set_aspect("equal", adjustable="box")
    axes.set_xlabel("x [m]")
    axes.set_ylabel("y [m]")
    axes.set_title("trajectory over the map")
    axes.grid(alpha=0.25)
    if handles:  # below the map, so it never hides part of it
        axes.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3, fontsize=8)


def draw_grid(axes, log: Log) -> tuple[list, list[np.ndarray]]:
    """Draw the known map (occupied cells) and the planner's inflated zone; returns the legend
    handles and the map's corners [m] (a bounds entry), both empty without a /map."""
    handles: list = []
    bounds: list[np.ndarray] = []  # points that must be inside the view [m]
    grid, inflated = log.map("/map"), log.map("/map_inflated")
    if grid is not None:
        extent = _extent(grid)
        if inflated is not None and inflated.shape == grid.shape:
            zone = inflated.occupied & ~grid.occupied
            overlay = np.zeros((*zone.shape, 4))
            overlay[zone] = (0.55, 0.7, 0.95, 0.55)
            axes.imshow(overlay, extent=extent, origin="upper", interpolation="nearest", zorder=1)
            handles.append(patches.Patch(color=(0.55, 0.7, 0.95), label="inflated zone (planner)"))
        cells = np.where(grid.occupied, 0.15, 1.0)
        axes.imshow(
            cells,
            cmap="gray",
            vmin=0,
            vmax=1,
            extent=extent,
            origin="upper",
            interpolation="nearest",
            zorder=0,
        )
        handles.append(patches.Patch(color="0.15", label="map: occupied"))
        bounds.append(np.array([[extent[0], extent[2]], [extent[1], extent[3]]]))
    return handles, bounds


def _extent(grid) -> tuple[float, float, float, float]:
    rows, cols = grid.shape
    x0, y0 = grid.origin
    return (x0, x0 + cols * grid.resolution, y0, y0 + rows * grid.resolution)


def _mark_interventions(axes, trajectory, modes) -> list:
    """Colour the trajectory points where the mixer was avoiding or recovering."""
    if modes is None:
        return []
    mode_t, mode_values = modes
    at = np.searchsorted(mode_t, trajectory.t, side="right") - 1
    mode_here = np.where(at >= 0, mode_values[np.clip(at, 0, len(mode_values) - 1)], 0)
    handles = []
    for mode, colour in MODE_COLORS.items():
        where = mode_here == mode
        if np.any(where):
            axes.scatter(trajectory.x[where], trajectory.y[where], s=9, color=colour, zorder=6, linewidths=0)
            handles.append(Line2D([], [], marker="o", color=colour, ls="none", ms=6, label=MODE_NAMES[mode]))
    return handles


# --- time series -----------------------------------------------------------------------------


def _modes(log: Log) -> tuple[np.ndarray, np.ndarray] | None:
    if "mixer" not in log.components:
        return None
    mixer = log.signals("mixer")
    return (mixer.t, np.rint(mixer["mode"]).astype(int)) if "mode" in mixer else None


def _first(log: Log, candidates: list[tuple[str, str]]):
    for component, name in candidates:
        if component in log.components:
            signals = log.signals(component)
            if name in signals:
                return component, name, signals
    return None


def _default_series(log: Log) -> list[Series]:
    series = []
    speed = _first(log, [("vehicle", "v_actual"), ("mixer", "v"), ("vehicle", "v")])
    if speed:
        component, name, signals = speed
        series.append(Series(f"{component}.{name}", "m/s", signals.t, signals[name], "speed"))
    steering = _first(log, [("vehicle", "steering_angle_actual"), ("mixer", "steering_angle")])
    is_bicycle = log.metadata.get("navcosim", {}).get("vehicle_type", "") == "bicycle" or (
        "vehicle" in log.components and "steering_angle_actual" in log.signals("vehicle")
    )
    turning = (
        steering
        if is_bicycle and steering
        else _first(log, [("vehicle", "omega_actual"), ("mixer", "omega"), ("vehicle", "yaw_rate")])
    )
    if turning:
        component, name, signals = turning
        unit = "rad" if "steering" in name else "rad/s"
        series.append(Series(f"{component}.{name}", unit, signals.t, signals[name], "turning"))
    for component, name, label in (
        ("pure_pursuit", "target_dir", "target direction (pure pursuit)"),
        ("vfh", "steering_dir", "VFH steering direction"),
    ):
        found = _first(log, [(component, name)])
        if found:
            series.append(Series(label, "rad", found[2].t, found[2][name], "direction"))
    ranges = _min_range(log)
    if ranges is not None:
        series.append(Series("minimum lidar range (/scan)", "m", *ranges, "range"))
    trajectory, goal = log.trajectory(), log.goal()
    if trajectory is not None and goal is not None:
        distance = np.hypot(trajectory.x - goal[0], trajectory.y - goal[1])
        series.append(Series("distance to the goal", "m", trajectory.t, distance, "goal"))
    return series


def _chosen_series(log: Log, names: list[str]) -> list[Series]:
    series = []
    for text in names:
        component, _, name = text.partition(".")
        if not name:
            raise CosimError(f"--signals {text!r}: expected COMPONENT.VARIABLE, e.g. vehicle.v_actual")
        signals = log.signals(component)
        series.append(Series(text, "", signals.t, signals[name], text))
    return series


def _min_range(log: Log) -> tuple[np.ndarray, np.ndarray] | None:
    """Per scan the shortest finite range [m] (NaN when every beam missed)."""
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


def _draw_series(figure, grid, series: list[Series], modes) -> None:
    panels: dict[str, list[Series]] = {}
    for item in series:
        panels.setdefault(item.panel, []).append(item)
    first_axes = None
    for row, items in enumerate(panels.values()):
        axes = figure.add_subplot(grid[row, 1], sharex=first_axes)
        first_axes = first_axes or axes
        for item in items:
            axes.plot(item.t, item.values, lw=1.2, label=item.label)
        shaded = _shade_modes(axes, modes)
        unit = items[0].unit
        axes.set_ylabel(f"[{unit}]" if unit else "value")
        handles = axes.get_legend_handles_labels()[0]
        if row == 0:  # explain the shading once
            handles += [
                patches.Patch(color=MODE_COLORS[mode], alpha=0.3, label=MODE_NAMES[mode]) for mode in shaded
            ]
        axes.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.85)
        axes.grid(alpha=0.3)
        if row < len(panels) - 1:
            axes.tick_params(labelbottom=False)
        else:
            axes.set_xlabel("time [s]")
    if not panels:
        axes = figure.add_subplot(grid[0, 1])
        axes.text(
            0.5, 0.5, "no navcosim signals in this log", ha="center", va="center", transform=axes.transAxes
        )
        axes.set_axis_off()


def _shade_modes(axes, modes) -> list[int]:
    """Shade the time intervals in which the mixer avoided (orange) or recovered (red); returns
    the modes that occur."""
    if modes is None:
        return []
    mode_t, mode_values = modes
    for mode, colour in MODE_COLORS.items():
        active = np.concatenate(([False], mode_values == mode, [False])).astype(int)
        starts = np.flatnonzero(np.diff(active) == 1)
        ends = np.flatnonzero(np.diff(active) == -1)
        for start, end in zip(starts, ends, strict=True):
            stop = mode_t[end] if end < len(mode_t) else mode_t[-1]
            axes.axvspan(mode_t[start], stop, color=colour, alpha=0.15, lw=0)
    return [mode for mode in MODE_COLORS if np.any(mode_values == mode)]
