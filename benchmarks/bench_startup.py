"""What a user waits for around the simulation: fresh `cosim` processes, as ratios to the import floor.

Every figure is the fastest of `--repeat` fresh processes (wall time, and the max RSS of that run;
CPU time, user + system, the least of them), measured in this run beside the import floor
`python3 -c "import numpy, scipy.ndimage, fmpy, mcap"` (the libraries a run loaded when the issue
was written). The floor and the warm runs are measured in rounds (floor, run, run with plot, the
same for a `--baseline` checkout, floor, ...), so a load that comes and goes hits them alike. Wall
time is the issue's measure; CPU time depends far less on other processes, so its ratios are the
ones to read on a busy machine:

- `run --no-plot, warm`: `cosim run SCENARIO --no-plot` with warm caches (the FMU and kernel builds,
  Python's bytecode: `PYTHONDONTWRITEBYTECODE` is dropped for every process measured, as a user's
  shell does not set it);
- `plot added`: the same run drawing its default PNG, minus the run without it. On Linux the PNG
  is drawn by a child forked before the run (`cosim.cli.plotter`), which imports matplotlib while
  the run goes: with a free core that is off the wall time, not off the CPU time (the child's
  CPU is in the figure: this process adopts and reaps the children `cosim` leaves to end by
  themselves, and adds their CPU time). The fastest run with the plot minus the fastest without:
  two minima of a few rounds each, which move by ~0.04x between identical checkouts in one
  benchmark run;
- `plot added, paired`: the median over the rounds of each round's run with the plot minus its
  run without (the two run one after the other): the same figure, less moved by a load that
  changes between rounds;
- `first run, nothing built`: a fresh copy of the checkout (no `__pycache__`, `build/` or logs, so
  no bytecode, no built FMUs and no built C kernels): the first run of a fresh source checkout,
  which builds its 4 FMUs and 5 kernels (side by side since issue 23). The user's own caches are
  never touched;
- `first run, FMUs built`: the same with the checkout's FMU build cache copied in (kernels only);
- `hybrid first call, cold`: `planner.plan(..., planner="hybrid")` in such a copy, in seconds;
- `sweep of 8 / 8 runs`: `cosim sweep SCENARIO --vary lidar.seed=0:3:4 --vary lidar.noise=0.02,0.05`
  (a local cluster, one worker per core, drawing its sweep.png) against the same 8 points as 8
  sequential `cosim run --no-plot` processes (the row `8 sequential runs`); the ratios are to those
  8 runs' wall and CPU time, not to the floor's. The CPU time is that of all of the sweep's
  processes. Spread over the machine's cores with none ever idle, it is the least wall time the
  sweep can take, printed under the table: a sweep that uses as much CPU as the 8 runs cannot be
  faster than 1 / cores of them;
- `sweep of 8 --no-plot / 8 runs`: the same sweep without its sweep.png, in the same rounds (what
  the plot adds to the sweep is the difference of the two rows).

The issue's figures (issue 23, measured before the work) are printed beside the ratios.
`--baseline DIR` runs the same commands in another checkout (e.g. `git worktree add /tmp/old <commit>`)
and prints its figures beside these, from the same run.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
FLOOR = [sys.executable, "-c", "import numpy, scipy.ndimage, fmpy, mcap"]
HYBRID = (
    "import planner\n"
    "grid = planner.OccupancyGrid.from_file('scenarios/maps/warehouse.yaml')\n"
    "planner.plan(grid, (6.0, 6.0, 0.0), (84.0, 53.0, 0.0), planner='hybrid', expansion_distance=2.25)\n"
)
# Issue 23's figures, measured before the work: ratio to the floor (the sweep: to 8 sequential runs).
ISSUE_BEFORE = {
    "run --no-plot, warm": "1.9x",
    "plot added": "",
    "plot added, paired": "",
    "first run, nothing built": "",
    "first run, FMUs built": "",
    "hybrid first call, cold": "",
    "sweep of 8 / 8 runs": "0.64x",
    "sweep of 8 --no-plot / 8 runs": "",
}
GOALS = {
    "run --no-plot, warm": "<= 1.2x",
    "plot added": "<= 0.3x",
    "plot added, paired": "<= 0.3x",
    "first run, nothing built": "<= 5x",
    "first run, FMUs built": "",
    "hybrid first call, cold": "",
    "sweep of 8 / 8 runs": "<= 0.4x",
    "sweep of 8 --no-plot / 8 runs": "",
}
SWEEP_POINTS = [(seed, noise) for seed in range(4) for noise in ("0.02", "0.05")]


def _adopt_orphans() -> None:
    """Make this process the one that reaps its descendants' orphans (Linux: PR_SET_CHILD_SUBREAPER),
    so that a measured process's CPU time includes the children it leaves to end by themselves
    (`wait4` counts only the children a process reaped)."""
    if _ADOPTING or not sys.platform.startswith("linux"):
        return
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(36, 1, 0, 0, 0) == 0:  # PR_SET_CHILD_SUBREAPER
        _ADOPTING.append(True)


_ADOPTING: list[bool] = []


def _timed(command: list[str], cwd: Path, env: dict[str, str]) -> tuple[float, float, float]:
    """Wall seconds, max RSS [MiB] and CPU seconds (user + system) of one fresh process (which must
    exit 0 or 1). CPU time hardly depends on other processes: the figure to trust on a busy machine."""
    _adopt_orphans()
    started = time.perf_counter()
    process = subprocess.Popen(command, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - started
    cpu = usage.ru_utime + usage.ru_stime
    while True:  # its children it did not wait for (the plot process ends after answering)
        try:
            _, _, orphan = os.wait4(-1, 0)
        except ChildProcessError:
            break
        cpu += orphan.ru_utime + orphan.ru_stime
    code = os.waitstatus_to_exitcode(status)
    if code not in (0, 1):
        error = process.stderr.read().decode(errors="replace").strip().splitlines()
        raise SystemExit(f"{' '.join(command)} in {cwd} exited {code}: {error[-1] if error else ''}")
    return wall, usage.ru_maxrss / 1024, cpu


def _environment(checkout: Path) -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    for name in (
        "NAVCOSIM_FMU_CACHE", "NAVCOSIM_NATIVE_CACHE", "PYTHONDONTWRITEBYTECODE",
        "PYTHONPYCACHEPREFIX",
    ):  # fmt: skip
        env.pop(name, None)
    return env


SKIP = shutil.ignore_patterns(
    ".git", "__pycache__", "build", "_native", "logs", "*.egg-info", ".pytest_cache",
    ".ruff_cache",
)  # fmt: skip


def _fresh_copy(checkout: Path, into: Path, with_fmus: bool) -> Path:
    """The checkout's files (times kept) in `into`, without bytecode, logs or builds; with
    `with_fmus`, the checkout's FMU build cache too (its stamps name the sources relative to the
    source tree, so the copied FMUs are up to date)."""
    copy = into / "checkout"
    shutil.copytree(checkout, copy, ignore=SKIP)
    fmus = checkout / "build" / "fmus"
    if with_fmus and fmus.is_dir():
        shutil.copytree(fmus, copy / "build" / "fmus", ignore=shutil.ignore_patterns("*.lock"))
    return copy


def _cold(checkout: Path, command, repeat: int, with_fmus: bool) -> tuple[float, float, float]:
    """Fastest of `repeat` first runs, each in its own fresh copy."""
    runs = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as scratch:
            scratch = Path(scratch)
            copy = _fresh_copy(checkout, scratch, with_fmus)
            env = _environment(copy)
            runs.append(_timed(command(scratch), copy, env))
    return _best(runs)


def _best(runs: list[tuple[float, float, float]]) -> tuple[float, float, float]:
    """The fastest run's wall time and RSS, and the least CPU time of all runs."""
    fastest = min(runs)
    return fastest[0], fastest[1], min(run[2] for run in runs)


