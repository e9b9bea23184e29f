"""A co-simulation system: components, the connections between their ports, the macro step and
the order in which a master steps and initialises them.

Connections
-----------
`System.connect("pure_pursuit.v", "mixer.v_in", scale, offset)` copies `source output * scale +
offset` into the target input before the target steps (a unit conversion, a sign flip, a bias).
An input takes at most one connection; unconnected inputs keep their start values (or what the user
set with `Component.set_inputs`, which sends them).

Ordering (which values a component sees at step k)
--------------------------------------------------
An output `P.o` is *direct* when it depends directly on at least one of P's inputs (its entry in
`P.feedthrough` is non-empty); otherwise it is a *state* output, fixed by P's past alone.

* **Gauss-Seidel** (default). The components are stepped one after the other in an order that is
  a topological order of the *direct* connections (P before C for every connection P.o -> C.i
  with P.o direct); components that this leaves unordered keep the order in which they were
  added to the system. Connections from state outputs put no constraint on the order; they break
  feedback cycles. At step k a due component C first gathers its inputs: from a producer P
  earlier in the order, C sees P's outputs after P's most recent step (that is P's step at k if
  P was due at k); from a producer later in the order, C sees P's outputs as they were before
  step k (P's step at k has not run yet). Then C steps and its outputs are read.
  A cycle of direct connections through direct outputs (P.o direct on P.i, P.i fed by a direct
  output ... back to P.o) is an algebraic loop. With `System(..., loops="delay")` (the default,
  `[simulation] algebraic_loops`) the connections on it (`System.delayed_links`: both ends among
  the strongly connected ports) carry the producer's outputs as they were before step k, as in
  Jacobi mode, so the loop's components step with their inputs from the previous communication
  point; every other connection keeps the Gauss-Seidel rule. Such a system steps in the Python
  loop (the compiled kernel is not used), and `Master` says so once on stderr. With
  `loops="iterate"` each loop (`System.loop_groups`) steps as one block at its place in the order
  (the graph of components with each loop contracted to one node, sorted as above) and iterates
  to a fixed point within the macro step, rolling its members back with their FMU state
  (`cosim.core.loops`; also the Python loop, also said once). With `loops="error"`
  `System.order()` raises `CosimError` naming the loop and the keys that run it.
* **Jacobi**. Every due component gathers its inputs first, all from the outputs as they were
  before step k (after each producer's most recent step before k); then all due components
  step. The order only fixes the sequence of calls. A loop of direct outputs is allowed (the
  one-step delay breaks it).

"""

from __future__ import annotations

import heapq
import itertools
import math
import operator
from array import array
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from operator import attrgetter, itemgetter
from typing import TYPE_CHECKING, NamedTuple

from cosim.core.component import Component, Port, closest_names
from cosim.core.loops import (
    DEFAULT_MAX_ITERATIONS,
    DEFAULT_TOLERANCE,
    cyclic_components,
    find_algebraic_loop,
    has_cycle,
)
from cosim.core.port_types import connection_problem
from cosim.core.timebase import NS_PER_S, seconds_to_ns
from cosim.errors import CosimError

if TYPE_CHECKING:
    from fractions import Fraction

MODES = ("gauss-seidel", "jacobi")
LOOP_HANDLING = ("delay", "iterate", "error")  # `[simulation] algebraic_loops` (`System.loops`)


@dataclass(frozen=True, init=False)
class Connection:
    """`source` output -> `target` input; the input receives `output * scale + offset`."""

    source: str  # "component.port"
    target: str
    scale: float = 1.0
    offset: float = 0.0  # [unit of the target input]

    def __init__(self, source: str, target: str, scale: float = 1.0, offset: float = 0.0) -> None:
        # Written out (not generated): a system of a 2000-waypoint path makes ~3,100 connections, and
        # a frozen dataclass's generated __init__ sets each field through object.__setattr__.
        self.__dict__.update(source=source, target=target, scale=scale, offset=offset)

    @property
    def is_plain(self) -> bool:
        """True when the value is copied unchanged (scale 1, offset 0)."""
        return self.scale == 1.0 and self.offset == 0.0

    @property
    def source_component(self) -> str:
        return self.source.split(".", 1)[0]

    @property
    def target_component(self) -> str:
        return self.target.split(".", 1)[0]


def _typed(port: Port) -> str:
    """A port's type as a connection message names it."""
    return port.fmi_type or port.type


