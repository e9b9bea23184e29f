"""FMU isolation benchmark (not a test): `python3 benchmarks/bench_isolation.py [--steps N] [--repeat R]`.

The two-FMU closed loop of `bench_orchestrator.py` part (a) (the project's DifferentialDrive and the
go-to-goal controller fixture, 1 ms macro step, master's Python loop as a run with observers uses
it) with both FMUs in-process, the vehicle alone in a child process, and both in child processes
(`IsolatedFmuComponent`). The runs are interleaved and each configuration's fastest of R is kept,
so a busy moment of the machine hits all of them alike.

Printed: µs per macro step, the ratio against in-process, and the extra cost per isolated
component step = (isolated - in-process) / (steps x isolated FMUs), against the goal of 15 µs
(issue 10). The floor beside it: one datagram round trip between two Python processes on the same
socket pair, the signalling cost no implementation over this transport can go below. Every run's
final pose is printed: isolation must not change a bit.
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import os
import socket
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO))

from fixtures.build_fixtures import build_fixture_fmu  # noqa: E402

from cosim.core.master import Master  # noqa: E402
from cosim.core.system import System  # noqa: E402
from cosim.fmi.builtin import builtin_fmu  # noqa: E402
from cosim.fmi.component import FmuComponent  # noqa: E402
from cosim.fmi.isolated import CHILD_SPIN, HOST_SPIN, IsolatedFmuComponent  # noqa: E402

MACRO_STEP = 0.001  # [s]
GOAL = (5.0, 3.0)  # [m]
POSE = ("x", "y", "theta")
GOAL_US = 15.0  # [us] extra per isolated component step (issue 10)
LAYOUTS = {  # name: (vehicle kind, controller kind)
    "in-process": (FmuComponent, FmuComponent),
    "vehicle isolated": (IsolatedFmuComponent, FmuComponent),
    "both isolated": (IsolatedFmuComponent, IsolatedFmuComponent),
}

ECHO = """
import os, sys
fd = int(sys.argv[1])
while True:
    packet = os.read(fd, 65536)
    if not packet:
        break
    os.write(fd, b"\\0")
"""


def load_baseline(directory: Path) -> type:
    """`IsolatedFmuComponent` of another tree (e.g. `git archive main cosim | tar -x -C DIR`),
    imported beside this one; its children run that tree's `cosim` (its PYTHONPATH is DIR)."""
    source = directory / "cosim" / "fmi" / "isolated.py"
    spec = importlib.util.spec_from_file_location("baseline_isolated", source)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.cosim = types.SimpleNamespace(__file__=str(directory / "cosim" / "__init__.py"))
    # `python -m` puts the working directory first on sys.path: start the children in DIR.
    popen = functools.partial(subprocess.Popen, cwd=directory)
    module.subprocess = types.SimpleNamespace(**{**vars(subprocess), "Popen": popen})
    return module.IsolatedFmuComponent


def configurations(spins: list[tuple[float, float]], baseline: type | None) -> dict[str, tuple]:
    """name: (vehicle kind, controller kind, (host spin, child spin) [s]) for every layout and
    handshake; spins (0, 0) is the blocking handshake (one wake-up through the kernel each way),
    "baseline" the --baseline tree's IsolatedFmuComponent."""
    result = {"in-process": (FmuComponent, FmuComponent, None)}
    for name, (vehicle_kind, controller_kind) in LAYOUTS.items():
        if name == "in-process":
            continue
        if baseline is not None:
            kinds = [
                baseline if kind is IsolatedFmuComponent else kind for kind in (vehicle_kind, controller_kind)
            ]
            result[f"{name}, baseline"] = (*kinds, "baseline")
        for spin in spins:
            if spin is None:
                label = "automatic"
            elif spin == (0, 0):
                label = "blocking"
            else:
                label = f"spin {spin[0] * 1e6:g}/{spin[1] * 1e6:g} us"
            result[f"{name}, {label}"] = (vehicle_kind, controller_kind, spin)
    return result


def closed_loop(
    vehicle_kind, controller_kind, spin, paths: tuple[Path, Path], steps: int
) -> tuple[float, str]:
    """Seconds per macro step of one run of `steps`, and its final pose as text."""
    vehicle_path, controller_path = paths
    system = System(MACRO_STEP)
    vehicle = system.add(vehicle_kind(vehicle_path, "vehicle", feedthrough_override={n: [] for n in POSE}))
    system.add(controller_kind(controller_path, "controller", {"goal_x": GOAL[0], "goal_y": GOAL[1]}))
    for component in system.components.values():
        if isinstance(component, IsolatedFmuComponent) and spin is not None:
            component.host_spin, component.child_spin = spin
    for name in POSE:
        system.connect(f"vehicle.{name}", f"controller.{name}")
    system.connect("controller.v", "vehicle.v")
    system.connect("controller.omega", "vehicle.omega")
    with Master(system) as master:
        master.initialize()
        master.run(100, compiled=False)  # warm up: first steps touch fresh pages and caches
        start = time.perf_counter()
        master.run(steps, compiled=False)
        seconds = time.perf_counter() - start
        pose = ", ".join(f"{value:.12f}" for value in vehicle.output_buffer[:3])
    return seconds / steps, pose


