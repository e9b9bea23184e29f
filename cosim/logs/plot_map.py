"""The map panel of a run's plot (`cosim.logs.plot`): the map and its inflated zone, the unknown
obstacles and their tracks, every plan (the one in force at the end dashed, each earlier one
solid and fainter the older it is, a ring where the robot replanned, a Hybrid A* plan's reverse
segments in their own colour), the driven trajectory with where the avoider took over, the start,
and each goal given (an earlier one hollow, labelled with the time it was replaced; the goal in
force at the end filled, with its tolerance circle). Several runs overlay over the first one's map,
each in its own colour."""

from __future__ import annotations

import numpy as np

from cosim.logs.plot_data import MODE_COLORS, ZONE_RGBA, PlotData, mode_name

PLAN_COLOR = "#1d4ed8"
REVERSE_COLOR = "#d946ef"  # a plan's reverse segments (Hybrid A*)
GOAL_COLOR = "#e76f51"
OLDEST_PLAN_ALPHA, PREVIOUS_PLAN_ALPHA = 0.2, 0.6  # earlier plans fade linearly between these
LABELLED_REPLANS = 6  # up to this many replans get their time written beside them
# one colour per run of an overlay (matplotlib's tab10 without its blue, the plans' colour here)
RUN_COLORS = ("#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf", "#7f7f7f")


def run_colour(index: int) -> str:
    """The colour of the `index`-th run of an overlay."""
    return RUN_COLORS[index % len(RUN_COLORS)]


def draw_map(axes, data: PlotData) -> None:
    """The map panel of one run (module docstring)."""
    draw_map_frame(axes, data)
    draw_map_run(axes, data)


def draw_map_frame(axes, data: PlotData) -> None:
    """What of the map panel is drawn under the run and known before it (`cosim.logs.plot.Draft`):
    the map image, the view's limits, the axes' labels, title and grid. Every artist of
    `draw_map_run` is above these (zorder 3 and up: the grid and ticks are at 1.5, the spines at 2.5)."""
    if data.image is not None:
        axes.imshow(data.image, extent=data.extent, origin="upper", interpolation="nearest", zorder=0)
    if data.limits is not None:
        axes.set_xlim(*data.limits[:2])
        axes.set_ylim(*data.limits[2:])
    axes.set_aspect("equal", adjustable="box")
    axes.set_xlabel("x [m]")
    axes.set_ylabel("y [m]")
    axes.set_title("trajectory over the map", y=1.0)  # y given: no search for what might be above
    axes.grid(alpha=0.25)


def draw_map_run(axes, data: PlotData) -> None:
    """The run over the map frame (`draw_map_frame`): obstacles, plans, trajectory, start, goals,
    and the legend below the map."""
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles: list = []
    if data.image is not None:
        if data.has_zone:
            handles.append(Patch(color=ZONE_RGBA[:3], label="inflated zone (planner)"))
        handles.append(Patch(color="0.15", label="map: occupied"))
    if data.obstacles:
        axes.add_collection(
            PolyCollection(data.obstacles, closed=True, color="#c1121f", alpha=0.75, zorder=3)
        )
        handles.append(Patch(color="#c1121f", alpha=0.75, label="unknown obstacles (lidar only)"))
    if data.tracks:
        axes.add_collection(LineCollection(data.tracks, colors="#c1121f", linestyles=":", lw=1.4, zorder=3))
        handles.append(
            Line2D(
                [], [], ls=":", color="#c1121f", lw=1.4, label="moving obstacles: tracks (last pose drawn)"
            )
        )
    handles += _draw_plans(axes, data)
    if data.trajectory is not None:
        (line,) = axes.plot(
            data.trajectory[:, 0], data.trajectory[:, 1], "-", color="#111111", lw=1.4,
            label="driven trajectory", zorder=5,
        )  # fmt: skip
        handles.append(line)
        if data.end is not None:
            x, y, reason = data.end
            axes.plot(x, y, marker="X", color="#7b2cbf", ms=11, ls="none", zorder=8)
            handles.append(
                Line2D([], [], marker="X", color="#7b2cbf", ls="none", ms=9, label=f"end: {reason}")
            )
        for mode, points in data.mode_points.items():
            colour = MODE_COLORS[mode]
            axes.scatter(points[:, 0], points[:, 1], s=9, color=colour, zorder=6, linewidths=0)
            handles.append(
                Line2D([], [], marker="o", color=colour, ls="none", ms=6, label=mode_name(mode, data.avoider))
            )
    if data.start is not None:
        x, y, theta = data.start
        axes.plot(x, y, marker="o", color="#2a9d8f", ms=10, ls="none", zorder=7)
        axes.annotate(
            "",
            xy=(x + np.cos(theta), y + np.sin(theta)),
            xytext=(x, y),
            arrowprops={"arrowstyle": "->", "color": "#2a9d8f", "lw": 2},
            zorder=7,
        )
        handles.append(
            Line2D([], [], marker="o", color="#2a9d8f", ls="none", ms=9, label="start (and heading)")
        )
    handles += _draw_goals(axes, data, GOAL_COLOR)
    if data.image is None and data.trajectory is None:
        axes.text(
            0.5,
            0.5,
            "no map and no trajectory in this log",
            ha="center",
            va="center",
            transform=axes.transAxes,
        )
    if handles:  # below the map, so it never hides part of it
        axes.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3, fontsize=8)


