"""Fleet benchmark (not a test): navcosim's cost per simulated second and peak memory against N.

Run: `python3 -m benchmarks --only fleet` or `python3 benchmarks/bench_fleet.py [--quick]
[--robots N ...] [--duration S] [--no-irsim]`.

The world: `scenarios/fleet_fifty.toml` (the generated 150 m x 80 m warehouse of
`scenarios/maps/warehouse_fifty.pgm`, robots parked in the top corridor, missions to shelves and a
packing station), its first N robots, N = 1, 5, 20, 50 by default. Each (simulator, N) runs in a
fresh process, so the peak RSS is that run's (the process's whole peak, interpreter and imports
included), and measures:

* navcosim: the fleet built as `cosim run` builds it (`run_fleet`'s steps: every robot's planner,
  Pure Pursuit, VFH, mixer and vehicle FMUs and its 360-beam lidar at 10 Hz seeing the map and the
  other robots; 10 ms macro step), run for the same simulated duration; the stepping loop's wall time
  (`FleetOutcome.wall_time`: every FMU stepped, every lidar scanning, contacts and outcome judged)
  per simulated second, and the time to build and initialise the fleet, without a log (IR-SIM
  writes none); then the same run with every signal and topic logged to MCAP as `cosim run` writes
  it ("logged": issue 24's goal is stated with logging). A robot that collides or completes stops
  being judged but its components keep stepping, so every N steps N full robots for the whole
  duration.
* IR-SIM 2.12 (`pip install ir-sim`, the `bench` extra), the anchor, in the same run: the same map
  (the PGM as IR-SIM's `obstacle_map`, same size in metres), the same N starts and first goals, the
  same robots as far as IR-SIM has them: differential drive, circle of radius 0.5 m, 1.5 m/s and
  0.5 rad/s limits, a 360-beam full-circle `lidar2d` with a 20 m range, IR-SIM's own `dash` behaviour
  toward the goal (it has no planner or VFH), collisions not stopping a robot ("unobstructed", as
  navcosim's robots keep stepping). IR-SIM scans every step, so its step is the lidar period, 0.1 s:
  the lidars run at 10 Hz in both; IR-SIM's kinematics at 10 Hz, navcosim's vehicle FMUs at 100 Hz.

Printed: a table N, navcosim ms per simulated second (without and with the log), build s, peak
RSS, IR-SIM ms per simulated second, its peak RSS, and how many times navcosim with every signal
logged is faster than IR-SIM (IR-SIM's cost / navcosim's logged cost); then the
cost-growth exponent of each (the slope of log cost against log N, least squares over the N
measured): 1 is linear in N, 2 quadratic.
Issue 24's goal at N = 50: <= 50 ms per simulated second with every signal logged, >= 100x IR-SIM.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # `python3 benchmarks/bench_fleet.py` from anywhere
    sys.path.insert(0, str(REPO))

SCENARIO = REPO / "scenarios" / "fleet_fifty.toml"
ROBOTS = (1, 5, 20, 50)
DURATION = 1.0  # [s] simulated (IR-SIM takes 1.4-2.4 s of wall time per robot and simulated second)
QUICK_ROBOTS = (1, 5)
QUICK_DURATION = 0.5
IRSIM_STEP = 0.1  # [s] IR-SIM's step: its lidars scan every step, so 10 Hz as navcosim's


def fleet_text(count: int, duration: float) -> str:
    """fleet_fifty.toml with its first `count` robots, the map by absolute path, `duration` [s]."""
    text = SCENARIO.read_text()
    head, _, rest = text.partition("\n[[robots]]")
    blocks = ("[[robots]]" + rest).split("\n[[robots]]")
    last = blocks[-1]
    tail = last[last.index("\n[planner]") :]
    blocks[-1] = last[: last.index("\n[planner]")]
    robots = [blocks[0], *("[[robots]]" + block for block in blocks[1:])][:count]
    if len(robots) < count:
        raise SystemExit(f"{SCENARIO.name} has {len(blocks)} robots, fewer than {count}")
    head = re.sub(r'file = "maps/', f'file = "{SCENARIO.parent / "maps"}/', head)
    tail = re.sub(r"stop_time = [0-9.]+", f"stop_time = {duration}", tail)
    return head + "\n" + "\n".join(robots) + "\n" + tail


def peak_rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def child_navcosim(count: int, duration: float, logged: bool = False) -> dict:
    """navcosim's fleet; `logged`: every signal and topic recorded to an MCAP log as `cosim run`
    writes it (in a temporary folder), else no log."""
    from cosim.navigation.fleet import run_fleet
    from cosim.scenario.load import load_scenario

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"fleet_{count}.toml"
        path.write_text(fleet_text(count, duration))
        started = time.perf_counter()
        fleet = load_scenario(path, fleet=True)
        outcome = run_fleet(fleet, log_path=Path(folder) / "fleet.mcap" if logged else None)
        total = time.perf_counter() - started
    if not math.isclose(outcome.time, duration) and outcome.reason != "completed":
        raise SystemExit(f"navcosim ran {outcome.time} s of {duration} s ({outcome.reason})")
    return {
        "simulated": outcome.time,
        "run": outcome.wall_time,
        "build": total - outcome.wall_time,
        "rss": peak_rss_mb(),
        "collisions": len(outcome.collisions),
    }


def irsim_world(count: int, folder: Path) -> Path:
    """The IR-SIM world file of the fleet's first `count` robots (module docstring)."""
    import tomllib

    import numpy as np

    from planner.mapio import load_map

    raw = tomllib.loads(SCENARIO.read_text())
    map_path = SCENARIO.parent / raw["map"]["file"]
    grid = load_map(map_path)
    height, width = (size * grid.resolution for size in grid.occupied.shape)
    robots = raw["robots"][:count]
    lidar = raw["lidar"]
    vehicle = raw["vehicle"]
    states = [[r["start"]["x"], r["start"]["y"], r["start"]["theta"]] for r in robots]
    goals = [[r["mission"][0]["x"], r["mission"][0]["y"], 0.0] for r in robots]
    image = folder / "map.png"
    from PIL import Image

    free = ~np.asarray(grid.occupied, dtype=bool)
    Image.fromarray((free * 254).astype("uint8")).save(image)  # row 0 at the top, as the PGM
    world = {
        "world": {
            "height": height,
            "width": width,
            "step_time": IRSIM_STEP,
            "sample_time": IRSIM_STEP,
            "offset": [0, 0],
            "collision_mode": "unobstructed",
            "obstacle_map": str(image),
        },
        "robot": [
            {
                "number": count,
                "distribution": {"name": "manual"},
                "kinematics": {"name": "diff"},
                "shape": {"name": "circle", "radius": vehicle["radius"]},
                "state": states,
                "goal": goals,
                "behavior": {"name": "dash"},
                "vel_max": [
                    raw["pure_pursuit"]["desired_linear_velocity"],
                    raw["pure_pursuit"]["max_angular_velocity"],
                ],
                "sensors": [
                    {
                        "type": "lidar2d",
                        "range_min": lidar["range"][0],
                        "range_max": lidar["range"][1],
                        "angle_range": 2 * math.pi,
                        "number": lidar["count"],
                    }
                ],
            }
        ],
    }
    path = folder / "world.yaml"
    path.write_text(json.dumps(world))  # JSON is YAML
    return path


