"""The compiled position checks (`world_check_positions` of cosim/world/native/world.c) against
their independent truth, Python itself: its `math.hypot` bit for bit on millions of pairs and the
special values, and `OutcomeMonitor`'s Python checks (`_check_in_python`) step for step on
random drives through a grid with unknown shapes: the same steps end the run for the same
reasons, and the distance, clearance, anchor and last position have the same bits."""

from __future__ import annotations

import ctypes
import math
import struct
import sys

import numpy as np
import pytest

from cosim.navigation.outcome import OutcomeMonitor
from cosim.world import kernels
from cosim.world.distance import WorldDistance
from cosim.world.shapes import Circle, Polygon, Rectangle
from planner.grid import OccupancyGrid

SMALLEST = 5e-324  # the smallest subnormal
TINY = sys.float_info.min  # 2^-1022, the smallest normal


def _bits(value: float) -> bytes:
    return struct.pack("<d", value)


def _compiled_hypot():
    return kernels.library().world_hypot


def test_hypot_matches_python_on_special_values():
    hypot = _compiled_hypot()
    specials = [
        0.0, -0.0, SMALLEST, -SMALLEST, 3 * SMALLEST, TINY, TINY / 3, TINY * (1 - 2**-52), 1e-300, 1e-160,
        0.5, 1.0, -1.0, 3.0, 4.0, 1e8, 1e154, 1e155, 1e300, sys.float_info.max, -sys.float_info.max,
        math.inf, -math.inf, math.nan, 2.0**-1074, 2.0**-537, 2.0**511, 2.0**512, 2.0**1023,
    ]  # fmt: skip
    for x in specials:
        for y in specials:
            expected, got = math.hypot(x, y), hypot(x, y)
            assert _bits(got) == _bits(expected) or (math.isnan(got) and math.isnan(expected)), (x, y)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_hypot_matches_python_bit_for_bit_on_a_million_random_pairs(seed):
    hypot = _compiled_hypot()
    rng = np.random.default_rng(seed)
    n = 1_000_000
    # Magnitudes from subnormal to huge, and pairs of like size (where the rounding is hardest).
    x = rng.normal(size=n) * 10.0 ** rng.integers(-310, 300, n)
    alike = x * rng.uniform(-2, 2, n)
    y = np.where(rng.random(n) < 0.5, alike, rng.normal(size=n) * 10.0 ** rng.integers(-310, 300, n))
    grid = rng.uniform(-100, 100, (2, n))  # the run's own scale: positions in a map
    differing = 0
    for a, b in zip([*x.tolist(), *grid[0].tolist()], [*y.tolist(), *grid[1].tolist()], strict=True):
        if _bits(hypot(a, b)) != _bits(math.hypot(a, b)):
            differing += 1
    assert differing == 0


def _world() -> WorldDistance:
    rng = np.random.default_rng(7)
    occupied = rng.random((60, 80)) < 0.04
    occupied[25:35, 30:50] = False  # a free room in the middle
    obstacles = (
        Circle((19.0, 14.5), 1.0),
        Rectangle((24.0, 15.0), (2.0, 1.0)),
        Polygon(((16.0, 13.0), (17.0, 12.0), (17.5, 13.5))),
    )
    return WorldDistance(OccupancyGrid(occupied, 0.5, (-2.0, -1.0)), obstacles)


def _drive(seed: int, steps: int):
    """A wandering drive from the room's middle: its times, xs, ys (Python floats)."""
    rng = np.random.default_rng(seed)
    heading = rng.uniform(0, 2 * math.pi, steps).cumsum() * 0.02
    xs = 18.0 + np.cumsum(0.03 * np.cos(heading))
    ys = 14.0 + np.cumsum(0.03 * np.sin(heading))
    times = (np.arange(1, steps + 1) * 10_000_000) / 1e9
    return times.tolist(), xs.tolist(), ys.tolist()


def _state(monitor: OutcomeMonitor):
    outcome = monitor.outcome
    numbers = (outcome.distance, outcome.min_clearance, outcome.time, *monitor.last_xy, *monitor._anchor)
    return [_bits(value) for value in numbers], outcome.reason, outcome.reached, outcome.collision_point


