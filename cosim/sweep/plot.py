"""`sweep.png`: each outcome metric against each varied key, or a map over two varied keys.

One key (or more than two): a grid of scatter plots, one row per metric and one column per key.
Two keys: one map per metric over the plane of the two keys; a grid sweep draws it as a heat map
of cells, a random or LHS sweep as points coloured by the metric. Only completed runs are drawn; a
key whose values are not all numbers is drawn as categories in sweep order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cosim.sweep.results import COMPLETED

UNITS = {"time": "s", "distance": "m", "min_clearance": "m", "recovery_time": "s"}


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


def _metric(rows: list[dict[str, str]], key: str) -> np.ndarray:
    if key == "reached":
        return np.array([1.0 if row.get(key) == "true" else 0.0 for row in rows])
    return np.array([_number(row.get(key)) for row in rows])


def _label(key: str) -> str:
    return f"{key} [{UNITS[key]}]" if key in UNITS else key


def plot_sweep(
    rows: list[dict[str, str]], keys: Sequence[str], outcome_keys: Sequence[str], png_path: Path, grid: bool
) -> Path | None:
    """Draw `png_path` from the completed rows; returns None when no run completed.

    Uses matplotlib's object API (no pyplot state), so it may draw in a thread of its own."""
    done = [row for row in rows if row.get("status") == COMPLETED]
    if not done:
        return None
    metrics = [key for key in outcome_keys if key != "reason" and np.isfinite(_metric(done, key)).any()]
    if len(keys) == 2:
        figure = _maps(done, keys, metrics, grid)
    else:
        figure = _scatters(done, keys, metrics)
    figure.savefig(png_path, dpi=90)
    return png_path


def _scatters(rows, keys, metrics):
    figure = Figure(figsize=(3.4 * len(keys), 2.2 * len(metrics)))
    axes = figure.subplots(len(metrics), len(keys), squeeze=False)
    for column, key in enumerate(keys):
        x, labels = _axis([row.get(key, "") for row in rows])
        for line, metric in enumerate(metrics):
            axis = axes[line][column]
            axis.plot(x, _metric(rows, metric), "o", markersize=4, alpha=0.7)
            if labels is not None:
                axis.set_xticks(range(len(labels)), labels, rotation=30, fontsize=7)
            if line == len(metrics) - 1:
                axis.set_xlabel(key)
            if column == 0:
                axis.set_ylabel(_label(metric), fontsize=8)
            axis.grid(alpha=0.3)
    figure.tight_layout()
    return figure


def _maps(rows, keys, metrics, grid: bool):
    columns = min(3, len(metrics))
    lines = math.ceil(len(metrics) / columns)
    figure = Figure(figsize=(4.2 * columns, 3.4 * lines))
    axes = figure.subplots(lines, columns, squeeze=False)
    x, x_labels = _axis([row.get(keys[1], "") for row in rows])
    y, y_labels = _axis([row.get(keys[0], "") for row in rows])
    for index, metric in enumerate(metrics):
        axis = axes[index // columns][index % columns]
        values = _metric(rows, metric)
        if grid:
            xs, ys = np.unique(x), np.unique(y)
            cells = np.full((len(ys), len(xs)), np.nan)
            for xi, yi, value in zip(np.searchsorted(xs, x), np.searchsorted(ys, y), values, strict=True):
                cells[yi, xi] = value  # a grid has one run per cell (duplicates are dropped)
            image = axis.imshow(cells, origin="lower", aspect="auto", cmap="viridis")
            if cells.size <= 64:  # small grids: the number in each cell too
                for (yi, xi), value in np.ndenumerate(cells):
                    if np.isfinite(value):
                        axis.text(xi, yi, f"{value:.3g}", ha="center", va="center", fontsize=7, color="w")
            axis.set_xticks(range(len(xs)), x_labels or [f"{v:g}" for v in xs], rotation=30, fontsize=7)
            axis.set_yticks(range(len(ys)), y_labels or [f"{v:g}" for v in ys], fontsize=7)
        else:
            image = axis.scatter(x, y, c=values, cmap="viridis", s=30)
            if x_labels is not None:
                axis.set_xticks(range(len(x_labels)), x_labels, rotation=30, fontsize=7)
            if y_labels is not None:
                axis.set_yticks(range(len(y_labels)), y_labels, fontsize=7)
        figure.colorbar(image, ax=axis)
        axis.set_title(_label(metric), fontsize=9)
        axis.set_xlabel(keys[1], fontsize=8)
        axis.set_ylabel(keys[0], fontsize=8)
    for index in range(len(metrics), lines * columns):
        axes[index // columns][index % columns].axis("off")
    figure.tight_layout()
    return figure
