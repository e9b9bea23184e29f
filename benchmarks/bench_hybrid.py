"""Time hybrid A* against grid A* on the warehouse queries, in the same run, and the first call of each on
cold caches, this tree against the baseline checkout.

    python3 benchmarks/bench_hybrid.py [--repeat 20] [--rounds 3] [--skip-cold] [--baseline DIR]

The car is the thesis's Table 4.4 bicycle (min turning radius 3.5 m, vehicle radius 1.5 m +
safety 0.75 m = expansion_distance 2.25 m); grid A* plans on the same inflated map. Compilation
is excluded (one warm-up plan per query); times are the median of --repeat plans [ms].
Hybrid times are split into inflation (cached per grid), the obstacle-aware heuristic grid (a
Dijkstra from the goal), the search, and sampling the path.

Warm, before/after: with `--baseline DIR`, the hybrid medians (wall and CPU time) of the baseline
checkout and of this tree, each in processes of its own alternating `--rounds` times (same queries
and repeats; the fastest round of each), and their ratios.

Cold start: the first plan() of a fresh process whose caches are all empty directories: numba's
(NUMBA_CACHE_DIR), the C kernels' (NAVCOSIM_NATIVE_CACHE) and Python's bytecode
(PYTHONPYCACHEPREFIX; PYTHONDONTWRITEBYTECODE unset), so every kernel the call uses is compiled
(wall time of the call; `planner`'s modules are imported on first use, inside it), then the same
in a second fresh process on the caches the first one filled (what every later process pays).
Grid A* and hybrid A* each in their own processes (hybrid A* runs grid A*'s Dijkstra kernel too),
for this tree and for `--baseline DIR` (default `<repo>/../baseline`) when it exists; and
"hybrid-own": hybrid A* on caches that already hold grid A*'s Dijkstra kernel (the heuristic
grid), so that only hybrid A*'s own kernels are cold. CPU time includes child processes (the C
compiler building a kernel).
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
    import json, math, os, sys, time
    import planner
    grid = planner.OccupancyGrid.from_file(sys.argv[1])
    if sys.argv[2] == "heuristic":  # grid A*'s Dijkstra as hybrid A*'s heuristic grid runs it
        planner.distance_to_goal(grid.inflate(2.25), grid.world_to_cell((84.0, 53.0)))
        print(json.dumps({}))
        sys.exit(0)
    if sys.argv[2].startswith("hybrid"):
        options = {"planner": "hybrid", **json.loads(sys.argv[3])}
        start, goal = (6.0, 6.0, 0.0), (84.0, 53.0, 0.0)
    else:
        start, goal, options = (6.0, 6.0), (84.0, 53.0), {"expansion_distance": 2.25}
    # CPU: this process's and its children's (a C compiler building a kernel)
    begin, cpu = time.perf_counter(), sum(os.times()[:4])
    result = planner.plan(grid, start, goal, **options)
    first, first_cpu = time.perf_counter() - begin, sum(os.times()[:4]) - cpu
    print(json.dumps({"first": first, "cpu": first_cpu, "length": result.length}))
    """
)


def cold_start(tree: Path, kind: str) -> tuple[dict, dict] | None:
    """(cold, warm) numbers of the first `kind` plan() of a fresh process in `tree`, or None.
    kind "hybrid-own": hybrid A* on caches that hold grid A*'s Dijkstra kernel only (a process ran
    the heuristic grid first), so the cold call compiles hybrid A*'s own kernels."""
    results = []
    with tempfile.TemporaryDirectory(prefix="navcosim-cold-cache-") as cache_dir:
        # Empty private caches: cleared without touching the tree's __pycache__ or build/native.
        cache = Path(cache_dir)
        environment = dict(
            os.environ,
            NUMBA_CACHE_DIR=str(cache / "numba"),
            NAVCOSIM_NATIVE_CACHE=str(cache / "native"),
            PYTHONPYCACHEPREFIX=str(cache / "pycache"),
        )
        for name in ("PYTHONPATH", "PYTHONDONTWRITEBYTECODE"):
            environment.pop(name, None)
        command = [sys.executable, "-c", COLD_SCRIPT, str(MAPS / "warehouse.yaml"), kind, json.dumps(CAR)]
        if kind == "hybrid-own":
            prewarm = [*command[:4], "heuristic", *command[5:]]
            subprocess.run(prewarm, cwd=tree, env=environment, capture_output=True, text=True, check=True)
        for _ in range(2):
            completed = subprocess.run(command, cwd=tree, env=environment, capture_output=True, text=True)
            if completed.returncode != 0:
                print(f"  {tree}: {kind} failed: {completed.stderr.strip().splitlines()[-1:]}")
                return None
            results.append(json.loads(completed.stdout.strip().splitlines()[-1]))
    return results[0], results[1]


