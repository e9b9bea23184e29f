"""Orchestrator benchmark with logging (not a test): `python3 benchmarks/bench_scenarios.py [--parts b,c]`.

(b) The two-FMU closed loop of bench_orchestrator part (a) (the project's DifferentialDrive and
    the `controller_fmi2` fixture, 1 ms macro step) with every signal of both FMUs written to an
    MCAP log by `cosim.record.recorder.Recorder` at every step (one `/signals/<component>` message per
    component per step, as `cosim run` writes them): `Master.run_recorded` keeps the rows in the
    compiled kernel and the recorder packs them per block of 1000 steps. Goal: >= 50k steps/s.
(c) Each shipped scenario (`scenarios/*.toml`; the commented example too, it is short) at its
    full settings through `cosim.navigation.run.run_scenario` with full logging: simulated time, wall time
    of the stepping loop, real-time factor, goal reached, distance and minimum clearance (the
    outcome, which optimisations must not change). Each scenario runs through the compiled
    kernel (after issue 15) and, interleaved with it, through the master's Python loop
    (`NAVCOSIM_LOOP=python`, the "now" of issue 15); both must give the same outcome.
    `--repeat R` keeps the fastest of R runs of each (on a shared machine the load of other
    processes only ever slows a run down). Goals: >= 100x real time; issue 15:
    warehouse_diff_drive_one_obstacle >= 500x (was 110-395x).
    `--baseline DIR`: each scenario also runs from the checkout DIR (e.g. the main branch), both
    trees in fresh processes (`python3 -c`, the tree first on sys.path), interleaved run by run, the
    fastest of R per tree: "before" (DIR) and "after" (this tree) measured in the same minutes on a
    shared machine, their ratio, and a check that both give the same outcome (time, distance).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from benchmarks.bench_orchestrator import Row, _fmus, _system  # noqa: E402
from cosim.core.master import Master  # noqa: E402
from cosim.record.recorder import Recorder  # noqa: E402


def part_b(steps: int) -> list[Row]:
    """Two-FMU closed loop, every signal of both FMUs to MCAP at every step."""
    steps = min(steps, 200_000)
    with tempfile.TemporaryDirectory() as scratch:
        work = Path(scratch)
        vehicle_path, controller_path = _fmus(work)
        system = _system(vehicle_path, controller_path)[0]
        log_path = work / "closed_loop.mcap"
        with Master(system) as master, Recorder(log_path) as recorder:
            master.initialize()
            periods = [system.period_steps(c) for c in master.order]
            h_ns = system.macro_step_ns
            channels = [
                recorder.signal_channel(
                    c.name,
                    c.signal_names(),
                    inputs=len(c.inputs),
                    initial=c.signal_values(),
                    period_ns=period * h_ns,
                )
                for c, period in zip(master.order, periods, strict=True)
            ]

            def record(first: int, count: int, histories: list[np.ndarray]) -> None:
                # Row j of a component with period P is its step k = first rounded up to P, + j P.
                blocks = []
                for channel, period, rows in zip(channels, periods, histories, strict=True):
                    first_k = -(-first // period) * period
                    times = master.start_time_ns + (first_k + period * np.arange(len(rows))) * h_ns
                    blocks.append((channel, times, rows))
                recorder.hold_signal_rows(blocks)

            master.run_recorded(1, record, compiled=True)  # fill the kernel tables once, outside the timing
            start = time.perf_counter()
            master.run_recorded(steps - 1, record, compiled=True)
            recorder.end_steps(master.time_ns)
            recorder.close()
            seconds = time.perf_counter() - start
        size = log_path.stat().st_size / 1e6
    return [Row("b", "navcosim master + Recorder, every signal", steps, seconds, f"{size:.1f} MB log")]


def part_c(_steps: int = 0, repeat: int = 1, only: list[str] | None = None) -> list[Row]:
    """Each shipped scenario at full settings with full logging (the fastest of `repeat` runs),
    through the compiled kernel (after) and the master's Python loop (now), interleaved."""
    import os

    from cosim.navigation.run import run_scenario
    from cosim.scenario.load import load_scenario

    rows = []
    before = os.environ.get("NAVCOSIM_LOOP")
    with tempfile.TemporaryDirectory() as scratch:
        for path in sorted((REPO / "scenarios").glob("*.toml")):
            if only and path.stem not in only:
                continue
            scenario = load_scenario(path)
            results: dict[str, list] = {"kernel": [], "python": []}
            try:
                for _ in range(repeat):
                    for loop in results:
                        os.environ["NAVCOSIM_LOOP"] = loop
                        out = Path(scratch) / f"{path.stem}.{loop}.mcap"
                        results[loop].append(run_scenario(scenario, out, force=True))
            finally:
                if before is None:
                    os.environ.pop("NAVCOSIM_LOOP", None)
                else:
                    os.environ["NAVCOSIM_LOOP"] = before
            every = results["kernel"] + results["python"]
            outcome = every[0].outcome
            if any((r.outcome.time, r.outcome.distance) != (outcome.time, outcome.distance) for r in every):
                raise SystemExit(f"{path.stem}: runs differ")  # a run is deterministic, either loop
            kernel = min(results["kernel"], key=lambda r: r.wall_time)
            python = min(results["python"], key=lambda r: r.wall_time)
            reached = "yes" if outcome.reached else "no"
            goal = ""
            if path.stem == "warehouse_diff_drive_one_obstacle":
                met = "met" if kernel.real_time_factor >= 500 else "not met"
                goal = f"; goal (issue 15) >= 500x: {met}"
            speedup = python.wall_time / kernel.wall_time
            note = (
                f"simulated {outcome.time:.2f} s, wall {kernel.wall_time:.2f} s, "
                f"{kernel.real_time_factor:.0f}x real time (now, Python loop: "
                f"{python.real_time_factor:.0f}x; after/now {speedup:.2f}){goal}, "
                f"reached: {reached}, distance {outcome.distance:.3f} m, "
                f"min clearance {outcome.min_clearance:.3f} m"
            )
            rows.append(Row("c", path.stem, kernel.steps, kernel.wall_time, note))
    return rows


