"""The graph work of a `System` done once per system and in linear time: whether it has an algebraic
loop (`System._acyclic`, a graph of dependency groups over port indices), the step order (`System.order`,
Kahn's algorithm with a heap), and the links, each remembered until the system changes.

Truths: the plain depth-first search over every named port (`cosim.core.loops._search_algebraic_loop`),
and Kahn's algorithm written out as the definition says it (scan for the first ready component, else
the first one left), on random systems."""

import random

import pytest

from cosim.core.component import Port, PythonComponent
from cosim.core.loops import _search_algebraic_loop
from cosim.core.system import System
from cosim.errors import CosimError


class _Node(PythonComponent):
    def __init__(self, name, inputs, outputs, feedthrough):
        super().__init__(name, [Port(n) for n in inputs], [Port(n) for n in outputs], feedthrough=feedthrough)

    def step(self, t, h):
        pass


def _random_system(rng: random.Random, collide: bool) -> System:
    system = System(0.01)
    names = [f"c{n}" for n in range(rng.randint(1, 6))]
    ports = {}
    for name in names:
        inputs = [f"u{k}" for k in range(rng.randint(1, 6))]
        outputs = [f"y{k}" for k in range(rng.randint(1, 6))]
        if collide and rng.random() < 0.5:  # an input and an output of one name: one node of names
            outputs.append(inputs[0])
        shared = rng.sample(inputs, rng.randint(0, len(inputs)))
        feedthrough = {}
        for output in outputs:
            draw = rng.random()
            if draw < 0.3:
                feedthrough[output] = shared  # one object for several outputs
            elif draw < 0.5:
                feedthrough[output] = list(shared)  # the same inputs, another object
            elif draw < 0.8:
                feedthrough[output] = rng.sample(inputs, rng.randint(0, min(2, len(inputs))))
            # else: not declared, it depends on every input
        system.add(_Node(name, inputs, outputs, feedthrough))
        ports[name] = (inputs, outputs)
    free = [(name, port) for name in names for port in ports[name][0]]
    rng.shuffle(free)
    for name, port in free[: rng.randint(0, len(free))]:
        source = rng.choice(names)
        system.connect(f"{source}.{rng.choice(ports[source][1])}", f"{name}.{port}")
    return system


def _port_search(system: System):
    pairs = tuple((c.source, c.target) for c in system.connections)
    dependencies = tuple(
        (name, tuple((output, tuple(depends)) for output, depends in c.feedthrough.items()))
        for name, c in system.components.items()
    )
    return _search_algebraic_loop(pairs, dependencies)


def test_the_system_finds_a_loop_exactly_when_the_search_over_named_ports_does():
    rng = random.Random(24)
    answers = {True: 0, False: 0}
    for trial in range(1500):
        system = _random_system(rng, collide=trial % 5 == 0)
        truth = _port_search(system)
        assert system._acyclic() == (truth is None)
        assert system.algebraic_loop() == truth  # and the same loop named
        assert (system._loop_ports() == {}) == (truth is None)
        answers[truth is None] += 1
    assert min(answers.values()) > 200  # both answers were exercised


def test_a_loop_made_after_asking_is_found():
    system = System(0.01)
    system.add(_Node("a", ["u"], ["y"], {"y": ["u"]}))
    system.add(_Node("b", ["u"], ["y"], {"y": ["u"]}))
    system.connect("a.y", "b.u")
    assert system.algebraic_loop() is None and system.order()[0].name == "a"
    assert set(system.links()) == {"b"}
    system.connect("b.y", "a.u")
    assert system.algebraic_loop() == ["a.y", "b.u", "b.y", "a.u", "a.y"]
    assert set(system.links()) == {"a", "b"}
    assert system.delayed_links() == {("a", "b"), ("b", "a")}


def _kahn_by_definition(edges, names):
    indegree = dict.fromkeys(names, 0)
    for _, consumer in edges:
        indegree[consumer] += 1
    order, remaining = [], list(names)
    while remaining:
        ready = next((n for n in remaining if indegree[n] == 0), remaining[0])
        remaining.remove(ready)
        order.append(ready)
        for producer, consumer in edges:
            if producer == ready and consumer in remaining:
                indegree[consumer] -= 1
    return order


