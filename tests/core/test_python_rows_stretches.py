"""`Master.run_blocks` with tables that give the Python components rows (`python_rows`): the
stretches go on through the Python components' steps, and every row, of the FMUs and of the
Python component, is what the master's Python loop (the truth: `Master.run` with a per-step
callback) holds after that step; `end_before_python` ends a stretch before a Python step."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from cosim.core.component import Port, PythonComponent
from cosim.core.master import Master

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
PERIOD = 7  # [macro steps] of the Python component


class SampleAndHold(PythonComponent):
    """Holds the vehicle's x between its steps (the controller sees the held x) and counts its
    steps: its outputs depend on when it stepped."""

    def __init__(self) -> None:
        super().__init__("hold", [Port("x")], [Port("x_held"), Port("count")], period=PERIOD * 0.001)

    def step(self, t: float, h: float) -> None:
        self.output_buffer[0] = self.input_buffer[0]
        self.output_buffer[1] += 1.0


def _build(tmp_path):
    from benchmarks.bench_orchestrator import _fmus
    from cosim.core.system import System
    from cosim.fmi.component import FmuComponent

    vehicle_path, controller_path = _fmus(tmp_path)
    system = System(0.001)
    state = ("x", "y", "theta")
    vehicle = system.add(FmuComponent(vehicle_path, "vehicle", feedthrough_override={n: [] for n in state}))
    system.add(FmuComponent(controller_path, "controller", {"goal_x": 5.0, "goal_y": 3.0}))
    hold = system.add(SampleAndHold())
    system.connect("vehicle.x", "hold.x")
    system.connect("hold.x_held", "controller.x")
    for name in ("y", "theta"):
        system.connect(f"vehicle.{name}", f"controller.{name}")
    system.connect("controller.v", "vehicle.v")
    system.connect("controller.omega", "vehicle.omega")
    return system, vehicle, hold


def _rows(component) -> np.ndarray:
    return np.concatenate((component.input_buffer, component.output_buffer))


def test_stretches_go_on_through_python_steps_with_the_python_loops_rows(tmp_path):
    steps = 2000
    system, vehicle, hold = _build(tmp_path)
    expected_vehicle, expected_hold = [], []
    with Master(system) as master:
        master.initialize()

        def after(m):
            k = m.step_index - 1
            expected_vehicle.append(_rows(vehicle))
            if k % PERIOD == 0:
                expected_hold.append(_rows(hold))

        master.run(steps, after, compiled=False)
    system, vehicle, hold = _build(tmp_path)
    got_vehicle, got_hold, stretches = [], [], []
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=200, python_rows=True)
        names = [component.name for component in master.order]

        def on_block(first, end, histories, clean):
            stretches.append((first, end))
            got_vehicle.extend(histories[names.index("vehicle")].copy())
            got_hold.extend(histories[names.index("hold")].copy())

        asked = []

        def end_before_python(k):
            asked.append(k)
            return k == 707  # a stretch ends before the Python step of step 707

        done = master.run_blocks(
            steps,
            tables,
            on_block,
            block=200,
            cut_after_python=lambda k: False,
            end_before_python=end_before_python,
        )
        assert done == steps
    assert np.array_equal(np.array(got_vehicle), np.array(expected_vehicle))
    assert np.array_equal(np.array(got_hold), np.array(expected_hold))
    lengths = [end - first for first, end in stretches]
    assert max(lengths) == 200 and sum(lengths) == steps  # through many Python steps, none longer
    assert any(end == 707 for _, end in stretches)
    assert 707 in asked and all(k % PERIOD == 0 for k in asked)


def test_without_python_rows_a_stretch_ends_before_every_python_step(tmp_path):
    system, vehicle, hold = _build(tmp_path)
    stretches = []
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=200)
        master.run_blocks(
            300,
            tables,
            lambda first, end, h, clean: stretches.append((first, end)),
            200,
            None,
            lambda k: False,
        )
    assert all(end - first <= PERIOD for first, end in stretches)
