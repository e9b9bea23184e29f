"""sweep.png is laid out so that its texts are readable: the heading, the panels' titles, axis
labels, tick labels and colour bar labels lie inside the figure, none over another nor over a
panel; each tick label sits at the value it names (read back through the panel's own data
transform); a colour bar shows, beside each of its labels, the colour its map gives that value.
Checked on the drawn figure and its pixels, in every layout the sweep draws."""

from __future__ import annotations

import itertools
import random

import numpy as np
import pytest
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.text import Text
from test_sweep_png_pixels import CASES as PIXEL_CASES
from test_sweep_report import KEYS, OUTCOME, _rows

from cosim.sweep.plot import sweep_figure


def _all_failed() -> list[dict[str, str]]:
    return _rows(seed=1, reasons=("failed",))


def _big_grid() -> list[dict[str, str]]:
    """A 10 x 10 grid (no values in the cells) of large and of small signed metrics."""
    rng, rows = random.Random(3), []
    for count in range(90, 390, 30):
        for stop in range(1000, 11000, 1000):
            row = _rows(seed=0)[0] | {"lidar.count": str(count), "simulation.stop_time": str(stop)}
            row.update(time=f"{rng.uniform(1e5, 3e6):.3f}", distance=f"{rng.uniform(-0.002, 0.001):.6f}")
            rows.append(
                row | {"run_id": f"{len(rows):016x}", "status": "completed", "reason": "goal_reached"}
            )
    return rows


def _scattered() -> list[dict[str, str]]:
    """30 points at random in the plane of two keys (as a random or LHS sweep draws them)."""
    rng, rows = random.Random(4), []
    for row in _rows(replicates=4, seed=8)[:30]:
        rows.append(row | {KEYS[0]: f"{rng.uniform(0, 1):.4f}", KEYS[1]: f"{rng.uniform(10, 20):.3f}"})
    return rows


def _one_key_categories() -> list[dict[str, str]]:
    names = ("maps/warehouse_with_a_long_name.yaml", "maps/b.yaml", "maps/c.yaml")
    return [row | {"map": name} for row, name in zip(_rows(seed=7)[:3], names, strict=True)]


CASES = PIXEL_CASES | {
    "all failed": (_all_failed, KEYS, True, 1),
    "10 x 10 grid": (_big_grid, ("lidar.count", "simulation.stop_time"), True, 1),
    "30 random points": (_scattered, KEYS, False, 1),
    "one key, categories": (_one_key_categories, ["map"], True, 1),
}


def _drawn(case: str):
    make_rows, keys, grid, replicates = CASES[case]
    figure = sweep_figure(make_rows(), keys, OUTCOME, grid, f"{case}: sweep", replicates)
    if not isinstance(figure.canvas, FigureCanvasAgg):
        FigureCanvasAgg(figure)
    figure.canvas.draw()
    return figure, figure.canvas.get_renderer(), keys, grid


def _frame_texts(figure, renderer) -> list[tuple[Text, object]]:
    """Every drawn text but the panels' own data texts (cell values, marks' counts) and legends."""
    inside = {id(text) for axis in figure.axes for text in axis.texts}
    for axis in figure.axes:
        if axis.get_legend() is not None:
            inside.update(id(text) for text in axis.get_legend().get_texts())
    return [
        (text, text.get_window_extent(renderer))
        for text in figure.findobj(Text)
        if text.get_visible() and text.get_text() and id(text) not in inside
    ]


def _overlap(one: Text, a, other: Text, b, renderer) -> bool:
    """Whether two texts' boxes overlap (by more than half a pixel): texts turned by the same angle
    as the rectangles they are (centred on their boxes), others as their upright boxes."""
    rotation = one.get_rotation()
    if rotation == other.get_rotation() != 0:
        angle = np.radians(rotation)
        sizes = []
        for text in (one, other):
            text.set_rotation(0)
            box = text.get_window_extent(renderer)
            text.set_rotation(rotation)
            sizes.append((box.width, box.height))
        dx, dy = (b.x0 + b.x1 - a.x0 - a.x1) / 2, (b.y0 + b.y1 - a.y0 - a.y1) / 2
        along, across = dx * np.cos(angle) + dy * np.sin(angle), -dx * np.sin(angle) + dy * np.cos(angle)
        return (
            abs(along) < (sizes[0][0] + sizes[1][0]) / 2 - 0.5
            and abs(across) < (sizes[0][1] + sizes[1][1]) / 2 - 0.5
        )
    overlap_x = min(a.x1, b.x1) - max(a.x0, b.x0)
    overlap_y = min(a.y1, b.y1) - max(a.y0, b.y0)
    return overlap_x > 0.5 and overlap_y > 0.5