def _pair(goal, radius=0.4):
    compiled = OutcomeMonitor(_world(), goal, 0.5, radius, (18.0, 14.0))
    python = OutcomeMonitor(_world(), goal, 0.5, radius, (18.0, 14.0))
    python._compiled = None
    assert compiled._compiled is not None
    return compiled, python


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("block", [1, 10, 997])
def test_compiled_checks_give_the_python_checks_bits(seed, block):
    times, xs, ys = _drive(seed, 3000)
    goal = (xs[2500], ys[2500] + 0.3) if seed % 2 else (90.0, 90.0)
    compiled, python = _pair(goal)
    at, reasons = 0, []
    while at < len(times):
        window = slice(at, at + block)
        got = compiled.check_positions(np.array(times[window]), np.array(xs[window]), np.array(ys[window]))
        expected = python.check_positions(times[window], xs[window], ys[window])
        assert got == expected
        assert _state(compiled) == _state(python)
        reasons.append(got[1])
        if got[1] is not None:
            break
        at += block
    assert compiled.outcome.min_clearance < math.inf  # the exact distance was asked for


def test_a_drive_into_an_obstacle_off_the_map_and_not_finite():
    compiled, python = _pair((90.0, 90.0), radius=0.1)
    times = [0.01 * k for k in range(1, 400)]
    xs = [18.0 + 0.01 * k for k in range(1, 400)]  # along y = 14.5 into the circle at (19, 14.5)
    ys = [14.5] * len(xs)
    assert compiled.check_positions(times, xs, ys) == python.check_positions(times, xs, ys)
    assert compiled.outcome.reason == "collision" and _state(compiled) == _state(python)
    for points in ([(-5.0, 3.0)], [(100.0, 1.0)], [(20.0, math.nan)], [(math.inf, 2.0)]):
        compiled, python = _pair((90.0, 90.0))
        x, y = zip(*points, strict=True)
        assert compiled.check_positions([0.01], list(x), list(y)) == python.check_positions([0.01], x, y)
        assert repr(_state(compiled)) == repr(_state(python))


def test_a_cell_rounded_off_the_grid_is_left_to_python():
    """x just below the map's far edge may divide to the column count (here: origin 0.1, 0.7 m
    cells): Python indexes there and fails; the compiled checks hand that step to Python."""
    grid = OccupancyGrid(np.zeros((10, 10), dtype=bool), 0.7, (0.1, 0.0))
    world = WorldDistance(grid, (Circle((1.5, 1.5), 0.2),))
    x = math.nextafter(world.x_max, 0.0)
    assert int((x - world.x_min) / world.resolution) == world.cols  # the rounding this is about
    compiled = OutcomeMonitor(world, (90.0, 90.0), 0.5, 0.4, (1.0, 1.0))
    python = OutcomeMonitor(world, (90.0, 90.0), 0.5, 0.4, (1.0, 1.0))
    python._compiled = None
    for monitor in (compiled, python):
        with pytest.raises(IndexError):
            monitor.check_positions([0.01, 0.02], [1.5, x], [3.0, 3.0])


@pytest.mark.parametrize(
    ("struct", "mirror", "source"),
    [
        ("Monitor", kernels.MonitorArrays, kernels.SOURCE),
        ("Judge", kernels.JudgeArrays, kernels.FLEET_SOURCE),
    ],
)
def test_the_monitor_struct_mirrors_the_c_struct(struct, mirror, source):
    from native import load as native

    library = native.load(source)
    function = library.navcosim_layout
    function.restype = ctypes.c_int64
    function.argtypes = [ctypes.POINTER(ctypes.c_char_p), ctypes.POINTER(ctypes.c_int64), ctypes.c_int64]
    count = function(None, None, 0)
    names, values = (ctypes.c_char_p * count)(), (ctypes.c_int64 * count)()
    function(names, values, count)
    layout = {name.decode(): value for name, value in zip(names, values, strict=True)}
    assert layout[f"sizeof {struct}"] == ctypes.sizeof(mirror)
    fields = {key.split(".", 1)[1]: value for key, value in layout.items() if key.startswith(f"{struct}.")}
    assert fields == {name: getattr(mirror, name).offset for name, *_ in mirror._fields_}
