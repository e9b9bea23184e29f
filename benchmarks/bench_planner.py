"""Grid A* benchmark on the Moving AI maps: this planner against tcod and pyastar2d, in one run, with the
code before the issue-9/15 work ("before", the baseline checkout) measured beside it.

Run: `python3 -m benchmarks.bench_planner [--maps NAME ...] [--limit N] [--repeat R] [--skip-startup]
[--baseline DIR]` (or `python3 benchmarks/bench_planner.py ...`). Not a test: it prints tables, it
asserts nothing.

For every query of every `.scen` file in `<repo>/../shared/data/movingai`:
- ours: `planner.plan(grid, start, goal, connectivity=8, heuristic="octile", corner_cutting=False)`;
- tcod: a `tcod.path.CustomGraph` with 8 edges whose diagonal edges carry a no-corner-cut condition
  array, octile integer costs (1e5 / 141421) and a matching A* heuristic; per query a new
  `Pathfinder`, `add_root(start)` and `path_to(goal)` (what a user calls for each query);
- pyastar2d: `astar_path(weights, start, goal, allow_diagonal=True)`. It cuts corners and charges a
  diagonal step like a straight one, so its paths are measured with octile costs and are often not
  optimal for the Moving AI rule; the table reports that fraction as it is;
- before: the same `plan()` call of the planner in `--baseline DIR` (default `<repo>/../baseline`,
  the checkout the issue's figures were taken on), in a subprocess (both packages are called
  `planner`), on the same queries, interleaved per query with pyastar2d in that process, so that
  before/pyastar2d is a ratio of one process and one moment, as after/pyastar2d is.
Per map, the objects a user builds once per map (our OccupancyGrid, tcod's graph, pyastar2d's
weights) are built outside the timed call; their build time is printed separately. Each planner
runs once before timing (our kernels' build or load, the peers' first-call costs), then every query
is timed once per planner, planners interleaved per query so they see the same machine state.
The per-call overhead column is a query between two adjacent free cells (the first free cell, in
row-major order, whose right neighbour is free): the fixed cost of a call, which grew with the map
before (a grid-sized array per call). It is measured for both trees in fresh processes alike
(alternating, the fastest of 3 each), not in this one: after tcod and other maps a process calls
~1 us slower, which would favour the tree measured in a fresh process.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # `python3 benchmarks/bench_planner.py` from anywhere
    sys.path.insert(0, str(REPO))

DATA = REPO.parent / "shared" / "data" / "movingai"
BASELINE = REPO.parent / "baseline"
OPTIONS = {"connectivity": 8, "heuristic": "octile", "corner_cutting": False}
OPTIMAL_TOLERANCE = 1e-6  # relative error vs the .scen optimal length
TCOD_CARDINAL = 100_000  # tcod costs are integers: octile costs scaled by 1e5
TCOD_DIAGONAL = 141_421
LARGE_MAP = "orz900d"  # the 656 x 1491 map of the startup/memory report


@dataclass(frozen=True)
class Query:
    start: tuple[int, int]  # (row, col)
    goal: tuple[int, int]
    optimal_length: float  # cells


@dataclass
class PlannerStats:
    times: list[float] = field(default_factory=list)  # s per query
    optimal: int = 0
    answered: int = 0

    def record(self, elapsed: float, length: float | None, optimal_length: float) -> None:
        self.times.append(elapsed)
        if length is not None:
            self.answered += 1
            if abs(length - optimal_length) <= OPTIMAL_TOLERANCE * max(optimal_length, 1.0):
                self.optimal += 1


def read_scenarios(path: Path, limit: int | None) -> list[Query]:
    """Queries of a Moving AI `.scen` file (x = column, y = row, 0-based from the top-left)."""
    queries = []
    for line in path.read_text().splitlines()[1:]:
        fields = line.split("\t")
        if len(fields) < 9:
            continue
        sx, sy, gx, gy = (int(value) for value in fields[4:8])
        queries.append(Query((sy, sx), (gy, gx), float(fields[8])))
        if limit is not None and len(queries) >= limit:
            break
    return queries


def octile_length(cells: np.ndarray) -> float:
    """Length of a cell path [cells] with straight steps 1 and diagonal steps sqrt(2)."""
    if len(cells) < 2:
        return 0.0
    steps = np.abs(np.diff(np.asarray(cells, dtype=np.int64), axis=0))
    return float(np.hypot(steps[:, 0], steps[:, 1]).sum())


def corner_cut_steps(cells: np.ndarray, occupied: np.ndarray) -> int:
    """Number of diagonal steps of a path that squeeze past an occupied orthogonal neighbour."""
    cells = np.asarray(cells, dtype=np.int64)
    if len(cells) < 2:
        return 0
    before, after = cells[:-1], cells[1:]
    diagonal = (before[:, 0] != after[:, 0]) & (before[:, 1] != after[:, 1])
    side_a = occupied[before[:, 0], after[:, 1]]
    side_b = occupied[after[:, 0], before[:, 1]]
    return int((diagonal & (side_a | side_b)).sum())


# -- the three planners, each as: build once per map -> callable(start, goal) -> path cells | None --
def ours_factory(occupied: np.ndarray):
    """plan() of the `planner` on sys.path (this tree's, or the baseline's in a --before-worker)."""
    import planner

    grid = planner.OccupancyGrid(occupied, resolution=1.0)

    def run(start: tuple[int, int], goal: tuple[int, int]):
        try:
            result = planner.plan(grid, grid.cell_to_world(start), grid.cell_to_world(goal), **OPTIONS)
        except planner.PlannerError:
            return None
        return result.cells

    return run


def tcod_factory(occupied: np.ndarray):
    import tcod.path

    free = ~occupied
    graph = tcod.path.CustomGraph(occupied.shape)
    cost = free.astype(np.int8)
    for d_row, d_col in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        graph.add_edge((d_row, d_col), TCOD_CARDINAL, cost=cost)
    # A diagonal edge (d_row, d_col) leaves a node only when both orthogonal neighbours it passes
    # are free: condition[r, c] = free[r + d_row, c] & free[r, c + d_col] (False off the map).
    padded = np.pad(free, 1, constant_values=False)
    rows, cols = occupied.shape
    for d_row in (-1, 1):
        for d_col in (-1, 1):
            vertical = padded[1 + d_row : 1 + d_row + rows, 1 : 1 + cols]
            horizontal = padded[1 : 1 + rows, 1 + d_col : 1 + d_col + cols]
            condition = (vertical & horizontal).astype(np.int8)
            graph.add_edge((d_row, d_col), TCOD_DIAGONAL, cost=cost, condition=condition)
    graph.set_heuristic(cardinal=TCOD_CARDINAL, diagonal=TCOD_DIAGONAL)

    def run(start: tuple[int, int], goal: tuple[int, int]):
        pathfinder = tcod.path.Pathfinder(graph)
        pathfinder.add_root(start)
        path = pathfinder.path_to(goal)
        return path if len(path) and tuple(path[-1]) == goal and tuple(path[0]) == start else None

    return run


def pyastar2d_factory(occupied: np.ndarray):
    import pyastar2d

    weights = np.where(occupied, np.inf, 1.0).astype(np.float32)

    def run(start: tuple[int, int], goal: tuple[int, int]):
        return pyastar2d.astar_path(weights, start, goal, allow_diagonal=True)

    return run


FACTORIES = {"ours": ours_factory, "tcod": tcod_factory, "pyastar2d": pyastar2d_factory}


def load_occupancy(map_path: Path) -> np.ndarray:
    import planner

    return planner.OccupancyGrid.from_file(map_path).occupied


def adjacent_cells(occupied: np.ndarray) -> tuple[tuple[int, int], tuple[int, int]]:
    """The first free cell (row-major) whose right neighbour is free, and that neighbour."""
    pairs = np.argwhere(~occupied[:, :-1] & ~occupied[:, 1:])
    row, col = (int(value) for value in pairs[0])
    return (row, col), (row, col + 1)


def call_overhead(occupied: np.ndarray, batches: int = 300, calls: int = 20) -> float:
    """Wall time [s] of one plan() call between two adjacent cells, world coordinates computed
    beforehand: the fastest batch of `calls` calls, as a mean (short batches, so that some of them
    run while no other process has the CPU)."""
    import planner

    grid = planner.OccupancyGrid(occupied, resolution=1.0)
    start, goal = (grid.cell_to_world(cell) for cell in adjacent_cells(occupied))
    planner.plan(grid, start, goal, **OPTIONS)
    best = math.inf
    for _ in range(batches):
        begin = time.perf_counter()
        for _ in range(calls):
            planner.plan(grid, start, goal, **OPTIONS)
        best = min(best, (time.perf_counter() - begin) / calls)
    return best


def bench_map(
    occupied: np.ndarray, queries: list[Query], repeat: int, names: tuple[str, ...]
) -> tuple[dict[str, PlannerStats], dict[str, float], int]:
    """Time the planners `names` on every query (the fastest of `repeat` calls, which filters out
    moments when another process had the CPU); returns stats, build time per planner [s], pyastar2d
    corner cuts."""
    runners, build_times = {}, {}
    for name in names:
        begin = time.perf_counter()
        runners[name] = FACTORIES[name](occupied)
        build_times[name] = time.perf_counter() - begin
    for run in runners.values():  # first call outside the timing: kernel load, caches
        run(queries[0].start, queries[0].goal)
    stats = {name: PlannerStats() for name in runners}
    pyastar_cuts = 0
    for query in queries:
        for name, run in runners.items():
            elapsed = math.inf
            for _ in range(repeat):
                begin = time.perf_counter()
                cells = run(query.start, query.goal)
                elapsed = min(elapsed, time.perf_counter() - begin)
            length = None if cells is None else octile_length(cells)
            stats[name].record(elapsed, length, query.optimal_length)
            if name == "pyastar2d" and cells is not None and corner_cut_steps(cells, occupied):
                pyastar_cuts += 1
    return stats, build_times, pyastar_cuts


# -- "before": the baseline planner in its own process -----------------------------------------------
def before_worker(baseline: Path, map_path: Path, scen_path: Path, limit: int | None, repeat: int) -> None:
    """Print (JSON) the baseline's and pyastar2d's per-query times.

    Runs in a subprocess whose sys.path starts with `baseline`, so `import planner` is the
    baseline's; Moving AI maps are read here (not by that planner) so both trees see the same grid."""
    import json

    sys.path.insert(0, str(baseline))
    import planner

    if Path(planner.__file__).resolve().parent.parent != baseline.resolve():
        raise SystemExit(f"bench_planner: the baseline's planner did not import from {baseline}")
    from planner.mapio import read_movingai  # present in the baseline as in this tree

    occupied = read_movingai(map_path)
    queries = read_scenarios(scen_path, limit)
    stats, _, _ = bench_map(occupied, queries, repeat, ("ours", "pyastar2d"))
    print(
        json.dumps(
            {
                "ours": stats["ours"].times,
                "pyastar2d": stats["pyastar2d"].times,
                "optimal": stats["ours"].optimal,
            }
        )
    )


