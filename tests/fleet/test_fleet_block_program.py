"""A fleet's Python components stepped in one C call a block (`_BlockProgram`, fleet.c's
`fleet_python_block`) against `_PythonSteps.step`'s Python path, which gathers, steps and feeds
each component in turn: the copies of its gathers against the connections applied link by link
(input = output * scale + offset, a plain copy a copy, bit for bit), and a small fleet run block by
block, one robot's lidar noisy (stepped by Python, handed back before its gather), the planners
handing their C step back to Python where a look-ahead or replan follows: after every block's
Python steps the same inputs and outputs of every component and the same planner states."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from fixtures.links import Box, linked_inputs

from cosim.core.system import System
from cosim.navigation import fleet as fleet_module
from cosim.navigation.planner import PlannerComponent
from cosim.scenario.load import load_scenario
from cosim.world import kernels
from cosim.world.lidar import Lidar

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


WIRINGS = {  # (producer, output, input)
    "scalar": [("a", 0, 2), ("a", 1, 0)],
    "interleaved_path": [("a", i, i) for i in range(3)]
    + [("a", 3 + 2 * k, 3 + k) for k in range(40)]
    + [("a", 4 + 2 * k, 43 + k) for k in range(40)],
    "reversed": [("a", i, 19 - i) for i in range(20)],
    "scattered": [("a", i, (7 * i) % 23) for i in range(23)],
    "two_producers": [("a", i, i) for i in range(10)] + [("b", 2 * i, 10 + i) for i in range(10)],
    "alternating_producers": [("a", i, 2 * i) for i in range(10)] + [("b", i, 2 * i + 1) for i in range(10)],
    "one_output_to_many": [("a", 5, i) for i in range(6)] + [("b", i, 6 + i) for i in range(4)],
}


@pytest.mark.parametrize("wiring", sorted(WIRINGS))
@pytest.mark.parametrize(
    "scale_offset",
    [(1.0, 0.0), (-0.5, 0.0), (1.0, 0.25), (2.0, 0.25)],
    ids=["copy", "scaled", "offset", "affine"],
)
def test_block_copies_are_the_connections_applied_one_by_one(wiring, scale_offset):
    triples = WIRINGS[wiring]
    sizes = {name: max(o for p, o, _ in triples if p == name) + 1 for name in {p for p, *_ in triples}}
    system = System(0.1)
    producers = {name: system.add(Box(name, outputs=size)) for name, size in sizes.items()}
    sink = system.add(Box("sink", inputs=max(i for *_, i in triples) + 3))  # two inputs unconnected
    scale, offset = scale_offset
    for number, (name, out, into) in enumerate(triples):
        # every third link plain: plain stretches broken by links with arithmetic
        plain = scale_offset != (1.0, 0.0) and number % 3 == 0
        system.connect(
            f"{name}.out[{out + 1}]", f"sink.in[{into + 1}]",
            scale=1.0 if plain else scale, offset=0.0 if plain else offset,
        )  # fmt: skip
    rng = np.random.default_rng(len(triples))
    for producer in producers.values():
        size = len(producer.output_buffer)
        producer.output_buffer[:] = rng.normal(size=size) * 10.0 ** rng.integers(-300, 300, size=size)
        producer.output_buffer[0] = -0.0
        producer.output_buffer[-1] = np.nan
    copies = fleet_module._block_copies(system, sink, system.links()["sink"])
    if scale_offset == (1.0, 0.0) and wiring in ("interleaved_path", "two_producers"):
        assert len(copies) < len(triples) // 5  # stretches copied at once
    program = fleet_module._BlockProgram(
        [kernels.BlockStepArrays(period=1, kind=kernels.BLOCK_COPIES, first_copy=0, copies=len(copies))],
        copies,
    )
    assert program.run(0, 0, 0.0) == 1
    assert sink.input_buffer.tobytes() == linked_inputs(system, sink).tobytes()


def test_no_block_copies_when_an_input_is_written_twice():
    system = System(0.1)
    system.add(Box("a", outputs=2))
    sink = system.add(Box("sink", inputs=1))
    system.connect("a.out[1]", "sink.in[1]")
    links = system.links()["sink"]
    assert fleet_module._block_copies(system, sink, links + links) is None


def _state(system) -> list[bytes]:
    """Every component's inputs and outputs, and each planner's step state and costmap marks, as bytes."""
    found = []
    for component in system.components.values():
        found += [component.input_buffer.tobytes(), component.output_buffer.tobytes()]
        if isinstance(component, PlannerComponent):
            state = component._state  # (its numbers: the addresses differ from run to run)
            numbers = [getattr(state, name) for name, kind in state._fields_ if kind is not ctypes.c_void_p]
            found.append(np.array(numbers, dtype=float).tobytes())
            found.append(component.costmap._marked.tobytes())
    return found


def _run_blocks(monkeypatch, tmp_path: Path, program: bool) -> tuple[list, dict]:
    """fleet_head_on, robot1's lidar noisy, for 8 s (the robots meet at ~7.4 s): the state after every
    block's Python steps, and how the components were stepped."""
    text = (SCENARIOS / "fleet_head_on.toml").read_text()
    text = text.replace('name = "robot1"\n', 'name = "robot1"\nlidar = { noise = 0.02, seed = 3 }\n', 1)
    text = text.replace('file = "maps/', f'file = "{SCENARIOS / "maps"}/')
    path = tmp_path / "fleet.toml"
    path.write_text(text)
    fleet = load_scenario(path, ["simulation.stop_time=8"], fleet=True)
    states, counts = [], {"python_lidar": 0, "handed": 0, "c_lidar": 0}
    step = fleet_module._PythonSteps.step

    def recorded(self, k):
        step(self, k)
        states.append((k, _state(self.master.system)))

    monkeypatch.setattr(fleet_module._PythonSteps, "step", recorded)
    if not program:
        monkeypatch.setattr(fleet_module._BlockProgram, "make", classmethod(lambda *_: None))
    lidar_step, planner_step = Lidar.step, PlannerComponent.step

    def counted_lidar(self, t, h):
        counts["python_lidar"] += 1
        lidar_step(self, t, h)

    def counted_planner(self, t, h):
        counts["handed"] += self._state.pending != 0
        planner_step(self, t, h)

    monkeypatch.setattr(Lidar, "step", counted_lidar)
    monkeypatch.setattr(PlannerComponent, "step", counted_planner)
    outcome = fleet_module.run_fleet(fleet)
    counts["time"] = outcome.time
    return states, counts