def round_trip_floor(count: int) -> float:
    """Seconds per one-byte datagram round trip to an echoing Python child."""
    host, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    process = subprocess.Popen([sys.executable, "-c", ECHO, str(child.fileno())], pass_fds=(child.fileno(),))
    child.close()
    fd = host.fileno()
    for _ in range(1000):
        os.write(fd, b"s")
        os.read(fd, 65536)
    start = time.perf_counter()
    for _ in range(count):
        os.write(fd, b"s")
        os.read(fd, 65536)
    seconds = (time.perf_counter() - start) / count
    host.close()
    process.wait()
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="macro steps per timed run")
    parser.add_argument("--repeat", type=int, default=5, help="runs per configuration; the fastest counts")
    parser.add_argument(
        "--spin",
        action="append",
        metavar="HOST_US/CHILD_US",
        help="a handshake to measure: how long the host polls for a reply and the child for the next "
        "request [us] before blocking, or auto (IsolatedFmuComponent's default: "
        f"{HOST_SPIN * 1e6:g}/{CHILD_SPIN * 1e6:g} while the host has fewer children than cores, "
        f"else {HOST_SPIN * 1e6:g}/0); repeatable (default: 0/0, the blocking handshake, and auto)",
    )
    parser.add_argument(
        "--baseline",
        type=Path,
        metavar="DIR",
        help="also measure the IsolatedFmuComponent of the tree in DIR (which holds cosim/)",
    )
    arguments = parser.parse_args()
    steps = arguments.steps
    texts = arguments.spin or ["0/0", "auto"]
    spins = [None if text == "auto" else tuple(float(v) * 1e-6 for v in text.split("/")) for text in texts]
    baseline = load_baseline(arguments.baseline.resolve()) if arguments.baseline else None
    configs = configurations(spins, baseline)
    best: dict[str, float] = {}
    poses: dict[str, set[str]] = {}
    floor = float("inf")
    with tempfile.TemporaryDirectory() as scratch:
        paths = builtin_fmu("DifferentialDrive"), build_fixture_fmu("controller_fmi2", Path(scratch))
        for _ in range(arguments.repeat):
            for name, (vehicle_kind, controller_kind, spin) in configs.items():
                seconds, pose = closed_loop(vehicle_kind, controller_kind, spin, paths, steps)
                best[name] = min(best.get(name, float("inf")), seconds)
                poses.setdefault(name, set()).add(pose)
            floor = min(floor, round_trip_floor(steps))
    reference = best["in-process"]
    print(f"two-FMU closed loop, {steps} macro steps of {MACRO_STEP} s, fastest of {arguments.repeat}\n")
    print("| configuration | us / macro step | vs in-process | extra us / isolated FMU step | final pose |")
    print("|---|---:|---:|---:|---|")
    for name, (vehicle_kind, controller_kind, _) in configs.items():
        isolated = sum(kind is not FmuComponent for kind in (vehicle_kind, controller_kind))
        extra = f"{(best[name] - reference) / isolated * 1e6:.1f}" if isolated else ""
        print(
            f"| {name} | {best[name] * 1e6:.1f} | {best[name] / reference:.2f}x | {extra} | "
            f"{' / '.join(sorted(poses[name]))} |"
        )
    print(f"| floor: one socket round trip, Python to Python | {floor * 1e6:.1f} | | | |")
    identical = len({pose for values in poses.values() for pose in values}) == 1
    print(f"\nfinal poses identical across configurations and runs: {'yes' if identical else 'NO'}")
    for spin, text in zip(spins, texts, strict=True):
        worst = max(
            (best[name] - reference) / sum(k is not FmuComponent for k in kinds[:2])
            for name, kinds in configs.items()
            if name != "in-process" and kinds[2] == spin
        )
        verdict = "met" if worst * 1e6 <= GOAL_US else "not met"
        print(
            f"handshake spin {text} us: goal <= {GOAL_US:g} us extra per isolated component step "
            f"{verdict} (worst {worst * 1e6:.1f} us)"
        )


if __name__ == "__main__":
    main()
