"""The kernel's link table (`KernelTables.link_addresses`, `link_numbers`, each row's first link
and count), made from the links by port indices worked out once per graph (`fast_loop._link_plan`),
is the table made from the buffers' addresses link by link, runs found on the addresses.

Truth: that address-based construction, written out here as the kernel tables made it before."""

from __future__ import annotations

import ctypes
import random
from pathlib import Path

import numpy as np
import pytest

from cosim.core import kernel as K
from cosim.core.component import Port, PythonComponent
from cosim.core.fast_loop import MIN_RUN, RUN_LINK, KernelTables, PlanEntry
from cosim.core.system import System

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


def _address_runs(links: list, numbers: list) -> tuple[list, list]:
    """Runs of plain links on the addresses (source address, target address, kind)."""
    order = sorted(range(len(links)), key=lambda j: links[j][1])
    links, numbers = [links[j] for j in order], [numbers[j] for j in order]
    out_links, out_numbers = [], []
    j = 0
    while j < len(links):
        source, target, kind = links[j]
        end = j + 1
        stride = links[j + 1][0] - source if j + 1 < len(links) else 0
        if kind == 0 and stride > 0 and stride % 8 == 0:
            while (
                end < len(links)
                and links[end][2] == 0
                and links[end][0] == source + stride * (end - j)
                and links[end][1] == target + 8 * (end - j)
            ):
                end += 1
        if end - j >= MIN_RUN:
            out_links.append((source, target, RUN_LINK))
            out_numbers.append((float(end - j), float(stride // 8)))
        else:
            out_links += links[j:end]
            out_numbers += numbers[j:end]
        j = end
    return out_links, out_numbers


def _address_table(plan: list[PlanEntry], system: System, skip: set[str]):
    links, numbers, rows = [], [], []
    fed = system.links()
    for entry in plan:
        component = entry.component
        first = len(links)
        if component.name not in skip:
            made, made_numbers = [], []
            for connection, producer_name, source, target in fed.get(component.name, ()):
                if producer_name in skip:
                    continue
                producer = system.components[producer_name]
                kind = 0 if connection.is_plain else (1 if connection.offset == 0.0 else 2)
                made.append(
                    (
                        ctypes.addressof(producer.output_cbuffer) + 8 * source,
                        ctypes.addressof(component.input_cbuffer) + 8 * target,
                        kind,
                    )
                )
                made_numbers.append((connection.scale, connection.offset))
            made, made_numbers = _address_runs(made, made_numbers)
            links += made
            numbers += made_numbers
        rows.append((first, len(links) - first) if component.name not in skip else None)
    return (
        np.array(links, dtype=np.int64).reshape(-1, 3),
        np.array(numbers, dtype=np.float64).reshape(-1, 2),
        rows,
    )


def _assert_same_table(tables: KernelTables, plan, system, skip) -> None:
    addresses, numbers, rows = _address_table(plan, system, skip)
    assert np.array_equal(tables.link_addresses, addresses)
    assert np.array_equal(tables.link_numbers, numbers)
    for row, expected in zip(tables.components, rows, strict=True):
        if expected is not None:
            assert (row[K.C_LINK_FIRST], row[K.C_LINK_COUNT]) == expected


class _Node(PythonComponent):
    def __init__(self, name, inputs, outputs):
        super().__init__(name, [Port(n) for n in inputs], [Port(n) for n in outputs], feedthrough={})

    def step(self, t, h):
        pass


def _random_system(rng: random.Random) -> tuple[System, set[str]]:
    system = System(0.1)
    names = [f"c{n}" for n in range(rng.randint(2, 5))]
    sizes = {name: (rng.randint(1, 40), rng.randint(1, 40)) for name in names}
    for name in names:
        inputs, outputs = sizes[name]
        system.add(_Node(name, [f"u[{k}]" for k in range(inputs)], [f"y[{k}]" for k in range(outputs)]))
    connections = []
    for name in names:
        inputs = list(range(sizes[name][0]))
        rng.shuffle(inputs)
        for slot in inputs[: rng.randint(0, len(inputs))]:
            producer = rng.choice(names)
            outputs = sizes[producer][1]
            # Often a stretch: the output that follows the slot's (a column, an array).
            output = (slot * rng.choice((1, 1, 2, 3)) + rng.randint(0, 1)) % outputs
            scale, offset = rng.choice([(1.0, 0.0)] * 6 + [(2.0, 0.0), (1.0, 0.5), (-1.0, -0.0)])
            connections.append((f"{producer}.y[{output}]", f"{name}.u[{slot}]", scale, offset))
    rng.shuffle(connections)
    system.connect_many(connections)
    skip = {name for name in names if rng.random() < 0.2}
    return system, skip


def test_random_systems_get_the_address_built_table():
    rng = random.Random(7)
    for _ in range(200):
        system, skip = _random_system(rng)
        plan = [PlanEntry(component, 1, None) for component in system.components.values()]
        tables = KernelTables(plan, system, skip, record=False, block=1)
        _assert_same_table(tables, plan, system, skip)


def test_a_scenario_run_gets_the_address_built_table_every_time():
    from cosim.core.master import Master
    from cosim.navigation.build import build_run
    from cosim.scenario.load import load_scenario

    for seed in (0, 1, 2):  # the second and third share the first one's graph and link plans
        scenario = load_scenario(SCENARIO, [f"lidar.seed={seed}", "simulation.stop_time=1"])
        built = build_run(scenario)
        master = Master(built.system, parameters=built.parameters, stop_time=scenario.stop_time)
        master.initialize()
        try:
            tables = master.kernel_tables(record=True, python_rows=True, scalar_rows=True)
            skip = {entry.component.name for entry in master._plan if entry.component.constant_outputs}
            _assert_same_table(tables, master._plan, built.system, skip)
            assert (tables.link_numbers[:, 0] > 100).any()  # the waypoints and scans went as runs
        finally:
            master.close()


def _tables(rows: int = 200_000) -> KernelTables:
    """Tables of two Python components whose record buffer is `rows` values and more (> 1 MiB)."""
    system = System(0.1)
    system.add(_Node("a", [], [f"y[{k}]" for k in range(rows // 1000)]))
    system.add(_Node("b", [f"u[{k}]" for k in range(rows // 1000)], []))
    system.connect_many([(f"a.y[{k}]", f"b.u[{k}]", 1.0, 0.0) for k in range(rows // 1000)])
    plan = [PlanEntry(component, 1, None) for component in system.components.values()]
    return KernelTables(plan, system, set(), record=True, block=1000, python_rows=True)


def test_a_released_record_buffer_serves_the_next_tables_zeroed_and_only_when_unheld():
    from cosim.core import fast_loop

    fast_loop._SPARE.clear()
    first = _tables()
    first.history[:] = 7.0  # what a run left in it
    buffer = first.history
    first.release()
    with pytest.raises(RuntimeError, match="after `release`"):
        first.warm_up()
    assert not fast_loop._SPARE  # `buffer` here still holds it: not kept
    del buffer
    held = _tables()
    view = held.history[10:20]
    held.release()
    assert not fast_loop._SPARE  # a view of it is left: not kept
    del view
    released = _tables()
    size = released.history.size
    released.release()
    assert set(fast_loop._SPARE) == {size}
    reused = _tables()
    assert reused._mapped and reused.history.size == size and not reused.history.any()
    assert not fast_loop._SPARE
    reused.warm_up()
    assert not reused.history.any()
