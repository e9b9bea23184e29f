"""Orchestrator benchmark (not a test): `python3 benchmarks/bench_orchestrator.py [--parts a] [--steps N]`.

(a) A two-FMU closed loop without logging: the project's DifferentialDrive and a go-to-goal
    controller FMU (the test fixture `controller_fmi2`, hand-written C), 1 ms macro step, both
    stepped every step. Steps/s of
      - a plain fmpy `FMU2Slave` loop through fmpy's methods (naive),
      - navcosim's master, Python loop (`run(n, compiled=False)`, what a run with per-step
        observers uses),
      - navcosim's master, compiled loop (`run(n)`, an FMU-only system with nobody observing: the
        C kernel `cosim/core/native/kernel.c`),
      - ecospy's `step(n)` (C++ master) on the same FMUs, when ecospy is installed.
      - the scenario loop with logging off (a position check after every step): the Python loop
        with a per-step callback, what `cosim run` used before issue 15 ("now"), and the compiled
        kernel (`Master.run_blocks`) that watches the position and calls back per block ("after").
    Goals: >= 200k steps/s and >= 0.5x ecospy; issue 15: the scenario loop >= 1x ecospy (was
    0.13-0.25x). Each engine's final pose is printed: they agree.

(b) The same loop with every signal to MCAP and (c) each shipped scenario at full settings come
from `benchmarks/bench_scenarios.py` (see there). `--parts a,b,c` runs them all into one table.

(d) The robot run's stepping loop (`cosim.navigation.run._RobotRun.loop`: kernel blocks, lidar and
    planner, outcome checks, every topic recorded to MCAP, no plot trace) of
    scenarios/warehouse_diff_drive_one_obstacle.toml, without the start-up (build, header) and the
    end (close): the median over `--repeat` runs in one process, and the floor measured in the
    same runs: the time inside the loop's compiled calls that no recording can save (the C
    stepping kernel and the C lidar sweeps). loop / floor is the figure to compare across
    machines and runs (1.0: everything else free); issue 24 asks the loop >= 2x faster.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO))  # `benchmarks.bench_scenarios` when run as a script

from fixtures.build_fixtures import build_fixture_fmu  # noqa: E402

from cosim.core.master import Master  # noqa: E402
from cosim.core.system import System  # noqa: E402
from cosim.fmi.builtin import builtin_fmu  # noqa: E402
from cosim.fmi.component import FmuComponent  # noqa: E402

MACRO_STEP = 0.001  # s
GOAL = (5.0, 3.0)  # m
STATE_OUTPUTS = ("x", "y", "theta")


@dataclass
class Row:
    part: str
    engine: str
    steps: int
    seconds: float
    note: str = ""

    @property
    def rate(self) -> float:
        return self.steps / self.seconds


def _fmus(work: Path) -> tuple[Path, Path]:
    return builtin_fmu("DifferentialDrive"), build_fixture_fmu("controller_fmi2", work)


def _system(vehicle_path: Path, controller_path: Path) -> tuple[System, FmuComponent]:
    system = System(MACRO_STEP)
    # The project's DifferentialDrive does not declare its outputs' dependencies (FMI: then they
    # depend on every input); the pose is a state, so say so.
    vehicle = system.add(
        FmuComponent(vehicle_path, "vehicle", feedthrough_override={name: [] for name in STATE_OUTPUTS})
    )
    system.add(FmuComponent(controller_path, "controller", {"goal_x": GOAL[0], "goal_y": GOAL[1]}))
    for name in STATE_OUTPUTS:
        system.connect(f"vehicle.{name}", f"controller.{name}")
    system.connect("controller.v", "vehicle.v")
    system.connect("controller.omega", "vehicle.omega")
    return system, vehicle


def _navcosim(vehicle_path: Path, controller_path: Path, steps: int, compiled: bool) -> Row:
    system, vehicle = _system(vehicle_path, controller_path)
    with Master(system) as master:
        master.initialize()
        note = ""
        if compiled:
            start = time.perf_counter()
            master.run(1, compiled=True)  # fill the kernel's tables (and load it) outside the timing
            note = f"first call {1e3 * (time.perf_counter() - start):.1f} ms; "
            steps -= 1
        start = time.perf_counter()
        master.run(steps, compiled=compiled)
        seconds = time.perf_counter() - start
        x, y = vehicle.output_buffer[0], vehicle.output_buffer[1]
    engine = "navcosim master, compiled loop" if compiled else "navcosim master, Python loop"
    return Row("a", engine, steps, seconds, note + f"final x, y = {x:.9f}, {y:.9f}")


def _scenario_loop(vehicle_path: Path, controller_path: Path, steps: int, kernel: bool) -> Row:
    """The scenario run's stepping with logging off, on the same FMUs: every step's position checked
    against a goal circle (the outcome check that ends a run). Before ("now"): the master's Python
    loop with a per-step callback, as `cosim run` stepped until issue 15. After: the compiled kernel
    (`Master.run_blocks`) watching the position, a Python callback per block of 1000 steps."""
    import numpy as np

    system, vehicle = _system(vehicle_path, controller_path)
    goal_x, goal_y, tolerance = GOAL[0] + 100.0, GOAL[1], 0.5  # never reached: the run goes on
    with Master(system) as master:
        master.initialize()
        x_slot, y_slot = vehicle.output_index["x"], vehicle.output_index["y"]
        buffer = vehicle.output_buffer
        checks = [0]
        if kernel:
            tables = master.kernel_tables()
            tables.watch_addresses[:] = (
                1,
                vehicle.output_buffer.ctypes.data + 8 * x_slot,
                vehicle.output_buffer.ctypes.data + 8 * y_slot,
            )
            tables.watch_numbers[:] = (goal_x, goal_y, tolerance**2, 0.0, 0.0, np.inf)

            def on_block(first: int, end: int, histories, clean: bool) -> bool:
                checks[0] += end - first
                x, y = buffer[x_slot], buffer[y_slot]
                return math.hypot(x - goal_x, y - goal_y) <= tolerance

            master.run_blocks(1, tables, on_block)  # load the kernel outside the timing
            start = time.perf_counter()
            master.run_blocks(steps - 1, tables, on_block)
        else:

            def after_step(current: Master) -> bool:
                checks[0] += 1
                x, y = buffer[x_slot], buffer[y_slot]
                return math.hypot(x - goal_x, y - goal_y) <= tolerance

            master.run(1, after_step)
            start = time.perf_counter()
            master.run(steps - 1, after_step)
        seconds = time.perf_counter() - start
        x, y = buffer[x_slot], buffer[y_slot]
    engine = (
        "scenario loop, logging off: compiled kernel (after)"
        if kernel
        else "scenario loop, logging off: Python loop + callback (now)"
    )
    return Row("a", engine, steps - 1, seconds, f"final x, y = {x:.9f}, {y:.9f}")


def _naive_fmpy(vehicle_path: Path, controller_path: Path, steps: int, work: Path) -> Row:
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    slaves, references = [], []
    for path, name in ((vehicle_path, "vehicle"), (controller_path, "controller")):
        description = read_model_description(str(path))
        unzipped = extract(str(path), unzipdir=str(work / f"naive-{name}"))
        slave = FMU2Slave(
            guid=description.guid,
            unzipDirectory=unzipped,
            modelIdentifier=description.coSimulation.modelIdentifier,
            instanceName=name,
        )
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        references.append({v.name: v.valueReference for v in description.modelVariables})
        slaves.append(slave)
    vehicle, controller = slaves
    vehicle_vr, controller_vr = references
    controller.setReal([controller_vr["goal_x"], controller_vr["goal_y"]], list(GOAL))
    for slave in slaves:
        slave.enterInitializationMode()
        slave.exitInitializationMode()
    pose_out = [vehicle_vr[name] for name in STATE_OUTPUTS]
    pose_in = [controller_vr[name] for name in STATE_OUTPUTS]
    command_out = [controller_vr["v"], controller_vr["omega"]]
    command_in = [vehicle_vr["v"], vehicle_vr["omega"]]
    start = time.perf_counter()
    for k in range(steps):
        t = k * MACRO_STEP
        controller.setReal(pose_in, vehicle.getReal(pose_out))
        controller.doStep(t, MACRO_STEP)
        vehicle.setReal(command_in, controller.getReal(command_out))
        vehicle.doStep(t, MACRO_STEP)
    seconds = time.perf_counter() - start
    x, y, _ = vehicle.getReal(pose_out)
    for slave in slaves:
        slave.terminate()
        slave.freeInstance()
    return Row("a", "plain fmpy FMU2Slave loop (naive)", steps, seconds, f"final x, y = {x:.9f}, {y:.9f}")


def _ecospy(vehicle_path: Path, controller_path: Path, steps: int) -> Row | None:
    try:
        from ecospy import EcosSimulation, EcosSimulationStructure
    except ImportError:  # needs `pip install ecospy` and Debian's libtbb12
        return None
    structure = EcosSimulationStructure()
    structure.add_model("vehicle", str(vehicle_path))
    structure.add_model("controller", str(controller_path))
    for name in STATE_OUTPUTS:
        structure.make_real_connection(f"vehicle::{name}", f"controller::{name}")
    structure.make_real_connection("controller::v", "vehicle::v")
    structure.make_real_connection("controller::omega", "vehicle::omega")
    structure.add_parameter_set("goal", {"controller::goal_x": GOAL[0], "controller::goal_y": GOAL[1]})
    with EcosSimulation(structure=structure, step_size=MACRO_STEP) as simulation:
        simulation.init(parameter_set="goal")
        start = time.perf_counter()
        simulation.step(steps)
        seconds = time.perf_counter() - start
        x, y = simulation.get_real("vehicle::x"), simulation.get_real("vehicle::y")
        simulation.terminate()
    return Row("a", "ecospy step(n)", steps, seconds, f"final x, y = {x:.9f}, {y:.9f}")


def part_a(steps: int) -> list[Row]:
    """Two-FMU closed loop without logging (see the module docstring)."""
    with tempfile.TemporaryDirectory() as scratch:
        work = Path(scratch)
        vehicle_path, controller_path = _fmus(work)
        rows = [
            _naive_fmpy(vehicle_path, controller_path, min(steps, 100_000), work),
            _navcosim(vehicle_path, controller_path, min(steps, 100_000), compiled=False),
            _navcosim(vehicle_path, controller_path, steps, compiled=True),
            _scenario_loop(vehicle_path, controller_path, min(steps, 100_000), kernel=False),
            _scenario_loop(vehicle_path, controller_path, steps, kernel=True),
        ]
        ecospy = _ecospy(vehicle_path, controller_path, steps)
        rows += [ecospy] if ecospy else []
    return rows


def part_b(steps: int) -> list[Row]:
    """The same loop with every signal to MCAP (benchmarks/bench_scenarios.py)."""
    from benchmarks.bench_scenarios import part_b as logged_loop

    return logged_loop(steps)


def part_c(steps: int) -> list[Row]:
    """Each shipped scenario at full settings with full logging (benchmarks/bench_scenarios.py)."""
    from benchmarks.bench_scenarios import part_c as scenarios

    return scenarios(steps)


ROBOT_SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


def part_d(_steps: int = 0, repeat: int = 7) -> list[Row]:
    """The robot run's stepping loop and its floor (see the module docstring)."""
    import statistics

    from cosim.core import kernel
    from cosim.navigation import run
    from cosim.scenario.load import load_scenario
    from cosim.world.lidar import Lidar

    spent = {"floor": 0.0}
    timed: list[tuple[float, float, int]] = []  # (loop [s], floor [s], steps) per run

    def timing(function):
        def call(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                spent["floor"] += time.perf_counter() - start

        return call

    def loop(self) -> None:
        spent["floor"] = 0.0
        start = time.perf_counter()
        loop.original(self)
        timed.append((time.perf_counter() - start, spent["floor"], self.master.step_index))

    patched = [(kernel.Kernel, "__call__"), (Lidar, "scan"), (run._RobotRun, "loop")]
    originals = [getattr(owner, name) for owner, name in patched]
    loop.original = run._RobotRun.loop
    kernel.Kernel.__call__ = timing(kernel.Kernel.__call__)
    Lidar.scan = timing(Lidar.scan)
    run._RobotRun.loop = loop
    try:
        with tempfile.TemporaryDirectory() as scratch:
            for index in range(repeat + 1):  # the first run warms the caches, uncounted
                scenario = load_scenario(ROBOT_SCENARIO)
                run.run_scenario(scenario, Path(scratch) / f"run{index}.mcap", force=True, trace=False)
    finally:
        for (owner, name), original in zip(patched, originals, strict=True):
            setattr(owner, name, original)
    counted = timed[1:]
    seconds = statistics.median(loop for loop, _, _ in counted)
    floor = statistics.median(floor for _, floor, _ in counted)
    ratio = statistics.median(loop / floor for loop, floor, _ in counted)
    note = (
        f"median of {len(counted)}: loop {1e3 * seconds:.1f} ms, floor (C kernel + C lidar calls) "
        f"{1e3 * floor:.1f} ms, loop / floor {ratio:.2f}"
    )
    return [Row("d", f"robot run loop, {ROBOT_SCENARIO.stem}", counted[0][2], seconds, note)]


PARTS: dict[str, Callable[[int], list[Row]]] = {"a": part_a, "b": part_b, "c": part_c, "d": part_d}


def print_table(rows: list[Row]) -> None:
    reference = next((row.rate for row in rows if row.engine.startswith("ecospy")), None)
    print("| part | engine | steps | steps/s | vs ecospy | note |\n|---|---|---:|---:|---:|---|")
    for row in rows:
        ratio = f"{row.rate / reference:.2f}x" if reference and row.part == "a" else ""
        print(f"| {row.part} | {row.engine} | {row.steps} | {row.rate:,.0f} | {ratio} | {row.note} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default=",".join(PARTS), help="comma-separated parts to run")
    parser.add_argument("--steps", type=int, default=1_000_000, help="macro steps of part (a)")
    arguments = parser.parse_args()
    rows: list[Row] = []
    for part in arguments.parts.split(","):
        if part not in PARTS:
            parser.error(f"unknown part '{part}'; parts: {', '.join(PARTS)}")
        rows += PARTS[part](arguments.steps)
    print_table(rows)


if __name__ == "__main__":
    main()
