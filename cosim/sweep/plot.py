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
from matplotlib import colormaps, patheffects, ticker
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
    renderer keeps each text's layout and each font's heights (the same pixels)."""
    from cosim.logs.plot import write_png

    figure = sweep_figure(rows, keys, outcome_keys, grid, title, replicates)
    if figure is None:
        return None
    canvas = figure.canvas
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
    """The figure `plot_sweep` saves (None when there is no row), on its canvas
    (`cosim.logs.plot.canvas_class`: its renderer measures the texts the layout makes room for)."""
    if not rows:
        return None
    points = group_points(rows, keys, outcome_keys)
    metrics, constant = _varying(points, metric_keys(outcome_keys))
    data = _Data(points, metrics)
    panels = [OUTCOME_PANEL, *metrics]
    if len(keys) == 2:
        figure, places = _maps(data, keys, panels, grid, replicates)
    elif len(keys) == 1:
        figure, places = _lines(data, keys[0], panels, replicates)
    else:
        figure, places = _columns(data, keys, panels, replicates)
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
    _legend(places[0][0].axis, points)
    _place(figure, places, "\n".join(lines))
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


# The figure is laid out here, not by a layout engine: each panel has a cell of the figure (lines
# and columns of equal cells under the heading) and its axes are placed in it with room for what
# is drawn around them (title, ticks and their labels, axis labels, colour bar), measured by the
# canvas's renderer. A panel's ticks and colour bar are drawn as lines, texts and bands of the
# figure, not by matplotlib's axis and colour bar machinery (which makes 5 artists a tick, and whose
# constrained layout measures each tick label several times over). Sizes in points.
PAD = 5.0  # inside each cell's edges, and at the figure's top
TICK, TICK_PAD, LABEL_PAD, TITLE_PAD = 3.5, 3.5, 4.0, 6.0  # matplotlib's defaults
TICK_WIDTH = 0.8
NUMBER_SIZE = 10.0  # the labels of a numeric axis and of a colour bar (matplotlib's default)
VALUE_SIZE = 7.0  # the labels of a key's values on a grid map, and of categories
TITLE_SIZE, LABEL_SIZE = 9.0, 8.0
BAR_PAD = 8.0  # between a map and its colour bar
BAR_ASPECT = 20.0  # a colour bar's height over its width (matplotlib's default)
GRID = {"color": "#b0b0b0", "linewidth": 0.8, "alpha": 0.3, "zorder": 1.5}  # axis.grid(alpha=0.3)


class _Ticks:
    """The ticks of one side of a panel: data positions, their labels, the labels' font size and
    rotation; `positions` None: numbers placed as matplotlib's default locator would, once the
    panel's length is known."""

    def __init__(self, positions=None, labels=(), size: float = NUMBER_SIZE, rotation: float = 0.0):
        self.numbers = positions is None
        self.positions = None if positions is None else np.asarray(positions, dtype=float)
        self.labels = list(labels)
        self.size = size
        self.rotation = rotation


class _Panel:
    """A panel's axes (matplotlib's own ticks off), and what `_place` draws around them."""

    def __init__(self, figure, title: str, xlabel: str = "", ylabel: str = "") -> None:
        self.axis = axis = figure.add_axes((0.0, 0.0, 1.0, 1.0), axes_class=_axes_class())
        axis.xaxis.set_major_locator(ticker.NullLocator())
        axis.yaxis.set_major_locator(ticker.NullLocator())
        for spine in axis.spines.values():  # (matplotlib places them as it makes the first ticks)
            spine.set_position(("outward", 0.0))
        axis.set_title(title, fontsize=TITLE_SIZE, y=1.0)  # (placed: no search for a free place)
        if xlabel:
            axis.set_xlabel(xlabel, fontsize=LABEL_SIZE)
        if ylabel:
            axis.set_ylabel(ylabel, fontsize=LABEL_SIZE)
        self.x, self.y = _Ticks(), _Ticks()
        self.colours = None  # (colour map, norm) of a colour bar at the right
        self.bar = _Ticks()  # of the colour bar
        self.grid = False


