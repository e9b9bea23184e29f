"""One FMU alone, `cosim fmu simulate` against `fmpy simulate` (not a test):
`python3 benchmarks/bench_fmu_simulate.py [--steps N] [--repeat R]`.

The project's DifferentialDrive (FMI 2.0) with v = 1 m/s, omega = 0.5 rad/s for N steps of 1 ms,
a communication point (and a result row) at every step, both ways:

- as commands, each in a fresh process: `cosim fmu simulate ... --csv` (MCAP log and CSV) against
  `fmpy simulate ... --output-interval 0.001 --output-file` (CSV), and `cosim fmu simulate` without
  `--csv` (the log alone);
- in this process: `cosim.ssp.simulate.simulate` (the log) against `fmpy.simulate_fmu` (the result
  array in memory).

The runs are interleaved and each one's fastest of R is kept, so a busy moment of the machine
hits all of them alike; the in-process ones run once untimed first (extracting the FMU, loading
the kernel and fmpy's modules are a command's start-up, which the process runs include).
Printed: wall time, µs per step and the ratio fmpy / navcosim; every row of both CSVs is
compared (they must agree to 1e-9).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import fmpy
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from cosim.fmi.builtin import builtin_fmu  # noqa: E402
from cosim.ssp.simulate import prepare, simulate  # noqa: E402

STEP = 0.001  # [s]
START = {"v": 1.0, "omega": 0.5}


def _timed(run) -> float:
    started = time.perf_counter()
    run()
    return time.perf_counter() - started


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000, help="steps of 1 ms (100000)")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each, the fastest kept (3)")
    args = parser.parse_args(argv)
    fmu = builtin_fmu("DifferentialDrive", 2)
    stop = args.steps * STEP
    values = [f"{k}={v}" for k, v in START.items()]
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        ours_csv, fmpy_csv = folder / "ours.csv", folder / "fmpy.csv"
        cosim = [sys.executable, "-m", "cosim", "fmu", "simulate", str(fmu), "--stop-time", repr(stop)]
        cosim += ["--step", repr(STEP), "--start-values", *values, "--quiet", "--force"]
        fmpy_command = [sys.executable, "-m", "fmpy.cli", "simulate", str(fmu), "--stop-time", repr(stop)]
        fmpy_command += ["--output-interval", repr(STEP), "--output-file", str(fmpy_csv), "--start-values"]
        fmpy_command += [text for k, v in START.items() for text in (k, repr(v))]
        simulation = prepare(fmu, stop_time=stop, step=STEP, start_values=START)
        runs = {
            "cosim fmu simulate --csv (process)": lambda: subprocess.run(
                [*cosim, "--out", str(folder / "a.mcap"), "--csv", str(ours_csv)], check=True, cwd=REPO
            ),
            "fmpy simulate --output-file (process)": lambda: subprocess.run(fmpy_command, check=True),
            "cosim fmu simulate, log only (process)": lambda: subprocess.run(
                [*cosim, "--out", str(folder / "b.mcap")], check=True, cwd=REPO
            ),
            "cosim.ssp.simulate.simulate (in process)": lambda: simulate(
                simulation, folder / "c.mcap", force=True
            ),
            "fmpy.simulate_fmu (in process)": lambda: fmpy.simulate_fmu(
                str(fmu), stop_time=stop, output_interval=STEP, start_values=START
            ),
        }
        best = {name: float("inf") for name in runs}
        for name, run in runs.items():
            if "in process" in name:
                run()
        for _ in range(args.repeat):
            for name, run in runs.items():
                best[name] = min(best[name], _timed(run))
        ours = np.genfromtxt(ours_csv, delimiter=",", names=True)
        theirs = np.genfromtxt(fmpy_csv, delimiter=",", names=True)
        deviation = max(float(np.max(np.abs(ours[n] - theirs[n]))) for n in ("time", "x", "y", "theta"))
    print(f"DifferentialDrive (FMI 2.0), {args.steps} steps of {STEP * 1e3:g} ms, fastest of {args.repeat}")
    print(f"{'run':<44} {'wall [s]':>9} {'us/step':>9}")
    for name, seconds in best.items():
        print(f"{name:<44} {seconds:9.3f} {seconds / args.steps * 1e6:9.2f}")
    processes = best["fmpy simulate --output-file (process)"] / best["cosim fmu simulate --csv (process)"]
    in_process = best["fmpy.simulate_fmu (in process)"] / best["cosim.ssp.simulate.simulate (in process)"]
    print(f"fmpy / navcosim: commands with CSV {processes:.1f}x, in process {in_process:.1f}x")
    print(f"largest |navcosim - fmpy| over time, x, y, theta of the CSVs: {deviation:.2e}")
    return 0 if deviation <= 1e-9 else 1


if __name__ == "__main__":
    sys.exit(main())
