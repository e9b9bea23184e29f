"""A synthetic run written with the Recorder, for the log tests (no run loop, no FMUs needed).

The robot drives a quarter circle of radius 4 m around (0, 0) at 0.5 m/s; the values of every
signal are closed-form functions of time, so tests can recompute what was written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cosim.record.recorder import Recorder
from cosim.world.shapes import Circle, Polygon, Rectangle
from planner.grid import OccupancyGrid

RADIUS = 4.0  # [m]
SPEED = 0.5  # [m/s]
STEP_NS = 50_000_000  # 20 Hz
STEPS = 120
SCAN_EVERY = 2
ANGLES = np.linspace(-np.pi / 2, np.pi / 2, 7)
RANGE_MIN, RANGE_MAX = 0.05, 8.0
GOAL = (0.0, 4.0)
OBSTACLES = [
    Circle((2.0, 2.0), 0.4),
    Rectangle((-1.0, 1.5), (1.2, 0.6), 0.5),
    Polygon(((1, -1), (2, -1), (1.5, 0))),
]
COMPONENTS = {
    "vehicle": ["x", "y", "theta", "v_actual", "omega_actual"],
    "pure_pursuit": ["v", "omega", "target_dir", "goal_distance"],
    "vfh": ["steering_dir", "free_sectors", "ranges[1]", "ranges[2]"],
    "mixer": ["v", "omega", "mode"],
}
METADATA = {
    "navcosim": {
        "scenario_name": "synthetic_quarter_circle",
        "navcosim_version": "0.1.0",
        "start": f"{RADIUS},0,{np.pi / 2}",
        "goal": f"{GOAL[0]},{GOAL[1]}",
        "goal_tolerance": "0.3",
        "macro_step": "0.05",
        "stop_time": "6",
    },
    "fmu/vehicle": {
        "path": "/fmus/DifferentialDrive.fmu",
        "model_name": "DifferentialDrive",
        "guid": "{11111111-2222-3333-4444-555555555555}",
        "generation_tool": "navcosim fmus build",
        "fmi_version": "2.0",
    },
}
OUTCOME = {"reached": "true", "reason": "goal", "time": "5.95", "distance": "2.98", "min_clearance": "0.7"}
SCENARIO_TEXT = '# synthetic\nname = "synthetic_quarter_circle"\n'


def make_grid() -> OccupancyGrid:
    """10 x 12 cells of 0.5 m with origin (-3, -2); a wall in the top row, a block low left."""
    occupied = np.zeros((10, 12), dtype=bool)
    occupied[0, :] = True
    occupied[7:9, 1:3] = True
    return OccupancyGrid(occupied, 0.5, (-3.0, -2.0))


def make_inflated() -> OccupancyGrid:
    grid = make_grid().occupied
    inflated = grid.copy()
    inflated[1, :] = True
    inflated[6:10, 0:4] = True
    return OccupancyGrid(inflated, 0.5, (-3.0, -2.0))


def pose_at(t: float) -> tuple[float, float, float]:
    angle = SPEED * t / RADIUS
    return RADIUS * np.cos(angle), RADIUS * np.sin(angle), angle + np.pi / 2


def values_at(component: str, k: int) -> np.ndarray:
    """The record of `component` at step k: closed-form, with a NaN and an inf to test exactness."""
    t = k * STEP_NS / 1e9
    x, y, theta = pose_at(t)
    omega = SPEED / RADIUS
    mode = 1.0 if 40 <= k < 60 else (2.0 if 60 <= k < 70 else 0.0)
    rows = {
        "vehicle": [x, y, theta, SPEED, omega],
        "pure_pursuit": [SPEED, omega, np.sin(t) * 0.3, np.hypot(x - GOAL[0], y - GOAL[1])],
        "vfh": [np.nan if k % 17 == 0 else 0.1 * np.cos(t), float(k % 5), 1.0 / 3.0 + k, np.inf],
        "mixer": [SPEED, omega + (0.2 if mode else 0.0), mode],
    }
    return np.array(rows[component], dtype=np.float64)


def scan_at(k: int) -> np.ndarray:
    ranges = 2.0 + 0.1 * np.arange(len(ANGLES)) + 0.01 * k
    ranges[3] = np.nan  # a missed beam
    return ranges


def planned_path() -> np.ndarray:
    angles = np.linspace(0.0, np.pi / 2, 12)
    return np.column_stack((RADIUS * np.cos(angles), RADIUS * np.sin(angles)))


@dataclass
class Written:
    path: Path
    signals: dict[str, np.ndarray] = field(default_factory=dict)  # component -> (steps, n)
    t_ns: np.ndarray = field(default_factory=lambda: np.arange(STEPS, dtype=np.int64) * STEP_NS)


def write_log(
    path: Path,
    steps: int = STEPS,
    outcome: dict | None = None,
    change: dict | None = None,
    flush_every: int = 0,
) -> Written:
    """Write the synthetic run to `path`. `change` = {component: delta} adds delta to every value
    of that component (a 'run with one parameter changed'); `flush_every` > 0 ends a chunk every
    that many steps."""
    change = change or {}
    written = Written(Path(path), t_ns=np.arange(steps, dtype=np.int64) * STEP_NS)
    with Recorder(path) as recorder:
        for name, data in METADATA.items():
            recorder.add_metadata(name, data)
        recorder.add_attachment("scenario.toml", "text/x-toml", SCENARIO_TEXT.encode())
        channels = {name: recorder.signal_channel(name, names) for name, names in COMPONENTS.items()}
        recorder.write_grid(0, make_grid(), "/map")
        recorder.write_grid(0, make_inflated(), "/map_inflated")
        recorder.write_path(0, planned_path())
        recorder.write_obstacles(0, OBSTACLES)
        recorder.write_goal(0, *GOAL, None)
        records = {name: [] for name in COMPONENTS}
        for k in range(steps):
            t_ns = k * STEP_NS
            for name, channel in channels.items():
                values = values_at(name, k) + change.get(name, 0.0)
                records[name].append(values)
                recorder.write_signals(channel, t_ns, values)
            x, y, theta = pose_at(t_ns / 1e9)
            recorder.write_pose(t_ns, x, y, theta, SPEED, SPEED / RADIUS)
            recorder.write_cmd_vel(t_ns, SPEED, SPEED / RADIUS)
            if k % SCAN_EVERY == 0:
                recorder.write_scan(t_ns, ANGLES, scan_at(k), RANGE_MIN, RANGE_MAX)
            if flush_every and k % flush_every == flush_every - 1:
                recorder.flush()
        recorder.close(OUTCOME if outcome is None else outcome)
    written.signals = {name: np.array(rows) for name, rows in records.items()}
    return written