_AXES: list = []


def _axes_class():
    """matplotlib's Axes whose two axes make no tick ahead of need (matplotlib's make one each,
    major and minor, when the axes are made: half the time of making them); here none is ever
    needed, the ticks being drawn by `_place`. (Axis.majorTicks and minorTicks, lazy lists of
    ticks, start empty; matplotlib's axes add to them as they need ticks.)"""
    if _AXES:
        return _AXES[0]
    from matplotlib.axes import Axes
    from matplotlib.axis import XAxis, YAxis

    class NoTicksAhead:
        def __set_name__(self, owner, name: str) -> None:
            self.name = name

        def __get__(self, instance, owner):
            if instance is None:
                return self
            ticks: list = []
            setattr(instance, self.name, ticks)  # until the axis is cleared
            return ticks

    class PanelXAxis(XAxis):
        majorTicks = NoTicksAhead()
        minorTicks = NoTicksAhead()

    class PanelYAxis(YAxis):
        majorTicks = NoTicksAhead()
        minorTicks = NoTicksAhead()

    class PanelAxes(Axes):
        def _init_axis(self) -> None:  # matplotlib's, with the axes above
            self.xaxis = PanelXAxis(self, clear=False)
            self.spines.bottom.register_axis(self.xaxis)
            self.spines.top.register_axis(self.xaxis)
            self.yaxis = PanelYAxis(self, clear=False)
            self.spines.left.register_axis(self.yaxis)
            self.spines.right.register_axis(self.yaxis)

    _AXES.append(PanelAxes)
    return PanelAxes


def _numbers(low: float, high: float, length: float, factor: float) -> tuple[np.ndarray, list[str]]:
    """Ticks of a numeric axis from `low` to `high`, `length` pt long, where matplotlib's default
    locator puts them (at most one per `factor` times the label's size, 9 bins at most), labelled
    in plain decimals (no offset, no power of ten apart)."""
    low, high = min(low, high), max(low, high)
    bins = int(np.clip(math.floor(length / (NUMBER_SIZE * factor)), 1, 9))
    positions = ticker.MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]).tick_values(low, high)
    close = 1e-10 * max(high - low, 1e-300)
    positions = positions[(positions >= low - close) & (positions <= high + close)]
    formatter = ticker.ScalarFormatter(useOffset=False)
    formatter.set_scientific(False)
    formatter.create_dummy_axis()
    formatter.axis.set_view_interval(low, high)
    return positions, formatter.format_ticks(positions)


class _Measure:
    """Sizes [pt] of texts as the figure's renderer lays them out (kept per text). A text of one
    line is as wide as the renderer measures it and as high as its font's line (matplotlib's
    `Text` sets a line between the font's ascent and descent, which hold ASCII's glyphs); turned by
    `rotation` [deg], the box of that rectangle. A text of several lines is laid out by a `Text`."""

    def __init__(self, figure) -> None:
        from matplotlib.font_manager import FontProperties
        from matplotlib.text import Text

        self.renderer = figure.canvas.get_renderer()
        self.scale = 72.0 / figure.dpi
        self.text = Text(0.0, 0.0, "")
        self.text.set_figure(figure)
        self.sizes: dict = {}
        self.fonts: dict = {}  # size: (FontProperties, line height [px])
        self.font_properties = FontProperties

    def __call__(self, text: str, size: float, rotation: float = 0.0) -> tuple[float, float]:
        key = (text, size, rotation)
        found = self.sizes.get(key)
        if found is None:
            if not text:
                found = (0.0, 0.0)
            elif "\n" in text:
                found = self._laid_out(text, size, rotation)
            else:
                font = self.fonts.get(size)
                if font is None:
                    height = self._laid_out("0", size, 0.0)[1] / self.scale
                    font = self.fonts[size] = (self.font_properties(size=size), height)
                width = self.renderer.get_text_width_height_descent(text, font[0], False)[0]
                cos, sin = abs(math.cos(math.radians(rotation))), abs(math.sin(math.radians(rotation)))
                height = font[1]
                found = ((width * cos + height * sin) * self.scale, (width * sin + height * cos) * self.scale)
            self.sizes[key] = found
        return found

    def _laid_out(self, text: str, size: float, rotation: float) -> tuple[float, float]:
        self.text.set_text(text)
        self.text.set_fontsize(size)
        self.text.set_rotation(rotation)
        box = self.text.get_window_extent(self.renderer)
        return box.width * self.scale, box.height * self.scale

    def widest(self, ticks: _Ticks) -> float:
        return max((self(label, ticks.size, ticks.rotation)[0] for label in ticks.labels), default=0.0)

    def highest(self, ticks: _Ticks) -> float:
        if ticks.numbers:  # one line of digits
            return self("0", ticks.size)[1]
        return max((self(label, ticks.size, ticks.rotation)[1] for label in ticks.labels), default=0.0)


