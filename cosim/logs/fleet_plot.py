"""Draw a fleet's run (a log of `cosim.navigation.fleet_log`): every robot over the one map.

Left: the map, and per robot in its own colour (`run_colour`, in the log's robot order) its
driven trajectory (its `/<robot>/odom` poses), its start (the first pose), the plan in force at
the end (its last `/<robot>/plan`), its goals (`/<robot>/goal`: an earlier one hollow, the last
filled) and, for a robot that did not complete, an X where it ended; each collision of the fleet
outcome is a black-edged marker at its place with the robots and the time beside it: a
robot-robot contact at the point where the two footprints touch (on the line between the centres,
one radius from the first), a robot hitting a wall or obstacle at the robot's centre; the texts
are placed so that none covers another or a marker. Right: each
robot's speed (the distance between consecutive poses over their time step) and its distance to
the goal in force, over time. The view holds the robots' trajectories, goals and plans. The
title: the scenario, the fleet's line (how it ended, collisions, makespan) and the log's file
name.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from cosim.logs.plot import DPI, _extent, build_figure, collector_paused, goal_distance, map_image, write_png
from cosim.logs.plot_data import PlotData, Series

if TYPE_CHECKING:
    from cosim.logs.reader import Log

COLLISION_COLOR = "#000000"
MARKER_SIZE = 13  # [points] a collision's X
LABEL_STEP = 12  # [points] between the places tried for a collision's text
LABEL_SIZE = 7  # [points]
LABEL_PAD = 0.15  # [font sizes] the white box around it
VIEW_MARGIN = 3.0  # [m] at least around what the robots did
VIEW_ASPECT = 1.6  # the view's least width / height


def is_fleet_log(log: Log) -> bool:
    """Whether `log` is a fleet's: it has the `fleet_outcome` record or `/<robot>/odom` topics."""
    return log.fleet_outcome is not None or bool(log.robots)


def plot_fleet(log: Log, png_path: str | Path, dpi: float = DPI, size=None) -> Path:
    """Draw the fleet's run of `log` to `png_path` (module docstring); returns its path."""
    with collector_paused():
        figure = build_fleet_figure(log, dpi, size)
        png_path = Path(png_path)
        png_path.parent.mkdir(parents=True, exist_ok=True)
        write_png(png_path, np.asarray(figure.canvas.buffer_rgba())[:, :, :3], dpi)
        return png_path


def build_fleet_figure(log: Log, dpi: float = DPI, size=None):
    """The drawn figure (matplotlib `Figure`): `figure.axes[0]` is the map, robot k's trajectory
    the line labelled `trajectory <robot>` (gid), each collision marker a line with gid
    `collision <i>`; then the speed and distance panels."""
    runs = fleet_runs(log)
    figure = build_figure(runs, dpi, size, title=fleet_title(log))
    axes = figure.axes[0]
    for line in axes.lines:  # name each robot's trajectory line (its colour and points tell it)
        for run in runs:
            if run.trajectory is not None and np.array_equal(line.get_xydata(), run.trajectory):
                line.set_gid(f"trajectory {run.label}")
    marks = collision_marks(log.fleet_outcome or {})
    for index, (x, y, _) in enumerate(marks):
        (marker,) = axes.plot(x, y, marker="X", mfc="#ffd60a", mec=COLLISION_COLOR, mew=1.5,
                              ms=MARKER_SIZE, ls="none", zorder=10)  # fmt: skip
        marker.set_gid(f"collision {index}")
    axes.set_title("robots over the map (X: collision)", y=1.0)
    if len(figure.axes) > 1:  # speeds from 0 (no offset notation for a near-constant speed)
        speeds = figure.axes[1]
        top = max((float(np.nanmax(line.get_ydata(), initial=0.0)) for line in speeds.lines), default=1.0)
        speeds.set_ylim(0.0, max(1.1 * top, 0.1))
    figure.canvas.draw()  # the axes' final place: the labels are placed in pixels
    _label_collisions(figure, axes, marks)
    figure.canvas.draw()
    return figure


def _label_collisions(figure, axes, marks: list[tuple[float, float, str]]) -> None:
    """Each collision's text beside its marker where it covers no other text and no marker: tried
    right and left of it, then in steps of `LABEL_STEP` above and below (contacts at a crossing
    lie within a metre of each other); a text moved off its marker's line gets a thin line to it."""
    from matplotlib.transforms import Bbox

    renderer = figure.canvas.get_renderer()
    half = MARKER_SIZE / 2 * figure.dpi / 72  # [px] half the marker
    taken = []
    for x, y, _ in marks:
        px, py = axes.transData.transform((x, y))
        taken.append(Bbox.from_extents(px - half, py - half, px + half, py + half))
    frame = axes.get_window_extent(renderer)
    steps = [0] + [sign * n for n in range(1, 9) for sign in (1, -1)]
    offsets = [(side * 10, LABEL_STEP * step) for step in steps for side in (1, -1)]
    box_style = {"boxstyle": f"round,pad={LABEL_PAD}", "fc": "white", "ec": "none", "alpha": 0.8}
    style = {"textcoords": "offset points", "fontsize": LABEL_SIZE, "color": COLLISION_COLOR, "zorder": 11,
             "va": "center", "bbox": box_style}  # fmt: skip
    pad = (LABEL_PAD * LABEL_SIZE + 0.5) * figure.dpi / 72  # [px] the white box around the text
    for x, y, text in marks:
        for dx, dy in offsets:
            label = axes.annotate(text, (x, y), xytext=(dx, dy), ha="left" if dx > 0 else "right", **style)
            box = label.get_window_extent(renderer).padded(pad)
            if frame.contains(box.x0, box.y0) and frame.contains(box.x1, box.y1):
                if not any(box.overlaps(other) for other in taken):
                    break
            label.remove()
        else:
            dx, dy = offsets[0]
            label = axes.annotate(text, (x, y), xytext=(dx, dy), ha="left", **style)
            box = label.get_window_extent(renderer).padded(pad)
        if dy:  # off the marker's line: a leader to it
            label.remove()
            leader = {"arrowstyle": "-", "lw": 0.6, "color": COLLISION_COLOR, "shrinkB": half}
            axes.annotate(text, (x, y), xytext=(dx, dy), ha="left" if dx > 0 else "right", arrowprops=leader,
                          **style)  # fmt: skip
        taken.append(box)


