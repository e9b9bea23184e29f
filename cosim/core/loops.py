"""Algebraic loops: finding them in a graph of ports (`find_algebraic_loop`, `cyclic_components`),
and their fixed-point iteration within a macro step (`[simulation] algebraic_loops = "iterate"`).

The graph's nodes are ports ("component.port"); its edges are the connections (output -> input)
and each component's direct dependencies (input -> the outputs that depend on it directly,
`Component.feedthrough`). A cycle in it is an algebraic loop. Both searches work on names alone,
so a system description is checked before any component exists.

A loop is a set of components whose ports form a cycle of direct dependencies (`System.loop_groups`:
the strongly connected sets of ports, joined where they share a component). The Gauss-Seidel
master steps a loop as one block at its place in the step order (after the producers that feed
it, before the consumers it feeds):

1. each member due at step k saves its state (`Component.save_state`: fmi2GetFMUstate /
   fmi3GetFMUState, which the FMU must declare with canGetAndSetFMUstate);
2. iteration n: the members step in order, each gathering its inputs as the Gauss-Seidel master
   does (from a member earlier in the loop, this iteration's outputs; from a later one, the
   previous iteration's, the outputs before the step in the first);
3. the loop's coupling values are compared: for every connection of the loop (both ends members
   due at k), the value the consumer stepped with, u, against what the producer's output now
   delivers, u' = output * scale + offset. The step is accepted when every one satisfies
   |u' - u| <= loop_tolerance * (1 + |u'|): a relative tolerance for values far from zero, an
   absolute one near it. Otherwise every member goes back to its saved state and steps again
   with u' (iteration n + 1), until `loop_max_iterations`; a loop that has not converged then
   is an error naming the loop, the time and the largest change.

The number of iterations of each macro step (the most any loop needed; 1 when the first step was
already consistent, 0 in a step where no loop member was due) is the output `loop_iterations` of a
component named `master` that the master adds to the system (`MasterSignals`), so the log has it
on `/signals/master` like any component's signals. Its record at t holds the iterations of the
macro step that ended at t; the one at the start time, the exchange passes initialisation needed
(the loop's connected values are exchanged until they agree to the same tolerance).

A system with such a loop steps in the Python master loop: the compiled kernel
(`cosim.core.native/kernel.c`) steps each component once per macro step and cannot roll back.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

from cosim.core.component import Component, Port, PythonComponent
from cosim.core.fast_loop import PlanEntry
from cosim.errors import CosimError

DEFAULT_TOLERANCE = 1e-8  # `[simulation] loop_tolerance`
DEFAULT_MAX_ITERATIONS = 50  # `[simulation] loop_max_iterations`
MASTER_SIGNALS = "master"  # the name of the component holding `loop_iterations`


class MasterSignals(PythonComponent):
    """The master's own signals as a component's outputs (`/signals/master`): `loop_iterations`,
    the fixed-point iterations of the macro step that ended at a record's time. The master sets
    it; stepping it (last in every step) takes the most over the loops."""

    def __init__(self, solvers: Sequence[LoopSolver]) -> None:
        super().__init__(MASTER_SIGNALS, outputs=[Port("loop_iterations", "integer")])
        self.solvers = list(solvers)

    def step(self, t: float, h: float) -> None:
        self.output_buffer[0] = max(solver.iterations for solver in self.solvers)


@dataclass(frozen=True)
class LoopLink:
    """A connection of a loop: producer output slot -> consumer input slot, as `gather` copies it."""

    name: str  # "producer.port -> consumer.port"
    producer: Component
    output: int
    consumer: Component
    input: int
    scale: float
    offset: float

    def change(self) -> float:
        """|u' - u| of this connection, relative as the module docstring says (NaN both: 0)."""
        new = self.producer.output_buffer[self.output]
        if self.scale != 1.0:
            new = new * self.scale
        if self.offset != 0.0:
            new = new + self.offset
        used = self.consumer.input_buffer[self.input]
        if new != new and used != used:  # both NaN: the same value
            return 0.0
        change = abs(new - used) / (1.0 + abs(new))
        return math.inf if change != change else float(change)


