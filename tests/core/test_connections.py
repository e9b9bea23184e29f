"""Connections deliver `output * scale + offset`, in the master's Python loop (scalar copies and
NumPy group copies) and in the compiled loop, bit for bit the same.

Truth: the arithmetic written out by hand here, and for the FMUs the closed form of two chained
integrators (the `failing_fmi2` fixture, y' = u, exact for a constant u per step).
"""

from __future__ import annotations

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.core.component import Port, PythonComponent
from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.component import FmuComponent


class Source(PythonComponent):
    """Outputs `out[i]` = values[i] * (k + 1) at its k-th step (values given)."""

    def __init__(self, name: str, values: list[float]):
        ports = [Port(f"out[{i + 1}]") for i in range(len(values))]
        super().__init__(name, outputs=ports, feedthrough={p.name: [] for p in ports})
        self.values = np.array(values)
        self.k = 0

    def step(self, t, h):
        self.k += 1
        self.output_buffer[:] = self.values * self.k


class Sink(PythonComponent):
    """Keeps a copy of its inputs at every step."""

    def __init__(self, name: str, count: int):
        super().__init__(name, inputs=[Port(f"in[{i + 1}]", start=-7.0) for i in range(count)])
        self.seen: list[np.ndarray] = []

    def step(self, t, h):
        self.seen.append(self.input_buffer.copy())


# (scale, offset) per link: plain copies, scaled only, affine; -0.0 shows that a plain copy is a copy.
LINKS = [(1.0, 0.0), (-0.5, 0.0), (2.0, 0.25), (1.0, -3.0), (0.1, 0.0), (1.0, 0.0), (3.0, 1e-3)]
VALUES = [-0.0, 1.5, -2.25, 0.3, 7.0, 1e300, -1e-300]


@pytest.mark.parametrize("count", [3, len(LINKS)], ids=["scalar_copies", "numpy_copies"])
def test_connection_delivers_output_times_scale_plus_offset(count):
    system = System(0.01)
    source = system.add(Source("source", VALUES[:count]))
    sink = system.add(Sink("sink", count))
    for i, (scale, offset) in enumerate(LINKS[:count]):
        connection = system.connect(f"source.out[{i + 1}]", f"sink.in[{i + 1}]", scale=scale, offset=offset)
        assert (connection.scale, connection.offset) == (scale, offset)
        assert connection.is_plain == (scale == 1.0 and offset == 0.0)
    with Master(system) as master:
        master.initialize()
        master.run(3)
    assert source.k == 3
    for k, seen in enumerate(sink.seen, start=1):
        expected = [VALUES[i] * k * scale + offset for i, (scale, offset) in enumerate(LINKS[:count])]
        # Plain copies leave the value alone, signed zero included.
        expected = [VALUES[i] * k if LINKS[i] == (1.0, 0.0) else value for i, value in enumerate(expected)]
        assert seen.tobytes() == np.array(expected).tobytes()


def test_offset_must_be_finite():
    system = System(0.01)
    system.add(Source("source", [1.0]))
    system.add(Sink("sink", 1))
    with pytest.raises(CosimError, match="scale and offset must be finite"):
        system.connect("source.out[1]", "sink.in[1]", offset=float("nan"))


def _integrators() -> tuple[System, FmuComponent, FmuComponent]:
    """first.y = integral of 1; second.u = first.y * SCALE + OFFSET; second.y = its integral."""
    system = System(0.001)
    first = system.add(FmuComponent(fixture_fmu("failing_fmi2"), "first"))
    second = system.add(FmuComponent(fixture_fmu("failing_fmi2"), "second"))
    system.connect("first.y", "second.u", scale=SCALE, offset=OFFSET)
    return system, first, second


SCALE, OFFSET = -0.75, 0.2
STEPS = 1000
PARAMETERS = {"first": {"fail_time": 10.0}, "second": {"fail_time": 10.0}}


def _run_integrators(compiled: bool) -> tuple[float, float, float]:
    system, first, second = _integrators()
    with Master(system, parameters=PARAMETERS) as master:
        assert [c.name for c in master.order] == ["first", "second"]  # y is a state: order as added
        master.initialize()
        assert master._kernel(record=False, block=1000) is not None  # the compiled kernel can step it
        master.run(STEPS, compiled=compiled)
        return first.output_buffer[0], second.input_buffer[0], second.output_buffer[0]


def test_fmu_connection_with_scale_and_offset_matches_the_closed_form():
    h = 0.001
    # second sees first.y after first's step k, (k + 1) h, so
    # second.y = sum_k h (SCALE (k + 1) h + OFFSET) = SCALE h^2 N (N + 1) / 2 + OFFSET h N.
    expected = SCALE * h * h * STEPS * (STEPS + 1) / 2 + OFFSET * h * STEPS
    python_loop = _run_integrators(compiled=False)
    first_y, second_u, second_y = python_loop
    assert first_y == pytest.approx(STEPS * h, rel=1e-12)
    assert second_u == first_y * SCALE + OFFSET
    assert second_y == pytest.approx(expected, rel=1e-11)
    assert _run_integrators(compiled=True) == python_loop  # the compiled loop, bit for bit
