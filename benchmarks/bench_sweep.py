"""Sweep benchmark (not a test): `python3 -m benchmarks.bench_sweep [--repeat R] [--baseline DIR]`.

Eight runs of `warehouse_diff_drive_one_obstacle` at full settings (lidar.seed 0..3 x lidar.noise
0.02, 0.05 m), made three ways in one benchmark run, each timed from the start of its command(s) to
their end:
- sequential `cosim run`: 8 subprocesses one after the other, as written (each draws its PNG), and
  with `--no-plot` (then each writes just its log, as a sweep does);
- `cosim sweep --workers 2`: the command starts a LocalCluster of 2 processes and stops it again,
  so start-up, the check build of the first run, collecting the logs and `sweep.png` are in the time;
- `cosim sweep --scheduler`: against a `dask scheduler` and `dask worker --nworkers 2 --nthreads 1`
  on 127.0.0.1, started before the timing (services run on, like a cluster's) and stopped by PID
  after; the first sweep meets cold workers, a second one (`warm`) workers that ran before.
Prints wall time, runs per minute, the ratio to sequential `cosim run`, and the CPU time of every
process the way ran (sampled every 50 ms, so a process's last moments are missed; the scheduler's
services count only while the sweep runs); checks that every way gives the same outcomes (each
sequential log's outcome metadata against the sweep's row of the same overrides). The load average
is printed before and after: other processes slow wall times down (CPU times much less).
`--repeat R` makes R rounds of every way (interleaved) and keeps the fastest of each. `--baseline DIR`
also measures the local sweep of another checkout (`git worktree add /tmp/old COMMIT`) in the same
run, against the same sequential time.
Goal (issue 11): the local sweep <= 0.33x the sequential `cosim run` time on a 2-core machine.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from cosim.logs import open_log  # noqa: E402
from cosim.sweep.adapter import outcome_keys  # noqa: E402

SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
SEEDS, NOISES = (0, 1, 2, 3), (0.02, 0.05)
VARY = ["--vary", "lidar.seed=0:3:4", "--vary", "lidar.noise=0.02,0.05"]
OUTCOME = outcome_keys()  # every key of a log's outcome metadata, each a column of results.csv
SAMPLE_INTERVAL = 0.05  # [s] between CPU-time samples of the processes a way runs
COSIM = [sys.executable, "-m", "cosim"]
ENVIRONMENT = {
    **os.environ,
    "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
}


class CpuMeter:
    """CPU time (user + system) of a process tree and of extra processes, sampled in a thread.

    Each process counts with the largest time seen for it (keyed by PID and start time), so what a
    process spends after its last sample (at most SAMPLE_INTERVAL) is missed."""

    def __init__(self, extra_pids: tuple[int, ...] = ()) -> None:
        self.extra = [psutil.Process(pid) for pid in extra_pids]
        self.seen: dict[tuple[int, float], float] = {}
        self.base: dict[tuple[int, float], float] = {}
        self.root: psutil.Process | None = None
        self.stop = threading.Event()
        for process in self._extra_tree():
            self.base[self._key(process)] = self._cpu(process) or 0.0
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    @staticmethod
    def _key(process: psutil.Process) -> tuple[int, float]:
        return process.pid, process.create_time()

    @staticmethod
    def _cpu(process: psutil.Process) -> float | None:
        try:
            times = process.cpu_times()
        except psutil.Error:
            return None
        return times.user + times.system

    def _extra_tree(self) -> list[psutil.Process]:
        found = []
        for process in self.extra:
            try:
                found += [process, *process.children(recursive=True)]
            except psutil.Error:
                pass
        return found

    def _sample(self) -> None:
        processes = self._extra_tree()
        root = self.root
        if root is not None:
            try:
                processes += [root, *root.children(recursive=True)]
            except psutil.Error:
                pass
        for process in processes:
            try:
                key = self._key(process)
            except psutil.Error:
                continue
            cpu = self._cpu(process)
            if cpu is not None:
                self.seen[key] = max(self.seen.get(key, 0.0), cpu)

    def _loop(self) -> None:
        while not self.stop.wait(SAMPLE_INTERVAL):
            self._sample()

    def finish(self) -> float:
        self._sample()
        self.stop.set()
        self.thread.join()
        return sum(cpu - self.base.get(key, 0.0) for key, cpu in self.seen.items())


def _environment(checkout: Path) -> dict[str, str]:
    """The environment that makes `python3 -m cosim` import `checkout`'s cosim."""
    return {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(checkout), os.environ.get("PYTHONPATH")])),
    }


