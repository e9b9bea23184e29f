"""`sweep.png`: how every point of a sweep ended, and each metric of its goal-reached runs.

The figure is titled with the scenario and the runs by outcome. Its first panel shows how the
points ended (the share of runs that reached the goal); one panel follows per metric that varies
(`time` [s], `distance` [m], ...), its value at a point being the mean over the point's runs that
reached the goal, so a collision's time never mixes in. A metric equal at every point is left out
and named under the figure. Points where a run collided are marked with a red X, where one ended
otherwise without the goal (stop time, no path) with an orange triangle, where one failed with a
black square; with replicates the marks carry the count ("2/5").

Layout by the number of varied keys:
- one key: the panels side by side (up to three a line), each the metric against the key; with
  replicates the mean with a bar of one standard deviation and ticks at the min and max;
- two keys: a map per panel over the plane of the two keys; a grid sweep draws cells holding the
  value, a random or LHS sweep points coloured by it;
- three or more: one line of panels per metric, one column per key (each key against the metric).
A key whose values are not all numbers is drawn as categories in sweep order.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib import colormaps, patheffects
from matplotlib.figure import Figure

from cosim.sweep.results import FAILED, GOAL, Point, count_outcomes, group_points, metric_keys

UNITS = {"time": "s", "distance": "m", "min_clearance": "m", "recovery_time": "s"}
OUTCOME_PANEL = "goal reached"
COLLISION = "collision"
# marker, colour, label: collided, ended otherwise without the goal, failed
MARKS = {
    COLLISION: ("X", "#d62728", "collision"),
    "other": ("^", "#ff7f0e", "ended without the goal"),
    FAILED: ("s", "black", "failed"),
}
COLUMNS = 3  # panels a line at most
DPI = 90
HALO = [patheffects.withStroke(linewidth=2.5, foreground="white")]  # text readable on any colour


def _number(text: str | None) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def _axis(values: list[str]) -> tuple[np.ndarray, list[str] | None]:
    """Numeric positions of a key's values, and category labels when they are not numbers."""
    numbers = np.array([_number(v) for v in values])
    if values and not np.isnan(numbers).any():
        return numbers, None
    labels = list(dict.fromkeys(values))
    return np.array([labels.index(v) for v in values], dtype=float), labels


def _label(key: str) -> str:
    return f"{key} [{UNITS[key]}]" if key in UNITS else key


def _marks(point: Point) -> list[tuple[str, int]]:
    """(mark, runs) of a point: collided runs, runs ended otherwise without the goal, failed runs."""
    other = point.runs - point.count(GOAL) - point.count(COLLISION) - point.count(FAILED)
    found = [(COLLISION, point.count(COLLISION)), ("other", other), (FAILED, point.count(FAILED))]
    return [(mark, count) for mark, count in found if count]


class _Data:
    """The points of a sweep as arrays: per metric the mean (NaN where no run reached the goal),
    the standard deviation and the extremes, and the share of runs that reached the goal."""

    def __init__(self, points: list[Point], metrics: Sequence[str]) -> None:
        self.points = points
        self.reached = np.array([point.count(GOAL) / point.runs for point in points])
        self.stats = {}
        for metric in metrics:
            columns = [point.metrics.get(metric) for point in points]
            self.stats[metric] = tuple(
                np.array([getattr(s, field) if s is not None else math.nan for s in columns])
                for field in ("mean", "std", "low", "high")
            )

    def values(self, panel: str) -> np.ndarray:
        return self.reached if panel == OUTCOME_PANEL else self.stats[panel][0]


def _varying(points: list[Point], metrics: Sequence[str]) -> tuple[list[str], dict[str, float]]:
    """The metrics to draw, and the constant ones with their value: the same in every goal-reached
    run (a metric that no goal-reached run has is in neither)."""
    varying, constant = [], {}
    for metric in metrics:
        stats = [point.metrics[metric] for point in points if metric in point.metrics]
        if not stats:
            continue
        low, high = min(s.low for s in stats), max(s.high for s in stats)
        if high - low <= 1e-12 * max(1.0, abs(high)):
            constant[metric] = stats[0].mean
        else:
            varying.append(metric)
    return varying, constant


