"""The compiled kernel's transfers: a plan's waypoints (2000 array inputs) reach Pure Pursuit as in
the master's Python loop (the truth: `Master.run(compiled=False)`, which sets every input before
each step), although the kernel copies runs of plain links at once, sends only the values that
changed since their last set (`set_changed` of kernel.c) and, with `scalar_rows`, keeps no array
elements in the rows; a value set by Python between two `run_blocks` calls is sent again."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from cosim.core import fast_loop
from cosim.core.component import PythonComponent, array_ports
from cosim.core.master import Master
from cosim.core.system import System
from cosim.fmi.builtin import builtin_fmu
from cosim.fmi.component import FmuComponent

H = 0.01  # [s] macro step
CAPACITY = 1000  # Pure Pursuit's waypoints
SWITCH = 0.55  # [s] the route gives its second path from then on


class Route(PythonComponent):
    """A plan that changes once: straight east, then (from SWITCH) north-east."""

    def __init__(self) -> None:
        super().__init__("route", [], array_ports("waypoints", CAPACITY, columns=2, unit="m"), period=0.1)

    def step(self, t: float, h: float) -> None:
        end = (20.0, 0.0) if t < SWITCH else (15.0, 15.0)
        path = np.linspace((0.0, 0.0), end, 30)
        self.output_buffer[:] = np.nan
        self.output_buffer[: path.size] = path.reshape(-1)


def _system():
    system = System(H)
    route = system.add(Route())
    pursuit = system.add(
        FmuComponent(builtin_fmu("PurePursuit"), "pursuit", {"lookahead_distance": 2.0}, period=5 * H)
    )
    state = ("x", "y", "theta")
    vehicle = system.add(
        FmuComponent(builtin_fmu("DifferentialDrive"), "vehicle", feedthrough_override={n: [] for n in state})
    )
    for name in state:
        system.connect(f"vehicle.{name}", f"pursuit.{name}")
    for port in route.outputs:
        system.connect(f"route.{port.name}", f"pursuit.{port.name}")
    system.connect("pursuit.v", "vehicle.v")
    system.connect("pursuit.omega", "vehicle.omega")
    return system, pursuit, vehicle


def _truth(steps: int, meddle_at: int | None = None, keep: bool = False) -> list[np.ndarray]:
    """The vehicle's outputs after each step, in the Python loop (`_meddle` at step `meddle_at`;
    `keep`: the route gives the wrong plan from then on, as if the FMU had kept it)."""
    system, pursuit, vehicle = _system()
    if keep:
        route = system.components["route"]

        def south(t: float, h: float) -> None:
            route.output_buffer[:] = np.nan
            route.output_buffer[: SOUTH.size] = SOUTH.reshape(-1)

    poses = []
    with Master(system) as master:
        master.initialize()
        first = steps if meddle_at is None else meddle_at
        master.run(first, lambda m: poses.append(vehicle.output_buffer.copy()), compiled=False)
        if meddle_at is not None:
            _meddle(pursuit)
            if keep:
                route.step = south
                south(0.0, 0.0)
            master.run(steps - first, lambda m: poses.append(vehicle.output_buffer.copy()), compiled=False)
    return poses


SOUTH = np.linspace((0.0, 0.0), (0.0, -20.0), 30)  # a wrong plan


def _meddle(pursuit) -> None:
    """Set a wrong plan (SOUTH) in the FMU behind the master's back, and leave the buffer as it was."""
    held = pursuit.input_buffer.copy()
    waypoints = {port.name: slot for slot, port in enumerate(pursuit.inputs)}
    for k, (x, y) in enumerate(SOUTH, start=1):
        pursuit.input_buffer[waypoints[f"waypoints[{k},1]"]] = x
        pursuit.input_buffer[waypoints[f"waypoints[{k},2]"]] = y
    pursuit.push_inputs()
    pursuit.input_buffer[:] = held