def child_irsim(count: int, duration: float) -> dict:
    import logging

    import matplotlib

    matplotlib.use("Agg")
    with tempfile.TemporaryDirectory() as folder:
        path = irsim_world(count, Path(folder))
        started = time.perf_counter()
        import irsim

        env = irsim.make(str(path), display=False, log_level="ERROR")
        logging.disable(logging.WARNING)
        built = time.perf_counter() - started
        steps = round(duration / IRSIM_STEP)
        started = time.perf_counter()
        for _ in range(steps):
            env.step()
        run = time.perf_counter() - started
        robots = env.robot_list
        if len(robots) != count or len(robots[0].get_lidar_scan()["ranges"]) != 360:
            raise SystemExit("IR-SIM built another world than asked")
    return {"simulated": steps * IRSIM_STEP, "run": run, "build": built, "rss": peak_rss_mb()}


def measure(simulator: str, count: int, duration: float) -> dict | None:
    """One (simulator, N) in a fresh process; None (and why, printed) when it failed."""
    command = [sys.executable, str(Path(__file__).resolve()), "--child", simulator, str(count), str(duration)]
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run(command, capture_output=True, text=True, cwd=REPO, env=environment)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        print(f"  {simulator} N = {count} failed: {(done.stderr or done.stdout).strip()[-400:]}", flush=True)
        return None
    return json.loads(lines[-1])


