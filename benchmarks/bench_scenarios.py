"""Orchestrator benchmark with logging (not a test): `python3 benchmarks/bench_scenarios.py [--parts b,c]`.

(b) The two-FMU closed loop of bench_orchestrator part (a) (the project's DifferentialDrive and
    the `controller_fmi2` fixture, 1 ms macro step) with every signal of both FMUs written to an
    MCAP log by `cosim.record.recorder.Recorder` at every step (one `/signals/<component>` message per
    component per step, as `cosim run` writes them): `Master.run_recorded` keeps the rows in the
    compiled loop and the recorder packs them per block of 1000 steps. Goal: >= 50k steps/s.
(c) Each shipped scenario (`scenarios/*.toml`; the commented example too, it is short) at its
    full settings through `cosim.navigation.run.run_scenario` with full logging: simulated time, wall time
    of the stepping loop, real-time factor, goal reached, distance and minimum clearance (the
    outcome, which optimisations must not change). `--repeat R` keeps the fastest of R runs
    (on a shared machine the load of other processes only ever slows a run down).
    Goal: >= 100x real time.
"""

from __future__ import annotations

import argparse
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

            master.run_recorded(1, record, compiled=True)  # compile once, outside the timing
            start = time.perf_counter()
            master.run_recorded(steps - 1, record, compiled=True)
            recorder.end_steps(master.time_ns)
            recorder.close()
            seconds = time.perf_counter() - start
        size = log_path.stat().st_size / 1e6
    return [Row("b", "navcosim master + Recorder, every signal", steps, seconds, f"{size:.1f} MB log")]


def part_c(_steps: int = 0, repeat: int = 1) -> list[Row]:
    """Each shipped scenario at full settings with full logging (the fastest of `repeat` runs)."""
    from cosim.navigation.run import run_scenario
    from cosim.scenario.load import load_scenario

    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for path in sorted((REPO / "scenarios").glob("*.toml")):
            scenario = load_scenario(path)
            results = [run_scenario(scenario, Path(scratch) / f"{path.stem}.mcap") for _ in range(repeat)]
            result = min(results, key=lambda r: r.wall_time)
            outcome = result.outcome
            if any((r.outcome.time, r.outcome.distance) != (outcome.time, outcome.distance) for r in results):
                raise SystemExit(f"{path.stem}: repeated runs differ")  # a run is deterministic
            reached = "yes" if outcome.reached else "no"
            note = (
                f"simulated {outcome.time:.2f} s, wall {result.wall_time:.2f} s, "
                f"{result.real_time_factor:.0f}x real time, reached: {reached}, "
                f"distance {outcome.distance:.3f} m, min clearance {outcome.min_clearance:.3f} m"
            )
            rows.append(Row("c", path.stem, result.steps, result.wall_time, note))
    return rows


PARTS = {"b": part_b, "c": part_c}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="b,c", help="comma-separated parts to run (b, c)")
    parser.add_argument("--steps", type=int, default=200_000, help="macro steps of part (b)")
    parser.add_argument("--repeat", type=int, default=1, help="part (c): fastest of R runs per scenario")
    arguments = parser.parse_args()
    print("| part | engine / scenario | steps | steps/s | note |\n|---|---|---:|---:|---|")
    for part in arguments.parts.split(","):
        if part not in PARTS:
            parser.error(f"unknown part '{part}'; parts: {', '.join(PARTS)}")
        rows = part_c(repeat=arguments.repeat) if part == "c" else PARTS[part](arguments.steps)
        for row in rows:
            print(f"| {row.part} | {row.engine} | {row.steps} | {row.rate:,.0f} | {row.note} |", flush=True)


if __name__ == "__main__":
    main()