def _cosim_run(scenario: str, *extra: str):
    return lambda scratch: [
        sys.executable, "-m", "cosim", "run", scenario, "--quiet", "--out", str(scratch / "run.mcap"), *extra
    ]  # fmt: skip


def measure(
    checkouts: dict[str, Path], scenario: str, repeat: int, cold_repeat: int
) -> tuple[tuple[float, float, float], dict[str, dict[str, tuple[float, float, float]]]]:
    """The floor, and per checkout the wall seconds, MiB and CPU seconds of each figure (the fastest
    of its processes; CPU the least of its processes'). Every checkout is measured in the same rounds
    as the floor, one after the other, so a changing load hits them alike."""
    envs = {name: _environment(path) for name, path in checkouts.items()}
    floor: list = []
    warm: dict[str, list] = {name: [] for name in checkouts}
    plotted: dict[str, list] = {name: [] for name in checkouts}
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        for name, path in checkouts.items():  # warm every cache
            _timed(_cosim_run(scenario, "--no-plot", "--force")(scratch), path, envs[name])
            _timed([sys.executable, "-c", HYBRID], path, envs[name])
        for _ in range(repeat):
            floor.append(_timed(FLOOR, REPO, envs["now"]))
            for name, path in checkouts.items():
                run = _cosim_run(scenario, "--no-plot", "--force")(scratch)
                warm[name].append(_timed(run, path, envs[name]))
                plotted[name].append(_timed(_cosim_run(scenario, "--force")(scratch), path, envs[name]))
            floor.append(_timed(FLOOR, REPO, envs["now"]))
    results: dict[str, dict[str, tuple[float, float, float]]] = {}
    for name in checkouts:
        warm_best, plot_best = _best(warm[name]), _best(plotted[name])
        added = tuple(with_plot - without for with_plot, without in zip(plot_best, warm_best, strict=True))
        pairs = [
            tuple(with_plot - without for with_plot, without in zip(plotted_run, warm_run, strict=True))
            for plotted_run, warm_run in zip(plotted[name], warm[name], strict=True)
        ]
        paired = tuple(statistics.median(pair[index] for pair in pairs) for index in range(3))
        results[name] = {"run --no-plot, warm": warm_best, "plot added": added, "plot added, paired": paired}
    cold = {
        "first run, nothing built": (_cosim_run(scenario, "--no-plot"), cold_repeat, False),
        "first run, FMUs built": (_cosim_run(scenario, "--no-plot"), 1, True),
        "hybrid first call, cold": (lambda _: [sys.executable, "-c", HYBRID], 1, True),
    }
    for what, (command, times, with_fmus) in cold.items():
        if cold_repeat == 0:
            break  # --cold-repeat 0: the warm figures only
        for name, path in checkouts.items():
            results[name][what] = _cold(path, command, times, with_fmus)
    return _best(floor), results