def _place(figure, places: list[list[_Panel | None]], heading: str) -> None:
    """Lay the figure out: the heading at its top, each panel's axes in its cell (lines of equal
    cells below the heading) with room for its title, ticks, axis labels and colour bar, each
    of which stays inside the cell; then draw the ticks and colour bars."""
    measure = _Measure(figure)
    width, height = figure.get_size_inches() * 72.0
    figure.suptitle(heading, fontsize=10, y=1.0 - PAD / height, va="top")
    top = PAD + measure(heading, 10)[1] + PAD
    lines, columns = len(places), len(places[0])
    cell_width, cell_height = width / columns - 2 * PAD, (height - top) / lines - 2 * PAD  # inside
    panels = [panel for line in places for panel in line if panel is not None]
    for panel in panels:
        panel.xlim, panel.ylim = panel.axis.get_xlim(), panel.axis.get_ylim()  # autoscaled now
        panel.axis.set_xlim(panel.xlim)
        panel.axis.set_ylim(panel.ylim)
    # Heights: each line of cells has room at its top for the titles, at its bottom for the tick
    # labels and the axis label under them; the numbers beside the axes are then placed.
    for line in places:
        here = [panel for panel in line if panel is not None]
        above = max(measure(panel.axis.get_title(), TITLE_SIZE)[1] for panel in here) + TITLE_PAD
        ticks = TICK + TICK_PAD + max(measure.highest(panel.x) for panel in here)
        label = max(measure(panel.axis.get_xlabel(), LABEL_SIZE)[1] for panel in here)
        below = ticks + (LABEL_PAD + label if label else 0.0)
        for panel in here:
            # (labels too long for the cell leave the panel a fifth of it: they then overlap)
            panel.height = max(cell_height - above - below, cell_height / 5)
            panel.below, panel.label_below = below, ticks + LABEL_PAD
            if panel.y.numbers:
                panel.y.positions, panel.y.labels = _numbers(*panel.ylim, panel.height, 2)
            if panel.colours is not None:
                norm = panel.colours[1]
                # (a colour bar's labels as sparse as an x axis's: 4 to 6 on a map's height)
                panel.bar.positions, panel.bar.labels = _numbers(norm.vmin, norm.vmax, panel.height, 3)
    # Widths: each column of cells has room at its left for the tick labels and the axis label
    # beside them, at its right for a colour bar and its labels; and room enough for what is
    # centred under or over the axes (the tick labels on their ticks, title and axis label).
    for column in range(columns):
        here = [line[column] for line in places if line[column] is not None]
        beside = TICK + TICK_PAD + max(measure.widest(panel.y) for panel in here)
        label = max(measure(panel.axis.get_ylabel(), LABEL_SIZE, 90.0)[0] for panel in here)
        left = beside + (LABEL_PAD + label if label else 0.0)
        right = max(
            BAR_PAD + panel.height / BAR_ASPECT + TICK + TICK_PAD + measure.widest(panel.bar)
            if panel.colours is not None
            else 0.0
            for panel in here
        )
        for _ in range(3):  # the labels under the axes depend on its width, and it on them
            span = max(cell_width - left - right, cell_width / 5)
            centred = []  # (distance from the axes' left, half width) of each
            for panel in here:
                if panel.x.numbers:
                    panel.x.positions, panel.x.labels = _numbers(*panel.xlim, span, 3)
                low, high = panel.xlim
                for position, text in zip(panel.x.positions, panel.x.labels, strict=True):
                    half = measure(text, panel.x.size, panel.x.rotation)[0] / 2
                    centred.append((span * (position - low) / (high - low), half))
                centred.append((span / 2, measure(panel.axis.get_title(), TITLE_SIZE)[0] / 2))
                centred.append((span / 2, measure(panel.axis.get_xlabel(), LABEL_SIZE)[0] / 2))
            need_left = max(left, *(half - at for at, half in centred))
            need_right = max(right, *(half - (span - at) for at, half in centred))
            if need_left <= left and need_right <= right:
                break
            left, right = need_left, need_right
        for line in range(lines):
            panel = places[line][column]
            if panel is not None:
                x0 = column * (cell_width + 2 * PAD) + PAD + left
                y0 = height - top - (line + 1) * (cell_height + 2 * PAD) + PAD + panel.below
                panel.axis.set_position((x0 / width, y0 / height, span / width, panel.height / height))
                panel.beside = beside
    for panel in panels:
        axis, grid = panel.axis, panel.axis if panel.grid else None
        _side(figure, panel.x, panel.xlim, axis.get_xaxis_transform(), "x", grid)
        _side(figure, panel.y, panel.ylim, axis.get_yaxis_transform(), "y", grid)
        axis.xaxis.set_label_coords(0.5, 0.0, _shifted(figure, axis.transAxes, 0.0, -panel.label_below))
        axis.yaxis.set_label_coords(
            0.0, 0.5, _shifted(figure, axis.transAxes, -panel.beside - LABEL_PAD, 0.0)
        )
        if panel.colours is not None:
            _colour_bar(figure, panel, width)