def _timed(
    commands: list[list[str]], cwd: Path, extra_pids: tuple[int, ...] = (), checkout: Path = REPO
) -> tuple[float, float]:
    """Wall time and CPU time of running `commands` one after the other (with `checkout`'s cosim)."""
    meter = CpuMeter(extra_pids)
    start = time.perf_counter()
    for command in commands:
        process = subprocess.Popen(
            command,
            cwd=cwd,
            env=_environment(checkout),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        meter.root = psutil.Process(process.pid)
        _, stderr = process.communicate()
        meter.root = None
        if process.returncode not in (0, 1):
            meter.finish()
            raise SystemExit(f"{' '.join(command)} failed ({process.returncode}): {stderr.strip()}")
    seconds = time.perf_counter() - start
    return seconds, meter.finish()


Outcomes = dict[tuple[int, float], dict[str, str]]


def sequential(work: Path, plot: bool) -> tuple[float, float, Outcomes]:
    folder = work / f"sequential-{'plot' if plot else 'no-plot'}"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    commands = []
    for seed in SEEDS:
        for noise in NOISES:
            log = folder / f"seed{seed}-noise{noise}.mcap"
            options = ["--set", f"lidar.seed={seed}", "--set", f"lidar.noise={noise}", "--quiet"]
            commands.append(
                [*COSIM, "run", str(SCENARIO), "--out", str(log), *options] + ([] if plot else ["--no-plot"])
            )
    seconds, cpu = _timed(commands, REPO)
    outcomes = {}
    for seed in SEEDS:
        for noise in NOISES:
            with open_log(folder / f"seed{seed}-noise{noise}.mcap") as log:
                outcomes[(seed, noise)] = {key: log.outcome.get(key, "") for key in OUTCOME}
    return seconds, cpu, outcomes


def sweep(
    work: Path, name: str, options: list[str], services: tuple[int, ...] = (), checkout: Path = REPO
) -> tuple[float, float, Outcomes]:
    out = work / name
    shutil.rmtree(out, ignore_errors=True)
    scenario = checkout / SCENARIO.relative_to(REPO)
    command = [*COSIM, "sweep", str(scenario), *VARY, "--out", str(out), "--quiet", *options]
    seconds, cpu = _timed([command], checkout, services, checkout)
    with open(out / "results.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    if len(rows) != 8 or any(row["status"] != "completed" for row in rows):
        raise SystemExit(f"{name}: expected 8 completed runs, got {[row['status'] for row in rows]}")
    return (
        seconds,
        cpu,
        {
            (int(row["lidar.seed"]), float(row["lidar.noise"])): {key: row[key] for key in OUTCOME}
            for row in rows
        },
    )


def _stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def start_services(work: Path) -> tuple[str, list[subprocess.Popen]]:
    """A scheduler on a random port of 127.0.0.1 and 2 single-thread workers, each in its own folder."""
    for folder in ("scheduler", "worker"):
        (work / folder).mkdir(exist_ok=True)
    scheduler_file = work / "scheduler" / "scheduler.json"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "start_new_session": True}
    dask = [sys.executable, "-m", "dask"]
    services = [
        subprocess.Popen(
            [*dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard"]
            + ["--scheduler-file", str(scheduler_file)],
            cwd=work / "scheduler",
            env=ENVIRONMENT,
            **quiet,
        )
    ]
    try:
        deadline = time.monotonic() + 120
        while not scheduler_file.exists() or not scheduler_file.read_text().strip():
            if time.monotonic() > deadline or services[0].poll() is not None:
                raise SystemExit("the dask scheduler did not start")
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        services.append(
            subprocess.Popen(
                [*dask, "worker", address, "--nworkers", "2", "--nthreads", "1", "--host", "127.0.0.1"]
                + ["--no-dashboard", "--local-directory", str(work / "worker")],
                cwd=work / "worker",
                env=ENVIRONMENT,
                **quiet,
            )
        )
    except BaseException:
        for process in services:
            _stop(process)
        raise
    return address, services


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="R rounds; the fastest of each way")
    parser.add_argument(
        "--baseline", type=Path, help="another checkout whose local sweep to measure beside this one's"
    )
    args = parser.parse_args(argv)
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench-sweep-") as scratch:
        work = Path(scratch)
        results: dict[str, tuple[float, float, Outcomes]] = {}

        def best(name: str, measure, *arguments, **keywords) -> None:
            seconds, cpu, outcomes = measure(*arguments, **keywords)
            if name not in results or seconds < results[name][0]:
                results[name] = (seconds, cpu, outcomes)

        # Round by round, every way once a round: a change of the machine's load hits all of them.
        for _ in range(args.repeat):
            best("sequential cosim run", sequential, work, plot=True)
            best("sequential cosim run --no-plot", sequential, work, plot=False)
            best("cosim sweep --workers 2", sweep, work, "local", ["--workers", "2"])
            if args.baseline is not None:
                baseline = args.baseline.resolve()
                best(
                    "baseline: cosim sweep --workers 2",
                    sweep,
                    work,
                    "baseline",
                    ["--workers", "2"],
                    checkout=baseline,
                )
            # New services each round, so that the first sweep meets cold workers.
            address, services = start_services(work)
            pids = tuple(process.pid for process in services)
            try:
                for name in ("cold", "warm"):
                    best(
                        f"cosim sweep --scheduler ({name})",
                        sweep,
                        work,
                        "remote",
                        ["--scheduler", address],
                        pids,
                    )
            finally:
                for process in reversed(services):
                    _stop(process)
    load_after = os.getloadavg()
    reference_name = "sequential cosim run"
    reference_seconds, _, reference = results[reference_name]
    print(f"8 runs of {SCENARIO.stem} (lidar.seed 0..3 x lidar.noise 0.02, 0.05), {os.cpu_count()} cores")
    print(
        f"load average (1, 5, 15 min): before {' '.join(f'{x:.2f}' for x in load_before)}, "
        f"after {' '.join(f'{x:.2f}' for x in load_after)}"
    )
    print(
        f"{'way':<34}{'wall [s]':>10}{'runs/min':>10}{'x sequential':>14}{'CPU [s]':>10}{'same outcomes':>15}"
    )
    for name, (seconds, cpu, outcomes) in results.items():
        same = "yes" if outcomes == reference else "NO"
        ratio = seconds / reference_seconds
        print(f"{name:<34}{seconds:>10.2f}{8 * 60 / seconds:>10.1f}{ratio:>14.2f}{cpu:>10.1f}{same:>15}")
    local = results["cosim sweep --workers 2"][0] / reference_seconds
    no_plot = results["cosim sweep --workers 2"][0] / results["sequential cosim run --no-plot"][0]
    verdict = "met" if local <= 0.33 else "NOT met"
    print(f"goal (issue 11): local sweep <= 0.33x sequential cosim run: {local:.2f}x, {verdict}")
    print(f"against sequential cosim run --no-plot (same outputs but the per-run PNGs): {no_plot:.2f}x")
    return 0 if all(outcomes == reference for _, _, outcomes in results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
