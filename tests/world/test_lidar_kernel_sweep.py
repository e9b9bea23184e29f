"""The lidar stepped by the master's compiled kernel (`Lidar.kernel_sweep`, the kernel's sweep
kind) against the truth of the lidar stepped in Python (`Lidar.step`, the master's Python loop):
the same ranges after every scan, bit for bit, and the kernel leaves to Python the lidars whose
step needs it (noise drawn from NumPy's generator)."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.core import kernel
from cosim.core.component import Port, PythonComponent
from cosim.core.master import Master
from cosim.core.system import System
from cosim.fmi.builtin import builtin_fmu
from cosim.fmi.component import FmuComponent
from cosim.world.lidar import Lidar
from cosim.world.shapes import Circle, Rectangle

LIDAR_PERIOD = 5  # [macro steps]


class Drive(PythonComponent):
    """A speed and turn rate that take the robot on a curve (so every scan sees a new pose)."""

    def __init__(self) -> None:
        super().__init__("drive", [Port("x")], [Port("v", start=1.0), Port("omega", start=0.4)])

    def step(self, t: float, h: float) -> None:
        self.output_buffer[:] = (1.0, 0.4)


def _system(noise: float):
    occupied = np.zeros((40, 40), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    occupied[12:15, 20:30] = True
    system = System(0.01)
    vehicle = system.add(
        FmuComponent(builtin_fmu("DifferentialDrive"), "vehicle", {"x0": 8.0, "y0": 9.0, "theta0": 0.3})
    )
    lidar = system.add(
        Lidar(
            "lidar", occupied, 0.5, (0.0, 0.0), (Circle((14.0, 12.0), 1.0), Rectangle((6.0, 14.0), (1, 2))),
            count=90, range_max=12.0, range_noise=noise, period=LIDAR_PERIOD * 0.01,
        )
    )  # fmt: skip
    system.add(Drive())
    system.connect("vehicle.x", "drive.x")
    system.connect("drive.v", "vehicle.v")
    system.connect("drive.omega", "vehicle.omega")
    for name in ("x", "y", "theta"):
        system.connect(f"vehicle.{name}", f"lidar.{name}")
    return system, vehicle, lidar


def test_the_kernel_sweeps_a_noise_free_lidar_as_its_python_step_does():
    steps = 400
    system, vehicle, lidar = _system(0.0)
    expected = []
    with Master(system) as master:
        master.initialize()

        def after(m):
            if (m.step_index - 1) % LIDAR_PERIOD == 0:
                expected.append(np.concatenate((lidar.input_buffer, lidar.output_buffer)))

        master.run(steps, after, compiled=False)
    system, vehicle, lidar = _system(0.0)
    got = []
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=100)
        index = [component.name for component in master.order].index("lidar")
        assert tables.components[index, kernel.C_KIND] == kernel.KIND_SWEEP
        master.run_blocks(
            steps, tables, lambda first, end, histories, clean: got.extend(histories[index].copy()), block=100
        )
    assert len(got) == len(expected) == steps // LIDAR_PERIOD
    assert np.array_equal(np.array(got), np.array(expected), equal_nan=True)
    ranges = np.array(got)[:, 3:93]
    assert np.isfinite(ranges).any() and not np.array_equal(ranges[0], ranges[-1], equal_nan=True)


def test_a_noisy_lidar_is_stepped_by_python():
    system, _, _ = _system(0.01)
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=100)
        index = [component.name for component in master.order].index("lidar")
        assert tables.components[index, kernel.C_KIND] == kernel.KIND_PYTHON


@pytest.mark.parametrize("rows", [False, True])
def test_a_polled_sweep_returns_before_it_steps(rows):
    """With `python_rows` the kernel returns before each sweep (POLL), so a stretch can end there."""
    system, _, _ = _system(0.0)
    with Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=100, python_rows=rows)
        asked = []
        master.run_blocks(
            50,
            tables,
            block=100,
            end_before_python=lambda k: asked.append(k) or False,
            cut_after_python=lambda k: False,
        )
    if not rows:
        assert asked == []  # not asked: every Python step ends a stretch anyway
        return
    # Asked at each hand-back (the drive, every step) and, at the lidar's steps, before the sweep.
    assert asked == sorted(asked)
    # (Step 0 starts the first call: a sweep where a call starts is stepped without a return.)
    assert [asked.count(k) for k in range(1, 50)] == [2 if k % LIDAR_PERIOD == 0 else 1 for k in range(1, 50)]


def _asked(tables, master, steps: int) -> list[int]:
    asked = []
    master.run_blocks(
        steps,
        tables,
        block=100,
        end_before_python=lambda k: asked.append(k) or False,
        cut_after_python=lambda k: False,
    )
    return asked


def test_a_sweep_polled_on_signals_returns_when_a_signal_came_or_the_circle_is_half_used():
    """`KernelTables.poll_on_signals(fd)`: the polled sweep returns only when socket fd holds a
    byte (a signal came: `cosim.core.interrupt.signal_socket`) or the watched position has used
    half of its free circle (where the caller draws a new one); the steps are the same."""
    import ctypes
    import socket

    system, vehicle, _ = _system(0.0)
    reader, writer = socket.socketpair()
    reader.setblocking(False)
    with reader, writer, Master(system) as master:
        master.initialize()
        tables = master.kernel_tables(record=True, block=100, python_rows=True)
        tables.poll_on_signals(reader.fileno())
        # No byte, no watch: asked at the drive's hand-backs only (every step), not before sweeps.
        assert _asked(tables, master, 20) == list(range(20))
        writer.send(b"\x02")  # a signal came (the byte stays until Python takes it)
        asked = _asked(tables, master, 20)
        # (A sweep where a call starts, step 20's, is stepped without a return.)
        assert [asked.count(k) for k in range(20, 40)] == [
            2 if k % LIDAR_PERIOD == 0 and k > 20 else 1 for k in range(20, 40)
        ]
        reader.recv(1)
        assert _asked(tables, master, 10) == list(range(40, 50))
        # A watch whose free circle the robot has used half of (but not left): before each sweep.
        x, y = vehicle.output_buffer[0], vehicle.output_buffer[1]
        address = ctypes.addressof(vehicle.output_cbuffer)
        tables.watch_addresses[:] = (1, address, address + 8)
        tables.watch_numbers[:] = (1e9, 1e9, 0.0, x + 100.0, y, 1.5e4)  # 100 m from a 122 m circle's centre
        asked = _asked(tables, master, 10)
        assert [asked.count(k) for k in range(50, 60)] == [
            2 if k % LIDAR_PERIOD == 0 and k > 50 else 1 for k in range(50, 60)
        ]
        tables.watch_numbers[5] = 1e6  # a 1000 m circle: a tenth used
        assert _asked(tables, master, 10) == list(range(60, 70))