def plot_sweep(
    rows: list[dict[str, str]],
    keys: Sequence[str],
    outcome_keys: Sequence[str],
    png_path: Path,
    grid: bool,
    title: str = "",
    replicates: int = 1,
) -> Path | None:
    """Draw `png_path` from the rows of every run (failed ones too); None when there is no row.

    Uses matplotlib's object API (no pyplot state), so it may draw in a thread of its own. The
    canvas is drawn once and its pixels written by `cosim.logs.plot.write_png` (the pixels
    `savefig` writes, in two thirds of its time: no second pass over the figure, no Pillow). The
    canvas is the run's figure's (`cosim.logs.plot.canvas_class`): matplotlib's Agg canvas whose
    renderer keeps each text's layout and each font's heights (the same pixels; the layout
    measures each tick label and title several times over: a sixth less CPU time here)."""
    from cosim.logs.plot import canvas_class, write_png

    figure = sweep_figure(rows, keys, outcome_keys, grid, title, replicates)
    if figure is None:
        return None
    canvas = canvas_class()(figure)
    canvas.draw()
    write_png(Path(png_path), np.asarray(canvas.buffer_rgba())[:, :, :3], DPI)  # the figure is opaque
    return png_path


def draw_png(arguments: dict, png_path: Path) -> Path | None:
    """`plot_sweep(png_path=png_path, **arguments)` with the collector paused (a figure is ~10^5
    young objects, in a process that may hold Dask's): how `cosim.sweep.engine` draws sweep.png,
    here or in a plot process (`cosim.cli.plotter`, which `cosim sweep` starts); None when no row."""
    from cosim.logs.plot import collector_paused

    with collector_paused():
        return plot_sweep(png_path=png_path, **arguments)


def sweep_figure(
    rows: list[dict[str, str]],
    keys: Sequence[str],
    outcome_keys: Sequence[str],
    grid: bool,
    title: str = "",
    replicates: int = 1,
) -> Figure | None:
    """The figure `plot_sweep` saves (None when there is no row)."""
    if not rows:
        return None
    points = group_points(rows, keys, outcome_keys)
    metrics, constant = _varying(points, metric_keys(outcome_keys))
    data = _Data(points, metrics)
    panels = [OUTCOME_PANEL, *metrics]
    if len(keys) == 2:
        figure = _maps(data, keys, panels, grid, replicates)
    elif len(keys) == 1:
        figure = _lines(data, keys[0], panels, replicates)
    else:
        figure = _columns(data, keys, panels, replicates)
    counts = count_outcomes(rows)
    outcomes = ", ".join(f"{count} {reason.replace('_', ' ')}" for reason, count in counts.items())
    runs = f"{len(points)} points x {replicates} replicates" if replicates > 1 else f"{len(rows)} runs"
    notes = ["metrics over the goal-reached runs only"]
    if replicates > 1:
        notes[0] += " (mean; bars ± 1 std, ticks min and max)" if len(keys) == 1 else " (mean)"
    if constant:
        shown = ", ".join(f"{metric} = {value:.4g}" for metric, value in constant.items())
        notes.append(f"the same in every goal-reached run, not drawn: {shown}")
    heading = [title] if title else []
    width = int(figure.get_figwidth() * 13)  # characters of 10 pt text across the figure
    lines = [*heading, f"{runs}: {outcomes}", *textwrap.wrap("; ".join(notes), width)]
    figure.suptitle("\n".join(lines), fontsize=10)
    _legend(figure.axes[0], points)
    return figure


def _legend(axis, points: list[Point]) -> None:
    """The marks' legend, in the first (outcome) panel."""
    from matplotlib.lines import Line2D

    present = {mark for point in points for mark, _ in _marks(point)}
    handles = [
        Line2D([], [], marker=MARKS[mark][0], color=MARKS[mark][1], linestyle="", label=MARKS[mark][2])
        for mark in MARKS
        if mark in present
    ]
    if handles:
        axis.legend(handles=handles, loc="lower left", fontsize=7, framealpha=0.8)


def _new_figure(width: float, height: float):
    """A figure of `width` x `height` inches, its panels laid out around their labels."""
    figure = Figure(figsize=(width, height), dpi=DPI, layout="constrained")
    figure.get_layout_engine().set(h_pad=0.1, w_pad=0.08)
    return figure