class Link(NamedTuple):
    """A connection into a component, its ends resolved (`System.links`)."""

    connection: Connection
    producer: str  # the producing component's name
    output: int  # index of the producer's output
    input: int  # index of the consumer's input


class LoopGroup(NamedTuple):
    """An algebraic loop (`System.loop_groups`): its member components, in the order they were added,
    and the connections on the loop."""

    members: list[str]
    connections: list[Connection]


class System:
    """Components, connections, the macro step [s] and the master algorithm (`mode`); how an
    algebraic loop runs (`loops`, and for "iterate" `loop_tolerance`, relative, and
    `loop_max_iterations`: `cosim.core.loops`)."""

    def __init__(
        self,
        macro_step: float | Fraction,
        mode: str = "gauss-seidel",
        loops: str = "delay",
        loop_tolerance: float = DEFAULT_TOLERANCE,
        loop_max_iterations: int = DEFAULT_MAX_ITERATIONS,
    ) -> None:
        self.macro_step_ns = seconds_to_ns(macro_step, "macro step")
        if self.macro_step_ns <= 0:
            raise CosimError(f"macro step must be > 0 s, got {macro_step}")
        if mode not in MODES:
            raise CosimError(f"master mode '{mode}' is not one of {', '.join(MODES)}")
        self.mode = mode
        self.handle_loops(loops, loop_tolerance, loop_max_iterations)
        self.components: dict[str, Component] = {}
        self.connections: list[Connection] = []
        self.text_connections: list[Connection] = []  # String/Binary ones (`System._connect_text`)
        self._targets: set[str] = set()  # connected inputs: a set, so connecting N inputs is O(N)
        # What the system computes once for its graph as it is (`_cached`): the resolved links, whether
        # it has an algebraic loop.
        self._cache: dict[str, tuple[tuple, object]] = {}
        # The graph shared with the systems of the same structure made before in this process
        # (`connect_many`), and the `_version` it holds for: its facts serve this system while the
        # system has nothing added since.
        self._graph: _Graph | None = None
        self._graph_version: tuple | None = None

    def handle_loops(
        self,
        loops: str,
        tolerance: float = DEFAULT_TOLERANCE,
        max_iterations: int = DEFAULT_MAX_ITERATIONS,
    ) -> None:
        """How algebraic loops run: `loops` ("delay", "iterate", "error"), and for "iterate" the
        relative `tolerance` and the most iterations per macro step (`cosim.core.loops`)."""
        if loops not in LOOP_HANDLING:
            raise CosimError(f"algebraic loop handling '{loops}' is not one of {', '.join(LOOP_HANDLING)}")
        if isinstance(tolerance, bool) or not (
            isinstance(tolerance, int | float) and math.isfinite(tolerance) and tolerance > 0
        ):
            raise CosimError(f"loop_tolerance must be a number > 0, got {tolerance!r}")
        if isinstance(max_iterations, bool) or not (isinstance(max_iterations, int) and max_iterations >= 1):
            raise CosimError(f"loop_max_iterations must be a whole number >= 1, got {max_iterations!r}")
        self.loops = loops
        self.loop_tolerance = float(tolerance)
        self.loop_max_iterations = max_iterations

    @property
    def macro_step(self) -> float:
        return self.macro_step_ns / NS_PER_S

    def add(self, component: Component) -> Component:
        if component.name in self.components:
            raise CosimError(f"component '{component.name}' added twice")
        self.components[component.name] = component
        return component

    def component(self, name: str) -> Component:
        if name not in self.components:
            raise CosimError(
                f"no component '{name}'; components: {closest_names(name, self.components) or 'none'}"
            )
        return self.components[name]

    def resolve(self, reference: str, direction: str) -> tuple[Component, int]:
        """'component.port' -> (component, index of the port in its inputs or outputs)."""
        name, dot, port = reference.partition(".")
        if not dot or not port:
            raise CosimError(f"connection end '{reference}' must be 'component.port'")
        component = self.component(name)
        ports = component.outputs if direction == "output" else component.inputs
        index = component.output_index if direction == "output" else component.input_index
        if port not in index:
            raise CosimError(
                f"component '{name}' has no {direction} '{port}'; {direction}s: "
                f"{closest_names(port, [p.name for p in ports]) or 'none'}"
            )
        return component, index[port]

    def connect(self, source: str, target: str, scale: float = 1.0, offset: float = 0.0) -> Connection:
        """Connect output `source` ("comp.port") to input `target`: input = output * scale + offset."""
        usual = self._connect_usual(source, target, scale, offset, {})
        if usual is not None:
            return usual
        text = self._connect_text(source, target, scale, offset)
        if text is not None:
            return text
        producer, output = self.resolve(source, "output")
        consumer, input_ = self.resolve(target, "input")
        problem = connection_problem(producer.outputs[output], consumer.inputs[input_])
        if problem is not None:
            raise CosimError(
                f"connection {source} ({_typed(producer.outputs[output])}) -> {target} "
                f"({_typed(consumer.inputs[input_])}) cannot convert: {problem}"
            )
        if target in self._targets:
            raise CosimError(f"input '{target}' is already connected")
        if not (math.isfinite(scale) and math.isfinite(offset)):
            raise CosimError(f"connection {source} -> {target}: scale and offset must be finite")
        connection = Connection(source, target, float(scale), float(offset))
        self.connections.append(connection)
        self._targets.add(target)
        return connection

    def connect_many(self, connections: Iterable[tuple[str, str, float, float]]) -> None:
        """`connect` each (source, target, scale, offset) in turn: the same checks, the same error at
        the first that fails (those before it made); the type conversion is checked once per pair of
        port types (a system of a 2000-waypoint path makes ~3,100)."""
        connections = tuple(connections)
        key = None
        fresh = not self.connections and not self.text_connections and not self._targets
        if fresh:
            _settle_pending()
            if _GRAPHS:  # (a process's first graph is kept without a key: `_PENDING`)
                try:
                    key = _graph_key(self.components, self.mode, self.loops, connections)
                    graph = _GRAPHS.get(key)
                except (TypeError, ValueError, AttributeError):  # not (str, str, number, number): below
                    key = graph = None
                if graph is not None:  # the same ports and connections: the same connections made
                    self.connections = list(graph.connections)
                    self._targets = set(graph.targets)
                    self._graph, self._graph_version = graph, self._version()
                    return
        converts: dict[tuple[str, str, str, str], bool] = {}
        for source, target, scale, offset in connections:
            if self._connect_usual(source, target, scale, offset, converts) is None:
                self.connect(source, target, scale, offset)  # the rest, and every error, as it says them
        if fresh and not self.text_connections:  # (a text connection feeds its consumer)
            graph = _Graph(tuple(self.connections), frozenset(self._targets))
            self._graph, self._graph_version = graph, self._version()
            if key is not None:
                _keep_graph(key, graph)
            elif not _GRAPHS:
                _PENDING[:] = [(dict(self.components), self.mode, self.loops, connections, graph)]

    def _connect_usual(
        self, source: str, target: str, scale: float, offset: float, converts: dict
    ) -> Connection | None:
        """The usual connection, checked as `connect` checks it: two numeric ports, the types
        convertible (`converts` remembers `connection_problem` by the four type fields it reads), the
        input free, finite numbers; None (nothing made) when it is not one."""
        source_name, _, source_port = source.partition(".")
        target_name, _, target_port = target.partition(".")
        producer = self.components.get(source_name)
        consumer = self.components.get(target_name)
        if producer is None or consumer is None:
            return None
        output = producer.output_index.get(source_port)
        input_ = consumer.input_index.get(target_port)
        if (
            output is None
            or input_ is None
            or target in self._targets
            or producer.text_port(source_port, "output") is not None
            or consumer.text_port(target_port, "input") is not None
            or not (math.isfinite(scale) and math.isfinite(offset))
        ):
            return None
        out, in_ = producer.outputs[output], consumer.inputs[input_]
        types = (out.fmi_type, out.type, in_.fmi_type, in_.type)
        fine = converts.get(types)
        if fine is None:
            fine = converts[types] = connection_problem(out, in_) is None
        if not fine:
            return None
        connection = Connection(source, target, float(scale), float(offset))
        self.connections.append(connection)
        self._targets.add(target)
        return connection

    def merge(self, other: System, prefix: str) -> None:
        """Take in every component of `other` under the name `prefix + name` (the component objects
        themselves, renamed: `other` keeps them under their old names) with its connections between
        them, as `other` checked them when it made them: `other` gives its connections up (it is left
        without any; a fleet's robots are ~3,100 connections each, kept once). A name already taken
        is a `CosimError`, before anything changes. A fleet puts its robots' systems into one this
        way (connecting each connection again cost as much as making them)."""
        names = {name: prefix + name for name in other.components}
        taken = [new for new in names.values() if new in self.components]
        if taken:
            raise CosimError(f"component '{taken[0]}' added twice")
        for name, component in other.components.items():
            component.name = names[name]
            self.components[component.name] = component
        for made, kept in (
            (other.connections, self.connections),
            (other.text_connections, self.text_connections),
        ):
            for c in made:
                target = prefix + c.target
                kept.append(Connection(prefix + c.source, target, c.scale, c.offset))
                self._targets.add(target)
            made.clear()

    def _connect_text(self, source: str, target: str, scale: float, offset: float) -> Connection | None:
        """A connection of String or Binary ports (`Component.text_port`), which the consumer itself
        reads before each of its steps (`Component.feed_text`); None when neither end is one."""
        producer = self.components.get(source.partition(".")[0])
        consumer = self.components.get(target.partition(".")[0])
        if producer is None or consumer is None:
            return None
        source_type = producer.text_port(source.partition(".")[2], "output")
        target_type = consumer.text_port(target.partition(".")[2], "input")
        if source_type is None and target_type is None:
            return None
        if source_type != target_type:
            raise CosimError(
                f"connection {source} ({source_type or 'a number'}) -> {target} "
                f"({target_type or 'a number'}) cannot convert: a String or Binary connects only to its own "
                "type"
            )
        if scale != 1.0 or offset != 0.0:
            raise CosimError(f"connection {source} -> {target}: a {source_type} takes no scale or offset")
        if target in self._targets:
            raise CosimError(f"input '{target}' is already connected")
        consumer.feed_text(target.partition(".")[2], producer, source.partition(".")[2])
        connection = Connection(source, target)
        self.text_connections.append(connection)
        self._targets.add(target)
        return connection

    def _version(self) -> tuple:
        """What the system's graph is made of, as far as the caches here can tell: the number of
        components and of connections, and the last connection (both lists only grow: `add`,
        `connect`, `merge`; a component's ports and dependencies never change once added)."""
        connections = self.connections
        return len(self.components), len(connections), connections[-1] if connections else None

    def _is_current(self, version: tuple | None) -> bool:
        """Whether `version` (a `_version` taken before) is the system's graph as it is now."""
        if version is None:
            return False
        now = self._version()
        return version[0] == now[0] and version[1] == now[1] and version[2] is now[2]

    def _cached(self, name: str):
        """The value cached under `name` for the system as it is now (`_version`), or None."""
        version, value = self._cache.get(name, (None, None))
        if self._is_current(version):
            return value
        shared = self._shared_facts()
        return None if shared is None else shared.get((name, self.mode, self.loops))

    def _keep(self, name: str, value):
        self._cache[name] = (self._version(), value)
        shared = self._shared_facts()
        if shared is not None:
            shared[(name, self.mode, self.loops)] = value
        return value

    def _shared_facts(self) -> dict | None:
        """The facts of the shared graph (`connect_many`), when the system is still that graph."""
        if self._graph is not None and self._is_current(self._graph_version):
            return self._graph.facts
        return None

    def _names_cached(self, name: str, compute: Callable[[], list[Component]]) -> list[Component]:
        """The components `compute()` gives, remembered by name for the graph as it is and the mode
        and loop handling (`handle_loops` may change it)."""
        key = (name, self.mode, self.loops)
        names = self._cached(key)
        if names is None:
            names = self._keep(key, tuple(component.name for component in compute()))
        components = self.components
        return [components[name] for name in names]

    def links(self) -> dict[str, list[Link]]:
        """The connections into each component (by name, in connection order), their ends resolved:
        (connection, producer name, output index, input index). Resolved once for the connections
        as they are (`connect` checked both ends, and a component's ports never change); the master
        reads them a dozen times while ordering and initialising a system of thousands."""
        incoming = self._cached("links")
        if incoming is None:
            incoming = {}
            components = self.components
            for c in self.connections:
                source_name, _, output = c.source.partition(".")
                target_name, _, input_ = c.target.partition(".")
                source_index = components[source_name].output_index[output]
                target_index = components[target_name].input_index[input_]
                link = Link(c, source_name, source_index, target_index)
                if target_name in incoming:
                    incoming[target_name].append(link)
                else:
                    incoming[target_name] = [link]
            self._keep("links", incoming)
        return incoming

    def unfed_inputs(self) -> dict[str, tuple[int, ...]]:
        """Component name -> the indices of its inputs (numeric: `Component.inputs`) that no
        connection feeds, for every component in the order added; worked out once for the graph
        (read-only)."""
        unfed = self._cached("unfed inputs")
        if unfed is None:
            fed = self._targets
            unfed = self._keep(
                "unfed inputs",
                {
                    name: tuple(
                        index
                        for index, port in enumerate(component.inputs)
                        if f"{name}.{port.name}" not in fed
                    )
                    for name, component in self.components.items()
                },
            )
        return unfed

    def period_steps(self, component: Component) -> int:
        """The component's period as a whole number of macro steps (>= 1)."""
        if component.period == 0:
            return 1
        period_ns = seconds_to_ns(component.period, f"period of '{component.name}'")
        steps, remainder = divmod(period_ns, self.macro_step_ns)
        if remainder or steps == 0:
            raise CosimError(
                f"period {component.period} s of '{component.name}' is not a multiple of the "
                f"macro step {self.macro_step} s"
            )
        return steps

    # ---- ordering ----------------------------------------------------------------------------

    def _topological(self, edges: set[tuple[str, str]], names: list[str] | None = None) -> list[str]:
        """Kahn's algorithm over `names` (default: every component); ready ones are taken in the
        order of `names` (the order they were added); when none is ready (a cycle), the first one
        left in that order."""
        names = list(self.components) if names is None else names
        position = {name: number for number, name in enumerate(names)}
        indegree = [0] * len(names)
        successors: list[list[int]] = [[] for _ in names]
        for producer, consumer in edges:
            indegree[position[consumer]] += 1
            successors[position[producer]].append(position[consumer])
        ready = [number for number, count in enumerate(indegree) if count == 0]  # a heap of positions
        heapq.heapify(ready)
        done = [False] * len(names)
        order: list[str] = []
        first_left = 0  # every position before it is done
        while len(order) < len(names):
            if ready:
                node = heapq.heappop(ready)
            else:
                while done[first_left]:
                    first_left += 1
                node = first_left
            done[node] = True
            order.append(names[node])
            for consumer in successors[node]:
                if not done[consumer]:
                    indegree[consumer] -= 1
                    if indegree[consumer] == 0:
                        heapq.heappush(ready, consumer)
        return order

    def algebraic_loop(self) -> list[str] | None:
        """A cycle of direct dependencies between ports ("comp.port", first = last), or None."""
        if self._acyclic():
            return None
        feedthrough = {name: c.feedthrough for name, c in self.components.items()}
        return find_algebraic_loop([(c.source, c.target) for c in self.connections], feedthrough)

    def _acyclic(self) -> bool:
        """Whether the graph of ports (connections and direct dependencies) has no cycle, decided
        once for the system as it is, in time linear in its ports and connections.

        Decided on a graph of groups: a group is the outputs of one component that depend on the
        same inputs (`feedthrough`, compared by content); group G reaches group H when a connection
        goes from an output of G to an input that an output of H depends on. A cycle of ports
        alternates connections (output -> input) and dependencies (input -> output), so it gives a
        cycle of groups, and a cycle of groups gives one of ports. That holds when no port name of
        a component is both an input and an output (one node in the graph of names) and every
        entry of `feedthrough` is an output; otherwise the search over the names decides."""
        known = self._cached("acyclic")
        if known is not None:
            return known
        components = self.components
        if not all(
            len(c.feedthrough) == len(c.output_index) and c.input_index.keys().isdisjoint(c.output_index)
            for c in components.values()
        ):
            feedthrough = {name: c.feedthrough for name, c in components.items()}
            pairs = [(c.source, c.target) for c in self.connections]
            return self._keep("acyclic", find_algebraic_loop(pairs, feedthrough) is None)
        group_of: dict[str, list[int]] = {}  # component -> the group of each output (-1: a state)
        feeds: dict[str, list[list[int] | None]] = {}  # component -> per input, the groups it feeds
        reaches: list[set[int]] = []  # group -> the groups it reaches
        for name, component in components.items():
            output_index, input_index = component.output_index, component.input_index
            groups = [-1] * len(output_index)
            fed: list[list[int] | None] = [None] * len(input_index)
            by_identity: dict[int, int] = {}
            by_content: dict[tuple[str, ...], int] = {}
            for output, depends in component.feedthrough.items():
                if not depends:
                    continue
                number = by_identity.get(id(depends))
                if number is None:
                    content = tuple(depends)
                    number = by_content.get(content)
                    if number is None:
                        number = by_content[content] = len(reaches)
                        reaches.append(set())
                        for input_ in content:
                            slot = input_index.get(input_)
                            if slot is not None:  # (an unknown input is fed by no connection)
                                if fed[slot] is None:
                                    fed[slot] = [number]
                                else:
                                    fed[slot].append(number)
                    by_identity[id(depends)] = number
                groups[output_index[output]] = number
            group_of[name] = groups
            feeds[name] = fed
        for consumer, links in self.links().items():
            fed = feeds[consumer]
            for link in links:
                number = group_of[link.producer][link.output]
                if number >= 0:
                    targets = fed[link.input]
                    if targets is not None:
                        reaches[number].update(targets)
        return self._keep("acyclic", not has_cycle(reaches))

    def check_algebraic_loops(self) -> None:
        """Raise `CosimError` naming a cycle of direct dependencies between ports, if any."""
        loop = self.algebraic_loop()
        if loop is not None:
            raise CosimError(
                "algebraic loop (direct feedthrough only): "
                + " -> ".join(loop)
                + "; an FMU output without declared dependencies depends on every input; "
                "`--set simulation.algebraic_loops=delay` (or simulation.master=jacobi) runs it "
                "with the loop's inputs from the previous communication point"
            )

    def _direct_edges(self) -> set[tuple[str, str]]:
        """(producer, consumer) for every connection from a direct output to another component."""
        direct: dict[str, list[bool]] = {}  # producer -> per output, whether it is direct
        edges = set()
        for consumer, links in self.links().items():
            for link in links:
                producer = link.producer
                if producer == consumer:
                    continue
                if producer not in direct:
                    component = self.components[producer]
                    direct[producer] = [bool(component.feedthrough[p.name]) for p in component.outputs]
                if direct[producer][link.output]:
                    edges.add((producer, consumer))
        return edges

    def _loop_ports(self) -> dict[str, int]:
        """Port -> number of its strongly connected component in the graph of ports (connections
        and direct dependencies), for the ports on a cycle; empty without an algebraic loop."""
        if self.mode != "gauss-seidel" or self._acyclic():
            return {}
        graph: dict[str, list[str]] = {}
        for c in self.connections:
            graph.setdefault(c.source, []).append(c.target)
        for name, component in self.components.items():
            for output, depends in component.feedthrough.items():
                for input_ in depends:
                    graph.setdefault(f"{name}.{input_}", []).append(f"{name}.{output}")
        return cyclic_components(graph)

    def loop_components(self) -> list[str]:
        """The components with a port on an algebraic loop (Gauss-Seidel with `loops="delay"`
        steps them Jacobi-style: the connections of the loop carry the outputs from before the
        step), in the order they were added; empty without a loop or in Jacobi mode."""
        ports = self._loop_ports()
        members = {port.split(".", 1)[0] for port in ports}
        return [name for name in self.components if name in members]

    def loop_connections(self) -> list[Connection]:
        """The connections on an algebraic loop (both ends in one strongly connected set of ports)."""
        ports = self._loop_ports()
        if not ports:
            return []
        return [c for c in self.connections if c.source in ports and ports[c.source] == ports.get(c.target)]

    def delayed_links(self) -> set[tuple[str, str]]:
        """(producer, consumer) pairs with a connection on an algebraic loop: delayed by one step
        (none when `loops == "iterate"`: the loops iterate instead)."""
        if self.loops == "iterate":
            return set()
        return {(c.source_component, c.target_component) for c in self.loop_connections()}

    def loop_groups(self) -> list[LoopGroup]:
        """The algebraic loops as (member components in the order they were added, connections of
        the loop): strongly connected sets of ports, joined where they share a component."""
        ports = self._loop_ports()
        group: dict[int, int] = {number: number for number in set(ports.values())}

        def root(number: int) -> int:
            while group[number] != number:
                number = group[number]
            return number

        first_set: dict[str, int] = {}
        for port, number in ports.items():
            name = port.split(".", 1)[0]
            if name in first_set:
                group[root(number)] = root(first_set[name])
            else:
                first_set[name] = number
        members: dict[int, list[str]] = {}
        for name in self.components:
            if name in first_set:
                members.setdefault(root(first_set[name]), []).append(name)
        links: dict[int, list[Connection]] = {}
        for c in self.loop_connections():
            links.setdefault(root(ports[c.source]), []).append(c)
        return [LoopGroup(names, links.get(number, [])) for number, names in members.items()]

    def order(self) -> list[Component]:
        """Step order (see the module docstring); checks algebraic loops in Gauss-Seidel mode
        when `loops == "error"`."""
        if self.mode == "gauss-seidel" and self.loops == "error":
            self.check_algebraic_loops()
        return self._names_cached("order", self._order)

    def _order(self) -> list[Component]:
        loop_links = {(c.source_component, c.target_component) for c in self.loop_connections()}
        edges = self._direct_edges() - loop_links
        order = self._topological(edges)
        groups = self.loop_groups() if self.loops == "iterate" else []
        if groups:  # each loop one node of the graph, its members in the order above
            leader = {name: group.members[0] for group in groups for name in group.members}
            nodes = [name for name in self.components if leader.get(name, name) == name]
            contracted = {(leader.get(p, p), leader.get(c, c)) for p, c in edges}
            position = {name: number for number, name in enumerate(order)}
            members = {group.members[0]: sorted(group.members, key=position.__getitem__) for group in groups}
            order = [
                name
                for node in self._topological({(p, c) for p, c in contracted if p != c}, nodes)
                for name in members.get(node, [node])
            ]
        return [self.components[name] for name in order]

    def initialization_order(self) -> list[Component]:
        """Producers before the consumers that need their values at initialisation.

        A consumer C needs producer P first when a connection P.o -> C.i feeds input i into an
        output of C that is itself connected (C's initial value of that output depends on i
        directly). A state output (no direct dependencies, e.g. a vehicle's pose) is valid as soon
        as its component is initialised, so a feedback loop through it orders its producer first
        (the vehicle before the controllers, whose commands only reach its unconnected outputs).
        """
        return self._names_cached("initialization order", self._initialization_order)

    def _initialization_order(self) -> list[Component]:
        consumed = {c.source for c in self.connections}
        # Per consumer, the inputs some connected output depends on directly (one pass over the
        # feedthrough; a planner's 2000 waypoints feed every output of a path follower).
        feeding: dict[str, set[str]] = {}
        for name, component in self.components.items():
            feeding[name] = set()
            seen: set[int] = set()  # (outputs share their list of inputs: `Component.feedthrough`)
            for output, depends in component.feedthrough.items():
                if id(depends) not in seen and f"{name}.{output}" in consumed:
                    seen.add(id(depends))
                    feeding[name].update(depends)
        edges = set()
        for name, links in self.links().items():
            inputs = self.components[name].inputs
            for link in links:
                if link.producer != name and inputs[link.input].name in feeding[name]:
                    edges.add((link.producer, name))
        # A text output's dependencies are not known (`Component.feedthrough` holds numbers): the
        # producer of a text connection initialises first, so its value reaches the consumer at t0.
        edges |= {(c.source_component, c.target_component) for c in self.text_connections}
        edges = {(producer, consumer) for producer, consumer in edges if producer != consumer}
        return [self.components[name] for name in self._topological(edges)]

    def initialized_early(self, order: list[Component]) -> list[Component]:
        """The components of initialisation `order` that initialised before a producer feeding an
        input some output of theirs depends on directly (connected or not: a vehicle's measured
        speed on its commanded one), in that order. The master hands them their connected inputs
        once more after every component is initialised and reads their outputs again, so every
        output at the start time reflects its connected inputs (within an algebraic loop, after
        one pass in this fixed order)."""
        names = tuple(component.name for component in order)
        return self._names_cached(("initialized early", names), lambda: self._initialized_early(order))

    def _initialized_early(self, order: list[Component]) -> list[Component]:
        position = {component.name: number for number, component in enumerate(order)}
        early = {
            c.target_component
            for c in self.text_connections
            if position[c.source_component] >= position[c.target_component]
        }
        for name, links in self.links().items():
            component = self.components[name]
            shared = {id(depends): depends for depends in component.feedthrough.values()}
            direct = {i for depends in shared.values() for i in depends}
            for link in links:
                if position[link.producer] >= position[name] and component.inputs[link.input].name in direct:
                    early.add(name)
        return [component for component in order if component.name in early]