class LoopSolver:
    """Steps one algebraic loop (`members`: the master's plan entries of its components, in step
    order) by fixed-point iteration; see the module docstring. `step_seconds(k, period)` is the
    master's step size of a component due at step k."""

    def __init__(
        self,
        label: str,
        members: Sequence[PlanEntry],
        links: Sequence[LoopLink],
        tolerance: float,
        max_iterations: int,
        step_seconds: Callable[[int, int], float],
    ) -> None:
        self.label = label
        self.members = list(members)
        self.links = list(links)
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self.step_seconds = step_seconds
        self.iterations = 0  # of the last macro step

    def worst(self, links: Sequence[LoopLink]) -> tuple[float, LoopLink] | None:
        """The largest relative change above the tolerance and its connection; None: converged."""
        worst = None
        for link in links:
            change = link.change()
            if change > self.tolerance and (worst is None or change > worst[0]):
                worst = (change, link)
        return worst

    def step(self, k: int, t: float) -> None:
        """Macro step k, from t [s]: the members due at k iterate until their loop agrees."""
        due = [member for member in self.members if member.period == 1 or k % member.period == 0]
        if not due:
            self.iterations = 0
            return
        stepping = {id(member.component) for member in due}
        links = [
            link for link in self.links if id(link.producer) in stepping and id(link.consumer) in stepping
        ]
        if links:  # a member not due holds its outputs: the loop is open at it
            for member in due:
                member.component.save_state()
        # A text recording hears of the accepted step only (`cosim.record.text_signals`).
        members = [member.component for member in due]
        listening = [(c, c.text_listener) for c in members if getattr(c, "text_listener", None)]
        for component, _ in listening:
            component.text_listener = None
        iteration = 1
        try:
            while True:
                for component, period, gather in due:
                    if gather is not None:
                        gather()
                        component.push_inputs()
                    component.do_step(t, self.step_seconds(k, period))
                    component.get_outputs()
                worst = self.worst(links) if links else None
                if worst is None:
                    break
                if iteration >= self.max_iterations:
                    raise self.not_converged(worst, f"in the macro step from t = {t:.9g} s")
                for component in members:
                    component.restore_state()
                iteration += 1
        finally:
            for component, listener in listening:
                component.text_listener = listener
        for _, listener in listening:
            listener(t)
        self.iterations = iteration

    def not_converged(self, worst: tuple[float, LoopLink], when: str) -> CosimError:
        change, link = worst
        return CosimError(
            f"algebraic loop {self.label} did not converge {when} in {self.max_iterations} iterations: "
            f"{link.name} still changed by {change:.3g} (relative, simulation.loop_tolerance = "
            f"{self.tolerance:g}); raise simulation.loop_max_iterations or loop_tolerance, or use "
            'simulation.algebraic_loops = "delay"'
        )


def find_algebraic_loop(
    connections: Iterable[tuple[str, str]], feedthrough: Mapping[str, Mapping[str, Iterable[str]]]
) -> list[str] | None:
    """A cycle of direct dependencies, as the ports along it ("comp.port", first = last), or None.

    `connections` are (source output, target input) pairs; `feedthrough[component][output]` names
    the inputs that output depends on directly. Works on names alone, so a system description can
    be checked before any component exists (`cosim.scenario.compose.describe_system`). The answer
    for the last few graphs is remembered: a scenario's description is checked, then the system
    built from it (the same graph), and a sweep's worker builds the same system for every run.
    """
    pairs = tuple((source, target) for source, target in connections)
    dependencies = tuple(
        (component, tuple(zip(outputs.keys(), map(tuple, outputs.values()), strict=True)))
        for component, outputs in feedthrough.items()
    )
    key = (pairs, dependencies)
    loop = _LOOPS.get(key, _UNKNOWN)  # (one look-up: hashing and comparing the key is most of the cost)
    if loop is _UNKNOWN:
        if len(_LOOPS) >= _LOOPS_KEPT:
            _LOOPS.pop(next(iter(_LOOPS)))
        acyclic = _has_cycle(pairs, dependencies) is False
        found = None if acyclic else _search_algebraic_loop(pairs, dependencies)
        loop = _LOOPS[key] = None if found is None else tuple(found)
    return None if loop is None else list(loop)


# `find_algebraic_loop` of the last few graphs, keyed by the graph itself (the connection pairs and
# every component's feedthrough, in order: the order decides which loop is named).
_LOOPS: dict[tuple, tuple[str, ...] | None] = {}
_UNKNOWN = object()
_LOOPS_KEPT = 8