# One timed run in a fresh process of a given tree: a first run (imports, FMU builds, caches) is
# not timed, the second is; prints the RunResult's figures as JSON.
_ONE_RUN = """
import json, sys, tempfile
from pathlib import Path
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario
scenario = load_scenario(Path(sys.argv[1]))
with tempfile.TemporaryDirectory() as scratch:
    out = Path(scratch) / "run.mcap"
    run_scenario(scenario, out, force=True)
    result = run_scenario(scenario, out, force=True)
outcome = result.outcome
print(json.dumps({"wall": result.wall_time, "time": outcome.time, "distance": outcome.distance,
                  "reached": outcome.reached, "steps": result.steps}))
"""


def _run_in(tree: Path, scenario: Path) -> dict:
    environment = dict(os.environ, PYTHONPATH=str(tree), NAVCOSIM_LOOP="kernel")
    completed = subprocess.run(
        [sys.executable, "-c", _ONE_RUN, str(scenario)],
        cwd=tree,
        env=environment,
        capture_output=True,
        text=True,
        check=False,
    )
    if completed.returncode != 0:
        raise SystemExit(f"{scenario.stem} in {tree}: {completed.stderr.strip().splitlines()[-1:]}")
    return json.loads(completed.stdout.strip().splitlines()[-1])


def part_c_baseline(baseline: Path, repeat: int = 1, only: list[str] | None = None) -> list[Row]:
    """Each shipped scenario with full logging from this tree (after) and from `baseline`
    (before), fresh processes interleaved, the fastest of `repeat` runs per tree."""
    rows = []
    for path in sorted((REPO / "scenarios").glob("*.toml")):
        if only and path.stem not in only:
            continue
        runs: dict[str, list[dict]] = {"after": [], "before": []}
        for _ in range(repeat):
            runs["after"].append(_run_in(REPO, path))
            runs["before"].append(_run_in(baseline, path))
        after = min(runs["after"], key=lambda r: r["wall"])
        before = min(runs["before"], key=lambda r: r["wall"])
        every = runs["after"] + runs["before"]
        if any(
            abs(r["time"] - after["time"]) > 1e-9 or abs(r["distance"] - after["distance"]) > 1e-9
            for r in every
        ):
            raise SystemExit(f"{path.stem}: the two trees' outcomes differ")
        rate_after, rate_before = after["time"] / after["wall"], before["time"] / before["wall"]
        goal = ""
        if path.stem == "warehouse_diff_drive_one_obstacle":
            goal = f"; goal (issue 15) >= 500x: {'met' if rate_after >= 500 else 'not met'}"
        note = (
            f"simulated {after['time']:.2f} s, {rate_after:.0f}x real time after "
            f"(wall {after['wall']:.3f} s), "
            f"{rate_before:.0f}x before ({before['wall']:.3f} s; {baseline}), after/before "
            f"{before['wall'] / after['wall']:.2f}{goal}, reached: {'yes' if after['reached'] else 'no'}, "
            f"distance {after['distance']:.3f} m (same in both trees)"
        )
        rows.append(Row("c", path.stem, after["steps"], after["wall"], note))
    return rows


PARTS = {"b": part_b, "c": part_c}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="b,c", help="comma-separated parts to run (b, c)")
    parser.add_argument("--steps", type=int, default=200_000, help="macro steps of part (b)")
    parser.add_argument("--repeat", type=int, default=1, help="part (c): fastest of R runs per scenario")
    parser.add_argument("--scenarios", nargs="*", help="part (c): only these scenarios (file stems)")
    parser.add_argument(
        "--baseline", type=Path, help="part (c): also run each scenario from this checkout (before/after)"
    )
    arguments = parser.parse_args()
    print("| part | engine / scenario | steps | steps/s | note |\n|---|---|---:|---:|---|")
    for part in arguments.parts.split(","):
        if part not in PARTS:
            parser.error(f"unknown part '{part}'; parts: {', '.join(PARTS)}")
        if part == "c" and arguments.baseline is not None:
            rows = part_c_baseline(arguments.baseline.resolve(), arguments.repeat, arguments.scenarios)
        elif part == "c":
            rows = part_c(repeat=arguments.repeat, only=arguments.scenarios)
        else:
            rows = PARTS[part](arguments.steps)
        for row in rows:
            print(f"| {row.part} | {row.engine} | {row.steps} | {row.rate:,.0f} | {row.note} |", flush=True)


if __name__ == "__main__":
    main()