class _Graph:
    """The connections `System.connect_many` made between components of one structure, with what the
    system works out from them (`facts`: links, acyclicity, orders; by (name, mode, loops)), shared by
    every system of that structure in this process. Everything here is read-only: the connections
    are frozen, the facts are tuples, booleans and the links, which nothing changes."""

    __slots__ = ("connections", "targets", "facts")

    def __init__(self, connections: tuple[Connection, ...], targets: frozenset[str]) -> None:
        self.connections = connections
        self.targets = targets
        self.facts: dict = {}


# Graphs by `_graph_key`: a sweep's worker builds the same system for every run (~3,100 connections
# made, their ends resolved and the graph ordered: ~17 ms each time). A few kept.
_GRAPHS: dict[tuple, _Graph] = {}
_GRAPHS_KEPT = 4
# The first graph of a process, with what its key is worked out from (the components as added, mode,
# loop handling, connections; none of them changes once connected): its key (~3 ms) is worked out when
# a second system is connected, so a process that runs one scenario (`cosim run`) never does.
_PENDING: list[tuple[dict[str, Component], str, str, tuple, _Graph]] = []


def _keep_graph(key: tuple, graph: _Graph) -> None:
    if len(_GRAPHS) >= _GRAPHS_KEPT:
        _GRAPHS.pop(next(iter(_GRAPHS)))
    _GRAPHS[key] = graph


