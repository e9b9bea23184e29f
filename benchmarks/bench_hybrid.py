"""Time hybrid A* against grid A* on the warehouse queries, in the same run.

    python3 benchmarks/bench_hybrid.py [--repeat 20]

The car is the thesis's Table 4.4 bicycle (min turning radius 3.5 m, vehicle radius 1.5 m +
safety 0.75 m = expansion_distance 2.25 m); grid A* plans on the same inflated map. Compilation
is excluded (one warm-up plan per query); times are the median of --repeat plans [ms].
Hybrid times are split into inflation (cached per grid), the obstacle-aware heuristic grid (a
Dijkstra from the goal), the search, and sampling the path.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
import tomllib
from pathlib import Path

import planner

MAPS = Path(__file__).resolve().parent.parent / "scenarios" / "maps"
CAR = {"min_turning_radius": 3.5, "expansion_distance": 2.25}
# Beyond the shipped queries: a turn-around in an aisle (needs reversing) and its reverse.
EXTRA = {
    "aisle_turnaround": ([64.0, 41.0, 0.0], [20.0, 30.0, math.pi / 2]),
    "aisle_to_aisle": ([20.0, 30.0, math.pi / 2], [64.0, 41.0, 0.0]),
    "top_right_to_start": ([90.0, 53.0, math.pi], [6.0, 6.0, 0.0]),
}


def _median_ms(function, repeat: int) -> tuple[float, object]:
    result = function()  # warm-up: JIT compilation and caches
    times = []
    for _ in range(repeat):
        began = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - began)
    return statistics.median(times) * 1e3, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args()
    grid = planner.OccupancyGrid.from_file(MAPS / "warehouse.yaml")
    with open(MAPS / "warehouse.queries.toml", "rb") as file:
        queries = {name: (q["start"], q["goal"]) for name, q in tomllib.load(file).items()}
    queries.update(EXTRA)

    header = (
        f"{'query':<20} {'planner':<8} {'length m':>9} {'nodes':>6} {'searched':>8} {'median ms':>10}"
        f" {'heur ms':>8} {'search ms':>9} {'path ms':>8} {'cusps':>5}"
    )
    print(
        f"warehouse {grid.shape[0]}x{grid.shape[1]} cells, {grid.resolution} m; car R 3.5 m, inflation 2.25 m"
    )
    print(header)
    print("-" * len(header))
    for name, (start, goal) in queries.items():
        grid_ms, grid_result = _median_ms(
            lambda start=start, goal=goal: planner.plan(grid, start[:2], goal[:2], expansion_distance=2.25),
            args.repeat,
        )
        hybrid_ms, hybrid = _median_ms(
            lambda start=start, goal=goal: planner.plan(grid, start, goal, planner="hybrid", **CAR),
            args.repeat,
        )
        print(
            f"{name:<20} {'grid A*':<8} {grid_result.length:9.2f} {grid_result.path_nodes:6d}"
            f" {grid_result.searched_nodes:8d} {grid_ms:10.2f}"
        )
        info = hybrid.info
        print(
            f"{'':<20} {'hybrid':<8} {hybrid.length:9.2f} {hybrid.path_nodes:6d} {hybrid.searched_nodes:8d}"
            f" {hybrid_ms:10.2f} {info['time_heuristic'] * 1e3:8.2f} {info['time_search'] * 1e3:9.2f}"
            f" {info['time_path'] * 1e3:8.2f} {info['cusps']:5d}"
        )


if __name__ == "__main__":
    main()
