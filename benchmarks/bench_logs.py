"""Benchmark the logs: signal reading throughput and recorder write throughput.

    python3 benchmarks/bench_logs.py [--size-mb 120] [--keep DIR]

1. Writes a log of at least --size-mb MB with the Recorder (six components, 20 and 300 variables
   mixed like a run: the vehicle every step, controllers and the lidar slower, plus poses).
2. Reads every component's signals with `open_log(...).signals(...)` and, on the same file,
   iterates it with the `mcap` reader alone (`make_reader(...).iter_messages()`, no decoding) and
   with mcap's NonSeekingReader; reports MB of log per second.
3. Write throughput of `Recorder.write_signals` for 20 and 300 variables (steps/s).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from mcap.reader import NonSeekingReader, make_reader

from cosim.logs import open_log
from cosim.record.recorder import Recorder

COMPONENTS = {  # name -> (variables, every how many steps)
    "vehicle": (20, 1),
    "pure_pursuit": (20, 5),
    "vfh": (300, 5),
    "mixer": (20, 5),
    "planner": (20, 50),
    "lidar": (300, 10),
}


def write_big_log(path: Path, size_mb: float) -> int:
    """Write until the file holds `size_mb` MB; returns the number of steps."""
    rng = np.random.default_rng(0)
    with Recorder(path) as recorder:
        channels = {
            name: recorder.signal_channel(name, [f"{name}_{i}" for i in range(count)])
            for name, (count, _) in COMPONENTS.items()
        }
        base = {name: rng.normal(size=count) for name, (count, _) in COMPONENTS.items()}
        step = 0
        while True:
            t_ns = step * 1_000_000
            for name, (count, every) in COMPONENTS.items():
                if step % every == 0:
                    # slowly varying values, like simulation signals (compress like them too)
                    recorder.write_signals(
                        channels[name], t_ns, base[name] + np.sin(step * 1e-3 + np.arange(count))
                    )
            if step % 20 == 0:
                recorder.write_pose(t_ns, step * 1e-3, 0.0, 0.1, 1.0, 0.0)
            step += 1
            if step % 20_000 == 0 and path.stat().st_size >= size_mb * 1e6:
                break
        recorder.close({"reached": "true"})
    return step


def read_with_api(path: Path) -> tuple[float, int]:
    start = time.perf_counter()
    log = open_log(path)
    records = sum(len(log.signals(name).t) for name in log.components)
    return time.perf_counter() - start, records


def read_with_mcap(path: Path) -> tuple[float, int]:
    start = time.perf_counter()
    count = 0
    with open(path, "rb") as handle:
        for _schema, _channel, _message in make_reader(handle).iter_messages():
            count += 1
    return time.perf_counter() - start, count


def read_with_mcap_stream(path: Path) -> tuple[float, int]:
    start = time.perf_counter()
    count = 0
    with open(path, "rb") as handle:
        for _schema, _channel, _message in NonSeekingReader(handle).iter_messages():
            count += 1
    return time.perf_counter() - start, count


def write_throughput(folder: Path, variables: int, steps: int = 100_000) -> tuple[float, float]:
    """(steps per wall second, steps per CPU second)."""
    values = np.random.default_rng(1).normal(size=variables)
    with Recorder(folder / f"write{variables}.mcap") as recorder:
        channel = recorder.signal_channel("vehicle", [f"v{i}" for i in range(variables)])
        start, cpu_start = time.perf_counter(), time.process_time()
        for step in range(steps):
            recorder.write_signals(channel, step * 1000, values)
        elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    return steps / elapsed, steps / cpu


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--size-mb", type=float, default=110.0)
    parser.add_argument("--keep", type=Path, help="write the logs here instead of a temporary folder")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as temporary:
        folder = args.keep or Path(temporary)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / "big.mcap"
        start = time.perf_counter()
        steps = write_big_log(path, args.size_mb)
        size_mb = path.stat().st_size / 1e6
        print(f"wrote {size_mb:.1f} MB ({steps} steps of 1 ms) in {time.perf_counter() - start:.1f} s")
        rows = []  # wall and CPU time: on a shared machine the CPU time is the fairer figure
        for label, reader in (
            ("open_log(...).signals(c) for every component", read_with_api),
            ("mcap make_reader().iter_messages() (no decoding)", read_with_mcap),
            ("mcap NonSeekingReader.iter_messages() (no decoding)", read_with_mcap_stream),
        ):
            cpu_start = time.process_time()
            elapsed, count = reader(path)
            rows.append((label, elapsed, time.process_time() - cpu_start, count))
        print(f"\nreading {size_mb:.1f} MB of log")
        print(f"{'reader':<54} {'wall [s]':>9} {'MB/s':>8} {'cpu [s]':>8} {'MB/s':>8} {'records':>10}")
        for label, elapsed, cpu, count in rows:
            speeds = f"{elapsed:>9.2f} {size_mb / elapsed:>8.1f} {cpu:>8.2f} {size_mb / cpu:>8.1f}"
            print(f"{label:<54} {speeds} {count:>10}")
        print("\nwrite_signals throughput (one component, 100k steps)")
        for variables in (20, 300):
            wall, cpu = write_throughput(folder, variables)
            print(f"  {variables:>3} variables: {wall:>9.0f} steps/s wall, {cpu:>9.0f} steps/s CPU")


if __name__ == "__main__":
    main()