def _shifted(figure, transform, right: float, up: float):
    """`transform` then a shift by `right`, `up` pt."""
    from matplotlib.transforms import ScaledTranslation

    return transform + ScaledTranslation(right / 72.0, up / 72.0, figure.dpi_scale_trans)


def _side(figure, ticks: _Ticks, limits, transform, which: str, grid_axis) -> None:
    """The ticks of one side of a panel: marks out of its bottom (x) or left (y) edge, labels past
    them, lines across the panel where it has a grid."""
    from matplotlib.lines import Line2D
    from matplotlib.markers import TICKDOWN, TICKLEFT
    from matplotlib.text import Text

    low, high = min(limits), max(limits)
    close = 1e-10 * (high - low)
    inside = [
        (position, label)
        for position, label in zip(ticks.positions, ticks.labels, strict=True)
        if low - close <= position <= high + close
    ]
    if not inside:
        return
    positions = np.array([position for position, _ in inside])
    edge = np.zeros(len(positions))
    x, y = (positions, edge) if which == "x" else (edge, positions)
    figure.add_artist(
        Line2D(
            x,
            y,
            linestyle="",
            marker=TICKDOWN if which == "x" else TICKLEFT,
            markersize=TICK,
            markeredgewidth=TICK_WIDTH,
            color="black",
            transform=transform,
        )
    )
    away = TICK + TICK_PAD
    labels = _shifted(figure, transform, *((0.0, -away) if which == "x" else (-away, 0.0)))
    for position, label in inside:
        at = (position, 0.0) if which == "x" else (0.0, position)
        figure.add_artist(
            Text(
                *at,
                label,
                fontsize=ticks.size,
                rotation=ticks.rotation,
                ha="center" if which == "x" else "right",
                va="top" if which == "x" else "center_baseline",
                transform=labels,
            )
        )
    if grid_axis:
        across = np.tile([0.0, 1.0, np.nan], len(positions))
        along = np.repeat(positions, 3)
        line = Line2D(*((along, across) if which == "x" else (across, along)), transform=transform, **GRID)
        grid_axis.add_artist(line)  # clipped to the panel, under its lines