# Medians of hybrid plans per query (wall and process CPU time) in a process of its own, in the
# tree of its working directory.
WARM_SCRIPT = textwrap.dedent(
    """
    import json, statistics, sys, time
    import planner
    grid = planner.OccupancyGrid.from_file(sys.argv[1])
    queries, options, repeat = json.loads(sys.argv[2]), json.loads(sys.argv[3]), int(sys.argv[4])
    medians = {}
    for name, (start, goal) in queries.items():
        planner.plan(grid, start, goal, planner="hybrid", **options)  # compile or load kernels
        walls, cpus = [], []
        for _ in range(repeat):
            begin, cpu = time.perf_counter(), time.process_time()
            planner.plan(grid, start, goal, planner="hybrid", **options)
            walls.append(time.perf_counter() - begin)
            cpus.append(time.process_time() - cpu)
        medians[name] = (statistics.median(walls) * 1e3, statistics.median(cpus) * 1e3)
    print(json.dumps(medians))
    """
)


def warm_medians(tree: Path, queries: dict, repeat: int) -> dict | None:
    """(wall, CPU) median ms per hybrid plan of each query, in a fresh process of `tree` (warm
    caches), or None."""
    environment = dict(os.environ)
    environment.pop("PYTHONPATH", None)
    command = [
        sys.executable, "-c", WARM_SCRIPT, str(MAPS / "warehouse.yaml"), json.dumps(queries), json.dumps(CAR),
        str(repeat),
    ]  # fmt: skip
    completed = subprocess.run(command, cwd=tree, env=environment, capture_output=True, text=True)
    if completed.returncode != 0:
        print(f"  {tree}: warm hybrid failed: {completed.stderr.strip().splitlines()[-1:]}")
        return None
    return json.loads(completed.stdout.strip().splitlines()[-1])


def warm_report(baseline: Path, queries: dict, repeat: int, rounds: int) -> None:
    """Hybrid medians of the baseline tree and this one, alternating processes `rounds` times; the
    fastest round per query and tree (the least disturbed by other load), wall and CPU time."""
    best: dict[str, dict[str, list[float]]] = {"before": {}, "after": {}}
    for _ in range(rounds):
        for label, tree in (("before", baseline), ("after", REPO)):
            medians = warm_medians(tree, queries, repeat)
            if medians is None:
                return
            for name, values in medians.items():
                previous = best[label].get(name, [math.inf, math.inf])
                best[label][name] = [min(old, new) for old, new in zip(previous, values, strict=True)]
    print(f"\nHybrid A* warm, median ms per plan (fastest of {rounds} alternating processes per tree):")
    columns = f"{'CPU before':>11} {'CPU after':>10} {'ratio':>6}"
    print(f"{'query':<20} {'before':>9} {'after':>9} {'ratio':>6} {columns}")
    rows = [(name, *best["before"][name], *best["after"][name]) for name in queries]
    rows.append(("all queries", *(sum(row[i] for row in rows) for i in range(1, 5))))
    for name, wall_before, cpu_before, wall_after, cpu_after in rows:
        print(
            f"{name:<20} {wall_before:9.2f} {wall_after:9.2f} {wall_after / wall_before:6.2f}"
            f" {cpu_before:11.2f} {cpu_after:10.2f} {cpu_after / cpu_before:6.2f}"
        )


# The hybrid A* first call on a cold cache as measured before the issue-15 work (wall [s]): the
# issue's figure and the last session's, on this 2-core machine with no other load.
HYBRID_COLD_BEFORE = "16-19 s (issue 15), 10.4 s (last session)"


def cold_report(baseline: Path | None) -> None:
    print(
        "\nFirst plan() of a fresh process [s] (imports on first use included), thesis_table_3_1,"
        " Table 4.4 car:"
    )
    columns = f"{'cold cache':>11} {'cold CPU':>9} {'warm cache':>11} {'cold/warm':>9}"
    print(f"{'planner':<10} {'tree':<8} {columns}")
    trees = [("before", baseline)] if baseline is not None else []
    for kind in ("grid", "hybrid", "hybrid-own"):
        for label, tree in [*trees, ("after", REPO)]:
            numbers = cold_start(tree, kind)
            if numbers is not None:
                cold, warm = numbers
                print(
                    f"{kind:<10} {label:<8} {cold['first']:11.2f} {cold['cpu']:9.2f} {warm['first']:11.2f}"
                    f" {cold['first'] / warm['first']:9.1f}"
                )
    print(f"Hybrid A* on a cold cache before: {HYBRID_COLD_BEFORE}. Goal (issue 15): <= 5 s.")
    print(
        "cold CPU: the CPU time of the cold call (the process and its children: the C compiler), less"
        " sensitive than wall time to other load."
    )
    print("hybrid-own: grid A*'s Dijkstra kernel (the heuristic grid) already cached, hybrid A*'s own cold.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--skip-cold", action="store_true", help="skip the cold-start report")
    parser.add_argument("--rounds", type=int, default=3, help="alternating processes per tree (warm)")
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
    baseline = args.baseline if (args.baseline / "planner" / "__init__.py").is_file() else None
    if baseline is not None:
        warm_report(baseline, queries, args.repeat, args.rounds)
    if not args.skip_cold:
        cold_report(baseline)


if __name__ == "__main__":
    main()
