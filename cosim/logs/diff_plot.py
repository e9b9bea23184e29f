"""Draw what `cosim log diff A B --png OUT` found: per signal above the tolerance (the largest
deviations first, up to `MAX_SIGNALS`) a row of two panels, A and B over time on the left and
A - B on the right (on A's sample times, B interpolated as the comparison does; an angle's
difference taken round the circle), with the time of the largest deviation marked. Nothing above
the tolerance: one line saying so (and the outcome's differences, if any)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from cosim.logs.diff import DiffReport, signal_difference
from cosim.logs.plot import DPI, GRID_ALPHA, collector_paused, write_png
from cosim.logs.plot_map import run_colour

if TYPE_CHECKING:
    from cosim.logs.reader import Log

MAX_SIGNALS = 12  # rows drawn; the title says how many more differ
ROW_HEIGHT = 1.7  # [in]
WIDTH = 14.0  # [in]
DIFFERENCE_COLOR = "#111111"


def plot_diff(
    report: DiffReport, log_a: Log, log_b: Log, png_path: str | Path, dpi: float = DPI, size=None
) -> Path:
    """Draw the signals of `report` above its tolerance, A and B and A - B, to `png_path`."""
    with collector_paused():
        figure = diff_figure(report, log_a, log_b, dpi, size)
        png_path = Path(png_path)
        png_path.parent.mkdir(parents=True, exist_ok=True)
        write_png(png_path, np.asarray(figure.canvas.buffer_rgba())[:, :, :3], dpi)
        return png_path


def diff_figure(report: DiffReport, log_a: Log, log_b: Log, dpi: float = DPI, size=None):
    """The drawn figure (canvas drawn); its axes are, per signal, the A/B panel then the A - B one."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    exceeding = report.exceeding
    shown = exceeding[:MAX_SIGNALS]
    rows = max(len(shown), 1)
    lines = [f"A: {log_a.path.name} (solid)   B: {log_b.path.name} (dashed)"]
    summary = f"{len(exceeding)} of {len(report.deviations)} common signals differ by more than "
    summary += f"{report.tolerance:g}"
    if len(exceeding) > len(shown):
        summary += f" (the {len(shown)} largest drawn)"
    lines.append(summary)
    if report.outcome_differences:
        lines.append("outcome differs in: " + ", ".join(key for key, _, _ in report.outcome_differences))
    width, height = WIDTH, 1.0 + 0.25 * len(lines) + ROW_HEIGHT * rows
    if size is not None:
        width, height = size[0] / dpi, size[1] / dpi
    figure = Figure(figsize=(width, height), dpi=dpi)
    canvas = FigureCanvasAgg(figure)
    grid = figure.add_gridspec(
        rows, 2, width_ratios=(1.4, 1.0), left=0.8 / width, right=1.0 - 0.2 / width,
        top=1.0 - (0.5 + 0.25 * len(lines)) / height, bottom=0.5 / height, wspace=0.18, hspace=0.45,
    )  # fmt: skip
    figure.suptitle("\n".join(lines), fontsize=11)
    if not shown:
        axes = figure.add_subplot(grid[0, :])
        axes.text(
            0.5, 0.5, f"no signal differs by more than {report.tolerance:g}", ha="center", va="center",
            transform=axes.transAxes,
        )  # fmt: skip
        axes.set_axis_off()
        canvas.draw()
        return figure
    shared = None
    for row, item in enumerate(shown):
        a, b = log_a.signals(item.component), log_b.signals(item.component)
        left = figure.add_subplot(grid[row, 0], sharex=shared)
        shared = shared or left
        right = figure.add_subplot(grid[row, 1], sharex=shared)
        left.plot(a.t, a[item.name], color=run_colour(0), lw=1.2)
        left.plot(b.t, b[item.name], "--", color=run_colour(1), lw=1.2)
        t_ns, difference = signal_difference(
            a.t_ns, a[item.name], b.t_ns, b[item.name], np.array_equal(a.t_ns, b.t_ns), item.angle
        )
        right.plot(t_ns / 1e9, difference, color=DIFFERENCE_COLOR, lw=1.1)
        unit = a.unit(item.name) or b.unit(item.name)
        name = f"{item.component}.{item.name}"
        left.set_title(f"{name}: A solid, B dashed", fontsize=9, loc="left", y=1.0)
        mod = " (mod 2 pi)" if item.angle else ""
        right.set_title(
            f"A - B{mod}: max |A-B| {item.max_deviation:.4g} at t = {item.at_time:.3f} s",
            fontsize=9,
            loc="left",
            y=1.0,
        )
        if np.isfinite(item.at_time):
            for axes in (left, right):
                axes.axvline(item.at_time, color="0.5", lw=0.8, ls=":")
        for axes in (left, right):
            axes.set_ylabel(f"[{unit}]" if unit else "value", fontsize=8)
            axes.tick_params(labelsize=8)
            axes.grid(alpha=GRID_ALPHA)
        if row == len(shown) - 1:
            left.set_xlabel("time [s]", fontsize=8)
            right.set_xlabel("time [s]", fontsize=8)
    canvas.draw()
    return figure
