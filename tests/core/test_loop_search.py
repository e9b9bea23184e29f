"""`find_algebraic_loop` decides that a graph has no loop on a graph of dependency groups
(`cosim.core.loops._has_cycle`); the truth here is the plain depth-first search over every port
(`_search_algebraic_loop`) on random systems, with shared dependency tuples as an FMU's ports have
them, and with port names that are both an input and an output (where the groups do not apply)."""

import random

from cosim.core.loops import _has_cycle, _search_algebraic_loop, find_algebraic_loop


def _random_system(rng: random.Random, collide: bool):
    components = [f"c{n}" for n in range(rng.randint(1, 5))]
    inputs = {c: [f"u{k}" for k in range(rng.randint(1, 6))] for c in components}
    outputs = {c: [f"y{k}" for k in range(rng.randint(1, 6))] for c in components}
    if collide:  # an input and an output of one name: one port node
        c = rng.choice(components)
        outputs[c].append(inputs[c][0])
    feedthrough = {}
    for c in components:
        shared = tuple(rng.sample(inputs[c], rng.randint(0, len(inputs[c]))))
        feedthrough[c] = {
            y: shared if rng.random() < 0.5 else tuple(rng.sample(inputs[c], min(len(inputs[c]), 2)))
            for y in outputs[c]
        }
    pairs = []
    for _ in range(rng.randint(0, 8)):
        a, b = rng.choice(components), rng.choice(components)
        pairs.append((f"{a}.{rng.choice(outputs[a])}", f"{b}.{rng.choice(inputs[b])}"))
    return pairs, feedthrough


def _dependencies(feedthrough):
    return tuple((c, tuple(outputs.items())) for c, outputs in feedthrough.items())


def test_the_group_graph_finds_a_cycle_exactly_when_the_port_search_does():
    rng = random.Random(23)
    decided = {True: 0, False: 0}
    for trial in range(3000):
        pairs, feedthrough = _random_system(rng, collide=trial % 4 == 0)
        dependencies = _dependencies(feedthrough)
        truth = _search_algebraic_loop(tuple(pairs), dependencies) is not None
        fast = _has_cycle(tuple(pairs), dependencies)
        if fast is not None:
            assert fast == truth, (pairs, feedthrough)
            decided[fast] += 1
        found = find_algebraic_loop(pairs, feedthrough)
        assert (found is not None) == truth
        if truth:
            assert found == _search_algebraic_loop(tuple(pairs), dependencies)  # the same loop named
    assert min(decided.values()) > 100  # both answers were exercised


def test_a_name_both_input_and_output_is_left_to_the_port_search():
    # c.x is an output depending on input c.x: a loop through one port, with no connection at all
    feedthrough = {"c": {"x": ("x",)}}
    assert _has_cycle((), _dependencies(feedthrough)) is None
    assert find_algebraic_loop([], feedthrough) == ["c.x", "c.x"]