def _draw_plans(axes, data: PlotData) -> list:
    """Every plan of the run, oldest first: the one in force at the end dashed, each earlier one
    solid and fainter the older it is, a replan's first point (where the robot was) ringed and,
    for a few, labelled with its time; reverse segments (`data.reverse`) in `REVERSE_COLOR`.
    Returns the legend handles."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_rgba
    from matplotlib.lines import Line2D

    if not data.plans:
        return []
    handles = []
    count = len(data.plans)
    earlier = count - 1
    forward_lines, forward_colours, reverse_lines, reverse_colours = [], [], [], []
    rings, ring_colours = [], []  # where each replan starts (the robot's position then)
    for index, ((_, points), reverse) in enumerate(zip(data.plans, data.reverse, strict=True)):
        alpha = 1.0 if index == earlier else _plan_alpha(index, earlier)
        for run, backwards in _direction_runs(points, reverse):
            if index == earlier and not backwards:
                axes.plot(run[:, 0], run[:, 1], "--", color=PLAN_COLOR, lw=1.6, zorder=4)
                continue
            (reverse_lines if backwards else forward_lines).append(run)
            colours = reverse_colours if backwards else forward_colours
            colours.append(to_rgba(REVERSE_COLOR if backwards else PLAN_COLOR, alpha))
        if 0 < index:
            rings.append(points[0])
            ring_colours.append(to_rgba(PLAN_COLOR, alpha))
    if rings:
        rings = np.array(rings)
        axes.scatter(rings[:, 0], rings[:, 1], s=49, facecolors="none", edgecolors=ring_colours, zorder=4)
    if count - 1 <= LABELLED_REPLANS:
        _label_replans(axes, data)
    if forward_lines:
        axes.add_collection(LineCollection(forward_lines, colors=forward_colours, lw=1.3, zorder=4))
    if reverse_lines:
        axes.add_collection(LineCollection(reverse_lines, colors=reverse_colours, lw=2.4, zorder=4))
    planner = "plan" if count == 1 else f"plan in force at the end (of {count})"
    handles.append(Line2D([], [], ls="--", color=PLAN_COLOR, lw=1.6, label=planner))
    if count > 1:
        handles += [
            Line2D(
                [],
                [],
                color=PLAN_COLOR,
                alpha=PREVIOUS_PLAN_ALPHA,
                lw=1.3,
                label="earlier plans (older: fainter)",
            ),
            Line2D([], [], marker="o", mfc="none", mec=PLAN_COLOR, ls="none", ms=7, label="replanned here"),
        ]
    if any(reverse.any() for reverse in data.reverse):
        handles.append(Line2D([], [], color=REVERSE_COLOR, lw=2.4, label="plan: reverse segments"))
    return handles


def _label_replans(axes, data: PlotData) -> None:
    """Write each replan's time beside its ring, the newest first; a label that would overlap a
    newer one's is left out."""
    from matplotlib.colors import to_rgba

    labelled: list[tuple[float, float]] = []
    span = data.limits[1] - data.limits[0] if data.limits else 1.0  # [m] of the view's width
    earlier = len(data.plans) - 1
    for index in range(earlier, 0, -1):
        t, points = data.plans[index]
        x, y = points[0]
        if any(abs(x - a) < 0.12 * span and abs(y - b) < 0.03 * span for a, b in labelled):
            continue
        labelled.append((x, y))
        alpha = 1.0 if index == earlier else _plan_alpha(index, earlier)
        axes.annotate(
            f"replan t = {t:.1f} s", (x, y), xytext=(5, 5), textcoords="offset points", fontsize=7,
            color=to_rgba(PLAN_COLOR, max(alpha, PREVIOUS_PLAN_ALPHA)), zorder=9,
        )  # fmt: skip


