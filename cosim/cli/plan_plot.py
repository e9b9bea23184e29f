"""Pictures of plans: the map, the inflated zone, the explored cells and the path, in metres.

One panel per plan; `save_plan_png` draws one, `save_comparison_png` draws several side by side
(`cosim plan compare`). Figures have a fixed size in pixels (see `figure_size_px`) so a caller
knows what it gets. Uses matplotlib's Agg backend: no display needed; matplotlib is imported when
a PNG is drawn, so `cosim plan` without `--png` does not load it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.errors import CosimError

DPI = 100
PANEL_SIZE_IN = (7.0, 5.0)  # one panel, inches (at DPI: 700 x 500 px)
MAX_PANELS_PER_ROW = 3

# Cell classes drawn as one image: 0 free, 1 explored, 2 untrusted point, 3 inflated zone, 4 obstacle.
_CELL_COLOURS = ["#ffffff", "#9ecae1", "#d9d9d9", "#fdd0a2", "#252525"]
_PATH_COLOUR = "#d62728"


@dataclass(frozen=True)
class PlanPanel:
    """One plan to draw: a title, the grid it was planned on, the result and the inflated cells."""

    title: str
    result: object  # planner.result.PlanResult
    inflated: np.ndarray | None = None  # bool [row, col]: free cells inside the expansion distance
    untrusted: np.ndarray | None = None  # bool [row, col]: cells closed before the search (untrusted points)


def panel_layout(panel_count: int) -> tuple[int, int]:
    """(rows, columns) of panels: one row up to three panels, four as 2 x 2, more three per row."""
    columns = 2 if panel_count == 4 else min(panel_count, MAX_PANELS_PER_ROW)
    return math.ceil(panel_count / columns), columns


def figure_size_px(panel_count: int) -> tuple[int, int]:
    """(width, height) [px] of the PNG for `panel_count` panels."""
    rows, columns = panel_layout(panel_count)
    return round(PANEL_SIZE_IN[0] * columns * DPI), round(PANEL_SIZE_IN[1] * rows * DPI)


def _cell_classes(grid, panel: PlanPanel) -> np.ndarray:
    classes = np.zeros(grid.shape, dtype=np.int8)
    explored = getattr(panel.result, "explored", None)
    if explored is not None and np.shape(explored) == grid.shape:
        classes[np.asarray(explored, dtype=bool)] = 1
    if panel.untrusted is not None:
        classes[panel.untrusted] = 2
    if panel.inflated is not None:
        classes[panel.inflated & ~grid.occupied] = 3
    classes[grid.occupied] = 4
    return classes


def _draw_panel(axes, grid, panel: PlanPanel, start, goal) -> None:
    from matplotlib.colors import ListedColormap

    rows, cols = grid.shape
    left, bottom = grid.origin
    extent = (left, left + cols * grid.resolution, bottom, bottom + rows * grid.resolution)
    # Row 0 is the top of the map, which is what imshow's origin="upper" draws at the top.
    axes.imshow(
        _cell_classes(grid, panel),
        cmap=ListedColormap(_CELL_COLOURS),
        vmin=0,
        vmax=4,
        extent=extent,
        origin="upper",
        interpolation="nearest",
    )
    path = np.asarray(panel.result.path)
    if len(path):
        axes.plot(path[:, 0], path[:, 1], color=_PATH_COLOUR, linewidth=1.8)
    axes.plot(start[0], start[1], marker="o", color="#2ca02c", markersize=8, markeredgecolor="black")
    axes.plot(goal[0], goal[1], marker="*", color="#ffd700", markersize=13, markeredgecolor="black")
    result = panel.result
    axes.set_title(
        f"{panel.title}\n{result.length:.2f} m, {result.path_nodes} path nodes, "
        f"{result.searched_nodes} searched",
        fontsize=9,
    )
    axes.set_xlabel("x [m]")
    axes.set_ylabel("y [m]")
    axes.set_xlim(extent[0], extent[1])
    axes.set_ylim(extent[2], extent[3])
    axes.set_aspect("equal")


def _legend_handles(with_inflation: bool, with_untrusted: bool) -> list:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [
        Patch(facecolor="#252525", label="obstacle"),
        Patch(facecolor="#9ecae1", label="explored (searched) cell"),
        Line2D([], [], color=_PATH_COLOUR, linewidth=1.8, label="path"),
        Line2D([], [], marker="o", color="#2ca02c", markeredgecolor="black", linestyle="", label="start"),
        Line2D([], [], marker="*", color="#ffd700", markeredgecolor="black", linestyle="", label="goal"),
    ]
    if with_untrusted:
        handles.insert(1, Patch(facecolor="#d9d9d9", label="untrusted point (closed before the search)"))
    if with_inflation:
        handles.insert(1, Patch(facecolor="#fdd0a2", label="inflated zone (expansion distance)"))
    return handles


def save_comparison_png(
    path: str | Path, grid, panels: list[PlanPanel], start, goal, suptitle: str = ""
) -> Path:
    """Draw one panel per plan (side by side, see panel_layout) into a PNG; returns its path."""
    if not panels:
        raise CosimError("nothing to draw: no plan")
    import matplotlib

    matplotlib.use("Agg")  # files only; never needs a display
    import matplotlib.pyplot as plt

    path = Path(path)
    width_px, height_px = figure_size_px(len(panels))
    rows, columns = panel_layout(len(panels))
    figure, axes_grid = plt.subplots(
        rows, columns, figsize=(width_px / DPI, height_px / DPI), dpi=DPI, squeeze=False, layout="constrained"
    )
    try:
        for index, axes in enumerate(axes_grid.flat):
            if index >= len(panels):
                axes.set_axis_off()
                continue
            _draw_panel(axes, grid, panels[index], start, goal)
        with_inflation = any(panel.inflated is not None and panel.inflated.any() for panel in panels)
        with_untrusted = any(panel.untrusted is not None and panel.untrusted.any() for panel in panels)
        figure.legend(
            handles=_legend_handles(with_inflation, with_untrusted),
            loc="outside lower center",
            ncol=3 if columns == 1 else 4,
            fontsize=8,
            frameon=False,
        )
        if suptitle:
            figure.suptitle(suptitle, fontsize=11)
        try:
            figure.savefig(path, dpi=DPI)
        except OSError as error:
            raise CosimError(f"cannot write {path}: {error.strerror or error}") from None
    finally:
        plt.close(figure)
    return path


def save_plan_png(path: str | Path, grid, panel: PlanPanel, start, goal, suptitle: str = "") -> Path:
    """Draw one plan into a PNG of figure_size_px(1); returns its path."""
    return save_comparison_png(path, grid, [panel], start, goal, suptitle)
