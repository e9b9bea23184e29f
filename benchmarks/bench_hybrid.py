"""Time hybrid A* against grid A* on the warehouse queries, in the same run, and the first call of each on
a cold numba cache, this tree against the baseline checkout.

    python3 benchmarks/bench_hybrid.py [--repeat 20] [--skip-cold] [--baseline DIR]

The car is the thesis's Table 4.4 bicycle (min turning radius 3.5 m, vehicle radius 1.5 m +
safety 0.75 m = expansion_distance 2.25 m); grid A* plans on the same inflated map. Compilation
is excluded (one warm-up plan per query); times are the median of --repeat plans [ms].
Hybrid times are split into inflation (cached per grid), the obstacle-aware heuristic grid (a
Dijkstra from the goal), the search, and sampling the path.

Cold start: the first plan() of a fresh process whose NUMBA_CACHE_DIR is an empty directory, so
every kernel the call uses is compiled (wall time of the call, imports excluded), then the same in
a second fresh process on the cache the first one filled (what every later process pays). Grid A*
and hybrid A* each in their own processes (hybrid A* compiles grid A*'s Dijkstra kernel too), for
this tree and for `--baseline DIR` (default `<repo>/../baseline`) when it exists.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # `python3 benchmarks/bench_hybrid.py` from anywhere
    sys.path.insert(0, str(REPO))

import planner  # noqa: E402

MAPS = REPO / "scenarios" / "maps"
BASELINE = REPO.parent / "baseline"
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


# One first call, in a process started for it; `python -c` imports `planner` from its working directory.
COLD_SCRIPT = textwrap.dedent(
    """
    import json, math, sys, time
    import planner
    grid = planner.OccupancyGrid.from_file(sys.argv[1])
    if sys.argv[2] == "hybrid":
        options = {"planner": "hybrid", **json.loads(sys.argv[3])}
        start, goal = (6.0, 6.0, 0.0), (84.0, 53.0, 0.0)
    else:
        start, goal, options = (6.0, 6.0), (84.0, 53.0), {"expansion_distance": 2.25}
    begin, cpu = time.perf_counter(), time.process_time()
    result = planner.plan(grid, start, goal, **options)
    first, first_cpu = time.perf_counter() - begin, time.process_time() - cpu
    print(json.dumps({"first": first, "cpu": first_cpu, "length": result.length}))
    """
)


def cold_start(tree: Path, kind: str) -> tuple[dict, dict] | None:
    """(cold, warm) numbers of the first `kind` plan() of a fresh process in `tree`, or None."""
    results = []
    with tempfile.TemporaryDirectory(prefix="navcosim-numba-cache-") as cache_dir:
        # An empty private NUMBA_CACHE_DIR: a cleared cache without touching the tree's __pycache__.
        environment = dict(os.environ, NUMBA_CACHE_DIR=cache_dir, PYTHONDONTWRITEBYTECODE="1")
        environment.pop("PYTHONPATH", None)
        command = [sys.executable, "-c", COLD_SCRIPT, str(MAPS / "warehouse.yaml"), kind, json.dumps(CAR)]
        for _ in range(2):
            completed = subprocess.run(command, cwd=tree, env=environment, capture_output=True, text=True)
            if completed.returncode != 0:
                print(f"  {tree}: {kind} failed: {completed.stderr.strip().splitlines()[-1:]}")
                return None
            results.append(json.loads(completed.stdout.strip().splitlines()[-1]))
    return results[0], results[1]


# The hybrid A* first call on a cold cache as measured before the issue-15 work (wall [s]): the
# issue's figure and the last session's, on this 2-core machine with no other load.
HYBRID_COLD_BEFORE = "16-19 s (issue 15), 10.4 s (last session)"


def cold_report(baseline: Path | None) -> None:
    print("\nFirst plan() of a fresh process [s] (numba import included), thesis_table_3_1, Table 4.4 car:")
    columns = f"{'cold cache':>11} {'cold CPU':>9} {'warm cache':>11} {'cold/warm':>9}"
    print(f"{'planner':<10} {'tree':<8} {columns}")
    trees = [("before", baseline)] if baseline is not None else []
    for kind in ("grid", "hybrid"):
        for label, tree in [*trees, ("after", REPO)]:
            numbers = cold_start(tree, kind)
            if numbers is not None:
                cold, warm = numbers
                print(
                    f"{kind:<10} {label:<8} {cold['first']:11.2f} {cold['cpu']:9.2f} {warm['first']:11.2f}"
                    f" {cold['first'] / warm['first']:9.1f}"
                )
    print(f"Hybrid A* on a cold cache before: {HYBRID_COLD_BEFORE}. Goal (issue 15): <= 5 s.")
    print("cold CPU: the process CPU time of the cold call, less sensitive than wall time to other load.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--skip-cold", action="store_true", help="skip the cold-start report")
    parser.add_argument(
        "--baseline", type=Path, default=BASELINE, help=f"checkout measured as 'before' (default {BASELINE})"
    )
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
    if not args.skip_cold:
        baseline = args.baseline if (args.baseline / "planner" / "__init__.py").is_file() else None
        cold_report(baseline)


if __name__ == "__main__":
    main()