def _plan_alpha(index: int, earlier: int) -> float:
    """Opacity of the `index`-th of `earlier` plans replaced during the run (0 the oldest)."""
    if earlier <= 1:
        return PREVIOUS_PLAN_ALPHA
    return OLDEST_PLAN_ALPHA + (PREVIOUS_PLAN_ALPHA - OLDEST_PLAN_ALPHA) * index / (earlier - 1)


def _direction_runs(points: np.ndarray, reverse: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """`points` cut into polylines of consecutive segments driven the same way: (points, reverse)."""
    if len(points) < 2:
        return [(points, False)]
    cuts = np.flatnonzero(np.diff(reverse.astype(np.int8))) + 1  # first segment of each new run
    starts = np.concatenate(([0], cuts))
    ends = np.concatenate((cuts, [len(reverse)]))
    return [(points[a : b + 1], bool(reverse[a])) for a, b in zip(starts, ends, strict=True)]


def _draw_goals(axes, data: PlotData, colour: str, label: str = "goal") -> list:
    """The goal in force at the end (a filled star and its tolerance circle) and each goal given
    before it (a hollow star, with the time it was replaced); returns the legend handles."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle

    handles = []
    earlier = [
        (x, y, data.goals[index + 1][0])
        for index, (_, x, y) in enumerate(data.goals[:-1])
        if (x, y) != tuple(data.goal or ())
    ]
    for x, y, until in earlier:
        axes.plot(x, y, marker="*", mfc="white", mec=colour, mew=1.5, ms=15, ls="none", zorder=7)
        axes.annotate(
            f"goal until t = {until:.1f} s", (x, y), xytext=(7, -11), textcoords="offset points",
            fontsize=7, color=colour, zorder=9,
        )  # fmt: skip
    if earlier:
        handles.append(
            Line2D([], [], marker="*", mfc="white", mec=colour, mew=1.5, ls="none", ms=12,
                   label=f"earlier {label}" + ("s" if len(earlier) > 1 else "")),
        )  # fmt: skip
    if data.goal is not None:
        axes.plot(*data.goal, marker="*", color=colour, ms=16, ls="none", zorder=7)
        if data.tolerance:
            axes.add_patch(Circle(data.goal, data.tolerance, fill=False, ls=":", color=colour, zorder=6))
        text = f"{label} (tolerance circle)" if not earlier else f"{label} at the end (tolerance circle)"
        handles.append(Line2D([], [], marker="*", color=colour, ls="none", ms=13, label=text))
    return handles


def draw_overlay_map(axes, runs: list[PlotData]) -> None:
    """Several runs over the first one's map: each run's trajectory, plan in force at the end,
    goals and end in its colour; the legend names the runs."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    first = runs[0]
    handles: list = []
    if first.image is not None:
        axes.imshow(first.image, extent=first.extent, origin="upper", interpolation="nearest", zorder=0)
        handles.append(Patch(color="0.15", label=f"map: occupied ({first.label})"))
    limits = []
    for index, run in enumerate(runs):
        colour = run_colour(index)
        if run.plan is not None:
            axes.plot(run.plan[:, 0], run.plan[:, 1], "--", color=colour, lw=1.2, alpha=0.7, zorder=4)
        if run.trajectory is not None:
            axes.plot(run.trajectory[:, 0], run.trajectory[:, 1], "-", color=colour, lw=1.5, zorder=5)
            if run.end is not None:
                axes.plot(*run.end[:2], marker="X", color=colour, ms=10, ls="none", zorder=8)
        if run.start is not None:
            axes.plot(*run.start[:2], marker="o", color=colour, ms=8, ls="none", zorder=7)
        _draw_goals(axes, run, colour)
        handles.append(Line2D([], [], color=colour, lw=2, label=run.label))
        if run.limits is not None:
            limits.append(run.limits)
    handles += [
        Line2D([], [], ls="--", color="0.3", label="plan in force at the end"),
        Line2D([], [], marker="o", color="0.3", ls="none", label="start"),
        Line2D([], [], marker="*", color="0.3", ls="none", ms=11, label="goal"),
        Line2D([], [], marker="X", color="0.3", ls="none", label="end (goal not reached)"),
    ]
    if limits:
        low, high = np.min(limits, axis=0), np.max(limits, axis=0)
        axes.set_xlim(low[0], high[1])
        axes.set_ylim(low[2], high[3])
    axes.set_aspect("equal", adjustable="box")
    axes.set_xlabel("x [m]")
    axes.set_ylabel("y [m]")
    axes.set_title("trajectories over the map", y=1.0)
    axes.grid(alpha=0.25)
    axes.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3, fontsize=8)
