"""Animate a run from its log alone: `cosim log animate LOG --out run.gif|run.mp4`.

Each frame shows, at one simulated time, the known map and inflated zone (as `cosim log plot`
draws them), the plan in force (the first one or the latest replan on /plan, its reverse segments
in their own colour), the goal in force (the latest /goal), the unknown obstacles where they stood
(the latest /obstacles message), the lidar beams of the latest /scan drawn from the pose the scan
was taken at, the driven trajectory so far, the vehicle's footprint and heading coloured by the
mixer's mode (follow / avoid / recover) and the time. The last frame shows the run's end time and
its outcome ("goal reached at t = 74.2 s", "goal NOT reached (collision)"). A fleet's log
(`_FleetScene`): every robot in its colour (trail, footprint, heading, plan and goal in force),
each collision's X from its time on, the fleet's line on the last frame.

Frame k shows simulated time t0 + k * speed / fps [s] up to the log's end time t1, and one more
frame at t1 when it falls between two: a run of D seconds has floor(D * fps / speed) + 1 frames,
+ 1 when D is not a multiple of speed / fps. Rendering draws the static background once and blits only the
moving artists per frame, so the cost per frame is a few moving artists, not a whole figure.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
import time
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib import patches
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from cosim.errors import CosimError
from cosim.logs.plot import (
    _modes,
    avoider_name,
    draw_grid,
    outcome_text,
    reverse_segments,
)
from cosim.logs.plot_data import MODE_AVOID, MODE_COLORS, MODE_RECOVER
from cosim.logs.plot_map import GOAL_COLOR, PLAN_COLOR, REVERSE_COLOR
from cosim.logs.reader import Log

FOLLOW_COLOR = "#2563eb"
MODE_LABELS = {0: "follow", MODE_AVOID: "avoid ({avoider})", MODE_RECOVER: "recover"}
DEFAULT_RADIUS = 0.5  # [m] footprint when the log's scenario gives none
WIDTH, HEIGHT = 720, 480  # [px] of a frame by default; even, as H.264's yuv420p needs
DPI = 80


@dataclass(frozen=True)
class Animation:
    path: Path
    frames: int
    size: tuple[int, int]  # (width, height) [px]
    seconds: float  # wall time of rendering and encoding [s]


def frame_times(start: float, end: float, fps: float, speed: float) -> np.ndarray:
    """Simulated times [s] of the frames: every speed/fps seconds from `start` up to `end`, and
    `end` itself when it falls between two (the last frame shows the run's end)."""
    step = speed / fps
    count = int(math.floor((end - start) / step + 1e-9)) + 1 if end >= start else 1
    times = start + step * np.arange(count)
    if end - times[-1] > 1e-9 * step:
        times = np.append(times, end)
    return times


def animate_log(
    log: Log,
    out: Path,
    fps: float = 20.0,
    speed: float = 10.0,
    progress: bool = True,
    dpi: float = DPI,
    size: tuple[int, int] = (WIDTH, HEIGHT),
) -> Animation:
    """Render `log` to `out` (.gif through Pillow, .mp4 through ffmpeg) at `fps` frames per second
    of video, `speed` seconds of simulated time per second of video; frames of `size` (width,
    height) [px], text and lines scaled by `dpi` [pixels per inch]."""
    if not (math.isfinite(fps) and fps > 0):
        raise CosimError(f"--fps must be > 0, got {fps}")
    if not (math.isfinite(speed) and speed > 0):
        raise CosimError(f"--speed must be > 0, got {speed}")
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise CosimError(f"--out {out}: unknown video format {out.suffix!r} (use .gif or .mp4)")
    if suffix == ".mp4" and (size[0] % 2 or size[1] % 2):
        raise CosimError(f"--size {size[0]}x{size[1]}: an MP4 frame needs an even width and height")
    ffmpeg = shutil.which("ffmpeg") if suffix == ".mp4" else None
    if suffix == ".mp4" and ffmpeg is None:
        raise CosimError(f"--out {out}: MP4 needs ffmpeg, which is not installed (install it, or use .gif)")
    began = time.perf_counter()
    scene = _FleetScene(log, size, dpi) if log.fleet_outcome is not None else _Scene(log, size, dpi)
    times = frame_times(log.start_time, log.end_time, fps, speed)
    decimals = max(1, math.ceil(-math.log10(speed / fps)) + 1)  # consecutive frames never show one time
    last = len(times) - 1
    frames = (
        scene.render(t, decimals, final=k == last) for k, t in enumerate(_progress(times, progress, out))
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".gif":
        _write_gif(frames, out, fps)
    else:
        _write_mp4(frames, out, fps, ffmpeg, size)
    return Animation(out, len(times), size, time.perf_counter() - began)


def _progress(times: np.ndarray, enabled: bool, out: Path):
    if not enabled:
        return times
    from tqdm import tqdm

    return tqdm(times, desc=f"rendering {out.name}", unit="frame", file=sys.stderr, leave=False)


def _write_gif(frames: Iterator[np.ndarray], out: Path, fps: float) -> None:
    from PIL import Image

    first = next(frames)
    # One palette for every frame (from the first frame plus swatches of the colours that appear
    # only later), so the unchanged map quantises identically and GIF stores only what moved.
    swatches = np.array(
        [
            _rgb(colour)
            for colour in (
                *MODE_COLORS.values(),
                FOLLOW_COLOR,
                "#16a34a",
                "#c1121f",
                "#111111",
                REVERSE_COLOR,
                GOAL_COLOR,
            )
        ],
        dtype=np.uint8,
    )
    sample = first[..., :3].copy()
    sample[: len(swatches), :8] = swatches[:, None, :]
    palette = Image.fromarray(sample).quantize(colors=64, dither=Image.Dither.NONE)

    def quantised(image: np.ndarray):
        return Image.fromarray(image[..., :3]).quantize(palette=palette, dither=Image.Dither.NONE)

    head = quantised(first)
    head.save(
        out,
        save_all=True,
        append_images=(quantised(frame) for frame in frames),
        duration=1000.0 / fps,
        loop=0,
        optimize=False,
    )


def _write_mp4(
    frames: Iterator[np.ndarray], out: Path, fps: float, ffmpeg: str, size: tuple[int, int]
) -> None:
    command = [
        ffmpeg, "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgba",
        "-s", f"{size[0]}x{size[1]}", "-framerate", f"{fps:g}", "-i", "-",
        "-c:v", "libx264", "-pix_fmt", "yuv420p", "-movflags", "+faststart", str(out),
    ]  # fmt: skip
    process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for frame in frames:
            process.stdin.write(np.ascontiguousarray(frame).tobytes())
        process.stdin.close()
    except BrokenPipeError:
        pass  # ffmpeg ended early; its message follows
    finally:
        error = process.stderr.read().decode(errors="replace").strip()
        code = process.wait()
    if code != 0:
        last = error.splitlines()[-1] if error else f"exit status {code}"
        raise CosimError(f"--out {out}: ffmpeg failed: {last}")


def _rgb(colour: str) -> tuple[int, int, int]:
    return tuple(int(colour[i : i + 2], 16) for i in (1, 3, 5))


def _latest(times: np.ndarray, t: float) -> int:
    """Index of the last entry of sorted `times` at or before t; -1 when none."""
    return int(np.searchsorted(times, t + 1e-9, side="right")) - 1


class _Scene:
    """The figure of one run: static background drawn once, moving artists updated per frame."""

    def __init__(self, log: Log, size: tuple[int, int] = (WIDTH, HEIGHT), dpi: float = DPI) -> None:
        trajectory = log.trajectory()
        if trajectory is None or len(trajectory.t) == 0:
            raise CosimError(f"{log.path}: no trajectory (vehicle x, y, theta or /pose) to animate")
        self.trajectory = trajectory
        self.radius = _footprint_radius(log)
        self.modes = _modes(log)
        self.plans = [(t, poses[:, :2], reverse_segments(poses)) for t, poses in log.plans()]
        self.plan_t = np.array([t for t, _, _ in self.plans])
        self.goals = log.goals()
        self.goal_t = np.array([t for t, _, _ in self.goals])
        self.outcome = outcome_text(log.outcome, log.is_complete)
        avoider = avoider_name(log.metadata)
        self.mode_labels = {mode: label.format(avoider=avoider) for mode, label in MODE_LABELS.items()}
        self.obstacles = [(t, [shape.polygon() for shape in shapes]) for t, shapes in log.obstacle_frames()]
        self.obstacle_t = np.array([t for t, _ in self.obstacles])
        self.scans = _scans(log, trajectory)
        self.scan_t = np.array([t for t, _ in self.scans])

        self.figure = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.figure)
        axes = self.axes = self.figure.add_axes((0.07, 0.17, 0.9, 0.75))
        handles, bounds = draw_grid(axes, log)
        start = log.start()
        if start is not None:
            axes.plot(*start[:2], marker="o", color="#2a9d8f", ms=7, ls="none", zorder=7)
        if self.goals:
            handles.append(
                Line2D([], [], marker="*", color=GOAL_COLOR, ls="none", ms=10, label="goal in force")
            )
        bounds.append(np.column_stack((trajectory.x, trajectory.y)))
        bounds += [points for _, points, _ in self.plans]
        bounds += [np.array([goal[1:]]) for goal in self.goals]
        low, high = np.min(np.vstack(bounds), axis=0), np.max(np.vstack(bounds), axis=0)
        margin = 0.02 * max(float(np.max(high - low)), 1.0)
        axes.set_xlim(low[0] - margin, high[0] + margin)
        axes.set_ylim(low[1] - margin, high[1] + margin)
        _style_map(axes, log)

        moving = {"animated": True}
        self.beams = LineCollection([], colors="#16a34a", linewidths=0.5, alpha=0.45, zorder=3, **moving)
        self.obstacle_patches = PolyCollection([], facecolors="#c1121f", alpha=0.8, zorder=4, **moving)
        (self.plan_line,) = axes.plot([], [], "--", color=PLAN_COLOR, lw=1.3, zorder=5, **moving)
        self.reverse_lines = LineCollection([], colors=REVERSE_COLOR, linewidths=2.2, zorder=5, **moving)
        (self.goal_marker,) = axes.plot(
            [], [], marker="*", color=GOAL_COLOR, ms=12, ls="none", zorder=7, **moving
        )
        (self.trail,) = axes.plot([], [], "-", color="#111111", lw=1.1, zorder=6, **moving)
        self.body = patches.Circle((0, 0), self.radius, zorder=8, ec="black", lw=0.8, **moving)
        (self.heading,) = axes.plot([], [], "-", color="black", lw=1.5, zorder=9, **moving)
        self.clock = axes.text(
            0.01, 0.98, "", transform=axes.transAxes, ha="left", va="top", fontsize=9, zorder=10,
            bbox={"boxstyle": "round", "fc": "white", "ec": "0.6", "alpha": 0.85}, **moving,
        )  # fmt: skip
        axes.add_collection(self.beams)
        self.banner = axes.text(
            0.5, 0.98, "", transform=axes.transAxes, ha="center", va="top", fontsize=12, zorder=11,
            bbox={"boxstyle": "round", "fc": "white", "ec": "0.3", "alpha": 0.9}, **moving,
        )  # fmt: skip
        axes.add_collection(self.obstacle_patches)
        axes.add_collection(self.reverse_lines)
        axes.add_patch(self.body)
        self.artists = [
            self.beams,
            self.obstacle_patches,
            self.plan_line,
            self.reverse_lines,
            self.goal_marker,
        ]
        self.artists += [self.trail, self.body, self.heading, self.clock, self.banner]
        handles += [
            Line2D([], [], ls="--", color=PLAN_COLOR, label="plan (latest)"),
            Line2D([], [], color="#111111", label="driven"),
            Line2D([], [], color="#16a34a", alpha=0.6, label="lidar beams"),
            patches.Patch(color="#c1121f", alpha=0.8, label="obstacles (lidar only)"),
        ]
        handles += [
            patches.Patch(color=colour, label=f"vehicle: {self.mode_labels[mode]}")
            for mode, colour in ((0, FOLLOW_COLOR), *MODE_COLORS.items())
        ]
        self.figure.legend(handles=handles, loc="lower center", ncol=5, fontsize=7, frameon=False)
        self.canvas.draw()  # everything but the animated artists
        self.background = self.canvas.copy_from_bbox(self.figure.bbox)

    def render(self, t: float, decimals: int = 1, final: bool = False) -> np.ndarray:
        """The frame at simulated time t [s] as an RGBA array (height x width x 4, a copy); the
        `final` one also says how the run ended."""
        traj = self.trajectory
        i = max(_latest(traj.t, t), 0)
        x, y, theta = float(traj.x[i]), float(traj.y[i]), float(traj.theta[i])
        self.trail.set_data(traj.x[: i + 1], traj.y[: i + 1])
        self.body.center = (x, y)
        mode = self._mode(t)
        self.body.set_facecolor(MODE_COLORS.get(mode, FOLLOW_COLOR))
        reach = max(2.0 * self.radius, 1.0)
        self.heading.set_data([x, x + reach * math.cos(theta)], [y, y + reach * math.sin(theta)])
        plan = _latest(self.plan_t, t)
        points, reverse = self.plans[plan][1:] if plan >= 0 else (np.zeros((0, 2)), np.zeros(0, dtype=bool))
        self.plan_line.set_data(points[:, 0], points[:, 1])
        self.reverse_lines.set_segments(np.stack((points[:-1], points[1:]), axis=1)[reverse])
        goal = max(_latest(self.goal_t, t), 0) if self.goals else -1
        self.goal_marker.set_data(
            *(([self.goals[goal][1]], [self.goals[goal][2]]) if goal >= 0 else ([], []))
        )
        obstacles = _latest(self.obstacle_t, t)
        self.obstacle_patches.set_verts(self.obstacles[obstacles][1] if obstacles >= 0 else [])
        scan = _latest(self.scan_t, t)
        self.beams.set_segments(self.scans[scan][1] if scan >= 0 else [])
        self.clock.set_text(f"t = {t:.{decimals}f} s   {self.mode_labels.get(mode, f'mode {mode}')}")
        self.banner.set_text(self.outcome if final else "")
        self.banner.set_visible(final)
        self.canvas.restore_region(self.background)
        for artist in self.artists:
            self.axes.draw_artist(artist)
        return np.array(self.canvas.buffer_rgba())

    def _mode(self, t: float) -> int:
        if self.modes is None:
            return 0
        mode_t, values = self.modes
        at = _latest(mode_t, t)
        return int(values[at]) if at >= 0 else 0


class _FleetScene:
    """The figure of a fleet's run: per robot (in its `run_colour`) the trail so far, the footprint
    and heading, the plan and goal in force; each collision's X from its time on; the fleet's line
    at the end."""

    def __init__(self, log: Log, size: tuple[int, int] = (WIDTH, HEIGHT), dpi: float = DPI) -> None:
        from cosim.logs.fleet_plot import collision_marks, fleet_runs
        from cosim.logs.info import collision_texts, fleet_line
        from cosim.logs.plot_map import run_colour

        fleet = log.fleet_outcome or {}
        runs = fleet_runs(log)
        self.names = log.robots
        if not self.names:
            raise CosimError(f"{log.path}: a fleet's log without /<robot>/odom: nothing to animate")
        self.trajectories = [log.robot_trajectory(name) for name in self.names]
        self.plans = [run.plans for run in runs]
        self.goals = [run.goals for run in runs]
        self.radius = _footprint_radius(log)
        self.final = fleet_line(fleet) if fleet else "fleet: no outcome recorded"
        marks = collision_marks(fleet)
        self.collisions = [(float(record["time"]), mark) for (record, _), mark in
                           zip(collision_texts(fleet), marks, strict=True)]  # fmt: skip

        self.figure = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.figure)
        axes = self.axes = self.figure.add_axes((0.07, 0.17, 0.9, 0.75))
        handles, _ = draw_grid(axes, log)
        x0, x1, y0, y1 = runs[0].limits
        axes.set_xlim(x0, x1)
        axes.set_ylim(y0, y1)
        _style_map(axes, log)
        moving = {"animated": True}
        self.robots = []
        for index, (name, trajectory) in enumerate(zip(self.names, self.trajectories, strict=True)):
            colour = run_colour(index)
            axes.plot(trajectory.x[0], trajectory.y[0], marker="o", color=colour, ms=6, ls="none", zorder=7)
            (plan,) = axes.plot([], [], "--", color=colour, lw=1.0, alpha=0.7, zorder=5, **moving)
            (goal,) = axes.plot([], [], marker="*", color=colour, ms=12, ls="none", zorder=7, **moving)
            (trail,) = axes.plot([], [], "-", color=colour, lw=1.2, zorder=6, **moving)
            body = patches.Circle((0, 0), self.radius, fc=colour, ec="black", lw=0.8, zorder=8, **moving)
            axes.add_patch(body)
            (heading,) = axes.plot([], [], "-", color="black", lw=1.3, zorder=9, **moving)
            self.robots.append((plan, goal, trail, body, heading))
            handles.append(patches.Patch(color=colour, label=name))
        (self.crashes,) = axes.plot([], [], marker="X", mfc="#ffd60a", mec="black", mew=1.2, ms=11, ls="none",
                                    zorder=10, **moving)  # fmt: skip
        self.clock = axes.text(
            0.01, 0.98, "", transform=axes.transAxes, ha="left", va="top", fontsize=9, zorder=10,
            bbox={"boxstyle": "round", "fc": "white", "ec": "0.6", "alpha": 0.85}, **moving,
        )  # fmt: skip
        self.banner = axes.text(
            0.5, 0.02, "", transform=axes.transAxes, ha="center", va="bottom", fontsize=8, zorder=11,
            bbox={"boxstyle": "round", "fc": "white", "ec": "0.3", "alpha": 0.9}, **moving,
        )  # fmt: skip
        handles.append(Line2D([], [], marker="X", mfc="#ffd60a", mec="black", ls="none", label="collision"))
        self.figure.legend(handles=handles, loc="lower center", ncol=6, fontsize=7, frameon=False)
        self.canvas.draw()
        self.background = self.canvas.copy_from_bbox(self.figure.bbox)

    def render(self, t: float, decimals: int = 1, final: bool = False) -> np.ndarray:
        """The frame at simulated time t [s] (RGBA, a copy); the `final` one shows the fleet's line."""
        artists = []
        for k, (plan, goal, trail, body, heading) in enumerate(self.robots):
            traj = self.trajectories[k]
            i = max(_latest(traj.t, t), 0)
            x, y, theta = float(traj.x[i]), float(traj.y[i]), float(traj.theta[i])
            trail.set_data(traj.x[: i + 1], traj.y[: i + 1])
            body.center = (x, y)
            reach = max(2.0 * self.radius, 1.0)
            heading.set_data([x, x + reach * math.cos(theta)], [y, y + reach * math.sin(theta)])
            plans = self.plans[k]
            at = _latest(np.array([when for when, _ in plans]), t) if plans else -1
            points = plans[at][1] if at >= 0 else np.zeros((0, 2))
            plan.set_data(points[:, 0], points[:, 1])
            goals = self.goals[k]
            at = max(_latest(np.array([g[0] for g in goals]), t), 0) if goals else -1
            goal.set_data(*(([goals[at][1]], [goals[at][2]]) if at >= 0 else ([], [])))
            artists += [plan, goal, trail, body, heading]
        happened = [mark for when, mark in self.collisions if when <= t + 1e-9]
        self.crashes.set_data([m[0] for m in happened], [m[1] for m in happened])
        self.clock.set_text(f"t = {t:.{decimals}f} s   collisions so far: {len(happened)}")
        self.banner.set_text(self.final if final else "")
        self.banner.set_visible(final)
        self.canvas.restore_region(self.background)
        for artist in [*artists, self.crashes, self.clock, self.banner]:
            self.axes.draw_artist(artist)
        return np.array(self.canvas.buffer_rgba())