def measure_before(baseline: Path, map_path: Path, scen_path: Path, limit: int | None, repeat: int):
    """The --before-worker's numbers for one map, or None (with the reason printed) if it failed."""
    import json
    import tempfile

    # Its own numba cache and no bytecode files: the baseline checkout is not written to.
    cache = Path(tempfile.gettempdir()) / "navcosim-bench-baseline-numba"
    environment = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1")
    environment.pop("PYTHONPATH", None)
    command = [sys.executable, str(Path(__file__).resolve()), "--before-worker", str(baseline),
               str(map_path), str(scen_path), str(limit or 0), str(repeat)]  # fmt: skip
    completed = subprocess.run(command, env=environment, capture_output=True, text=True, check=False)
    if completed.returncode != 0:
        last = (completed.stderr.strip().splitlines() or ["no output"])[-1]
        print(f"bench_planner: baseline run on {map_path.name} failed: {last}", file=sys.stderr)
        return None
    return json.loads(completed.stdout.strip().splitlines()[-1])


def overhead_worker(tree: Path, map_path: Path) -> None:
    """Print (JSON) call_overhead of the planner of `tree` on the map, in a process of its own."""
    import json

    sys.path.insert(0, str(tree))
    import planner

    if Path(planner.__file__).resolve().parent.parent != tree.resolve():
        raise SystemExit(f"bench_planner: the planner did not import from {tree}")
    from planner.mapio import read_movingai

    print(json.dumps({"overhead": call_overhead(read_movingai(map_path))}))