def _colour_bar(figure, panel: _Panel, width: float) -> None:
    """The colour bar right of a map: its colours from bottom to top, framed, the values ticked."""
    from matplotlib.collections import QuadMesh
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D
    from matplotlib.markers import TICKRIGHT
    from matplotlib.patches import Rectangle
    from matplotlib.text import Text

    colours, norm = panel.colours
    box = panel.axis.get_position()
    bar_width = panel.height / BAR_ASPECT / width
    left, bottom, top = box.x1 + BAR_PAD / width, box.y0, box.y1
    # a band per colour of the map, bottom to top (as matplotlib's colour bar draws it)
    heights = np.linspace(bottom, top, colours.N + 1)
    corners = np.stack(np.broadcast_arrays(*np.meshgrid([left, left + bar_width], heights)), axis=-1)
    bands = QuadMesh(
        corners,
        array=(np.arange(colours.N) + 0.5) / colours.N,
        cmap=colours,
        norm=Normalize(0.0, 1.0),
        antialiased=False,
        transform=figure.transFigure,
    )
    figure.add_artist(bands)
    figure.add_artist(
        Rectangle(
            (left, bottom),
            bar_width,
            top - bottom,
            fill=False,
            linewidth=TICK_WIDTH,
            edgecolor="black",
            transform=figure.transFigure,
        )
    )
    low, high = norm.vmin, norm.vmax
    ticks = panel.bar
    at = bottom + (top - bottom) * (ticks.positions - low) / (high - low)
    edge = left + bar_width
    figure.add_artist(
        Line2D(
            np.full(len(at), edge),
            at,
            linestyle="",
            marker=TICKRIGHT,
            markersize=TICK,
            markeredgewidth=TICK_WIDTH,
            color="black",
            transform=figure.transFigure,
        )
    )
    for y, label in zip(at, ticks.labels, strict=True):
        figure.add_artist(
            Text(
                edge + (TICK + TICK_PAD) / width,
                y,
                label,
                fontsize=NUMBER_SIZE,
                ha="left",
                va="center_baseline",
                transform=figure.transFigure,
            )
        )


def _new_figure(width: float, height: float):
    """A figure of `width` x `height` inches on its canvas (laid out by `_place`)."""
    from cosim.logs.plot import canvas_class

    figure = Figure(figsize=(width, height), dpi=DPI)
    canvas_class()(figure)
    return figure


def _figure(titles: list[str], width: float, height: float, xlabel: str = "", ylabel: str = ""):
    """A figure of a panel per title, `COLUMNS` a line at most (the places of a last line left
    empty get no panel), each `width` x `height` inches; its places (lines of panels or None)."""
    count = len(titles)
    columns = min(COLUMNS, count)
    lines = math.ceil(count / columns)
    figure = _new_figure(width * columns, height * lines + 0.6)
    panels = [_Panel(figure, title, xlabel, ylabel) for title in titles]
    panels += [None] * (lines * columns - count)
    return figure, [panels[line * columns : (line + 1) * columns] for line in range(lines)]


def _panel_title(panel: str) -> str:
    return "share of runs that reached the goal" if panel == OUTCOME_PANEL else _label(panel)


def _mark_text(count: int, point: Point, replicates: int) -> str:
    return f"{count}/{point.runs}" if replicates > 1 else ""


