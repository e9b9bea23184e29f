"""Draw a log that is not a robot run (an SSP run, `cosim fmu simulate`, any system without a map,
goal or trajectory): its signals over time, one panel each, titled by the system's name.

`plot_any` chooses (`cosim log plot`): a log with a map, a goal or a driven trajectory gets the
robot picture (`cosim.logs.plot.plot_log`, unchanged), any other this one. Every variable of every
`/signals/<component>` is drawn (`component.variable`, with its unit), or the ones chosen; panels
go in up to three columns and share the time axis; past `MAX_PANELS` signals the title says how
many are left out. Several logs overlay: the first log's signals (or the ones chosen), each log's
line in its own colour, named by the log's file stem.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from cosim.core.component import closest_names
from cosim.errors import CosimError
from cosim.logs.fleet_plot import is_fleet_log, plot_fleet
from cosim.logs.plot import DPI, GRID_ALPHA, collector_paused, plot_logs, write_png
from cosim.logs.plot_map import run_colour

if TYPE_CHECKING:
    from cosim.logs.reader import Log

MAX_PANELS = 48  # a picture of more is unreadable; --signals picks others
PANEL_HEIGHT = 1.6  # [in]
COLUMN_WIDTH = 7.0  # [in]


@dataclass
class SignalPanel:
    label: str  # "component.variable"
    unit: str
    t: np.ndarray  # [s]
    values: np.ndarray
    run: int = 0  # which log of an overlay


def plot_any(
    logs: Log | list[Log], png_path: str | Path, signals: list[str] | None = None, dpi: float = DPI, size=None
) -> Path:
    """Draw `logs` (one, or several to overlay) to `png_path` as robots' runs when each is one,
    else as signals over time (module docstring); `signals` ("component.variable") None: the
    picture's defaults; one fleet's log: `cosim.logs.fleet_plot` (with `signals`: those over time);
    `dpi` [pixels per inch], `size` (width, height) [px] or None: the
    picture's own. Returns the PNG path."""
    logs = logs if isinstance(logs, list) else [logs]
    if len(logs) == 1 and is_fleet_log(logs[0]):  # its robots' signals: robot1:vehicle.x
        if signals is None:
            return plot_fleet(logs[0], png_path, dpi, size)
        return plot_signals(logs, png_path, signals, dpi, size)
    if all(is_robot_log(log) for log in logs):
        return plot_logs(logs, Path(png_path), signals, dpi, size)
    return plot_signals(logs, png_path, signals, dpi, size)


def is_robot_log(log: Log) -> bool:
    """Whether `log` is a robot's run: it has a map, a goal or a driven trajectory."""
    return log.map("/map") is not None or log.goal() is not None or log.trajectory() is not None


def signal_panels(log: Log, signals: list[str] | None = None) -> list[SignalPanel]:
    """The panels of `signals` ("component.variable"; None: every signal of every component, in
    the log's order); `CosimError` naming an unknown one with the closest names."""
    if signals is None:
        chosen = [(component, name) for component in log.components for name in log.signal_names(component)]
    else:
        chosen = [_reference(log, text) for text in signals]
    panels = []
    for component, name in chosen:
        recorded = log.signals(component)
        panels.append(SignalPanel(f"{component}.{name}", recorded.unit(name), recorded.t, recorded[name]))
    return panels


def _reference(log: Log, text: str) -> tuple[str, str]:
    component, _, name = text.partition(".")
    if not name:
        raise CosimError(f"--signals {text!r}: expected COMPONENT.VARIABLE, e.g. vehicle.v_actual")
    if component not in log.components:
        known = closest_names(component, log.components) if log.components else "none"
        raise CosimError(
            f"--signals {text!r}: no component '{component}' in {log.path.name}; components: {known}"
        )
    names = log.signal_names(component)
    if name not in names:
        raise CosimError(
            f"--signals {text!r}: no signal '{name}' of {component}; signals: {closest_names(name, names)}"
        )
    return component, name


