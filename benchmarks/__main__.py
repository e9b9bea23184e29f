"""Run every benchmark, one after the other: `python3 -m benchmarks [--only NAME ...]`.

Each benchmark prints its own table (ratios against a peer measured in the same run); this runner
only sequences them, each in a fresh process so one benchmark's JIT caches and memory do not skew the
next, and prints how long each took and whether it finished.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = {
    "fmus": ["bench_fmus.py"],
    "planner": ["bench_planner.py"],
    "mapf": ["bench_mapf.py"],
    "hybrid": ["bench_hybrid.py"],
    "orchestrator": ["bench_orchestrator.py", "--parts", "a,b,c"],
    "isolation": ["bench_isolation.py"],
    "logs": ["bench_logs.py"],
    "startup": ["bench_startup.py"],
    "sweep": ["bench_sweep.py"],
    "live": ["bench_live.py"],
    "mcap_writers": ["bench_mcap_writers.py"],
    "png": ["bench_png.py"],
    "fmu_simulate": ["bench_fmu_simulate.py"],
    "fleet": ["bench_fleet.py"],
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m benchmarks", description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=sorted(BENCHMARKS), help="run only these")
    args = parser.parse_args(argv)
    summary = []
    for name in args.only or BENCHMARKS:
        script, *options = BENCHMARKS[name]
        print(f"\n=== {name}: {script} {' '.join(options)}", flush=True)
        started = time.perf_counter()
        code = subprocess.call([sys.executable, str(HERE / script), *options], cwd=HERE.parent)
        summary.append((name, code, time.perf_counter() - started))
    print("\nbenchmark      exit  wall [s]")
    for name, code, seconds in summary:
        print(f"{name:<14} {code:>4}  {seconds:8.1f}")
    return max((code for _, code, _ in summary), default=0)


if __name__ == "__main__":
    sys.exit(main())