def _settle_pending() -> None:
    """Keep the pending graph (`_PENDING`) under its key."""
    if not _PENDING:
        return
    components, mode, loops, connections, graph = _PENDING.pop()
    try:
        key = _graph_key(components, mode, loops, connections)
    except (TypeError, ValueError, AttributeError):
        return
    _keep_graph(key, graph)


_TYPES = attrgetter("type")
_FMI_TYPES = attrgetter("fmi_type")
_SCALE_OFFSET = itemgetter(2, 3)


class _PortTypes:
    """A component's ports in a `_graph_key`, as far as connecting reads them: each port's `type`
    and `fmi_type`. Equal when the ports are the same objects (a project FMU's and an array's ports
    are kept by what makes them, and a port never changes) or have the same types; hashed as one
    (the key hashes the ports' names beside it)."""

    __slots__ = ("ports",)

    def __init__(self, ports) -> None:
        self.ports = tuple(ports)

    def __hash__(self) -> int:
        return 0

    def __eq__(self, other) -> bool:
        if not isinstance(other, _PortTypes):
            return NotImplemented
        mine, theirs = self.ports, other.ports
        if len(mine) != len(theirs):
            return False
        if all(map(operator.is_, mine, theirs)):
            return True
        same = list(map(_TYPES, mine)) == list(map(_TYPES, theirs))
        return same and list(map(_FMI_TYPES, mine)) == list(map(_FMI_TYPES, theirs))


