"""What a user waits for around the simulation: fresh `cosim` processes, as ratios to the import floor.

Every figure is the fastest of `--repeat` fresh processes (wall time, and the max RSS of that run),
measured in this run beside the import floor `python3 -c "import numpy, scipy.ndimage, fmpy, mcap"`
(the libraries any run must load), so the ratios hold on a noisy machine:

- `run --no-plot (warm)`: `cosim run SCENARIO --no-plot` with warm numba and FMU caches;
- `plot added`: the same run with its default PNG, minus the run without it;
- `first run, cold numba`: an empty `NUMBA_CACHE_DIR` (FMUs already built);
- `first run, cold numba + FMUs`: also an empty FMU build cache (`NAVCOSIM_FMU_CACHE`), as a fresh
  source checkout's first run;
- `hybrid first call, cold`: `planner.plan(..., planner="hybrid")` in a fresh process with an empty
  numba cache.

`--baseline DIR` runs the same commands in another checkout (e.g. `git worktree add /tmp/old <commit>`)
and prints its figures beside these, from the same run.
"""

from __future__ import annotations

import argparse
import os
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


def _timed(command: list[str], cwd: Path, env: dict[str, str]) -> tuple[float, float]:
    """Wall seconds and max RSS [MiB] of one fresh process (which must exit 0 or 1)."""
    started = time.perf_counter()
    process = subprocess.Popen(command, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - started
    code = os.waitstatus_to_exitcode(status)
    if code not in (0, 1):
        error = process.stderr.read().decode(errors="replace").strip().splitlines()
        raise SystemExit(f"{' '.join(command)} in {cwd} exited {code}: {error[-1] if error else ''}")
    return wall, usage.ru_maxrss / 1024


def _fastest(command, cwd: Path, env: dict[str, str], repeat: int, fresh_env=None) -> tuple[float, float]:
    runs = []
    for _ in range(repeat):
        run_env = dict(env)
        with tempfile.TemporaryDirectory() as scratch:
            if fresh_env:
                run_env.update(fresh_env(Path(scratch)))
            runs.append(_timed(command(Path(scratch)) if callable(command) else command, cwd, run_env))
    return min(runs)


def measure(checkout: Path, scenario: str, repeat: int) -> dict[str, tuple[float, float]]:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    env.pop("NUMBA_CACHE_DIR", None)
    env.pop("NAVCOSIM_FMU_CACHE", None)

    def cosim_run(*extra: str):
        return lambda scratch: (
            [sys.executable, "-m", "cosim", "run", scenario, "--quiet"]
            + [
                "--out",
                str(scratch / "run.mcap"),
                *extra,
            ]
        )

    _timed(cosim_run("--no-plot")(Path(tempfile.mkdtemp())), checkout, env)  # warm both caches
    _timed([sys.executable, "-c", HYBRID], checkout, env)
    cold_numba = lambda scratch: {"NUMBA_CACHE_DIR": str(scratch / "numba")}  # noqa: E731
    cold_all = lambda scratch: {  # noqa: E731
        "NUMBA_CACHE_DIR": str(scratch / "numba"),
        "NAVCOSIM_FMU_CACHE": str(scratch / "fmus"),
    }
    figures = {
        "run --no-plot (warm)": _fastest(cosim_run("--no-plot"), checkout, env, repeat),
        "run with plot (warm)": _fastest(cosim_run(), checkout, env, repeat),
        "first run, cold numba": _fastest(
            cosim_run("--no-plot"), checkout, env, max(1, repeat // 2), cold_numba
        ),
        "first run, cold numba + FMUs": _fastest(cosim_run("--no-plot"), checkout, env, 1, cold_all),
        "hybrid first call, cold": _fastest([sys.executable, "-c", HYBRID], checkout, env, 1, cold_numba),
    }
    plot = figures.pop("run with plot (warm)")
    warm = figures["run --no-plot (warm)"]
    figures = {
        "run --no-plot (warm)": warm,
        "plot added": (plot[0] - warm[0], plot[1] - warm[1]),
        **{k: v for k, v in figures.items() if k != "run --no-plot (warm)"},
    }
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="scenarios/warehouse_diff_drive_one_obstacle.toml")
    parser.add_argument("--repeat", type=int, default=5, help="fresh processes per figure (fastest)")
    parser.add_argument("--baseline", type=Path, help="another checkout to measure beside this one")
    args = parser.parse_args(argv)
    checkouts = {"now": REPO} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    results = {name: measure(path, args.scenario, args.repeat) for name, path in checkouts.items()}
    floor = _fastest(FLOOR, REPO, dict(os.environ), args.repeat)
    print(f"import floor: {floor[0]:.3f} s, {floor[1]:.0f} MiB (fastest of {args.repeat})")
    header = f"{'what':<30}" + "".join(f"{name + ' [s]':>15}{'/ floor':>9}{'MiB':>7}" for name in results)
    print(header)
    for what in results["now"]:
        row = f"{what:<30}"
        for figures in results.values():
            seconds, rss = figures[what]
            row += f"{seconds:>15.3f}{seconds / floor[0]:>9.2f}{rss:>7.0f}"
        print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