def exponent(counts: list[int], costs: list[float]) -> float | None:
    """Least-squares slope of log cost against log N."""
    import numpy as np

    pairs = [(n, c) for n, c in zip(counts, costs, strict=True) if c is not None and c > 0]
    if len(pairs) < 2:
        return None
    x, y = np.log([p[0] for p in pairs]), np.log([p[1] for p in pairs])
    return float(np.polyfit(x, y, 1)[0])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", help=f"fleet sizes N (default {ROBOTS})")
    parser.add_argument("--duration", type=float, help=f"simulated seconds (default {DURATION})")
    parser.add_argument("--quick", action="store_true", help=f"N = {QUICK_ROBOTS}, {QUICK_DURATION} s")
    parser.add_argument("--no-irsim", action="store_true", help="navcosim only")
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        simulator, count, duration = args.child
        if simulator == "irsim":
            result = child_irsim(int(count), float(duration))
        else:
            result = child_navcosim(int(count), float(duration), logged=simulator == "navcosim-log")
        print(json.dumps(result), flush=True)
        return 0
    counts = args.robots or (QUICK_ROBOTS if args.quick else ROBOTS)
    duration = args.duration or (QUICK_DURATION if args.quick else DURATION)
    try:
        import irsim  # noqa: F401

        anchor = not args.no_irsim
    except ImportError:
        print("IR-SIM is not installed (pip install ir-sim, the bench extra): navcosim only")
        anchor = False
    if anchor and abs(round(duration / IRSIM_STEP) * IRSIM_STEP - duration) > 1e-9:
        raise SystemExit(f"--duration must be a multiple of IR-SIM's {IRSIM_STEP:g} s step")
    print(f"fleet benchmark: {SCENARIO.name}'s first N robots, {duration:g} s simulated each", flush=True)
    print(f"load average before: {os.getloadavg()[0]:.1f} (2 cores: more is other jobs' time)", flush=True)
    rows = []
    for count in counts:
        ours = measure("navcosim", count, duration)
        logged = measure("navcosim-log", count, duration)
        theirs = measure("irsim", count, duration) if anchor else None
        rows.append((count, ours, theirs, logged))
        cost = f"{1000 * ours['run'] / ours['simulated']:.1f} ms/sim-s" if ours else "failed"
        print(f"  N = {count}: navcosim {cost}", flush=True)

    def per_second(result):
        return None if result is None else 1000.0 * result["run"] / result["simulated"]

    header = ("N", "navcosim ms/sim-s", "logged ms/sim-s", "build s", "RSS MB", "IR-SIM ms/sim-s",
              "IR-SIM RSS MB", "IR-SIM / logged")  # fmt: skip
    table = [header]
    for count, ours, theirs, logged in rows:
        mine, anchor_cost, with_log = per_second(ours), per_second(theirs), per_second(logged)
        table.append(
            (
                str(count),
                "-" if mine is None else f"{mine:.1f}",
                "-" if with_log is None else f"{with_log:.1f}",
                "-" if ours is None else f"{ours['build']:.1f}",
                "-" if ours is None else f"{ours['rss']:.0f}",
                "-" if anchor_cost is None else f"{anchor_cost:.1f}",
                "-" if theirs is None else f"{theirs['rss']:.0f}",
                "-" if with_log is None or anchor_cost is None else f"{anchor_cost / with_log:.0f}x",
            )
        )
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    print()
    for row in table:
        print("  ".join(cell.rjust(width) for cell, width in zip(row, widths, strict=True)))
    print(f"load average after: {os.getloadavg()[0]:.1f}")
    counts_done = [count for count, *_ in rows]
    for name, index in (("navcosim", 1), ("navcosim logged", 3), ("IR-SIM", 2)):
        slope = exponent(counts_done, [per_second(row[index]) for row in rows])
        if slope is not None:
            print(f"cost growth in N ({name}): exponent {slope:.2f} (cost ~ N^{slope:.2f})")
    failed = any(ours is None or logged is None for _, ours, _, logged in rows)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