def _kernel(steps: int, meddle_at: int | None = None, block: int = 200):
    system, pursuit, vehicle = _system()
    poses, pursuit_rows = [], []
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=block, python_rows=True, scalar_rows=True)
        assert tables is not None
        names = [component.name for component in master.order]

        def on_block(first, end, histories, clean):
            poses.extend(histories[names.index("vehicle")][:, -len(vehicle.outputs) :].copy())
            pursuit_rows.extend(histories[names.index("pursuit")].copy())

        first = steps if meddle_at is None else meddle_at
        master.run_blocks(first, tables, on_block, block=block, cut_after_python=lambda k: False)
        if meddle_at is not None:
            _meddle(pursuit)
            master.run_blocks(steps - first, tables, on_block, block=block, cut_after_python=lambda k: False)
    return poses, np.array(pursuit_rows), pursuit, tables


def test_the_kernel_sends_a_plan_and_its_change_as_the_python_loop_does():
    steps = 150
    truth = _truth(steps)
    poses, rows, pursuit, tables = _kernel(steps)
    assert np.array_equal(np.array(poses), np.array(truth))
    # It turned when the plan changed (the test sees a plan change, not one plan throughout).
    assert truth[40][1] == 0.0 and truth[-1][1] > 0.01
    # The rows keep the scalar inputs (x, y, theta) and the outputs, not the 2000 waypoints.
    kept = tables.row_inputs[[c.name for c in tables._keep].index("pursuit")]
    assert kept == slice(0, 3)
    n_in = len(pursuit.inputs)
    before = [np.zeros(3)] + [pose[:3] for pose in truth]  # the pose before each step
    assert np.array_equal(rows[:, :3], np.array(before[:steps:5]))
    assert not rows[:, 3:n_in].any()


@pytest.mark.parametrize("block", [7, 200])
def test_a_value_set_between_run_blocks_calls_is_sent_again(block):
    steps, meddle_at = 150, 23
    truth = _truth(steps, meddle_at)
    poses, _, _, _ = _kernel(steps, meddle_at, block)
    assert np.array_equal(np.array(poses), np.array(truth))
    # The wrong plan, if the FMU kept it (not sent again), would change the run.
    assert not np.array_equal(np.array(truth), np.array(_truth(steps, meddle_at, keep=True)))


class _Ports(PythonComponent):
    def __init__(self, name, inputs=0, outputs=0):
        super().__init__(name, array_ports("u", inputs), array_ports("y", outputs), feedthrough={})

    def step(self, t, h):
        pass


def _plan(connections, producers=("p",)):
    """`fast_loop._link_plan` of consumer `c` (40 inputs) fed by `connections` (producer, output,
    input, scale) from producers of 40 outputs each."""
    system = System(0.1)
    for name in producers:
        system.add(_Ports(name, outputs=40))
    system.add(_Ports("c", inputs=40))
    for producer, output, input_, scale in connections:
        system.connect(f"{producer}.y[{output + 1}]", f"c.u[{input_ + 1}]", scale)
    entries, numbers, _ = fast_loop._link_plan(system, system.links(), "c", set())
    return list(entries), list(numbers)