def _mark(axis, x: float, y: float, marker: str, colour: str, size: float, **properties) -> None:
    """A mark of `axis`: a line of one point, as `axis.plot([x], [y], marker, ...)` draws it, without
    its parsing of the arguments nor its update of the data limits (~0.4 ms a mark)."""
    from matplotlib.lines import Line2D

    properties.setdefault("transform", axis.transData)
    axis.add_artist(
        Line2D([x], [y], marker=marker, color=colour, markersize=size, linestyle="None", **properties)
    )


def _bottom_marks(axis, x: np.ndarray, points: list[Point], replicates: int) -> None:
    """The marks of each point along the bottom of a panel (at its x, in axis height); the panel's
    x range takes in every point's."""
    transform = axis.get_xaxis_transform()
    axis.update_datalim(np.column_stack([x, np.zeros(len(x))]), updatey=False)
    for position, point in zip(x, points, strict=True):
        for level, (mark, count) in enumerate(_marks(point)):
            marker, colour, _ = MARKS[mark]
            height = 0.05 + 0.09 * level
            _mark(axis, position, height, marker, colour, 7, transform=transform, clip_on=False)
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


def _categories(labels: list[str] | None, rotation: float = 0.0) -> _Ticks:
    """The ticks of a key's values: numbers placed by length, or its categories in sweep order."""
    if labels is None:
        return _Ticks()
    return _Ticks(range(len(labels)), labels, VALUE_SIZE, rotation)


def _draw_against(panel: _Panel, x: np.ndarray, data: _Data, name: str, replicates: int, line: bool) -> None:
    """`name` against one key: the mean (and spread) of each point, the marks at the bottom."""
    axis = panel.axis
    order = np.argsort(x, kind="stable")
    if name == OUTCOME_PANEL:  # a bar a point, centred on it (one collection, not a patch a bar)
        from matplotlib.collections import PolyCollection

        half = _bar_width(x) / 2
        bars = [
            [(at - half, 0.0), (at - half, top), (at + half, top), (at + half, 0.0)]
            for at, top in zip(x, data.reached, strict=True)
        ]
        axis.add_collection(PolyCollection(bars, facecolors="#2ca02c", edgecolors="none", alpha=0.6))
        axis.set_ylim(0.0, 1.05)
    else:
        mean, std, low, high = data.stats[name]
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
    axis.autoscale_view()
    panel.grid = True


def _bar_width(x: np.ndarray) -> float:
    distinct = np.unique(x)
    return 0.6 * float(np.min(np.diff(distinct))) if distinct.size > 1 else 0.6


def _lines(data: _Data, key: str, names: list[str], replicates: int):
    figure, places = _figure([_panel_title(name) for name in names], 4.0, 2.9, xlabel=key)
    x, labels = _axis([point.values[key] for point in data.points])
    panels = [panel for line in places for panel in line if panel is not None]
    for panel, name in zip(panels, names, strict=True):
        _draw_against(panel, x, data, name, replicates, line=labels is None)
        panel.x = _categories(labels, 30.0)
    return figure, places


def _columns(data: _Data, keys: Sequence[str], names: list[str], replicates: int):
    figure = _new_figure(3.6 * len(keys), 2.5 * len(names) + 0.6)
    places = [
        [_Panel(figure, _panel_title(name), key if line == len(names) - 1 else "") for key in keys]
        for line, name in enumerate(names)
    ]
    for column, key in enumerate(keys):
        x, labels = _axis([point.values[key] for point in data.points])
        for line, name in enumerate(names):
            panel = places[line][column]
            _draw_against(panel, x, data, name, replicates, line=False)
            panel.x = _categories(labels, 30.0)
    return figure, places