def _graph_key(
    components: dict[str, Component], mode: str, loops: str, connections: tuple[tuple, ...]
) -> tuple:
    """Everything the connections made of `connections` and the facts worked out from them depend
    on: per component (in the order added) its name and class, its input and output names with
    their types (what `connection_problem` reads), whether each is a text port
    (`Component.text_port`; asked only of a class that has text ports) and its feedthrough (which
    outputs share a tuple of inputs, and those inputs); the mode and loop handling; the connections
    (and the bits of each scale and offset: -0.0 equals 0.0 but adds differently)."""
    parts = []
    for name, component in components.items():
        inputs, outputs = component.inputs, component.outputs
        text = None
        if type(component).text_port is not Component.text_port:
            text_port = component.text_port
            text = (
                tuple(map(text_port, component.input_index, itertools.repeat("input"))),
                tuple(map(text_port, component.output_index, itertools.repeat("output"))),
            )
        groups: dict[int, int] = {}
        shared: dict[int, tuple[str, ...]] = {}
        for depends in component.feedthrough.values():
            if id(depends) not in groups:
                groups[id(depends)] = len(groups)
                shared[id(depends)] = tuple(depends)
        parts.append(
            (
                name,
                type(component),
                tuple(component.input_index),
                tuple(component.output_index),
                _PortTypes(inputs),
                _PortTypes(outputs),
                text,
                tuple(component.feedthrough),
                tuple([groups[id(depends)] for depends in component.feedthrough.values()]),
                tuple(shared.values()),
            )
        )
    numbers = array("d", itertools.chain.from_iterable(map(_SCALE_OFFSET, connections))).tobytes()
    return tuple(parts), mode, loops, connections, numbers
