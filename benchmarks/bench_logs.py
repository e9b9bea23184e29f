"""Benchmark the logs: signal reading throughput and recorder write throughput.

    python3 benchmarks/bench_logs.py [--size-mb 120] [--keep DIR]

1. Writes a log of at least --size-mb MB with the Recorder (six components, 20 and 300 variables
   mixed like a run: the vehicle every step, controllers and the lidar slower, plus poses).
2. Reads every component's signals with `open_log(...).signals(...)` and, on the same file,
   iterates it with the `mcap` reader alone (`make_reader(...).iter_messages()`, no decoding) and
   with mcap's NonSeekingReader; reports MB of log per second.
3. Write throughput of `Recorder.write_signals` for 20 and 300 variables (steps/s).
4. `cosim log info` on a decompression bomb (a killed run's log whose last chunk is a zstd frame
   of 3 GiB of zeros, declared at its size and declared as 1 MiB) against `cosim log info` on the
   same log without the bomb (the floor), each in a fresh process: wall time and peak resident
   memory (`/usr/bin/time`'s %M, when it is installed). `--skip-bomb` leaves it out.
"""

from __future__ import annotations

import argparse
import struct
import subprocess
import sys
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


BOMB_BYTES = 3 * 2**30  # zeros in the bomb's zstd frame


def bomb_logs(folder: Path) -> dict[str, Path]:
    """A killed run's log (no summary, no footer) and two copies ending in a bomb chunk."""
    import zstandard

    base = folder / "base.mcap"
    with Recorder(base) as recorder:
        channel = recorder.signal_channel("vehicle", ["x", "y"])
        for k in range(3000):
            recorder.write_signals(channel, k * 10_000_000, np.array([k * 0.01, 1.0]))
    data = base.read_bytes()
    summary_start = struct.unpack_from("<Q", data, len(data) - 8 - 29 + 9)[0]
    cut = data[: summary_start - 13]  # as a SIGKILL between chunks leaves it
    compressor = zstandard.ZstdCompressor(level=1).compressobj(size=BOMB_BYTES)
    zeros = bytes(2**20)
    parts = [compressor.compress(zeros) for _ in range(BOMB_BYTES // len(zeros))]
    frame = b"".join([*parts, compressor.flush()])
    paths = {"killed run, no bomb (floor)": folder / "cut.mcap"}
    paths["killed run, no bomb (floor)"].write_bytes(cut)
    for label, declared in (("bomb declaring 3 GiB", BOMB_BYTES), ("bomb declaring 1 MiB", 2**20)):
        body = struct.pack("<QQQII", 30 * 10**9, 30 * 10**9, declared, 0, 4) + b"zstd"
        body += struct.pack("<Q", len(frame)) + frame
        path = folder / f"bomb{declared}.mcap"
        path.write_bytes(cut + struct.pack("<BQ", 6, len(body)) + body)
        paths[label] = path
    return paths


def info_in_child(path: Path) -> tuple[float, int, int, str]:
    """(wall [s], peak RSS [bytes], exit code, last stderr line) of `cosim log info` in a child
    process, measured by `/usr/bin/time` (a child forked from this big process would inherit its
    peak, so the kernel's figure for a direct child is only an upper bound)."""
    command = [sys.executable, "-m", "cosim", "log", "info", str(path)]
    timer = Path("/usr/bin/time")
    with tempfile.NamedTemporaryFile("w+", suffix=".time") as report:
        wrapped = [str(timer), "-f", "%e %M", "-o", report.name, *command] if timer.exists() else command
        start = time.perf_counter()
        completed = subprocess.run(wrapped, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        elapsed = time.perf_counter() - start
        figures = report.read().split()
    peak = int(figures[-1]) * 1024 if timer.exists() else 0  # [kB] -> bytes; 0: not measured
    lines = completed.stderr.strip().splitlines()
    return elapsed, peak, completed.returncode, (lines or [""])[-1]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--size-mb", type=float, default=110.0)
    parser.add_argument("--keep", type=Path, help="write the logs here instead of a temporary folder")
    parser.add_argument("--skip-bomb", action="store_true", help="leave out part 4 (decompression bomb)")
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
        if not args.skip_bomb:
            print("\ncosim log info on a decompression bomb (fresh process each; ratios to the floor)")
            print(
                f"{'log':<30} {'wall [s]':>9} {'x floor':>8} {'max RSS [MB]':>13} {'x floor':>8}"
                " exit  last stderr"
            )
            floor = None
            for label, log_path in bomb_logs(folder).items():
                elapsed, peak, code, last = info_in_child(log_path)
                floor = floor or (elapsed, peak)
                ratios = f"{elapsed / floor[0]:>8.2f} {peak / 1e6:>13.0f} {peak / max(floor[1], 1):>8.2f}"
                print(f"{label:<30} {elapsed:>9.2f} {ratios} {code:>4}  {last[:90]}")


if __name__ == "__main__":
    main()
