"""Animate a run from its log alone: `cosim log animate LOG --out run.gif|run.mp4`.

Each frame shows, at one simulated time, the known map and inflated zone (as `cosim log plot`
draws them), the plan in force (the first one or the latest replan on /plan), the unknown
obstacles where they stood (the latest /obstacles message), the lidar beams of the latest /scan
drawn from the pose the scan was taken at, the driven trajectory so far, the vehicle's footprint
and heading coloured by the mixer's mode (follow / avoid / recover) and the time.

Frame k shows simulated time t0 + k * speed / fps [s]; a run of D seconds has
floor(D * fps / speed) + 1 frames. Rendering draws the static background once and blits only the
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
from cosim.logs.plot import MODE_AVOID, MODE_COLORS, MODE_RECOVER, _modes, draw_grid
from cosim.logs.reader import Log

FOLLOW_COLOR = "#2563eb"
MODE_LABELS = {0: "follow", MODE_AVOID: "avoid (VFH)", MODE_RECOVER: "recover"}
DEFAULT_RADIUS = 0.5  # [m] footprint when the log's scenario gives none
WIDTH, HEIGHT = 720, 480  # [px] of a frame; even, as H.264's yuv420p needs
DPI = 80


@dataclass(frozen=True)
class Animation:
    path: Path
    frames: int
    size: tuple[int, int]  # (width, height) [px]
    seconds: float  # wall time of rendering and encoding [s]


def frame_times(start: float, end: float, fps: float, speed: float) -> np.ndarray:
    """Simulated times [s] of the frames: every speed/fps seconds from `start` up to `end`."""
    step = speed / fps
    count = int(math.floor((end - start) / step + 1e-9)) + 1 if end >= start else 1
    return start + step * np.arange(count)


def animate_log(
    log: Log, out: Path, fps: float = 20.0, speed: float = 10.0, progress: bool = True
) -> Animation:
    """Render `log` to `out` (.gif through Pillow, .mp4 through ffmpeg) at `fps` frames per second
    of video, `speed` seconds of simulated time per second of video."""
    if not (math.isfinite(fps) and fps > 0):
        raise CosimError(f"--fps must be > 0, got {fps}")
    if not (math.isfinite(speed) and speed > 0):
        raise CosimError(f"--speed must be > 0, got {speed}")
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise CosimError(f"--out {out}: unknown video format {out.suffix!r} (use .gif or .mp4)")
    ffmpeg = shutil.which("ffmpeg") if suffix == ".mp4" else None
    if suffix == ".mp4" and ffmpeg is None:
        raise CosimError(f"--out {out}: MP4 needs ffmpeg, which is not installed (install it, or use .gif)")
    began = time.perf_counter()
    scene = _Scene(log)
    times = frame_times(log.start_time, log.end_time, fps, speed)
    decimals = max(1, math.ceil(-math.log10(speed / fps)) + 1)  # consecutive frames never show one time
    frames = (scene.render(t, decimals) for t in _progress(times, progress, out))
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".gif":
        _write_gif(frames, out, fps)
    else:
        _write_mp4(frames, out, fps, ffmpeg)
    return Animation(out, len(times), (WIDTH, HEIGHT), time.perf_counter() - began)


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
        [_rgb(colour) for colour in (*MODE_COLORS.values(), FOLLOW_COLOR, "#16a34a", "#c1121f", "#111111")],
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


def _write_mp4(frames: Iterator[np.ndarray], out: Path, fps: float, ffmpeg: str) -> None:
    command = [
        ffmpeg, "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgba",
        "-s", f"{WIDTH}x{HEIGHT}", "-framerate", f"{fps:g}", "-i", "-",
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

    def __init__(self, log: Log) -> None:
        trajectory = log.trajectory()
        if trajectory is None or len(trajectory.t) == 0:
            raise CosimError(f"{log.path}: no trajectory (vehicle x, y, theta or /pose) to animate")
        self.trajectory = trajectory
        self.radius = _footprint_radius(log)
        self.modes = _modes(log)
        self.plans = log.plans()
        self.plan_t = np.array([t for t, _ in self.plans])
        self.obstacles = [(t, [shape.polygon() for shape in shapes]) for t, shapes in log.obstacle_frames()]
        self.obstacle_t = np.array([t for t, _ in self.obstacles])
        self.scans = _scans(log, trajectory)
        self.scan_t = np.array([t for t, _ in self.scans])

        self.figure = Figure(figsize=(WIDTH / DPI, HEIGHT / DPI), dpi=DPI)
        self.canvas = FigureCanvasAgg(self.figure)
        axes = self.axes = self.figure.add_axes((0.07, 0.17, 0.9, 0.75))
        handles, bounds = draw_grid(axes, log)
        start, goal = log.start(), log.goal()
        if start is not None:
            axes.plot(*start[:2], marker="o", color="#2a9d8f", ms=7, ls="none", zorder=7)
        if goal is not None:
            axes.plot(*goal, marker="*", color="#e76f51", ms=12, ls="none", zorder=7)
            handles.append(Line2D([], [], marker="*", color="#e76f51", ls="none", ms=10, label="goal"))
        bounds.append(np.column_stack((trajectory.x, trajectory.y)))
        for _, points in self.plans:
            bounds.append(points)
        low, high = np.min(np.vstack(bounds), axis=0), np.max(np.vstack(bounds), axis=0)
        margin = 0.02 * max(float(np.max(high - low)), 1.0)
        axes.set_xlim(low[0] - margin, high[0] + margin)
        axes.set_ylim(low[1] - margin, high[1] + margin)
        axes.set_aspect("equal", adjustable="box")
        axes.set_xlabel("x [m]", fontsize=8)
        axes.set_ylabel("y [m]", fontsize=8)
        axes.tick_params(labelsize=7)
        axes.grid(alpha=0.25)
        axes.set_title(log.scenario_name or log.path.stem, fontsize=10)

        moving = {"animated": True}
        self.beams = LineCollection([], colors="#16a34a", linewidths=0.5, alpha=0.45, zorder=3, **moving)
        self.obstacle_patches = PolyCollection([], facecolors="#c1121f", alpha=0.8, zorder=4, **moving)
        (self.plan_line,) = axes.plot([], [], "--", color="#1d4ed8", lw=1.3, zorder=5, **moving)
        (self.trail,) = axes.plot([], [], "-", color="#111111", lw=1.1, zorder=6, **moving)
        self.body = patches.Circle((0, 0), self.radius, zorder=8, ec="black", lw=0.8, **moving)
        (self.heading,) = axes.plot([], [], "-", color="black", lw=1.5, zorder=9, **moving)
        self.clock = axes.text(
            0.01, 0.98, "", transform=axes.transAxes, ha="left", va="top", fontsize=9, zorder=10,
            bbox={"boxstyle": "round", "fc": "white", "ec": "0.6", "alpha": 0.85}, **moving,
        )  # fmt: skip
        axes.add_collection(self.beams)
        axes.add_collection(self.obstacle_patches)
        axes.add_patch(self.body)
        self.artists = [self.beams, self.obstacle_patches, self.plan_line, self.trail]
        self.artists += [self.body, self.heading, self.clock]
        handles += [
            Line2D([], [], ls="--", color="#1d4ed8", label="plan (latest)"),
            Line2D([], [], color="#111111", label="driven"),
            Line2D([], [], color="#16a34a", alpha=0.6, label="lidar beams"),
            patches.Patch(color="#c1121f", alpha=0.8, label="obstacles (lidar only)"),
        ]
        handles += [
            patches.Patch(color=colour, label=f"vehicle: {MODE_LABELS[mode]}")
            for mode, colour in ((0, FOLLOW_COLOR), *MODE_COLORS.items())
        ]
        self.figure.legend(handles=handles, loc="lower center", ncol=5, fontsize=7, frameon=False)
        self.canvas.draw()  # everything but the animated artists
        self.background = self.canvas.copy_from_bbox(self.figure.bbox)

    def render(self, t: float, decimals: int = 1) -> np.ndarray:
        """The frame at simulated time t [s] as an RGBA array (HEIGHT x WIDTH x 4, a copy)."""
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
        points = self.plans[plan][1] if plan >= 0 else np.zeros((0, 2))
        self.plan_line.set_data(points[:, 0], points[:, 1])
        obstacles = _latest(self.obstacle_t, t)
        self.obstacle_patches.set_verts(self.obstacles[obstacles][1] if obstacles >= 0 else [])
        scan = _latest(self.scan_t, t)
        self.beams.set_segments(self.scans[scan][1] if scan >= 0 else [])
        self.clock.set_text(f"t = {t:.{decimals}f} s   {MODE_LABELS.get(mode, f'mode {mode}')}")
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