def _has_cycle(
    pairs: tuple[tuple[str, str], ...], dependencies: tuple[tuple[str, tuple], ...]
) -> bool | None:
    """Whether the graph of `_search_algebraic_loop` has a cycle, decided on a graph of groups;
    None when the ports do not allow it (then the search decides).

    A group is the outputs of one component that depend on one and the same tuple of inputs (an FMU's
    outputs without declared dependencies share the tuple of all its inputs): each of those inputs
    reaches each of those outputs. Group G reaches group H when a connection goes from an output of G
    to an input of H. When no port is both an output (a connection's source, a group's output) and an
    input (a connection's target, a group's input), every edge of the port graph goes from an output to
    an input or back, so a cycle of ports alternates connections and dependencies and gives a cycle of
    groups, and a cycle of groups gives one of ports: one exists exactly when the other does. With a
    2000-waypoint planner and a 720-beam lidar: ~6000 ports, 24 000 edges, 6 groups.
    """
    member_of: dict[str, int] = {}  # output -> its group
    inputs_of: list[tuple[str, tuple]] = []  # group -> (component, inputs)
    for component, outputs in dependencies:
        numbers: dict[int, int] = {}
        for output, depends in outputs:
            if not depends:
                continue
            number = numbers.get(id(depends))
            if number is None:
                number = numbers[id(depends)] = len(inputs_of)
                inputs_of.append((component, depends))
            member_of[f"{component}.{output}"] = number
    feeds: dict[str, list[int]] = {}  # input -> the groups it feeds
    for number, (component, depends) in enumerate(inputs_of):
        for name in depends:
            feeds.setdefault(f"{component}.{name}", []).append(number)
    sources = {source for source, _ in pairs}
    targets = {target for _, target in pairs}
    if not (sources | member_of.keys()).isdisjoint(targets | feeds.keys()):
        return None
    reaches: list[set[int]] = [set() for _ in inputs_of]
    for source, target in pairs:
        group = member_of.get(source)
        if group is not None and target in feeds:
            reaches[group].update(feeds[target])
    return has_cycle(reaches)


def has_cycle(successors: Sequence[Iterable[int]]) -> bool:
    """Whether the graph of nodes 0 .. n-1, `successors[node]` the nodes it reaches, has a cycle
    (an iterative depth-first search: linear in nodes and edges)."""
    colour = [0] * len(successors)  # 1 = on the current path, 2 = finished
    for start in range(len(successors)):
        if colour[start]:
            continue
        colour[start] = 1
        stack = [(start, iter(successors[start]))]
        while stack:
            node = next(stack[-1][1], None)
            if node is None:
                colour[stack.pop()[0]] = 2
            elif colour[node] == 1:
                return True
            elif not colour[node]:
                colour[node] = 1
                stack.append((node, iter(successors[node])))
    return False


def _search_algebraic_loop(
    pairs: tuple[tuple[str, str], ...], dependencies: tuple[tuple[str, tuple], ...]
) -> list[str] | None:
    """A depth-first search of the graph of ports for a cycle (`find_algebraic_loop`)."""
    graph: dict[str, list[str]] = {}
    for source, target in pairs:
        graph.setdefault(source, []).append(target)
    for component, outputs in dependencies:
        for output, depends in outputs:
            for name in depends:
                graph.setdefault(f"{component}.{name}", []).append(f"{component}.{output}")
    colour: dict[str, int] = {}  # 1 = on the current path, 2 = finished
    for start in list(graph):
        if colour.get(start):
            continue
        path = [start]
        iterators = [iter(graph.get(start, []))]
        colour[start] = 1
        while iterators:
            node = next(iterators[-1], None)
            if node is None:
                colour[path.pop()] = 2
                iterators.pop()
            elif colour.get(node) == 1:
                return path[path.index(node) :] + [node]
            elif not colour.get(node):
                colour[node] = 1
                path.append(node)
                iterators.append(iter(graph.get(node, [])))
    return None


def cyclic_components(graph: Mapping[str, list[str]]) -> dict[str, int]:
    """Node -> number of its strongly connected component, for nodes on a cycle (Tarjan's
    algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: dict[str, int] = {}
    counter = 0
    for root in list(graph):
        if root in index:
            continue
        work = [(root, iter(graph.get(root, ())))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            nxt = next(successors, None)
            if nxt is not None:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(graph.get(nxt, ()))))
                elif nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                members = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    members.append(member)
                    if member == node:
                        break
                if len(members) > 1 or node in graph.get(node, ()):
                    for member in members:
                        found[member] = index[node]
    return found
