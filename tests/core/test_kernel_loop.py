"""The compiled kernel (`cosim.core.kernel`, `Master.run_blocks`) against the master's Python loop.

Truth: the Python loop (`Master.run` with a per-step callback), which the kernel must reproduce bit
for bit: the same outputs after every step, the same rows recorded, and for scenario runs the
same log bytes and outcome, including where a run stops (goal reached, collision, FMU failure,
interrupt) at the step the Python loop stops.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.core import interrupt
from cosim.core.master import Master
from cosim.navigation import run as run_module
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
SCENARIOS = REPO / "scenarios"


def _closed_loop(tmp_path):
    from benchmarks.bench_orchestrator import _fmus, _system

    return _system(*_fmus(tmp_path))


@pytest.mark.parametrize("mode", ["gauss-seidel", "jacobi"])
def test_kernel_steps_an_fmu_system_as_the_python_loop(tmp_path, mode):
    steps = 3000
    system, vehicle = _closed_loop(tmp_path)
    system.mode = mode
    expected = []
    with Master(system) as master:
        master.initialize()
        master.run(steps, lambda m: expected.append(vehicle.output_buffer.copy()) and False)
    system, vehicle = _closed_loop(tmp_path)
    system.mode = mode
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=128)
        assert tables is not None
        rows = []

        def on_block(first, end, histories, clean):
            index = [c.name for c in master.order].index("vehicle")
            history = histories[index]
            width = len(vehicle.inputs)
            rows.extend(history[:, width:].copy())
            assert len(history) == end - first and clean

        done = master.run_blocks(steps, tables, on_block, block=128)
        assert done == steps and master.step_index == steps
    assert np.array_equal(np.array(rows), np.array(expected))


def _scenario_file(tmp_path: Path, source: Path, extra: str = "") -> Path:
    text = source.read_text()
    map_file = (source.parent / "maps" / "warehouse.yaml").resolve()
    text = re.sub(r'(?m)^file = "maps/warehouse.yaml"', f'file = "{map_file}"', text) + extra
    path = tmp_path / source.name
    path.write_text(text)
    return path


def _both(tmp_path, monkeypatch, path: Path, overrides=()):
    """Run `path` through the Python loop and through the kernel; return both results and logs."""
    results = []
    for loop in ("python", "kernel"):
        monkeypatch.setenv("NAVCOSIM_LOOP", loop)
        scenario = load_scenario(path, list(overrides))
        out = tmp_path / f"{loop}.mcap"
        results.append((run_scenario(scenario, out), out.read_bytes()))
    (python, python_log), (kernel, kernel_log) = results
    assert kernel.outcome == python.outcome
    assert kernel.steps == python.steps
    assert kernel.failure == python.failure
    assert kernel_log == python_log
    return python


@pytest.mark.parametrize(
    "name, overrides, reason",
    [
        # VFH, lidar, a replan; stopped by the stop time.
        ("warehouse_diff_drive_one_obstacle", ["simulation.stop_time=8"], "stop_time"),
        # The FMI 3.0 builds: array variables set whole, C bool flags, Int32 and Boolean ports.
        (
            "warehouse_diff_drive_one_obstacle",
            ["simulation.stop_time=5", "simulation.fmi_version=3"],
            "stop_time",
        ),
        # The goal within reach: the run ends at the first step inside the tolerance.
        ("warehouse_diff_drive_no_obstacle", ["goal.x=16.0", "goal.y=6.0"], "goal_reached"),
        # A collision: a wide footprint starting next to the box, the kernel watching every step there.
        (
            "warehouse_diff_drive_one_obstacle",
            ["vehicle.radius=1.5", "start.x=52", "start.y=19.25", "simulation.stop_time=20"],
            "collision",
        ),
        # Moving obstacles: short blocks, the world at each block's time.
        ("warehouse_moving_crossing", ["simulation.stop_time=8"], None),
    ],
)
def test_scenario_runs_give_the_same_log_through_both_loops(tmp_path, monkeypatch, name, overrides, reason):
    result = _both(tmp_path, monkeypatch, SCENARIOS / f"{name}.toml", overrides)
    if reason is not None:
        assert result.outcome.reason == reason


def test_a_failing_fmu_stops_both_loops_at_the_same_step(tmp_path, monkeypatch):
    inputs = ", ".join(
        f'{port} = "u"' for port in ("v_in", "omega_in", "target_dir", "steering_dir", "goal_reached")
    )
    outputs = ", ".join(f'{port} = "y"' for port in ("v", "omega", "steering_angle", "mode"))
    extra = f"""