def _number(text: str) -> float | None:
    try:
        return float(text.replace("\N{MINUS SIGN}", "-"))
    except ValueError:
        return None


@pytest.mark.parametrize("case", CASES)
def test_no_label_is_cut_or_over_another_or_over_a_panel(case):
    figure, renderer, _, _ = _drawn(case)
    width, height = figure.canvas.get_width_height()
    texts = _frame_texts(figure, renderer)
    titles = [axis.get_title() for axis in figure.axes]
    assert len(texts) > 3 * len(figure.axes)  # titles, labels, ticks: not just a few
    for text, box in texts:
        assert box.x0 >= 0 and box.y0 >= 0 and box.x1 <= width and box.y1 <= height, text.get_text()
    for (one, a), (other, b) in itertools.combinations(texts, 2):
        assert not _overlap(one, a, other, b, renderer), (one.get_text(), other.get_text())
    panels = [axis.get_window_extent(renderer) for axis in figure.axes if axis.get_title() in titles]
    for (text, box), panel in itertools.product(texts, panels):
        overlap_x = min(box.x1, panel.x1) - max(box.x0, panel.x0)
        overlap_y = min(box.y1, panel.y1) - max(box.y0, panel.y0)
        assert overlap_x <= 0.5 or overlap_y <= 0.5, text.get_text()


@pytest.mark.parametrize("case", CASES)
def test_each_panel_is_framed_at_its_edges(case):
    figure, renderer, _, _ = _drawn(case)
    for axis in (axis for axis in figure.axes if axis.get_title()):
        box = axis.get_window_extent(renderer)
        for side, spine in axis.spines.items():
            line = spine.get_window_extent(renderer)
            edge = {"left": box.x0, "right": box.x1, "bottom": box.y0, "top": box.y1}[side]
            if side in ("bottom", "top"):
                along, across, ends = (line.x0, line.x1), (line.y0, line.y1), (box.x0, box.x1)
            else:
                along, across, ends = (line.y0, line.y1), (line.x0, line.x1), (box.y0, box.y1)
            assert spine.get_visible() and across == pytest.approx((edge, edge), abs=1), side
            assert along == pytest.approx(ends, abs=1), side


def _tick_labels(texts, panel, side: str):
    """Texts under a panel (side x) or left of it (side y), within its extent along that side."""
    found = []
    for text, box in texts:
        middle_x, middle_y = (box.x0 + box.x1) / 2, (box.y0 + box.y1) / 2
        if side == "x" and box.y1 <= panel.y0 + 0.5 and panel.x0 - 1 <= middle_x <= panel.x1 + 1:
            if panel.y0 - box.y1 < 12:  # the labels next to the edge, not the axis label
                found.append((text.get_text(), middle_x))
        if side == "y" and box.x1 <= panel.x0 + 0.5 and panel.y0 - 1 <= middle_y <= panel.y1 + 1:
            if panel.x0 - box.x1 < 12 and text.get_rotation() == 0:
                found.append((text.get_text(), middle_y))
    return found