def _sequential(scenario: str, scratch: Path, checkout: Path, env: dict[str, str]) -> tuple[float, float]:
    """Wall seconds of the sweep's 8 points as 8 `cosim run --no-plot` processes, one after the other,
    and their CPU seconds."""
    started = time.perf_counter()
    cpu = 0.0
    for seed, noise in SWEEP_POINTS:
        points = ["--set", f"lidar.seed={seed}", "--set", f"lidar.noise={noise}", "--no-plot", "--force"]
        cpu += _timed(_cosim_run(scenario, *points)(scratch), checkout, env)[2]
    return time.perf_counter() - started, cpu


def _sweep(
    scenario: str, scratch: Path, checkout: Path, env: dict[str, str], *extra: str
) -> tuple[float, float]:
    """Wall and CPU seconds of `cosim sweep` over the same 8 points on a local cluster (into a new
    folder). The CPU time is that of every process of the sweep (its fork server, workers, plot
    process and multiprocessing's resource tracker: each is reaped by its parent or, orphaned, by
    this process)."""
    out = Path(tempfile.mkdtemp(dir=scratch))
    vary = ["--vary", "lidar.seed=0:3:4", "--vary", "lidar.noise=0.02,0.05"]
    command = [
        sys.executable,
        "-m",
        "cosim",
        "sweep",
        scenario,
        *vary,
        "--out",
        str(out / "sweep"),
        "--quiet",
        *extra,
    ]
    wall, _, cpu = _timed(command, checkout, env)
    shutil.rmtree(out)
    return wall, cpu