def _footprint_radius(log: Log) -> float:
    """The vehicle's collision radius [m] from the scenario attached to the log."""
    try:
        scenario = tomllib.loads(log.scenario_text or "")
    except tomllib.TOMLDecodeError:
        return DEFAULT_RADIUS
    for section, key in (("vehicle", "radius"), ("vfh", "robot_radius")):
        value = scenario.get(section, {}).get(key)
        if isinstance(value, int | float) and value > 0:
            return float(value)
    return DEFAULT_RADIUS


def _scans(log: Log, trajectory) -> list[tuple[float, np.ndarray]]:
    """Per /scan message (t [s], segments K x 2 x 2 [m]) of the beams that hit something, drawn
    from the vehicle's pose at the scan's time (the scan's frame is base_link)."""
    if not log.has_topic("/scan"):
        return []
    scans = []
    for item in log.messages("/scan"):
        scan = item.message
        ranges = np.asarray(scan.ranges, dtype=float)
        angles = scan.angle_min + scan.angle_increment * np.arange(len(ranges))
        hit = np.isfinite(ranges) & (ranges >= scan.range_min) & (ranges < scan.range_max)
        i = max(_latest(trajectory.t, item.t), 0)
        x, y, theta = trajectory.x[i], trajectory.y[i], trajectory.theta[i]
        world = angles[hit] + theta
        ends = np.column_stack((x + ranges[hit] * np.cos(world), y + ranges[hit] * np.sin(world)))
        starts = np.broadcast_to((x, y), ends.shape)
        scans.append((item.t, np.stack((starts, ends), axis=1)))
    return scans


def _style_map(axes, log) -> None:
    """The map axes of a frame: equal scale, metre labels, a light grid, the run's name as title."""
    axes.set_aspect("equal", adjustable="box")
    axes.set_xlabel("x [m]", fontsize=8)
    axes.set_ylabel("y [m]", fontsize=8)
    axes.tick_params(labelsize=7)
    axes.grid(alpha=0.25)
    axes.set_title(log.scenario_name or log.path.stem, fontsize=10)