[mixer]
fmu = "{fixture_fmu("failing_fmi2")}"
fail_time = 3.0
fail_status = 3
ports = {{ {inputs}, {outputs} }}
"""
    path = _scenario_file(tmp_path, SCENARIOS / "warehouse_diff_drive_one_obstacle.toml", extra)
    result = _both(tmp_path, monkeypatch, path)
    assert result.outcome.reason == "fmu_failed" and "fmi2DoStep at t = 3 s" in result.failure


@pytest.mark.parametrize("stop_step", [101, 250, 255])
def test_an_interrupt_at_a_block_edge_stops_both_loops_at_that_step(tmp_path, monkeypatch, stop_step):
    """A signal noticed at step `stop_step` (a lidar step; the step after and a mid-period step,
    where the kernel's blocks do not end: a block goes on past the Python components' step unless
    that step has something to write): the Python loop stops there; the kernel at its next block
    edge, which is that step when the step is a block edge."""
    masters = []

    class Watched(Master):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            masters.append(self)

    monkeypatch.setattr(run_module, "Master", Watched)
    monkeypatch.setattr(interrupt, "take", lambda: "SIGINT" if masters[-1].step_index >= stop_step else None)
    # No signal comes, so none shows on the wakeup socket the kernel's sweeps look at: without
    # the socket they return before each sweep to ask `take` (a real signal's byte makes them
    # return there: tests/world/test_lidar_kernel_sweep.py, tests/core/test_interrupt_socket.py).
    monkeypatch.setattr(interrupt, "signal_socket", lambda: -1)
    path = SCENARIOS / "warehouse_diff_drive_one_obstacle.toml"
    if stop_step % 10 == 0:
        result = _both(tmp_path, monkeypatch, path)
        assert result.outcome.reason == "interrupted" and result.steps == stop_step
    else:
        monkeypatch.setenv("NAVCOSIM_LOOP", "kernel")
        result = run_scenario(load_scenario(path), tmp_path / "kernel.mcap")
        # The next block edge: the lidar step at a multiple of 10.
        assert result.outcome.reason == "interrupted" and result.steps == -(-stop_step // 10) * 10


def test_a_goal_given_during_the_run_ends_both_loops_at_the_same_step(tmp_path, monkeypatch):
    """The run's goal hook (the live view's /goal_pose) moves the goal at a planner step; the kernel
    watches the new goal from its next block, and the run ends where the Python loop ends it."""

    class Goals:
        def __init__(self):
            self.calls, self.reports = 0, []

        def take(self):
            self.calls += 1
            return (16.0, 6.0) if self.calls == 3 else None

        def report(self, text, warning=True):
            self.reports.append((warning, text))

    results = []
    for loop in ("python", "kernel"):
        monkeypatch.setenv("NAVCOSIM_LOOP", loop)
        scenario = load_scenario(SCENARIOS / "warehouse_diff_drive_one_obstacle.toml")
        goals = Goals()
        out = tmp_path / f"{loop}.mcap"
        results.append((run_scenario(scenario, out, goals=goals), out.read_bytes(), goals.reports))
    (python, python_log, python_reports), (kernel, kernel_log, kernel_reports) = results
    assert python_reports == kernel_reports and [w for w, _ in python_reports] == [False]
    assert python.outcome.reason == "goal_reached" and python.outcome.time < 20.0
    assert kernel.outcome == python.outcome and kernel.steps == python.steps
    assert kernel_log == python_log


def test_the_kernel_warms_up_without_a_system(tmp_path):
    """`cosim.core.kernel.warm_up` loads (building on a machine's first use) the kernel's library
    without a system; a run then steps through that same library."""
    from cosim.core import kernel

    kernel.warm_up()
    loaded = kernel._kernel()
    system, _ = _closed_loop(tmp_path)
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True)
        master.run_blocks(10, tables, lambda *block: False)
        assert master.step_index == 10
    assert kernel._kernel() is loaded


@pytest.mark.slow
def test_stepping_through_the_kernel_never_imports_numba():
    """The kernel is C loaded with ctypes: a process that steps an FMU system through every kernel
    path (`run`, `run_recorded`, `run_blocks`) has not imported numba (its import and set-up cost
    every run ~0.7 s)."""
    import subprocess

    script = f"""
import sys
from cosim.core.master import Master
from cosim.core.system import System
from cosim.fmi.component import FmuComponent
system = System(0.01)
system.add(FmuComponent({str(fixture_fmu("diffdrive_plain_fmi2"))!r}, "vehicle"))
with Master(system) as master:
    master.initialize()
    master.run(300, compiled=True)
    master.run_recorded(300, lambda *block: None, compiled=True)
    master.run_blocks(300, master.kernel_tables(record=True))
    assert master.step_index == 900
print("numba" in sys.modules)
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["False"]


def test_blocks_longer_than_the_recorded_rows_are_refused(tmp_path):
    """Tables that record hold the rows of `block` steps: a longer block would write past them."""
    from cosim.errors import CosimError

    system, _ = _closed_loop(tmp_path)
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=100)
        with pytest.raises(CosimError, match="block must be 1 to 100 steps, got 101"):
            master.run_blocks(500, tables, block=101)
        with pytest.raises(CosimError, match="block must be 1 to 100 steps, got 0"):
            master.run_blocks(500, tables, block=0)
        assert master.run_blocks(500, tables, block=100) == 500
