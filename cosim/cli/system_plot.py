"""The block diagram of `cosim system --png`: components as boxes, connections as labelled arrows.

Columns follow the step order: a connection from a component stepped earlier to one stepped later
is drawn forward (left to right, solid); one into a component stepped earlier (feedback through a
state output, e.g. the vehicle pose) is drawn as a dashed arc. Each arrow carries the ports it
connects (arrays folded, `waypoints[1..1000,1..2]`) and any scale or offset. Uses matplotlib's
Agg backend: no display needed.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

from cosim.cli.wiring import fold  # noqa: E402
from cosim.scenario.description import TEMPLATE, SystemDescription  # noqa: E402

BOX_WIDTH, BOX_HEIGHT = 2.2, 1.0  # [diagram units]
COLUMN, ROW = 3.4, 2.2  # spacing of the boxes
INCH_PER_UNIT = 0.9  # figure inches per diagram unit
LABEL_MARGIN = 0.15  # [diagram units] between a label and the boxes beside it
MAX_LABEL_LINES = 4
_FMU_COLOUR, _PYTHON_COLOUR, _ADDED_COLOUR = "#dbe9f6", "#e5f5e0", "#fde0c5"


def _columns(description: SystemDescription, order: list[str]) -> dict[str, int]:
    """Column of each component: the longest chain of forward connections leading to it."""
    position = {name: i for i, name in enumerate(order)}
    column = dict.fromkeys(order, 0)
    for name in order:  # producers come first in the step order, so one pass suffices
        for connection in description.connections:
            source, target = connection.source_component, connection.target_component
            if target == name and position[source] < position[target]:
                column[name] = max(column[name], column[source] + 1)
    return column


def _label(links) -> str:
    lines = []
    for link in links:
        source, target = link.source.split(".", 1)[1], link.target.split(".", 1)[1]
        text = source if source == target else f"{source} → {target}"
        if link.scale != 1.0:
            text += f" ×{link.scale:g}"
        if link.offset != 0.0:
            text += f" {link.offset:+g}"
        lines.append(text)
    if len(", ".join(lines)) <= 24:  # short plain port lists on one line: "x, y, theta"
        return ", ".join(lines)
    if len(lines) > MAX_LABEL_LINES:
        lines = lines[: MAX_LABEL_LINES - 1] + [f"… ({len(lines) - MAX_LABEL_LINES + 1} more)"]
    return "\n".join(lines)


def _label_width(text: str) -> float:
    """The width [diagram units] of a label at 8 pt: ~0.6 em a character, 0.9 inch a unit."""
    return max((len(line) for line in text.splitlines()), default=0) * 8 * 0.6 / 72 / INCH_PER_UNIT


def _column_x(column: dict[str, int], rows: dict[str, int], pairs: dict) -> list[float]:
    """The x of each column's centre: COLUMN apart, wider where a label of an arrow between two
    neighbouring boxes (same row, next column) would not fit between them."""
    gaps = [COLUMN - BOX_WIDTH] * max(column.values(), default=0)
    for (source, target), links in pairs.items():
        if column[target] == column[source] + 1 and rows[source] == rows[target]:
            needed = _label_width(_label(links)) + 2 * LABEL_MARGIN
            gaps[column[source]] = max(gaps[column[source]], needed)
    xs = [0.0]
    for gap in gaps:
        xs.append(xs[-1] + BOX_WIDTH + gap)
    return xs


def draw_system(description: SystemDescription, order: list[str], png: Path, title: str = "") -> None:
    """Write the block diagram of `description` (stepped in `order`) to `png`."""
    figure = system_figure(description, order, title)
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(png)
    plt.close(figure)


def system_figure(description: SystemDescription, order: list[str], title: str = ""):
    """The block diagram as a matplotlib figure (its boxes, then the arrows' labels, are the axes'
    patches and texts with gid "box" and "label")."""
    import textwrap

    column = _columns(description, order)
    pairs: dict[tuple[str, str], list] = {}
    for link in fold(description.connections):
        pairs.setdefault((link.source.split(".")[0], link.target.split(".")[0]), []).append(link)
    rows: dict[int, int] = {}
    row_of: dict[str, int] = {}
    for name in order:
        row_of[name] = rows.get(column[name], 0)
        rows[column[name]] = row_of[name] + 1
    xs = _column_x(column, row_of, pairs)
    centre = {name: (xs[column[name]], -row_of[name] * ROW) for name in order}
    width = xs[-1] + COLUMN
    height = max(rows.values()) * ROW + 2.0
    figure_width = max(8.0, width * INCH_PER_UNIT)
    figure, axes = plt.subplots(figsize=(figure_width, max(4.5, height * 1.1)), dpi=100)
    position = {name: i for i, name in enumerate(order)}
    for (source, target), links in pairs.items():
        forward = position[source] < position[target]
        (x0, y0), (x1, y1) = centre[source], centre[target]
        added = any(link.where != TEMPLATE for link in links)
        colour = "#d95f02" if added else ("#333333" if forward else "#7f7f7f")
        if forward:
            start, end = (x0 + BOX_WIDTH / 2, y0), (x1 - BOX_WIDTH / 2, y1)
            if abs(y1 - y0) > 1e-9:
                rad = -0.15
            else:  # over the boxes it skips, if any
                rad = 0.0 if column[target] - column[source] == 1 else -0.3
        else:  # feedback: from the bottom of the producer round under the boxes to the consumer
            start, end = (x0, y0 - BOX_HEIGHT / 2), (x1, y1 - BOX_HEIGHT / 2)
            rad = -0.3
        arrow = FancyArrowPatch(
            start,
            end,
            connectionstyle=f"arc3,rad={rad}",
            arrowstyle="-|>",
            mutation_scale=14,
            linewidth=1.4,
            color=colour,
            linestyle="-" if forward else "--",
            zorder=1,
        )
        axes.add_patch(arrow)
        # The middle of matplotlib's arc3 curve (a quadratic Bezier whose control point lies `rad`
        # times the chord length off the chord's middle): the chord's middle + rad/2 (dy, -dx).
        dx, dy = end[0] - start[0], end[1] - start[1]
        middle = ((start[0] + end[0]) / 2 + rad * dy / 2, (start[1] + end[1]) / 2 - rad * dx / 2)
        # Above a forward arrow, below a feedback arc, on a sloping one (its box hides the line).
        sloping = forward and abs(dy) > 1e-9
        above = forward and not sloping
        axes.text(
            middle[0],
            middle[1] + (0.0 if sloping else 0.08 if above else -0.08),
            _label(links),
            ha="center",
            va="center" if sloping else "bottom" if above else "top",
            fontsize=8,
            color=colour,
            bbox={"boxstyle": "round,pad=0.15", "facecolor": "white", "edgecolor": "none", "alpha": 0.85},
            zorder=3,
            gid="label",
        )
    for name in order:
        component = description.components[name]
        x, y = centre[name]
        fill = _PYTHON_COLOUR if component.kind != "fmu" else _FMU_COLOUR
        if component.where.startswith("[components."):
            fill = _ADDED_COLOUR
        box = FancyBboxPatch(
            (x - BOX_WIDTH / 2, y - BOX_HEIGHT / 2),
            BOX_WIDTH,
            BOX_HEIGHT,
            boxstyle="round,pad=0.04",
            facecolor=fill,
            edgecolor="#333333",
            linewidth=1.2,
            zorder=2,
            gid="box",
        )
        axes.add_patch(box)
        rate = "every step" if component.rate is None else f"{component.rate:g} Hz"
        if component.kind == "fmu":
            detail = f"{component.model_name}\nFMI {component.fmi_version}.0, {rate}"
        else:
            detail = f"Python {component.kind}\n{rate}"
        axes.text(
            x,
            y + 0.22,
            f"{position[name] + 1}. {name}",
            ha="center",
            va="center",
            fontsize=10,
            weight="bold",
            zorder=4,
        )
        axes.text(x, y - 0.18, detail, ha="center", va="center", fontsize=7.5, zorder=4)
    lowest = min(y for _, y in centre.values())
    axes.set_xlim(-COLUMN * 0.5, width - COLUMN * 0.5)
    axes.set_ylim(lowest - ROW * 1.6, ROW * 0.9)
    axes.set_aspect("equal")
    axes.axis("off")
    heading = f"{title}: " if title else ""
    changes = []
    if description.removed:
        changes.append(f"removed from the template: {', '.join(description.removed)}")
    if description.replacing:
        changes.append(f"replaced by the scenario's FMU: {', '.join(description.replacing)}")
    if description.dropped:
        changes.append(f"{len(description.dropped)} template connections dropped")
    # Wrapped to the figure's width (~0.6 em a character at 9 pt) so that no part is cut off.
    characters = max(40, int(figure_width * 72 / (9 * 0.6) * 0.95))
    lines = [
        f"{heading}{len(description.components)} components, {len(description.connections)} connections; "
        "numbers = step order, dashed = feedback into an earlier-stepped component, orange = the scenario's",
        *(["; ".join(changes)] if changes else []),
    ]
    axes.set_title("\n".join(textwrap.fill(line, characters) for line in lines), fontsize=9)
    figure.tight_layout()
    return figure
