"""The master: integer time base, periods, Gauss-Seidel and Jacobi orderings as documented,
algebraic loops, connection errors, and the compiled loop against the Python loop."""

from fractions import Fraction

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.core.component import Port, PythonComponent
from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.component import FmuComponent


class Counter(PythonComponent):
    """State output `count` = number of completed steps (no feedthrough). Records step times."""

    def __init__(self, name, period=0.0):
        super().__init__(name, [], [Port("count")], period=period)
        self.times = []

    def step(self, t, h):
        self.times.append((t, h))
        self.output_buffer[0] += 1


class Echo(PythonComponent):
    """Direct feedthrough: `out` = the `seen` input at its last step; records what it saw."""

    def __init__(self, name, period=0.0):
        super().__init__(name, [Port("seen", start=-1.0)], [Port("out", start=-1.0)], period=period)
        self.history = []

    def on_initialize(self):
        self.output_buffer[0] = self.input_buffer[0]

    def step(self, t, h):
        self.history.append(self.input_buffer[0])
        self.output_buffer[0] = self.input_buffer[0]


def chain(order, mode, echo_period=0.0):
    """counter.count -> first.seen, first.out -> second.seen, components added in `order`."""
    system = System(0.01, mode)
    made = {"counter": Counter("counter"), "first": Echo("first", echo_period), "second": Echo("second")}
    for name in order:
        system.add(made[name])
    system.connect("counter.count", "first.seen")
    system.connect("first.out", "second.seen")
    return system, made


@pytest.mark.parametrize("added", [("counter", "first", "second"), ("second", "first", "counter")])
def test_gauss_seidel_ordering_matches_the_documentation(added):
    system, made = chain(added, "gauss-seidel")
    with Master(system) as master:
        order = [c.name for c in master.order]
        master.initialize()
        master.run(5)
    # Only first.out is direct, so first precedes second; counter is unconstrained and keeps its
    # place in the adding order.
    assert order.index("first") < order.index("second")
    counter_first = order.index("counter") < order.index("first")
    assert counter_first == (added[0] == "counter")
    for k in range(5):
        # The counter's output after its step at k is k + 1, before it k.
        expected_first = k + 1 if counter_first else k
        assert made["first"].history[k] == expected_first
        # second comes after first, so it sees first's output of the same step.
        assert made["second"].history[k] == expected_first


def test_jacobi_reads_only_values_from_before_the_step():
    system, made = chain(("counter", "first", "second"), "jacobi")
    with Master(system) as master:
        master.initialize()
        master.run(5)
    # first sees count before step k: k. second sees first.out before step k: first's output of
    # step k - 1 (k - 1), or first's initial output (count 0 at initialisation) at k = 0.
    assert made["first"].history == [0, 1, 2, 3, 4]
    assert made["second"].history == [0, 0, 1, 2, 3]


def test_periods_hold_outputs_between_steps():
    system, made = chain(("counter", "first", "second"), "gauss-seidel", echo_period=0.03)
    with Master(system) as master:
        master.initialize()
        master.run(7)
    # first steps at k = 0, 3, 6 (seeing count k + 1); second steps every k and sees the held value.
    assert made["first"].history == [1, 4, 7]
    assert made["second"].history == [1, 1, 1, 4, 4, 4, 7]
    assert len(made["counter"].times) == 7


def test_integer_time_base_two_million_steps_end_at_exactly_2000_s():
    system = System(0.001)
    slow = system.add(Counter("slow", period=0.5))
    with Master(system) as master:
        master.initialize()
        master.run(2_000_000)
        assert master.step_index == 2_000_000
        assert master.time_ns == 2_000_000_000_000
        assert master.time == 2000.0
    times = [t for t, _ in slow.times]
    assert len(times) == 4000
    assert times == [i / 2 for i in range(4000)]  # every step time exact
    assert all(h == 0.5 for _, h in slow.times)
    # What the integer base avoids: summing the float step drifts.
    total = 0.0
    for _ in range(2_000_000):
        total += 0.001
    assert total != 2000.0


def test_time_base_rejects_steps_and_periods_that_do_not_fit():
    with pytest.raises(CosimError, match="whole number of nanoseconds"):
        System(1e-10)
    with pytest.raises(CosimError, match="macro step must be > 0"):
        System(0.0)
    with pytest.raises(CosimError, match="mode 'seidel'"):
        System(0.01, "seidel")
    system = System(Fraction(1, 100))
    system.add(Counter("odd", period=0.015))
    with pytest.raises(
        CosimError, match="period 0.015 s of 'odd' is not a multiple of the macro step 0.01 s"
    ):
        Master(system)


def test_start_time_offsets_the_time_base():
    system = System(0.25)
    counter = system.add(Counter("counter"))
    with Master(system, start_time=10.0) as master:
        master.initialize()
        master.run(4)
        assert master.time == 11.0
    assert [t for t, _ in counter.times] == [10.0, 10.25, 10.5, 10.75]


def test_algebraic_loop_is_named_and_jacobi_accepts_it():
    for mode in ("gauss-seidel", "jacobi"):
        system = System(0.01, mode, loops="error")
        system.add(Echo("a"))
        system.add(Echo("b"))
        system.connect("a.out", "b.seen")
        system.connect("b.out", "a.seen")
        if mode == "jacobi":
            Master(system)
            continue
        with pytest.raises(
            CosimError, match=r"algebraic loop .*a\.out -> b\.seen -> b\.out -> a\.seen -> a\.out"
        ):
            Master(system)