@pytest.mark.parametrize("case", CASES)
def test_each_tick_label_sits_at_its_value(case):
    figure, renderer, keys, grid = _drawn(case)
    texts = _frame_texts(figure, renderer)
    make_rows = CASES[case][0]
    rows = make_rows()
    checked = 0
    for axis in (axis for axis in figure.axes if axis.get_title()):
        panel = axis.get_window_extent(renderer)
        for side in ("x", "y"):
            labels = _tick_labels(texts, panel, side)
            assert labels, (axis.get_title(), side)
            # A key on a grid map or with category values: ticks at the cells, in sweep order or
            # sorted by value; otherwise numbers at their own value.
            if len(keys) == 2:
                key = keys[1 if side == "x" else 0]
            else:  # one key: along x; more: numbers here
                key = keys[0] if len(keys) == 1 and side == "x" else None
            values = list(dict.fromkeys(row[key] for row in rows)) if key else []
            numeric = not values or all(_number(value) is not None for value in values)
            if key and numeric:
                values = sorted(set(values), key=float)
            for text, at in labels:
                if key and not numeric:  # categories, in sweep order
                    position = values.index(text)
                elif key and grid and len(keys) == 2:  # a grid map's cells: the values sorted
                    position = [f"{float(value):g}" for value in values].index(text)
                else:
                    position = _number(text)
                    assert position is not None, text
                point = (position, 0.0) if side == "x" else (0.0, position)
                drawn_at = axis.transData.transform(point)[0 if side == "x" else 1]
                # (a label is centred on its digits, not on its box: up to 2 px apart)
                assert drawn_at == pytest.approx(at, abs=3), (axis.get_title(), side, text)
                checked += 1
    assert checked >= 4 * len([axis for axis in figure.axes if axis.get_title()])


@pytest.mark.parametrize("case", [case for case in CASES if len(CASES[case][1]) == 2])
def test_a_colour_bar_shows_the_colour_of_each_value_it_names(case):
    figure, renderer, _, _ = _drawn(case)
    pixels = np.asarray(figure.canvas.buffer_rgba())[::-1, :, :3].astype(float) / 255  # y upwards
    texts = _frame_texts(figure, renderer)
    for axis in (axis for axis in figure.axes if axis.get_title()):
        panel = axis.get_window_extent(renderer)
        image = next(child for child in axis.get_children() if hasattr(child, "get_cmap"))
        colours, norm = image.get_cmap(), image.norm
        if "reached the goal" in axis.get_title():
            assert colours.name.startswith("RdYlGn") and (norm.vmin, norm.vmax) == (0.0, 1.0)
        values = np.asarray(image.get_array(), dtype=float)
        finite = values[np.isfinite(values)]
        assert norm.vmin <= finite.min() and finite.max() <= norm.vmax
        # The bar's labels: numbers right of the panel, within its height, the nearest ones to it.
        labels = [
            (float(text.get_text().replace("\N{MINUS SIGN}", "-")), box)
            for text, box in texts
            if _number(text.get_text()) is not None
            and panel.x1 < box.x0 < panel.x1 + 80
            and panel.y0 - 1 <= (box.y0 + box.y1) / 2 <= panel.y1 + 1
        ]
        nearest = min(box.x0 for _, box in labels)  # its labels, left-aligned; not the next panel's
        labels = [(value, box) for value, box in labels if box.x0 < nearest + 1]
        assert len(labels) >= 3, axis.get_title()
        assert [value for value, _ in labels] == sorted(value for value, _ in labels)
        for value, box in labels:
            assert norm.vmin - 1e-9 <= value <= norm.vmax + 1e-9
            # (a value at an end of the bar: the colour a row inside its frame)
            row = int(np.clip(round((box.y0 + box.y1) / 2), panel.y0 + 2, panel.y1 - 3))
            # Between the panel and the label: white, the bar (framed) and the tick; inside the
            # frame, a few pixels of the value's colour.
            between = pixels[row, int(panel.x1) + 1 : int(box.x0)]
            expected = np.asarray(colours(norm(value)))[:3]
            near = np.abs(between - expected).max(axis=1) < 0.04
            runs = np.convolve(near, np.ones(3), mode="valid")
            assert runs.max(initial=0) == 3, (axis.get_title(), value, expected)


def test_the_maps_colour_maps_are_the_sweeps():
    figure, _, _, _ = _drawn("grid")
    images = [
        next(child for child in axis.get_children() if hasattr(child, "get_cmap"))
        for axis in figure.axes
        if axis.get_title()
    ]
    assert images[0].get_cmap().name.startswith(colormaps["RdYlGn"].name)
    assert all(image.get_cmap().name.startswith("viridis") for image in images[1:])