def test_the_c_block_steps_as_the_python_steps(monkeypatch, tmp_path):
    made = _made(monkeypatch)
    with monkeypatch.context() as patched:
        fast, fast_counts = _run_blocks(patched, tmp_path, program=True)
    slow, slow_counts = _run_blocks(monkeypatch, tmp_path, program=False)
    assert made and made[0] is not None
    kinds = [entry.kind for entry in made[0].steps]
    # robot1's noisy lidar stepped by Python, robot2's in C, both planners by their C step
    assert kinds.count(kernels.BLOCK_PYTHON) == 1 and kinds.count(kernels.BLOCK_LIDAR) == 1
    assert kinds.count(kernels.BLOCK_C_STEP) == 2 and kinds[-1] == kernels.BLOCK_COPIES
    blocks = len(slow)
    assert fast_counts["python_lidar"] == blocks and slow_counts["python_lidar"] == 2 * blocks
    assert fast_counts["handed"] > 0 and fast_counts["handed"] == slow_counts["handed"]  # hand-backs
    assert fast_counts["time"] == slow_counts["time"]
    assert len(fast) == blocks
    for (k, found), (k_slow, expected) in zip(fast, slow, strict=True):
        assert k == k_slow
        assert found == expected, f"block at step {k}"


def _threads(monkeypatch, threads: int) -> None:
    """Programs made from here on step on `threads` threads, already from two robots' chains."""
    monkeypatch.setattr(fleet_module._BlockProgram, "threads", threads)
    monkeypatch.setattr(fleet_module._BlockProgram, "MIN_CHAINS", 2)