def measure_sweep(
    checkouts: dict[str, Path], scenario: str, repeat: int
) -> dict[str, tuple[tuple[float, float], ...]]:
    """Per checkout (wall seconds, CPU seconds) of 8 sequential runs, of the 8-run local sweep and of
    the same sweep with --no-plot, in rounds (sequential, sweep, sweep --no-plot, for each
    checkout in turn): the fastest wall, the least CPU."""
    envs = {name: _environment(path) for name, path in checkouts.items()}
    timings: dict[str, tuple[list[tuple[float, float]], ...]] = {name: ([], [], []) for name in checkouts}
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        for _ in range(repeat):
            for name, path in checkouts.items():
                timings[name][0].append(_sequential(scenario, scratch, path, envs[name]))
                timings[name][1].append(_sweep(scenario, scratch, path, envs[name]))
                timings[name][2].append(_sweep(scenario, scratch, path, envs[name], "--no-plot"))
    return {
        name: tuple((min(wall for wall, _ in figures), min(cpu for _, cpu in figures)) for figures in rounds)
        for name, rounds in timings.items()
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="scenarios/warehouse_diff_drive_one_obstacle.toml")
    parser.add_argument("--repeat", type=int, default=5, help="rounds of warm processes (fastest)")
    parser.add_argument(
        "--cold-repeat", type=int, default=2, help="cold first runs (fastest); 0 leaves out every cold figure"
    )
    parser.add_argument(
        "--sweep-repeat", type=int, default=2, help="rounds of the sweep figure (fastest); 0 leaves it out"
    )
    parser.add_argument("--baseline", type=Path, help="another checkout to measure beside this one")
    args = parser.parse_args(argv)
    checkouts = {"now": REPO} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    load = os.getloadavg()
    floor, results = measure(checkouts, args.scenario, args.repeat, args.cold_repeat)
    floor_wall, floor_rss, floor_cpu = floor
    after = os.getloadavg()[0]
    print(f"scenario {args.scenario}; load average at start {load[0]:.2f}, after the runs {after:.2f}")
    print(f"import floor: {floor_wall:.3f} s wall, {floor_cpu:.3f} s CPU, {floor_rss:.0f} MiB")
    header = f"{'what':<30}" + "".join(
        f"{name + ' wall':>14}{'/ floor':>8}{'CPU':>8}{'/ floor':>8}{'MiB':>6}" for name in results
    )
    print(header + f"{'issue before':>14}{'goal':>9}")
    for what in ISSUE_BEFORE:
        if what not in results["now"]:
            continue
        row = f"{what:<30}"
        for figures in results.values():
            wall, rss, cpu = figures[what]
            row += f"{wall:>13.3f}s{wall / floor_wall:>7.2f}x{cpu:>7.3f}s{cpu / floor_cpu:>7.2f}x{rss:>6.0f}"
        print(row + f"{ISSUE_BEFORE[what]:>14}{GOALS[what]:>9}")
    if args.sweep_repeat > 0:
        sweeps = measure_sweep(checkouts, args.scenario, args.sweep_repeat)
        # (the sweep rows: ratios to the 8 sequential runs' wall and CPU, not to the floor's)
        row = f"{'8 sequential runs':<30}"
        for figures in sweeps.values():
            (wall, cpu) = figures[0]
            row += f"{wall:>13.3f}s{1.0:>7.2f}x{cpu:>7.3f}s{1.0:>7.2f}x{'':>6}"
        print(row)
        for what, column in (("sweep of 8 / 8 runs", 1), ("sweep of 8 --no-plot / 8 runs", 2)):
            row = f"{what:<30}"
            for figures in sweeps.values():
                (sequential, sequential_cpu), (sweep, cpu) = figures[0], figures[column]
                row += f"{sweep:>13.3f}s{sweep / sequential:>7.2f}x"
                row += f"{cpu:>7.3f}s{cpu / sequential_cpu:>7.2f}x{'':>6}"
            print(row + f"{ISSUE_BEFORE[what]:>14}{GOALS[what]:>9}")
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        for name, figures in sweeps.items():
            (sequential, _), (_, cpu) = figures[0], figures[1]
            print(
                f"{name}: the sweep's CPU time spread over {cores} cores, no core ever idle: "
                f"{cpu / cores:.3f} s, {cpu / cores / sequential:.2f}x the 8 sequential runs "
                "(its wall time is no less)"
            )
    print(f"load average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