def test_runs_of_plain_links_become_one_link():
    run = fast_loop.RUN_LINK
    six = [("p", j, j, 1.0) for j in range(6)] + [("q", 0, 6, 2.0), ("q", 5, 7, 1.0)]
    assert _plan(six, ("p", "q")) == (
        [("p", 0, 0, run), ("q", 0, 6, 1), ("q", 5, 7, 0)],
        [(6.0, 1.0), (2.0, 0.0), (1.0, 0.0)],
    )
    # Taken in the order of their targets: two columns of a row-major array (x, y interleaved)
    # to the x inputs, then the y inputs (as a plan reaches Pure Pursuit).
    interleaved = [("p", j, j // 2 + 10 * (j % 2), 1.0) for j in range(20)]
    assert _plan(interleaved) == ([("p", 0, 0, run), ("p", 1, 10, run)], [(10.0, 2.0)] * 2)
    # One column of a two-column array (sources two values apart) to consecutive targets.
    assert _plan([("p", 2 * j, j, 1.0) for j in range(5)]) == ([("p", 0, 0, run)], [(5.0, 2.0)])
    short = [("p", j, j, 1.0) for j in range(fast_loop.MIN_RUN - 1)]
    assert _plan(short) == ([("p", j, j, 0) for j in range(len(short))], [(1.0, 0.0)] * len(short))
    gap = [("p", 0, 0, 1.0), ("p", 1, 1, 1.0), ("p", 3, 2, 1.0), ("p", 4, 3, 1.0)]  # source skips one
    assert _plan(gap)[0] == [("p", j, t, 0) for _, j, t, _ in gap]
    # A stretch from two producers is no run, wherever their buffers lie.
    two = [("p", 0, 0, 1.0), ("p", 1, 1, 1.0), ("q", 2, 2, 1.0), ("q", 3, 3, 1.0)]
    assert _plan(two, ("p", "q"))[0] == [(name, j, t, 0) for name, j, t, _ in two]


def test_rows_keep_every_input_without_scalar_rows():
    """Without `scalar_rows` a row keeps every input, as `Master.run_recorded` promises."""
    system, _, _ = _system()
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=50, python_rows=True)
        kept = zip(tables.row_inputs, tables._keep, strict=True)
        assert all(inputs == slice(0, len(component.inputs)) for inputs, component in kept)


# fmi2SetReal(instance, value references, count, values)
_SET_REAL = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)


def _counted_sets(tables, index: int, counts: list[int]):
    """Route component `index`'s float64 setter group through a counter: each call's value count
    into `counts`, then the FMU's own fmi2SetReal. Returns the callback (keep it alive)."""
    from cosim.core import kernel as K

    row = tables.components[index]
    first = int(row[K.C_SET_FIRST])
    (group,) = [g for g in range(first, first + int(row[K.C_SET_COUNT])) if tables.groups[g, K.G_SENT] != 0]
    real = _SET_REAL(int(tables.groups[group, K.G_FUNCTION]))

    def counted(instance, references, count, values):
        counts.append(count)
        return real(instance, references, count, values)

    callback = _SET_REAL(counted)
    tables.groups[group, K.G_FUNCTION] = ctypes.cast(callback, ctypes.c_void_p).value
    return callback


@pytest.mark.parametrize("kept", [False, True])
def test_sent_values_kept_from_call_to_call_when_the_caller_holds_nothing_else_sets_them(kept):
    # A fleet's loop: one run_blocks call per block of 10 steps, nothing but the kernel setting the
    # FMUs' inputs between them. With `sent_kept` the plan's 2003 values are sent once (and the
    # values that change: the pose, the new plan), not again at each call; the run is the same.
    steps, block = 150, 10
    truth = _truth(steps)
    system, pursuit, vehicle = _system()
    poses, counts = [], []
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=block, python_rows=True, scalar_rows=True)
        tables.sent_kept = kept
        names = [component.name for component in master.order]
        callback = _counted_sets(tables, names.index("pursuit"), counts)

        def on_block(first, end, histories, clean):
            poses.extend(histories[names.index("vehicle")][:, -len(vehicle.outputs) :].copy())

        for _ in range(steps // block):
            master.run_blocks(block, tables, on_block, block=block, cut_after_python=lambda k: False)
        del callback
    assert np.array_equal(np.array(poses), np.array(truth))
    whole = len(pursuit.inputs)  # x, y, theta and 2000 waypoints
    full_sends = sum(count == whole for count in counts)
    assert full_sends == (1 if kept else steps // block)
    # Besides those: the pose at each of Pursuit's steps (every 5th), the new plan once.
    assert sum(count for count in counts if count != whole) <= 3 * steps // 5 + whole
