"""Systems of one structure share the connections `System.connect_many` made and what the system
works out from them (links, acyclicity, the step and initialisation orders), kept per process by
everything they depend on (`cosim.core.system._graph_key`); a system that differs in anything they
read is not served from it.

Truth: the same system built with the shared graphs emptied (each connection made and checked, each
fact worked out again), and `System.connect` one connection at a time."""

import math

import pytest

import cosim.core.system as system_module
from cosim.core.component import Port, PythonComponent
from cosim.core.system import System
from cosim.errors import CosimError


class _Node(PythonComponent):
    def __init__(self, name, inputs, outputs, feedthrough=None, types=None):
        types = types or {}
        super().__init__(
            name,
            [Port(n, types.get(n, "real")) for n in inputs],
            [Port(n, types.get(n, "real")) for n in outputs],
            feedthrough=feedthrough,
        )

    def step(self, t, h):
        pass


CONNECTIONS = [
    ("plant.y", "control.e", 1.0, 0.0),
    ("control.u", "plant.u", -2.0, 0.5),
    ("plant.z", "sink.a", 1.0, 0.0),
    ("control.u", "sink.b", 1.0, 0.0),
]


def _system(types=None, feedthrough=None, connections=CONNECTIONS, loops="delay"):
    system = System(0.1, loops=loops)
    system.add(_Node("sink", ["a", "b"], ["s"], {"s": ["a"]}))
    system.add(_Node("control", ["e"], ["u"], feedthrough if feedthrough is not None else {"u": ["e"]}))
    system.add(_Node("plant", ["u"], ["y", "z"], {"y": [], "z": ["u"]}, types))
    system.connect_many(connections)
    return system


def _facts(system: System):
    order = system.initialization_order()
    links = {
        name: [(link.connection, link.producer, link.output, link.input) for link in fed]
        for name, fed in system.links().items()
    }
    return (
        [(c.source, c.target, c.scale, c.offset, math.copysign(1.0, c.scale)) for c in system.connections],
        links,
        system.algebraic_loop(),
        [c.name for c in system.order()],
        [c.name for c in order],
        [c.name for c in system.initialized_early(order)],
        system.delayed_links(),
    )


def _forget():
    """As in a fresh process: no graph kept, none pending."""
    system_module._GRAPHS.clear()
    system_module._PENDING.clear()


def _unshared(**given):
    _forget()
    facts = _facts(_system(**given))
    _forget()
    return facts


def test_a_second_system_of_the_same_structure_shares_the_graph_and_its_facts():
    truth = _unshared()
    first = _system()
    first_facts = _facts(first)
    second = _system()
    assert second._graph is first._graph and second.connections[0] is first.connections[0]
    assert _facts(second) == first_facts == truth
    # The orders are of this system's own components, not the first one's.
    assert all(c is second.components[c.name] for c in second.order())
    assert all(c is second.components[c.name] for c in second.initialization_order())


def test_connect_many_makes_what_connect_makes_one_by_one():
    _forget()
    one_by_one = _system(connections=[])
    for connection in CONNECTIONS:
        one_by_one.connect(*connection)
    _system()
    assert _facts(_system()) == _facts(one_by_one)


def _grown(system: System) -> System:
    system.add(_Node("late", ["q"], ["r"], {"r": ["q"]}))
    system.connect("sink.s", "late.q")
    return system


def test_a_system_changed_after_connecting_works_its_facts_out_again():
    _forget()
    truth = _facts(_grown(_system()))
    _forget()
    first = _system()
    _facts(first)  # the shared graph's facts worked out
    grown = _grown(_system())
    assert grown._graph is first._graph
    assert _facts(grown) == truth and "late" in grown.links()
    assert _facts(_system()) == _facts(first)  # the grown system left the shared facts as they were


@pytest.mark.parametrize(
    "change",
    [
        {"feedthrough": {"u": []}},  # the controller's output a state: another order
        {"connections": [*CONNECTIONS[:1], ("control.u", "plant.u", -2.0, -0.0), *CONNECTIONS[2:]]},
        {"connections": [*CONNECTIONS[:1], ("control.u", "plant.u", 2.0, 0.5), *CONNECTIONS[2:]]},
        {"loops": "iterate"},
    ],
)
def test_a_system_that_differs_is_not_served_the_shared_graph(change):
    _system()
    truth = _unshared(**change)
    _system()  # the unchanged one kept
    changed = _system(**change)
    assert _facts(changed) == truth
    scales = [math.copysign(1.0, c.offset) for c in changed.connections]
    expected = [math.copysign(1.0, c[3]) for c in change.get("connections", CONNECTIONS)]
    assert scales == expected


def test_a_port_type_that_refuses_the_connection_is_refused_again():
    _system()
    with pytest.raises(CosimError, match="only a Boolean feeds a Boolean"):
        _system(types={"u": "boolean"})
    with pytest.raises(CosimError, match="already connected"):
        _system(connections=[*CONNECTIONS, ("plant.y", "sink.a", 1.0, 0.0)])


def test_the_order_follows_a_change_of_loop_handling():
    _forget()
    truth = {}
    for loops in ("delay", "iterate"):
        alone = _system(feedthrough={"u": ["e"]}, loops=loops)
        truth[loops] = [c.name for c in alone.order()]
        _forget()
    system = _system()
    assert [c.name for c in system.order()] == truth["delay"]
    system.handle_loops("iterate")
    assert [c.name for c in system.order()] == truth["iterate"]


def test_the_first_graph_of_a_process_works_out_no_key_until_a_second_system_comes(monkeypatch):
    _forget()

    def refuse(*_args):
        raise AssertionError("a key worked out for the first graph")

    monkeypatch.setattr(system_module, "_graph_key", refuse)
    first = _system()
    assert first._graph is not None and not system_module._GRAPHS
    monkeypatch.undo()
    second = _system()
    assert second._graph is first._graph and len(system_module._GRAPHS) == 1


def test_port_types_in_the_key_compare_by_type_and_fmi_type():
    ports = [Port("a"), Port("b", "integer", fmi_type="Int32")]
    same = system_module._PortTypes(ports)
    assert same == system_module._PortTypes(ports)  # the same port objects
    assert same == system_module._PortTypes([Port("a"), Port("b", "integer", fmi_type="Int32")])
    assert same != system_module._PortTypes([Port("a"), Port("b", "integer", fmi_type="Int64")])
    assert same != system_module._PortTypes([Port("a"), Port("b", "boolean")])
    assert same != system_module._PortTypes(ports[:1])