def measure_overheads(trees: dict[str, Path], map_path: Path, rounds: int = 3) -> dict[str, float]:
    """call_overhead of each tree's planner, each in fresh processes alike (the same imports, no other
    work before), alternating between the trees `rounds` times; the fastest per tree. Measured apart
    from the per-query runs: a process that has run tcod and several maps first calls slower (~1 us
    here) than a fresh one, which would favour whichever tree ran in the fresh process."""
    import json
    import tempfile

    cache = Path(tempfile.gettempdir()) / "navcosim-bench-baseline-numba"
    environment = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1")
    environment.pop("PYTHONPATH", None)
    best = {label: math.inf for label in trees}
    for _ in range(rounds):
        for label, tree in trees.items():
            command = [sys.executable, str(Path(__file__).resolve()), "--overhead-worker", str(tree),
                       str(map_path)]  # fmt: skip
            completed = subprocess.run(command, env=environment, capture_output=True, text=True, check=False)
            if completed.returncode != 0:
                last = (completed.stderr.strip().splitlines() or ["no output"])[-1]
                print(f"bench_planner: {label}'s call overhead on {map_path.name}: {last}", file=sys.stderr)
                continue
            overhead = json.loads(completed.stdout.strip().splitlines()[-1])["overhead"]
            best[label] = min(best[label], overhead)
    return best