def test_the_order_is_kahns_algorithm_taking_the_first_ready_component():
    rng = random.Random(7)
    for _ in range(2000):
        system = System(0.01)
        names = [f"c{n}" for n in range(rng.randint(1, 9))]
        for name in names:
            system.add(_Node(name, ["u"], ["y"], {}))
        edges = {(rng.choice(names), rng.choice(names)) for _ in range(rng.randint(0, 14))}
        edges = {(p, c) for p, c in edges if p != c}
        assert system._topological(edges) == _kahn_by_definition(edges, names)
        subset = rng.sample(names, rng.randint(1, len(names)))
        within = {(p, c) for p, c in edges if p in subset and c in subset}
        assert system._topological(within, subset) == _kahn_by_definition(within, subset)


def _robot() -> System:
    system = System(0.01)
    system.add(_Node("vehicle", ["v"], ["x", "y"], {"x": [], "y": []}))
    system.add(_Node("control", ["x", "y"], ["v"], {}))
    system.connect("vehicle.x", "control.x", scale=2.0)
    system.connect("vehicle.y", "control.y", offset=-1.0)
    system.connect("control.v", "vehicle.v")
    return system


def test_merging_systems_is_connecting_their_components_anew_under_the_new_names():
    merged, connected = System(0.01), System(0.01)
    for prefix in ("r1:", "r2:"):
        robot = _robot()
        merged.merge(robot, prefix)
        assert robot.connections == [] and set(robot.components) == {"vehicle", "control"}  # given up
        robot = _robot()
        for name, component in robot.components.items():
            component.name = prefix + name
            connected.add(component)
        for c in robot.connections:
            connected.connect(prefix + c.source, prefix + c.target, c.scale, c.offset)
    assert list(merged.components) == list(connected.components)
    assert all(merged.components[name].name == name for name in merged.components)
    assert merged.connections == connected.connections
    assert [c.name for c in merged.order()] == [c.name for c in connected.order()]
    with pytest.raises(CosimError, match="already connected"):
        merged.connect("r2:vehicle.x", "r1:control.x")
    with pytest.raises(CosimError, match="'r1:vehicle' added twice"):
        merged.merge(_robot(), "r1:")
    assert len(merged.components) == 4


class _Counter(PythonComponent):
    def __init__(self):
        super().__init__("c", [Port("n", "integer")], [Port("k", "integer")])

    def step(self, t, h):
        pass


def _typed_system() -> System:
    system = System(0.01)
    system.add(_Node("a", ["u"], ["y", "z"], {}))
    system.add(_Node("b", ["u", "v", "w"], ["y"], {}))
    system.add(_Counter())
    return system


def _outcome(make, wiring):
    system = _typed_system()
    try:
        make(system, wiring)
    except CosimError as error:
        return system.connections, str(error)
    return system.connections, None


def test_connecting_many_is_connecting_each_in_turn():
    wirings = [
        [("a.y", "b.u", 1.0, 0.0), ("a.z", "b.v", 2.0, -1.0), ("c.k", "b.w", 1.0, 0.0)],
        [("a.y", "b.u", 1.0, 0.0), ("a.z", "b.u", 1.0, 0.0)],  # already connected
        [("a.y", "b.x", 1.0, 0.0), ("a.y", "b.u", 1.0, 0.0)],  # no such input
        [("a.y", "c.n", 1.0, 0.0)],  # a float cannot feed an integer
        [("c.k", "a.u", 1.0, float("inf"))],  # not finite
        [("a.y", "b.u", 1.0, 0.0), ("nobody.y", "b.v", 1.0, 0.0)],
    ]
    for wiring in wirings:
        one_by_one = _outcome(lambda s, w: [s.connect(*c) for c in w], wiring)
        many = _outcome(lambda s, w: s.connect_many(iter(w)), wiring)
        assert many == one_by_one
    assert _outcome(lambda s, w: s.connect_many(w), wirings[0])[1] is None
    assert _outcome(lambda s, w: s.connect_many(w), wirings[3])[1].count("cannot convert") == 1