def _made(monkeypatch) -> list:
    made = []
    make = fleet_module._BlockProgram.make.__func__

    def recorded(cls, *args):
        made.append(make(cls, *args))
        return made[-1]

    monkeypatch.setattr(fleet_module._BlockProgram, "make", classmethod(recorded))
    return made


def test_the_threaded_block_steps_as_the_one_thread_block(monkeypatch, tmp_path):
    """fleet_head_on, robot1's lidar stepped by Python (a component every chain waits for or
    follows), the planners handing back: the chains side by side on two threads leave the same
    bytes after every block as the one-thread call, and hand back the same components."""
    with monkeypatch.context() as patched:
        _threads(patched, 2)
        made = _made(patched)
        threaded, threaded_counts = _run_blocks(patched, tmp_path, program=True)
    with monkeypatch.context() as patched:
        _threads(patched, 1)
        single_made = _made(patched)
        single, single_counts = _run_blocks(patched, tmp_path, program=True)
    assert made[0].program is not None and single_made[0].program is None
    # robot2's lidar and planner, robot1's planner alone
    assert made[0]._firsts.tolist() == [0, 2, 3]
    assert threaded_counts == single_counts and threaded_counts["handed"] > 0
    assert len(threaded) == len(single)
    for (k, found), (k_single, expected) in zip(threaded, single, strict=True):
        assert k == k_single
        assert found == expected, f"block at step {k}"


@pytest.mark.slow  # a fleet run of several seconds
def test_ten_robots_on_three_threads_as_on_one(monkeypatch, tmp_path):
    """fleet_missions (ten robots, every lidar and planner in C) for 6 s on three threads, its
    chains taken by whichever thread is free: every component's inputs, outputs and planner state
    after each block are the one-thread call's."""
    text = (SCENARIOS / "fleet_missions.toml").read_text()
    text = text.replace('file = "maps/', f'file = "{SCENARIOS / "maps"}/')
    path = tmp_path / "fleet.toml"
    path.write_text(text)

    def run(threads: int) -> tuple[list, list]:
        states = []
        with monkeypatch.context() as patched:
            _threads(patched, threads)
            made = _made(patched)
            step = fleet_module._PythonSteps.step

            def recorded(self, k):
                step(self, k)
                states.append((k, _state(self.master.system)))

            patched.setattr(fleet_module._PythonSteps, "step", recorded)
            fleet_module.run_fleet(load_scenario(path, ["simulation.stop_time=6"], fleet=True))
        return states, made

    threaded, made = run(3)
    single, single_made = run(1)
    assert made[0].program is not None and len(made[0]._firsts) - 1 == 10
    assert single_made[0].program is None
    assert len(threaded) == len(single) > 0
    for (k, found), (k_single, expected) in zip(threaded, single, strict=True):
        assert k == k_single
        assert found == expected, f"block at step {k}"


def test_chains_join_the_components_reading_each_other():
    """A component joins the chain of each one stepped in C whose outputs it reads (before or after
    it in the order); a producer stepped by Python or an FMU (not in `chained`) joins nothing."""

    class Link:
        def __init__(self, producer):
            self.producer = producer

    chained = {"lidar1": 0, "lidar2": 1, "lidar3": 2, "planner1": 3, "planner2": 4, "planner3": 5}
    links = {
        "planner1": [Link("lidar1"), Link("vehicle1")],
        "planner2": [Link("lidar2"), Link("noisy")],
        "planner3": [Link("lidar3")],
        "lidar3": [Link("planner2")],  # (an output of the last step)
    }
    assert fleet_module._chains(chained, links) == [[0, 3], [1, 2, 4, 5]]
    assert fleet_module._chains(chained, {}) == [[i] for i in range(6)]