class Plant(PythonComponent):
    """x' = u, explicit Euler; the output x is a state output (no feedthrough)."""

    def __init__(self, name):
        super().__init__(name, [Port("u")], [Port("x", start=1.0)], feedthrough={"x": []})

    def step(self, t, h):
        self.output_buffer[0] += h * self.input_buffer[0]


@pytest.mark.parametrize("added", [("plant", "controller"), ("controller", "plant")])
def test_state_output_breaks_a_feedback_loop(added):
    system = System(0.01)
    made = {"plant": Plant("plant"), "controller": Echo("controller")}
    for name in added:
        system.add(made[name])
    system.connect("plant.x", "controller.seen")
    system.connect("controller.out", "plant.u", scale=-1.0)
    with Master(system) as master:
        assert [c.name for c in master.order] == ["controller", "plant"]
        master.initialize()
        master.run(100)
        # Controller first: the plant steps with u = -x(t_k), explicit Euler on x' = -x.
        assert made["plant"].output_buffer[0] == pytest.approx(0.99**100, rel=1e-12)


def test_connection_errors_name_the_ports():
    system = System(0.01)
    system.add(Echo("a"))
    system.add(Echo("b"))
    with pytest.raises(CosimError, match="no output 'ot'; outputs: out"):
        system.connect("a.ot", "b.seen")
    with pytest.raises(CosimError, match="no component 'c'"):
        system.connect("c.out", "b.seen")
    with pytest.raises(CosimError, match="'component.port'"):
        system.connect("a", "b.seen")
    system.connect("a.out", "b.seen", scale=2.0)
    with pytest.raises(CosimError, match="already connected"):
        system.connect("b.out", "b.seen")
    with pytest.raises(CosimError, match="added twice"):
        system.add(Echo("a"))


def test_connection_scale_and_step_after_close():
    system = System(0.01)
    counter = system.add(Counter("counter"))
    echo = system.add(Echo("echo"))
    system.connect("counter.count", "echo.seen", scale=-0.5)
    master = Master(system)
    master.initialize()
    master.run(4)
    assert echo.history == [-0.5, -1.0, -1.5, -2.0]
    master.close()
    with pytest.raises(CosimError, match="not running"):
        master.step()
    assert counter.state.name == "FREED"


def _robot(kind, mode="gauss-seidel"):
    system = System(0.001, mode)
    vehicle = system.add(FmuComponent(fixture_fmu(kind), "vehicle", {"theta0": 0.3}))
    system.add(
        FmuComponent(
            fixture_fmu("controller_fmi2"), "controller", {"goal_x": 2.0, "goal_y": 1.0}, period=0.005
        )
    )
    for port in ("x", "y", "theta"):
        system.connect(f"vehicle.{port}", f"controller.{port}")
    system.connect("controller.v", "vehicle.v")
    system.connect("controller.omega", "vehicle.omega")
    return system, vehicle


@pytest.mark.parametrize("mode", ["gauss-seidel", "jacobi"])
def test_compiled_loop_is_bit_identical_to_the_python_loop(mode):
    results = []
    for compiled in (False, True):
        system, vehicle = _robot("diffdrive_plain_fmi2", mode)
        with Master(system) as master:
            master.initialize()
            master.run(3000, compiled=compiled)
            results.append(vehicle.output_buffer.copy())
            assert master.time == 3.0
    assert np.array_equal(results[0], results[1])
    assert np.hypot(results[0][0] - 2.0, results[0][1] - 1.0) < 0.5  # it drove towards the goal


def test_run_recorded_rows_are_each_components_values_after_its_steps():
    """Compiled and Python `run_recorded` hand over, per block, exactly the inputs and outputs a
    per-step observer sees after each of a component's steps (the controller every 5th step)."""
    observed = []
    system, _ = _robot("diffdrive_plain_fmi2")
    with Master(system) as master:
        master.initialize()

        def observe(current):
            k = current.step_index - 1
            for index, component in enumerate(current.order):
                if k % system.period_steps(component) == 0:
                    observed.append(
                        (index, k, np.concatenate((component.input_buffer, component.output_buffer)))
                    )

        master.run(1234, observe)
    for compiled in (False, True):
        system, _ = _robot("diffdrive_plain_fmi2")
        blocks = []
        with Master(system) as master:
            master.initialize()
            periods = [system.period_steps(c) for c in master.order]

            def keep(first, count, histories, periods=periods, blocks=blocks):
                assert count <= 500
                for index, (period, rows) in enumerate(zip(periods, histories, strict=True)):
                    steps = [k for k in range(first, first + count) if k % period == 0]
                    assert len(rows) == len(steps)
                    blocks.extend((index, k, row.copy()) for k, row in zip(steps, rows, strict=True))

            assert master.run_recorded(1234, keep, block=500, compiled=compiled) == 1234
            assert master.step_index == 1234
        blocks.sort(key=lambda entry: (entry[1], entry[0]))
        assert [(i, k) for i, k, _ in blocks] == [(i, k) for i, k, _ in observed]
        assert all(np.array_equal(a, b) for (_, _, a), (_, _, b) in zip(blocks, observed, strict=True))