def plot_signals(
    logs: Log | list[Log], png_path: str | Path, signals: list[str] | None = None, dpi: float = DPI, size=None
) -> Path:
    """Draw the signals of `logs` (all of the first log's, or `signals`; several logs overlaid)
    to `png_path`; returns the PNG path."""
    logs = logs if isinstance(logs, list) else [logs]
    panels = signal_panels(logs[0], signals)
    names = [(panel.label, *panel.label.split(".", 1)) for panel in panels[:MAX_PANELS]]
    drawn = list(panels[:MAX_PANELS])
    for run, log in enumerate(logs[1:], start=1):
        for label, component, name in names:
            if component in log.components and name in log.signal_names(component):
                recorded = log.signals(component)
                drawn.append(SignalPanel(label, recorded.unit(name), recorded.t, recorded[name], run))
    title = signal_title(logs[0], len(panels))
    if len(logs) > 1:
        title = f"{len(logs)} logs overlaid: " + ", ".join(log.path.stem for log in logs) + "\n" + title
    with collector_paused():
        return _render(drawn, title, Path(png_path), dpi, size, [log.path.stem for log in logs])


def signal_title(log: Log, signals: int) -> str:
    """The picture's title: the system's name (the scenario's, the SSP's, the FMU's model), how
    many of its `signals` are drawn when not all, then the file and how the run ended."""
    title = log.scenario_name or log.path.stem
    if signals > MAX_PANELS:
        title += f" (the first {MAX_PANELS} of {signals} signals; choose others with --signals)"
    outcome = log.outcome
    if outcome is None:
        ended = "no outcome recorded" + ("" if log.is_complete else " (log cut short)")
    else:
        at = f" at t = {float(outcome['time']):.6g} s" if outcome.get("time") else ""
        ended = f"ended{at}: {outcome.get('reason', 'unknown reason')}"
    return f"{title}\n{log.path.name}, {ended}"


def _render(
    drawn: list[SignalPanel],
    title: str,
    png_path: Path,
    dpi: float = DPI,
    size=None,
    runs: list[str] | None = None,
) -> Path:
    """One panel per label of `drawn` (in order), each run's line in its colour when `runs` names
    more than one."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    panels: dict[str, list[SignalPanel]] = {}
    for item in drawn:
        panels.setdefault(item.label, []).append(item)
    overlay = runs is not None and len(runs) > 1
    columns = 1 if len(panels) <= 6 else 2 if len(panels) <= 16 else 3
    rows = max(1, math.ceil(len(panels) / columns))
    title_lines = title.count("\n") + 1
    width, height = COLUMN_WIDTH * columns + 1.0, 1.3 + 0.22 * (title_lines - 2) + PANEL_HEIGHT * rows
    if size is not None:
        width, height = size[0] / dpi, size[1] / dpi
    figure = Figure(figsize=(width, height), dpi=dpi)
    canvas = FigureCanvasAgg(figure)
    grid = figure.add_gridspec(
        rows, columns, left=0.9 / width, right=0.985, top=1.0 - (0.8 + 0.22 * (title_lines - 2)) / height,
        bottom=0.5 / height, wspace=0.22, hspace=0.35,
    )  # fmt: skip
    shared = None
    for index, (label, items) in enumerate(panels.items()):
        row, column = divmod(index, columns)
        axes = figure.add_subplot(grid[row, column], sharex=shared)
        shared = shared or axes
        for item in items:
            axes.plot(item.t, item.values, lw=1.2, **({"color": run_colour(item.run)} if overlay else {}))
        axes.set_title(label, fontsize=9, loc="left", y=1.0)
        unit = items[0].unit
        axes.set_ylabel(f"[{unit}]" if unit else "value", fontsize=8)
        axes.tick_params(labelsize=8)
        axes.grid(alpha=GRID_ALPHA)
        if index + columns >= len(panels):  # the lowest panel of its column
            axes.set_xlabel("time [s]", fontsize=8)
        if overlay and index == 0:
            from matplotlib.lines import Line2D

            handles = [Line2D([], [], color=run_colour(k), label=name) for k, name in enumerate(runs)]
            axes.legend(handles=handles, loc="upper right", fontsize=7)
    if not panels:
        axes = figure.add_subplot(grid[0, 0])
        axes.text(
            0.5, 0.5, "no navcosim signals in this log", ha="center", va="center", transform=axes.transAxes
        )
        axes.set_axis_off()
    figure.suptitle(title, fontsize=12)
    canvas.draw()
    png_path.parent.mkdir(parents=True, exist_ok=True)
    write_png(png_path, np.asarray(canvas.buffer_rgba())[:, :, :3], dpi)
    return png_path