def print_table(rows: list[dict]) -> None:
    header = (
        f"{'map':<24}{'queries':>8}{'before ms':>10}{'ours ms':>10}{'tcod ms':>9}{'pya ms':>9}"
        f"{'bef/pya':>8}{'ours/pya':>9}{'ours/tcod':>10}{'opt ours':>9}{'opt bef':>8}{'opt pya':>8}"
        f"{'pya cuts':>9}{'call us bef':>12}{'call us':>8}"
    )
    print(header)
    print("-" * len(header))
    for row in rows:
        count, stats, before = row["queries"], row["stats"], row["before"]
        median = {key: statistics.median(value.times) for key, value in stats.items()}
        fraction = {key: value.optimal / count for key, value in stats.items()}
        if before is not None:
            before_ms = statistics.median(before["ours"])
            before_ratio = before_ms / statistics.median(before["pyastar2d"])
            before_cells = (
                f"{before_ms * 1e3:>10.3f}",
                f"{before_ratio:>8.2f}",
                f"{before['optimal'] / count:>8.1%}",
                f"{row['overhead_before'] * 1e6:>12.2f}",
            )
        else:
            before_cells = (f"{'-':>10}", f"{'-':>8}", f"{'-':>8}", f"{'-':>12}")
        print(
            f"{row['map']:<24}{count:>8}{before_cells[0]}{median['ours'] * 1e3:>10.3f}"
            f"{median['tcod'] * 1e3:>9.3f}{median['pyastar2d'] * 1e3:>9.3f}{before_cells[1]}"
            f"{median['ours'] / median['pyastar2d']:>9.2f}{median['ours'] / median['tcod']:>10.2f}"
            f"{fraction['ours']:>9.1%}{before_cells[2]}{fraction['pyastar2d']:>8.1%}"
            f"{row['cuts'] / count:>9.1%}"
            f"{before_cells[3]}{row['overhead'] * 1e6:>8.2f}"
        )
    missed = [
        row["map"]
        for row in rows
        if statistics.median(row["stats"]["ours"].times)
        > 0.7 * statistics.median(row["stats"]["pyastar2d"].times)
        or row["stats"]["ours"].optimal < row["queries"]
        or row["overhead"] > 4e-6
    ]
    print(
        f"\nGoal (issue 15: <= 0.7x pyastar2d, 100 % optimal, a call between adjacent cells <= 4 us): met on "
        f"{len(rows) - len(missed)} of {len(rows)} maps"
        + (f"; missed on {', '.join(missed)}" if missed else "")
    )
    print()
    print("Per-map build time outside the timed calls [ms]:")
    for row in rows:
        print(
            f"  {row['map']:<24} "
            + "  ".join(f"{key} {value * 1e3:.1f}" for key, value in row["build"].items())
        )


LEGEND = """\
Legend: median over queries of the wall time [ms] of the call a user makes per query (with --repeat R,
the fastest of R calls per query, made back to back: the later ones find the branch predictor trained
on that very query, which every planner gets alike; our C search measured up to 2x faster per expanded
node on room-64-64-8 that way than once per query), after one untimed warm-up call per planner and
map. Included:
ours = planner.plan(grid, start_xy, goal_xy, connectivity=8, heuristic="octile", corner_cutting=False)
(input checks, search, path and PlanResult); before = the same call of the baseline planner
(--baseline), in its own process with its own pyastar2d times (bef/pya is that process's ratio);
tcod = new Pathfinder(graph) + add_root + path_to; pyastar2d = astar_path(weights, ...) (it copies
the weights per call). Not included: building OccupancyGrid / tcod CustomGraph (+ no-corner-cut
condition arrays) / pyastar2d weights once per map (printed below). opt = fraction of queries whose
octile path length equals the .scen optimum (relative error <= 1e-6, Moving AI rule: no corner
cutting). pya cuts = fraction of pyastar2d paths with at least one corner-cutting diagonal step
(pyastar2d allows them and charges diagonals as straight steps, so it does not solve the Moving AI
problem). call us = wall time of one plan() between two adjacent free cells (fastest batch of 20
calls), the fixed cost per call; bef = the baseline's; both measured in fresh processes alike,
alternating, 3 processes per tree, the fastest kept."""


