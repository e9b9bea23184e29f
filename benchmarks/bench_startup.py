"""What a user waits for around the simulation: fresh `cosim` processes, as ratios to the import floor.

Every figure is the fastest of `--repeat` fresh processes (wall time, and the max RSS of that run;
CPU time, user + system, the least of them), measured in this run beside the import floor
`python3 -c "import numpy, scipy.ndimage, fmpy, mcap"` (the libraries any run must load). The floor
and the warm runs are measured in rounds (floor, run, run with plot, the same for a `--baseline`
checkout, floor, ...), so a load that comes and goes hits them alike. Wall time is the issue's
measure; CPU time depends far less on other processes, so its ratios are the ones to read on a busy
machine:

- `run --no-plot, warm`: `cosim run SCENARIO --no-plot` with warm caches (numba's, the FMU builds,
  Python's bytecode: `PYTHONDONTWRITEBYTECODE` is dropped for every process measured, as a user's
  shell does not set it);
- `plot added`: the same run drawing its default PNG, minus the run without it. On Linux the PNG
  is drawn by a child forked before the run (`cosim.cli.plotter`), which imports matplotlib while
  the run goes: with a free core that is off the wall time, not off the CPU time (the child's
  CPU is in the figure: `wait4` counts the children a process has reaped);
- `first run, cold caches`: a fresh copy of the checkout (no `__pycache__`, `build/` or logs, so no
  bytecode, no in-tree numba index files and no built C kernels: `planner.native` compiles them into
  the copy's `build/native/`) with an empty `NUMBA_CACHE_DIR` and the FMUs already
  built (the user's FMU build cache copied in): the first run of a fresh install. The user's own
  caches are never touched;
- `first run, cold caches + FMUs`: the same without built FMUs (a fresh source checkout builds them);
- `hybrid first call, cold`: `planner.plan(..., planner="hybrid")` in such a copy, in seconds.

The issue's figures (issue 15, "now", measured before the work) are printed beside the ratios.
`--baseline DIR` runs the same commands in another checkout (e.g. `git worktree add /tmp/old <commit>`)
and prints its figures beside these, from the same run.
"""

from __future__ import annotations

import argparse
import os
import shutil
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
# Issue 15's "now" column (before): ratio to the floor, or seconds for Hybrid A*.
ISSUE_BEFORE = {
    "run --no-plot, warm": "5.0x",
    "plot added": "3.9x",
    "first run, cold caches": "27x",
    "first run, cold caches + FMUs": "",
    "hybrid first call, cold": "16-19 s",
}
GOALS = {
    "run --no-plot, warm": "<= 2.5x",
    "plot added": "<= 1.5x",
    "first run, cold caches": "<= 10x",
    "first run, cold caches + FMUs": "",
    "hybrid first call, cold": "<= 5 s",
}


def _timed(command: list[str], cwd: Path, env: dict[str, str]) -> tuple[float, float, float]:
    """Wall seconds, max RSS [MiB] and CPU seconds (user + system) of one fresh process (which must
    exit 0 or 1). CPU time hardly depends on other processes: the figure to trust on a busy machine."""
    started = time.perf_counter()
    process = subprocess.Popen(command, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - started
    code = os.waitstatus_to_exitcode(status)
    if code not in (0, 1):
        error = process.stderr.read().decode(errors="replace").strip().splitlines()
        raise SystemExit(f"{' '.join(command)} in {cwd} exited {code}: {error[-1] if error else ''}")
    return wall, usage.ru_maxrss / 1024, usage.ru_utime + usage.ru_stime


def _environment(checkout: Path) -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    for name in (
        "NUMBA_CACHE_DIR", "NAVCOSIM_FMU_CACHE", "NAVCOSIM_NATIVE_CACHE", "PYTHONDONTWRITEBYTECODE",
        "PYTHONPYCACHEPREFIX",
    ):  # fmt: skip
        env.pop(name, None)
    return env


SKIP = shutil.ignore_patterns(
    ".git", "__pycache__", "*.nbi", "*.nbc", "build", "_native", "logs", "*.egg-info", ".pytest_cache",
    ".ruff_cache",
)  # fmt: skip


def _fresh_copy(checkout: Path, into: Path, with_fmus: bool) -> Path:
    """The checkout's files (times kept) in `into`, without bytecode, numba cache files, logs or
    builds; with `with_fmus`, the checkout's FMU build cache too (its stamps name the sources relative
    to the source tree, so the copied FMUs are up to date)."""
    copy = into / "checkout"
    shutil.copytree(checkout, copy, ignore=SKIP)
    fmus = checkout / "build" / "fmus"
    if with_fmus and fmus.is_dir():
        shutil.copytree(fmus, copy / "build" / "fmus", ignore=shutil.ignore_patterns("*.lock"))
    return copy


def _cold(checkout: Path, command, repeat: int, with_fmus: bool) -> tuple[float, float, float]:
    """Fastest of `repeat` first runs, each in its own fresh copy with an empty numba cache."""
    runs = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as scratch:
            scratch = Path(scratch)
            copy = _fresh_copy(checkout, scratch, with_fmus)
            env = _environment(copy) | {"NUMBA_CACHE_DIR": str(scratch / "numba")}
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
        results[name] = {"run --no-plot, warm": warm_best, "plot added": added}
    cold = {
        "first run, cold caches": (_cosim_run(scenario, "--no-plot"), cold_repeat, True),
        "first run, cold caches + FMUs": (_cosim_run(scenario, "--no-plot"), 1, False),
        "hybrid first call, cold": (lambda _: [sys.executable, "-c", HYBRID], 1, True),
    }
    for what, (command, times, with_fmus) in cold.items():
        if cold_repeat == 0:
            break  # --cold-repeat 0: the warm figures only
        for name, path in checkouts.items():
            results[name][what] = _cold(path, command, times, with_fmus)
    return _best(floor), results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="scenarios/warehouse_diff_drive_one_obstacle.toml")
    parser.add_argument("--repeat", type=int, default=5, help="rounds of warm processes (fastest)")
    parser.add_argument(
        "--cold-repeat", type=int, default=2, help="cold first runs (fastest); 0 leaves out every cold figure"
    )
    parser.add_argument("--baseline", type=Path, help="another checkout to measure beside this one")
    args = parser.parse_args(argv)
    checkouts = {"now": REPO} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    load = os.getloadavg()
    floor, results = measure(checkouts, args.scenario, args.repeat, args.cold_repeat)
    floor_wall, floor_rss, floor_cpu = floor
    print(f"scenario {args.scenario}; load average at start {load[0]:.2f}, at end {os.getloadavg()[0]:.2f}")
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
