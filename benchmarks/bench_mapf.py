"""MAPF benchmark on the Moving AI maps: planner.mapf.solve at N = 50 ... 1000 agents.

Run: `python3 -m benchmarks.bench_mapf [--maps NAME ...] [--agents N ...] [--time-limit S] [--json OUT]`
(or `python3 benchmarks/bench_mapf.py ...`). Not a test: it prints a table, it asserts nothing.

For every map with a `<map>-random-1.scen` in `<repo>/../shared/data/movingai` (`--data DIR`) and every
N: the first N agents of the scenario, one `solve(grid, starts, goals, time_limit=S)` call (S = 10 s,
the MAPF benchmark's usual budget), and per instance: solved within S, time to the first solution,
the CPU time the solve got (on a shared machine less than the wall time), the sum of costs over the
lower bound at S (the sum of the agents' own shortest distances: a ratio of 1.0 is optimal, above it
an upper bound on the gap), the makespan, why the solver stopped, and the
verdict of the tests' independent checker (tests/planner/test_mapf_checker.py: moves, waits,
starts, goals, vertex and swap conflicts, costs and bound recomputed) on the solution.

Goals (issue 25): >= 99 % of the instances solved within 10 s (LaCAM*'s figure on the benchmark),
sum of costs <= 1.2 x the lower bound on the warehouse maps at 200 agents.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # `python3 benchmarks/bench_mapf.py` from anywhere
    sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests" / "planner"))  # the independent checker

DATA = REPO.parent / "shared" / "data" / "movingai"
AGENTS = (50, 100, 200, 400, 700, 1000)
TIME_LIMIT = 10.0  # s
GOAL_SUCCESS = 0.99
GOAL_RATIO = 1.2  # sum of costs / lower bound on the warehouse maps at GOAL_AGENTS
GOAL_AGENTS = 200


def scenario_of(data: Path, map_name: str) -> Path | None:
    found = sorted(data.glob(f"{map_name}-random-*.scen"))
    return found[0] if found else None


def run_instance(grid, scen: Path, agents: int, time_limit: float, seed: int, verify: bool) -> dict:
    from test_mapf_checker import check

    from planner.mapf import solve
    from planner.mapf_scen import read_scen

    starts, goals = read_scen(scen, agents)
    cpu = time.process_time()
    result = solve(grid, starts, goals, time_limit=time_limit, seed=seed)
    cpu = time.process_time() - cpu
    verdict = "-"
    if result.solved and verify:
        try:
            check(grid.occupied.tolist(), starts, goals, result)
            verdict = "valid"
        except AssertionError as error:
            verdict = f"INVALID: {error}"
    return {
        "solved": result.solved,
        "status": result.status,
        "first": result.first_solution,
        "elapsed": result.elapsed,
        "cpu": cpu,
        "ratio": result.sum_of_costs / result.lower_bound if result.solved and result.lower_bound else None,
        "sum_of_costs": result.sum_of_costs,
        "lower_bound": result.lower_bound,
        "makespan": result.makespan,
        "neighbourhoods": result.neighbourhoods,
        "check": verdict,
    }


def load_after() -> str:
    """The 1-minute load average, as text ('-' where the OS has none)."""
    try:
        return f"{os.getloadavg()[0]:.2f}"
    except (AttributeError, OSError):
        return "-"


def print_table(rows: list[dict], time_limit: float) -> None:
    header = (
        f"{'map':<24}{'N':>6}{'solved':>8}{'first s':>9}{'total s':>9}{'CPU s':>7}{'SoC/LB':>8}"
        f"{'makespan':>9}{'LNS iter':>9}  {'stopped':<13}checker"
    )
    print(header)
    print("-" * len(header))
    for row in rows:
        first = f"{row['first']:.3f}" if row["first"] is not None else "-"
        ratio = f"{row['ratio']:.3f}" if row["ratio"] is not None else "-"
        makespan = row["makespan"] if row["makespan"] is not None else "-"
        print(
            f"{row['map']:<24}{row['agents']:>6}{'yes' if row['solved'] else 'NO':>8}{first:>9}"
            f"{row['elapsed']:>9.2f}{row['cpu']:>7.2f}{ratio:>8}{makespan:>9}{row['neighbourhoods']:>9}"
            f"  {row['status']:<13}{row['check']}"
        )
    solved = sum(row["solved"] for row in rows)
    invalid = [row for row in rows if row["check"].startswith("INVALID")]
    share = solved / max(len(rows), 1)
    valid = sum(row["check"] == "valid" for row in rows)
    print(
        f"\nsolved within {time_limit:g} s: {solved} of {len(rows)} ({share:.1%}; "
        f"goal >= {GOAL_SUCCESS:.0%}); "
        f"checker: {valid} valid, {len(invalid)} invalid"
    )
    warehouse = [row for row in rows if row["map"].startswith("warehouse") and row["agents"] == GOAL_AGENTS]
    for row in warehouse:
        met = row["ratio"] is not None and row["ratio"] <= GOAL_RATIO
        ratio = f"{row['ratio']:.3f}" if row["ratio"] is not None else "unsolved"
        verdict = "met" if met else "missed"
        print(f"{row['map']} at {GOAL_AGENTS} agents: SoC/LB {ratio} (goal <= {GOAL_RATIO}: {verdict})")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench_mapf", description=__doc__.splitlines()[0])
    parser.add_argument("--maps", nargs="+", metavar="NAME", help="map names (stems), default: every one")
    parser.add_argument(
        "--agents", nargs="+", type=int, default=list(AGENTS), metavar="N", help="agent counts"
    )
    parser.add_argument(
        "--time-limit", type=float, default=TIME_LIMIT, metavar="S", help="per instance [s] (10)"
    )
    parser.add_argument("--seed", type=int, default=0, metavar="K", help="solver seed (0)")
    parser.add_argument("--data", type=Path, default=DATA, help=f"Moving AI folder (default {DATA})")
    parser.add_argument("--no-check", action="store_true", help="skip the independent checker")
    parser.add_argument("--json", type=Path, metavar="OUT", help="also write the rows as JSON")
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"bench_mapf: {args.data} not found; nothing to benchmark (skipped)")
        return 0
    from tqdm import tqdm

    from planner import OccupancyGrid

    names = sorted(path.stem for path in args.data.glob("*.map"))
    if args.maps:
        unknown = sorted(set(args.maps) - set(names))
        if unknown:
            print(f"bench_mapf: no such map in {args.data}: {', '.join(unknown)}", file=sys.stderr)
            return 2
        names = [name for name in names if name in args.maps]
    plan = []
    for name in names:
        scen = scenario_of(args.data, name)
        if scen is None:
            print(f"bench_mapf: {name}: no .scen file, skipped", file=sys.stderr)
            continue
        available = sum(1 for line in scen.read_text().splitlines()[1:] if line.strip())
        for agents in sorted(args.agents):
            if agents > available:
                print(
                    f"bench_mapf: {name}: {agents} agents asked for, {scen.name} has {available}; skipped",
                    file=sys.stderr,
                )
                continue
            plan.append((name, scen, agents))
    rows, grids = [], {}
    load_before = load_after()
    began = time.perf_counter()
    with tqdm(plan, unit="instance", file=sys.stderr, dynamic_ncols=True) as progress:
        for name, scen, agents in progress:
            progress.set_description(f"{name} N={agents}")
            if name not in grids:
                grids = {name: OccupancyGrid.from_file(args.data / f"{name}.map")}  # one map held at a time
            row = run_instance(grids[name], scen, agents, args.time_limit, args.seed, not args.no_check)
            rows.append({"map": name, "agents": agents, **row})
    print(
        f"\n{len(rows)} instances in {time.perf_counter() - began:.0f} s; "
        f"time limit {args.time_limit:g} s each, "
        f"seed {args.seed}; load average {load_before} before, {load_after()} after (2 cores shared: a busy "
        "machine lowers the success and raises the times)\n"
    )
    print_table(rows, args.time_limit)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