def _figure(count: int, width: float, height: float):
    """A figure of `count` panels, `COLUMNS` a line at most; the places of a last line left empty
    get no axes (the layout is the same: their column is sized by the panels above)."""
    columns = min(COLUMNS, count)
    lines = math.ceil(count / columns)
    figure = _new_figure(width * columns, height * lines + 0.6)
    places = figure.add_gridspec(lines, columns)
    return figure, [figure.add_subplot(places[index // columns, index % columns]) for index in range(count)]


def _panel_title(panel: str) -> str:
    return "share of runs that reached the goal" if panel == OUTCOME_PANEL else _label(panel)


def _mark_text(count: int, point: Point, replicates: int) -> str:
    return f"{count}/{point.runs}" if replicates > 1 else ""


def _bottom_marks(axis, x: np.ndarray, points: list[Point], replicates: int) -> None:
    """The marks of each point along the bottom of a panel (at its x, in axis height)."""
    transform = axis.get_xaxis_transform()
    for position, point in zip(x, points, strict=True):
        for level, (mark, count) in enumerate(_marks(point)):
            marker, colour, _ = MARKS[mark]
            height = 0.05 + 0.09 * level
            axis.plot(
                [position], [height], marker, color=colour, markersize=7, transform=transform, clip_on=False
            )
            text = _mark_text(count, point, replicates)
            if text:
                axis.annotate(
                    text,
                    (position, height),
                    xycoords=transform,
                    xytext=(5, 0),
                    textcoords="offset points",
                    color=colour,
                    fontsize=6,
                    va="center",
                )


def _categories(axis, labels: list[str] | None, which: str = "x") -> None:
    if labels is None:
        return
    if which == "x":
        axis.set_xticks(range(len(labels)), labels, rotation=30, fontsize=7)
    else:
        axis.set_yticks(range(len(labels)), labels, fontsize=7)


def _draw_against(axis, x: np.ndarray, data: _Data, panel: str, replicates: int, line: bool) -> None:
    """`panel` against one key: the mean (and spread) of each point, the marks at the bottom."""
    order = np.argsort(x, kind="stable")
    if panel == OUTCOME_PANEL:
        axis.bar(x, data.reached, width=_bar_width(x), color="#2ca02c", alpha=0.6)
        axis.set_ylim(0.0, 1.05)
    else:
        mean, std, low, high = data.stats[panel]
        if replicates > 1:
            axis.errorbar(x, mean, yerr=np.nan_to_num(std), fmt="none", ecolor="C0", capsize=3, alpha=0.8)
            axis.plot(x, low, "_", color="C0", markersize=8)
            axis.plot(x, high, "_", color="C0", markersize=8)
        axis.plot(x[order] if line else x, mean[order] if line else mean, "o-" if line else "o", markersize=4)
        finite = mean[np.isfinite(mean)]
        if finite.size:  # room at the bottom for the marks
            span = max(float(np.nanmax(high)) - float(np.nanmin(low)), 1e-9)
            axis.set_ylim(float(np.nanmin(low)) - 0.3 * span, float(np.nanmax(high)) + 0.1 * span)
    _bottom_marks(axis, x, data.points, replicates)
    axis.set_title(_panel_title(panel), fontsize=9)
    axis.grid(alpha=0.3)


def _bar_width(x: np.ndarray) -> float:
    distinct = np.unique(x)
    return 0.6 * float(np.min(np.diff(distinct))) if distinct.size > 1 else 0.6


def _lines(data: _Data, key: str, panels: list[str], replicates: int):
    figure, axes = _figure(len(panels), 4.0, 2.9)
    x, labels = _axis([point.values[key] for point in data.points])
    for axis, panel in zip(axes, panels, strict=True):
        _draw_against(axis, x, data, panel, replicates, line=labels is None)
        _categories(axis, labels)
        axis.set_xlabel(key, fontsize=8)
    return figure


def _columns(data: _Data, keys: Sequence[str], panels: list[str], replicates: int):
    figure = _new_figure(3.6 * len(keys), 2.5 * len(panels) + 0.6)
    axes = figure.subplots(len(panels), len(keys), squeeze=False)
    for column, key in enumerate(keys):
        x, labels = _axis([point.values[key] for point in data.points])
        for line, panel in enumerate(panels):
            axis = axes[line][column]
            _draw_against(axis, x, data, panel, replicates, line=False)
            _categories(axis, labels)
            if line == len(panels) - 1:
                axis.set_xlabel(key, fontsize=8)
    return figure


def _maps(data: _Data, keys: Sequence[str], panels: list[str], grid: bool, replicates: int):
    figure, axes = _figure(len(panels), 4.3, 3.5)
    x, x_labels = _axis([point.values[keys[1]] for point in data.points])
    y, y_labels = _axis([point.values[keys[0]] for point in data.points])
    xs, ys = np.unique(x), np.unique(y)
    for axis, panel in zip(axes, panels, strict=True):
        values = data.values(panel)
        # A cell without a value (no run of the point reached the goal) is grey, not white.
        colours = colormaps["RdYlGn" if panel == OUTCOME_PANEL else "viridis"].with_extremes(bad="0.88")
        limits = {"vmin": 0.0, "vmax": 1.0} if panel == OUTCOME_PANEL else {}
        if grid:
            columns, lines = np.searchsorted(xs, x), np.searchsorted(ys, y)
            cells = np.full((len(ys), len(xs)), np.nan)
            cells[lines, columns] = values  # a grid has one point per cell
            image = axis.imshow(cells, origin="lower", aspect="auto", cmap=colours, **limits)
            if cells.size <= 64:  # small grids: the value in each cell too
                _cell_texts(axis, data, panel, columns, lines, replicates)
            axis.set_xticks(range(len(xs)), x_labels or [f"{v:g}" for v in xs], rotation=30, fontsize=7)
            axis.set_yticks(range(len(ys)), y_labels or [f"{v:g}" for v in ys], fontsize=7)
            mark_x, mark_y = columns + 0.3, lines + 0.3
        else:
            image = axis.scatter(x, y, c=values, cmap=colours, s=36, **limits)
            _categories(axis, x_labels, "x")
            _categories(axis, y_labels, "y")
            mark_x, mark_y = x, y
        for position_x, position_y, point, value in zip(mark_x, mark_y, data.points, values, strict=True):
            centred = grid and not np.isfinite(value)  # an empty cell: the mark in its middle
            for level, (mark, count) in enumerate(_marks(point)):
                marker, colour, _ = MARKS[mark]
                # In a cell: up to three marks a column at its left (empty) or right edge, inside it.
                at_x = position_x - (0.6 if centred else 0.0)
                at_y = position_y - ((0.3 if centred else 0.0) + 0.2 * level if grid else 0.0)
                axis.plot([at_x], [at_y], marker, color=colour, markersize=9 if grid else 6)
                text = _mark_text(count, point, replicates)
                if centred and not text:
                    text = MARKS[mark][2] if mark != "other" else next(iter(point.outcomes)).replace("_", " ")
                if text:
                    axis.text(
                        at_x, at_y, f"  {text}", color=colour, fontsize=7, va="center", path_effects=HALO
                    )
        figure.colorbar(image, ax=axis)
        axis.set_title(_panel_title(panel), fontsize=9)
        axis.set_xlabel(keys[1], fontsize=8)
        axis.set_ylabel(keys[0], fontsize=8)
    return figure


def _cell_texts(axis, data: _Data, panel: str, columns, lines, replicates: int) -> None:
    for column, line, index in zip(columns, lines, range(len(data.points)), strict=True):
        point = data.points[index]
        if panel == OUTCOME_PANEL:
            text = f"{point.count(GOAL)}/{point.runs}"
            if point.count(GOAL) == 0:
                text += "\n" + next(iter(point.outcomes)).replace("_", " ")
        else:
            mean, std = data.stats[panel][0][index], data.stats[panel][1][index]
            if not np.isfinite(mean):
                continue
            text = f"{mean:.3g}" + (f"\n± {std:.2g}" if replicates > 1 and np.isfinite(std) else "")
        # Centred in its cell, inside the panel: left out of the layout (each text in it is measured
        # a few times over, 40 texts a tenth of the plot's time). The same pixels as when it was in
        # it, up to an 8 x 8 grid whose edge cells hold two-line outcomes ("0/1", "stop time").
        axis.text(
            column,
            line,
            text,
            ha="center",
            va="center",
            fontsize=7,
            color="black",
            path_effects=HALO,
            in_layout=False,
        )