def _maps(data: _Data, keys: Sequence[str], names: list[str], grid: bool, replicates: int):
    from matplotlib.colors import Normalize

    titles = [_panel_title(name) for name in names]
    figure, places = _figure(titles, 4.3, 3.5, xlabel=keys[1], ylabel=keys[0])
    x, x_labels = _axis([point.values[keys[1]] for point in data.points])
    y, y_labels = _axis([point.values[keys[0]] for point in data.points])
    xs, ys = np.unique(x), np.unique(y)
    panels = [panel for line in places for panel in line if panel is not None]
    for panel, name in zip(panels, names, strict=True):
        axis = panel.axis
        values = data.values(name)
        # A cell without a value (no run of the point reached the goal) is grey, not white.
        colours = colormaps["RdYlGn" if name == OUTCOME_PANEL else "viridis"].with_extremes(bad="0.88")
        norm = Normalize(0.0, 1.0) if name == OUTCOME_PANEL else Normalize(*_value_range(values))
        panel.colours = colours, norm
        if grid:
            columns, lines = np.searchsorted(xs, x), np.searchsorted(ys, y)
            cells = np.full((len(ys), len(xs)), np.nan)
            cells[lines, columns] = values  # a grid has one point per cell
            # the cells as quadrilaterals (matplotlib draws them at once, an image is resampled)
            axis.pcolormesh(
                np.arange(len(xs) + 1) - 0.5, np.arange(len(ys) + 1) - 0.5, cells, cmap=colours, norm=norm
            )
            if cells.size <= 64:  # small grids: the value in each cell too
                _cell_texts(axis, data, name, columns, lines, replicates, colours, norm)
            panel.x = _Ticks(range(len(xs)), x_labels or [f"{v:g}" for v in xs], VALUE_SIZE, 30.0)
            panel.y = _Ticks(range(len(ys)), y_labels or [f"{v:g}" for v in ys], VALUE_SIZE)
            mark_x, mark_y = columns + 0.3, lines + 0.3
        else:
            axis.scatter(x, y, c=values, cmap=colours, norm=norm, s=36)
            panel.x = _categories(x_labels, 30.0)
            panel.y = _categories(y_labels)
            mark_x, mark_y = x, y
        for position_x, position_y, point, value in zip(mark_x, mark_y, data.points, values, strict=True):
            centred = grid and not np.isfinite(value)  # an empty cell: the mark in its middle
            for level, (mark, count) in enumerate(_marks(point)):
                marker, colour, _ = MARKS[mark]
                # In a cell: up to three marks a column at its left (empty) or right edge, inside it.
                at_x = position_x - (0.6 if centred else 0.0)
                at_y = position_y - ((0.3 if centred else 0.0) + 0.2 * level if grid else 0.0)
                _mark(axis, at_x, at_y, marker, colour, 9 if grid else 6)
                text = _mark_text(count, point, replicates)
                if centred and not text:
                    text = MARKS[mark][2] if mark != "other" else next(iter(point.outcomes)).replace("_", " ")
                if text:
                    axis.text(
                        at_x, at_y, f"  {text}", color=colour, fontsize=7, va="center", path_effects=HALO
                    )
    return figure, places


def _value_range(values: np.ndarray) -> tuple[float, float]:
    """The colours' range of a map: its values' (NaN left out), widened by a tenth of the value
    either way when they are all the same (each then gets the middle colour)."""
    finite = values[np.isfinite(values)]
    if not finite.size:
        return 0.0, 1.0
    low, high = float(finite.min()), float(finite.max())
    if high - low <= 1e-12 * max(1.0, abs(high)):
        widen = 0.1 * abs(high) if high else 0.1
        low, high = low - widen, high + widen
    return low, high


def _cell_texts(axis, data: _Data, panel: str, columns, lines, replicates: int, colours, norm) -> None:
    """The value of each cell, in black on a light cell and white on a dark one."""
    red, green, blue, _ = colours(norm(data.values(panel))).T
    light = 0.2126 * red + 0.7152 * green + 0.0722 * blue > 0.45  # (their luminance)
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
        colour = "black" if light[index] else "white"
        axis.text(column, line, text, ha="center", va="center", fontsize=7, color=colour)
