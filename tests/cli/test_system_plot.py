"""The block diagram of `cosim system --png` keeps every label readable: no arrow label lies over
a component box, and the title lies inside the figure (it was cut off on narrow diagrams, and
`waypoints[1..1000,1..2]` covered pure_pursuit's name). Checked on the rendered figure's extents."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import pytest

from cosim.cli.system_plot import system_figure
from cosim.navigation.build import build_run
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]


def _extents(figure):
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    axes = figure.axes[0]
    boxes = [patch.get_window_extent(renderer) for patch in axes.patches if patch.get_gid() == "box"]
    labels = [
        (text.get_text(), text.get_window_extent(renderer))
        for text in axes.texts
        if text.get_gid() == "label"
    ]
    return boxes, labels, axes.title.get_window_extent(renderer), figure.bbox


@pytest.mark.parametrize(
    ("scenario", "title"),
    [
        ("warehouse_diff_drive_one_obstacle.toml", "warehouse_diff_drive_one_obstacle"),
        ("warehouse_bicycle_one_obstacle.toml", "a long title " * 20),
    ],
)
def test_labels_stay_off_the_boxes_and_the_title_inside_the_figure(scenario, title):
    built = build_run(load_scenario(REPO / "scenarios" / scenario))
    order = [component.name for component in built.system.order()]
    figure = system_figure(built.description, order, title=title)
    try:
        boxes, labels, title_box, page = _extents(figure)
        assert len(boxes) == len(order) and labels
        for text, extent in labels:
            for box in boxes:
                assert not extent.overlaps(box), f"label {text!r} lies over a component box"
        assert page.x0 <= title_box.x0 and title_box.x1 <= page.x1, "title cut off at the sides"
        assert title_box.y1 <= page.y1, "title cut off at the top"
    finally:
        plt.close(figure)