# -- first-call compile time and peak memory on the large map, in fresh processes ------------------
STARTUP_SCRIPT = textwrap.dedent(
    """
    import json, resource, sys, time, tracemalloc
    def max_rss_mib():
        # VmHWM restarts at exec; ru_maxrss would carry over the parent's peak from the fork.
        try:
            with open("/proc/self/status") as status:
                line = next(line for line in status if line.startswith("VmHWM:"))
            return int(line.split()[1]) / 1024
        except (OSError, StopIteration):
            return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    numbers = dict(rss_start=max_rss_mib())
    begin = time.perf_counter()
    import planner
    numbers["import_time"] = time.perf_counter() - begin
    numbers["rss_import"] = max_rss_mib()
    start, goal = (int(sys.argv[2]), int(sys.argv[3])), (int(sys.argv[4]), int(sys.argv[5]))
    options = dict(connectivity=8, heuristic="octile", corner_cutting=False)
    def plan_on(grid):
        return planner.plan(grid, grid.cell_to_world(start), grid.cell_to_world(goal), **options)
    grid = planner.OccupancyGrid.from_file(sys.argv[1])
    begin = time.perf_counter()
    plan_on(grid)
    numbers["first"] = time.perf_counter() - begin
    numbers["rss_first"] = max_rss_mib()
    # Memory a user pays per map and per call: a new grid one blocked column wider (the planner shares
    # work arrays between grids of one size, so the same size would hide them), then a repeat.
    import numpy
    fresh = planner.OccupancyGrid(numpy.pad(grid.occupied, ((0, 0), (0, 1)), constant_values=True))
    tracemalloc.start()
    begin = time.perf_counter()
    plan_on(fresh)
    numbers["new_grid"] = time.perf_counter() - begin
    numbers["traced_new_grid"] = tracemalloc.get_traced_memory()[1] / 2**20
    held = tracemalloc.get_traced_memory()[0]  # the per-grid arrays kept between calls
    tracemalloc.reset_peak()
    begin = time.perf_counter()
    plan_on(fresh)
    numbers["repeat"] = time.perf_counter() - begin
    numbers["traced_repeat"] = (tracemalloc.get_traced_memory()[1] - held) / 2**20
    tracemalloc.stop()
    numbers["rss_end"] = max_rss_mib()
    print(json.dumps(numbers))
    """
)