def fleet_runs(log: Log) -> list[PlotData]:
    """One `PlotData` per robot: its trajectory, start, goals, plans, speed and distance to goal;
    the first holds the map image; every one the view's limits (all robots and the map)."""
    fleet = log.fleet_outcome or {}
    grid = log.map("/map")
    runs, bounds = [], []  # the view: the robots' trajectories, goals and plans (the map where none)
    for name in log.robots:
        robot = fleet.get("robots", {}).get(name, {})
        status = robot.get("status", "?")
        data = PlotData(f"{name}: {status}", label=name)
        trajectory = log.robot_trajectory(name)
        if len(trajectory.t):
            data.trajectory = np.column_stack((trajectory.x, trajectory.y))
            data.start = (float(trajectory.x[0]), float(trajectory.y[0]), float(trajectory.theta[0]))
            bounds.append(data.trajectory)
            if status != "completed":
                data.end = (float(trajectory.x[-1]), float(trajectory.y[-1]), status)
            steps = np.diff(trajectory.t)
            moved = np.hypot(np.diff(trajectory.x), np.diff(trajectory.y))
            speed = np.divide(moved, steps, out=np.zeros_like(moved), where=steps > 0)
            data.series.append(Series("speed (from the poses)", "m/s", trajectory.t[1:], speed, "speed"))
        data.goals = log.robot_goals(name)
        if data.goals:
            data.goal = data.goals[-1][1:]
            bounds.append(np.array([goal[1:] for goal in data.goals]))
            if len(trajectory.t):
                distance = goal_distance(data.goals, trajectory.t, trajectory.x, trajectory.y)
                data.series.append(Series("distance to goal", "m", trajectory.t, distance, "distance"))
        data.plans = [(t, poses[:, :2]) for t, poses in log.robot_plans(name) if len(poses)]
        bounds += [points for _, points in data.plans]
        runs.append(data)
    if not runs:
        runs.append(PlotData("fleet: no robot in this log", label="fleet"))
    if grid is not None:
        runs[0].image, runs[0].extent = map_image(grid, None), _extent(grid)
    if not bounds and grid is not None:
        x0, x1, y0, y1 = _extent(grid)
        bounds.append(np.array([[x0, y0], [x1, y1]]))
    if bounds:
        low, high = np.min(np.vstack(bounds), axis=0), np.max(np.vstack(bounds), axis=0)
        margin = max(0.08 * float(np.max(high - low)), VIEW_MARGIN)
        low, high = low - margin, high + margin
        width, height = high - low
        if width < VIEW_ASPECT * height:  # widened: a tall view leaves no room for the legend below
            low[0], high[0] = (
                low[0] - (VIEW_ASPECT * height - width) / 2,
                high[0] + (VIEW_ASPECT * height - width) / 2,
            )
        limits = (low[0], high[0], low[1], high[1])
        for run in runs:
            run.limits = limits
    return runs


def collision_marks(fleet: dict) -> list[tuple[float, float, str]]:
    """Where each collision of a fleet outcome is drawn, (x, y [m], text): a robot-robot contact
    where the footprints touch, a wall or obstacle hit at the robot's centre."""
    marks = []
    for contact in fleet.get("collisions", []):
        (a, b), (ca, cb) = contact["robots"], np.asarray(contact["centers"], dtype=float)
        radius = float(contact.get("radii", [0.0])[0])
        gap = float(np.hypot(*(cb - ca)))
        point = ca + (cb - ca) * (radius / gap) if gap > 0 else ca
        marks.append((float(point[0]), float(point[1]), f"{a}-{b} t = {contact['time']:.2f} s"))
    for name, robot in fleet.get("robots", {}).items():
        if robot.get("collision"):
            t, x, y = robot["collision"]
            marks.append((float(x), float(y), f"{name} hits wall t = {t:.2f} s"))
    return marks


def fleet_title(log: Log) -> str:
    """The scenario and the fleet's line, each robot's status, the log's file name."""
    fleet = log.fleet_outcome
    name = log.scenario_name or log.path.stem
    if fleet is None:
        return f"{name}: fleet: no outcome recorded (the run did not end)\n{log.path.name}"
    contacts = len(fleet.get("collisions", []))
    walls = sum(1 for robot in fleet.get("robots", {}).values() if robot.get("collision"))
    makespan = fleet.get("makespan")
    parts = [
        f"{fleet.get('reason')} at t = {fleet.get('time', 0.0):.2f} s",
        f"{contacts} collision{'s' if contacts != 1 else ''}" + (f" + {walls} with walls" if walls else ""),
        f"makespan {'-' if makespan is None else f'{makespan:.2f} s'}",
    ]
    robots = ", ".join(
        f"{robot}: {record.get('status')} {record.get('goals_reached')}/{record.get('goals')}"
        for robot, record in fleet.get("robots", {}).items()
    )
    return f"{name}: fleet: {', '.join(parts)}\n{robots}\n{log.path.name}"