def startup_report(map_path: Path, query: Query, baseline: Path | None) -> None:
    """First plan() call in a fresh process with empty kernel caches (numba's for the baseline, the C
    kernels' for this tree), then with warm ones; memory. For this tree and, when given, the baseline
    ("before")."""
    import json
    import tempfile

    print(f"\nFirst-call time and memory on {map_path.name} (fresh process each; query {query}):")
    trees = [("before", baseline)] if baseline is not None else []
    for tree_label, tree in [*trees, ("after", REPO)]:
        with tempfile.TemporaryDirectory(prefix="navcosim-kernel-cache-") as cache_dir:
            # A private NUMBA_CACHE_DIR and NAVCOSIM_NATIVE_CACHE give cleared caches without touching a
            # tree's __pycache__ or build/; `python -c` imports `planner` from its working directory.
            environment = dict(os.environ, NUMBA_CACHE_DIR=cache_dir, NAVCOSIM_NATIVE_CACHE=cache_dir)
            environment["PYTHONDONTWRITEBYTECODE"] = "1"
            environment.pop("PYTHONPATH", None)
            arguments = [str(map_path), *map(str, query.start), *map(str, query.goal)]
            for label in ("cold kernel cache (compiles)", "warm kernel cache"):
                completed = subprocess.run(
                    [sys.executable, "-c", STARTUP_SCRIPT, *arguments],
                    env=environment,
                    capture_output=True,
                    text=True,
                    cwd=tree,
                    check=False,
                )
                if completed.returncode != 0:
                    print(f"  {tree_label}, {label}: failed: {completed.stderr.strip().splitlines()[-1:]}")
                    continue
                numbers = json.loads(completed.stdout.strip().splitlines()[-1])
                print(
                    f"  {tree_label}, {label}: import planner {numbers['import_time']:.2f} s; first plan() "
                    f"{numbers['first']:.2f} s (kernels' compile or load, search); plan() on a "
                    f"new grid {numbers['new_grid'] * 1e3:.1f} ms, repeated {numbers['repeat'] * 1e3:.1f} ms"
                )
                print(
                    f"    max RSS [MiB]: interpreter {numbers['rss_start']:.0f}, after import "
                    f"{numbers['rss_import']:.0f}, after first plan() {numbers['rss_first']:.0f}, end "
                    f"{numbers['rss_end']:.0f}; tracemalloc peak [MiB]: plan() on a new grid "
                    f"{numbers['traced_new_grid']:.1f}, repeated {numbers['traced_repeat']:.1f}"
                )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench_planner", description=__doc__.splitlines()[0])
    parser.add_argument("--maps", nargs="+", metavar="NAME", help="map names (stems), default: all")
    parser.add_argument("--limit", type=int, metavar="N", help="at most N queries per map")
    parser.add_argument(
        "--repeat", type=int, default=1, metavar="R", help="time each query R times, keep the fastest (1)"
    )
    parser.add_argument("--skip-startup", action="store_true", help="skip the compile-time/memory report")
    parser.add_argument("--data", type=Path, default=DATA, help=f"Moving AI folder (default {DATA})")
    parser.add_argument(
        "--baseline", type=Path, default=BASELINE, help=f"checkout measured as 'before' (default {BASELINE})"
    )
    parser.add_argument("--before-worker", nargs=5, metavar="ARG", help=argparse.SUPPRESS)
    parser.add_argument("--overhead-worker", nargs=2, metavar="ARG", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.before_worker:
        baseline, map_path, scen_path, limit, repeat = args.before_worker
        before_worker(Path(baseline), Path(map_path), Path(scen_path), int(limit) or None, int(repeat))
        return 0
    if args.overhead_worker:
        tree, map_path = args.overhead_worker
        overhead_worker(Path(tree), Path(map_path))
        return 0
    if not args.data.is_dir():
        print(f"bench_planner: {args.data} not found; nothing to benchmark (skipped)")
        return 0
    baseline = args.baseline if (args.baseline / "planner" / "__init__.py").is_file() else None
    if baseline is None:
        print(f"bench_planner: no baseline checkout at {args.baseline}; the 'before' columns stay empty")
    import pyastar2d  # noqa: F401  (imported here so no map's build time includes an import)
    import tcod.path  # noqa: F401

    scenario_files = sorted(args.data.glob("*.scen"))
    rows = []
    repeat = max(1, args.repeat)
    for scenario_file in scenario_files:
        map_name = scenario_file.name.split("-random-")[0].removesuffix(".scen")
        if args.maps and map_name not in args.maps:
            continue
        map_path = args.data / f"{map_name}.map"
        queries = read_scenarios(scenario_file, args.limit)
        if not map_path.is_file() or not queries:
            print(f"bench_planner: {scenario_file.name}: map or queries missing, skipped")
            continue
        before = measure_before(baseline, map_path, scenario_file, args.limit, repeat) if baseline else None
        occupied = load_occupancy(map_path)
        stats, build, cuts = bench_map(occupied, queries, repeat, tuple(FACTORIES))
        trees = {"before": baseline, "after": REPO} if baseline else {"after": REPO}
        overheads = measure_overheads(trees, map_path)
        rows.append(
            {"map": map_name, "queries": len(queries), "stats": stats, "build": build, "cuts": cuts,
             "before": before, "overhead": overheads["after"], "overhead_before": overheads.get("before")}
        )  # fmt: skip
        print(f"  {map_name}: {len(queries)} queries done", file=sys.stderr)
    print()
    print_table(rows)
    print()
    print(LEGEND)
    large = args.data / f"{LARGE_MAP}.map"
    large_scen = next(iter(sorted(args.data.glob(f"{LARGE_MAP}*.scen"))), None)
    if not args.skip_startup and large.is_file() and large_scen is not None:
        queries = read_scenarios(large_scen, None)
        longest = max(queries, key=lambda query: query.optimal_length)
        startup_report(large, longest, baseline)
    return 0


if __name__ == "__main__":
    sys.exit(main())
