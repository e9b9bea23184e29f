"""The master algorithm: a system of components and connections stepped on an integer time base.

Time base
---------
The macro step h is held as an integer number of nanoseconds; step k starts at
t_k = start + k * h exactly (`Master.time_ns`), and the float time handed to components is that
integer divided once by 1e9, so time never accumulates rounding: 2,000,000 steps of 1 ms end at
exactly 2000.0 s. A component's `period` is an integer multiple P of h (0 = every step); it is
stepped at the steps k with k % P == 0, by `do_step(t_k, P * h)`. Between its steps its outputs
hold their last values (sample and hold).

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

Initialisation follows libcosim and ecos (FMI allows other orders; some FMUs rely on this one):
every component is instantiated, then set up (FMI 2.0: fmi2SetupExperiment with the start and stop
times, then the parameters, so an FMU that resets its variables in setupExperiment keeps the
values), then enters initialisation (FMI 3.0's enterInitializationMode takes the times; FMI 1.0
has no such mode: fmiInitializeSlave takes them when the component initialises). The connected
values are then exchanged in an order where a producer comes before a consumer whose input feeds
one of the consumer's *connected* outputs directly (`System.initialization_order`): a vehicle whose
pose outputs are states initialises before the controllers that read the pose, even though the
controllers' commands feed its (unconnected) velocity outputs. Each component gathers its inputs
from the producers already initialised (other inputs keep their start values), initialises, and
has its outputs read. A component that initialised before a producer of an input that any output
of its depends on directly (`System.initialized_early`: the vehicle's measured velocity on its
commands) then gathers all its connected inputs once more and has its outputs read again, so at
the start time every output reflects its connected inputs (within an algebraic loop, after that
one pass in a fixed order; with `loops="iterate"` the loop's members exchange their connected
values again until they agree to `loop_tolerance`, and the components they feed take them once
more). Jacobi mode uses the same initialisation.

Stop time
---------
A master given a stop time tells every component (`Component.setup`), never steps past it, and
cuts the steps that would end after it: a component due at step k steps by
min(P * h, stop - t_k) (`Master.step_seconds`), so a stop time that is no whole number of macro
steps (or of a component's period) after the start ends with a shorter step, exactly at the stop
time (`Master.steps_to_stop` steps; `time` is then the stop time). An FMU without
canHandleVariableCommunicationStepSize (`Component.can_vary_step`) cannot take that shorter step:
`Master` refuses such a stop time in one line, naming the component and the nearest stop times it
can end at (`cosim fmu simulate` refuses it too). Stepping past the stop time would break the
stop time the FMU was told, and ending at the last whole step before it (fmpy's choice) would end
the run silently early. The compiled kernel takes those
last steps one at a time, with the cut step sizes written into its tables.

Loops
-----
`Master.run` steps in Python (with a per-step callback, or always when `compiled=False`) or, for a
system whose stepped components are all FMUs stepped by C calls and nobody observing the steps,
in the compiled kernel (`cosim.core.kernel`, C, reading tables filled by `cosim.core.fast_loop`);
`Master.run_recorded` likewise, keeping the rows per block. `Master.run_blocks` steps through the
same kernel, handing components that need Python back where they are due, recording the FMUs'
buffers and watching a position; its callback runs per block of steps. All loops give
bit-identical values.

Failures
--------
A component that raises `CosimError` while stepping stops the master: `step()`/`run()` re-raise
it, further steps are refused, and `close()` terminates the healthy components and frees all
(a failed FMU is not terminated; freeing it is safe).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cosim.core import fast_loop
from cosim.core.component import Component, Port, State, closest_names
from cosim.core.loops import (
    DEFAULT_MAX_ITERATIONS,
    DEFAULT_TOLERANCE,
    MASTER_SIGNALS,
    LoopLink,
    LoopSolver,
    MasterSignals,
)
from cosim.core.port_types import connection_problem
from cosim.errors import CosimError

if TYPE_CHECKING:
    from fractions import Fraction

NS_PER_S = 1_000_000_000
MODES = ("gauss-seidel", "jacobi")
LOOP_HANDLING = ("delay", "iterate", "error")  # `[simulation] algebraic_loops` (`System.loops`)
# Below this many values from one producer, per-value ctypes copies beat one NumPy fancy-index copy.
_SCALAR_COPY_LIMIT = 4
# `run`/`run_recorded` with `compiled=None` step through the kernel from this many steps on: fewer
# do not repay filling its tables (about the cost of 20 Python-loop steps of two FMUs).
COMPILED_MIN_STEPS = 100
# Most steps per call of the compiled kernel (`Master.run_blocks`).
KERNEL_BLOCK = 1000
# `Master.run` without a callback: nobody looks between blocks, so longer ones (about 0.1 s each,
# after which a KeyboardInterrupt gets through).
_RUN_BLOCK = 100_000


def due_from(k: int, period: int) -> int:
    """The first step at or after step k at which a component of `period` steps is due."""
    return -(-k // period) * period


def seconds_to_ns(seconds: float | Fraction | int, what: str) -> int:
    """Convert a duration [s] to integer nanoseconds; `CosimError` if not a whole number of ns."""
    if isinstance(seconds, float):
        if not math.isfinite(seconds):
            raise CosimError(f"{what} must be finite, got {seconds}")
        # A float such as 0.001 is not exactly 1e6 ns; accept it when it is the nearest float.
        nanoseconds = round(seconds * NS_PER_S)
        if abs(nanoseconds - seconds * NS_PER_S) > 1e-6 * max(1.0, abs(seconds * NS_PER_S)):
            raise CosimError(f"{what} {seconds} s is not a whole number of nanoseconds")
        return nanoseconds
    from fractions import Fraction  # exact durations only (its import costs a run ~4 ms)

    if isinstance(seconds, bool) or not isinstance(seconds, int | Fraction):
        raise CosimError(f"{what} must be a number of seconds, got {seconds!r}")
    exact = Fraction(seconds) * NS_PER_S
    nanoseconds = round(exact)
    if exact != nanoseconds:
        raise CosimError(f"{what} {seconds} s is not a whole number of nanoseconds")
    return nanoseconds


@dataclass(frozen=True)
class Connection:
    """`source` output -> `target` input; the input receives `output * scale + offset`."""

    source: str  # "component.port"
    target: str
    scale: float = 1.0
    offset: float = 0.0  # [unit of the target input]

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


# A connection into a component, resolved (`System.links`): connection, producer, output index, input index.
Link = tuple[Connection, str, int, int]


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
        self._links: tuple[list[Connection], dict[str, list[Link]]] = ([], {})

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

    def links(self) -> dict[str, list[Link]]:
        """The connections into each component (by name, in connection order), their ends resolved:
        (connection, producer name, output index, input index). Resolved once for the connections
        as they are (`connect` checked both ends, and a component's ports never change); the master
        reads them a dozen times while ordering and initialising a system of thousands."""
        resolved_for, incoming = self._links
        if resolved_for != self.connections:  # a list compare: the same objects, element by element
            incoming = {}
            for c in self.connections:
                source_name, _, output = c.source.partition(".")
                target_name, _, input_ = c.target.partition(".")
                source_index = self.components[source_name].output_index[output]
                target_index = self.components[target_name].input_index[input_]
                incoming.setdefault(target_name, []).append((c, source_name, source_index, target_index))
            self._links = (list(self.connections), incoming)
        return incoming

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
        order of `names` (the order they were added)."""
        names = list(self.components) if names is None else names
        indegree = dict.fromkeys(names, 0)
        for _, consumer in edges:
            indegree[consumer] += 1
        order: list[str] = []
        remaining = list(names)
        while remaining:
            ready = next((n for n in remaining if indegree[n] == 0), remaining[0])
            remaining.remove(ready)
            order.append(ready)
            for producer, consumer in edges:
                if producer == ready and consumer in remaining:
                    indegree[consumer] -= 1
        return order

    def algebraic_loop(self) -> list[str] | None:
        """A cycle of direct dependencies between ports ("comp.port", first = last), or None."""
        feedthrough = {name: c.feedthrough for name, c in self.components.items()}
        return find_algebraic_loop([(c.source, c.target) for c in self.connections], feedthrough)

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
        components = self.components
        return {
            (producer, consumer)
            for consumer, links in self.links().items()
            for _, producer, output, _ in links
            if producer != consumer
            and components[producer].feedthrough[components[producer].outputs[output].name]
        }

    def _loop_ports(self) -> dict[str, int]:
        """Port -> number of its strongly connected component in the graph of ports (connections
        and direct dependencies), for the ports on a cycle; empty without an algebraic loop."""
        if self.mode != "gauss-seidel" or self.algebraic_loop() is None:
            return {}
        graph: dict[str, list[str]] = {}
        for c in self.connections:
            graph.setdefault(c.source, []).append(c.target)
        for name, component in self.components.items():
            for output, depends in component.feedthrough.items():
                for input_ in depends:
                    graph.setdefault(f"{name}.{input_}", []).append(f"{name}.{output}")
        return _cyclic_components(graph)

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
        return [c for c in self.connections if c.source in ports and ports[c.source] == ports.get(c.target)]

    def delayed_links(self) -> set[tuple[str, str]]:
        """(producer, consumer) pairs with a connection on an algebraic loop: delayed by one step
        (none when `loops == "iterate"`: the loops iterate instead)."""
        if self.loops == "iterate":
            return set()
        return {(c.source_component, c.target_component) for c in self.loop_connections()}

    def loop_groups(self) -> list[tuple[list[str], list[Connection]]]:
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
        return [(names, links.get(number, [])) for number, names in members.items()]

    def order(self) -> list[Component]:
        """Step order (see the module docstring); checks algebraic loops in Gauss-Seidel mode
        when `loops == "error"`."""
        if self.mode == "gauss-seidel" and self.loops == "error":
            self.check_algebraic_loops()
        loop_links = {(c.source_component, c.target_component) for c in self.loop_connections()}
        edges = self._direct_edges() - loop_links
        order = self._topological(edges)
        groups = self.loop_groups() if self.loops == "iterate" else []
        if groups:  # each loop one node of the graph, its members in the order above
            leader = {name: names[0] for names, _ in groups for name in names}
            nodes = [name for name in self.components if leader.get(name, name) == name]
            contracted = {(leader.get(p, p), leader.get(c, c)) for p, c in edges}
            position = {name: number for number, name in enumerate(order)}
            members = {names[0]: sorted(names, key=position.__getitem__) for names, _ in groups}
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
        consumed = {c.source for c in self.connections}
        # Per consumer, the inputs some connected output depends on directly (one pass over the
        # feedthrough; a planner's 2000 waypoints feed every output of a path follower).
        feeding: dict[str, set[str]] = {}
        for name, component in self.components.items():
            feeding[name] = set()
            for output, depends in component.feedthrough.items():
                if f"{name}.{output}" in consumed:
                    feeding[name].update(depends)
        edges = set()
        for name, links in self.links().items():
            inputs = self.components[name].inputs
            for _, producer, _, index in links:
                if producer != name and inputs[index].name in feeding[name]:
                    edges.add((producer, name))
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
        position = {component.name: number for number, component in enumerate(order)}
        early = {
            c.target_component
            for c in self.text_connections
            if position[c.source_component] >= position[c.target_component]
        }
        for name, links in self.links().items():
            component = self.components[name]
            direct = {i for depends in component.feedthrough.values() for i in depends}
            for _, producer, _, index in links:
                if position[producer] >= position[name] and component.inputs[index].name in direct:
                    early.add(name)
        return [component for component in order if component.name in early]


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
        (component, tuple((output, tuple(depends)) for output, depends in outputs.items()))
        for component, outputs in feedthrough.items()
    )
    key = (pairs, dependencies)
    if key not in _LOOPS:
        if len(_LOOPS) >= _LOOPS_KEPT:
            _LOOPS.pop(next(iter(_LOOPS)))
        loop = _search_algebraic_loop(pairs, dependencies)
        _LOOPS[key] = None if loop is None else tuple(loop)
    loop = _LOOPS[key]
    return None if loop is None else list(loop)


# `find_algebraic_loop` of the last few graphs, keyed by the graph itself (the connection pairs and
# every component's feedthrough, in order: the order decides which loop is named).
_LOOPS: dict[tuple, tuple[str, ...] | None] = {}
_LOOPS_KEPT = 8


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


def _cyclic_components(graph: Mapping[str, list[str]]) -> dict[str, int]:
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


def _no_outputs() -> None:
    """`get_outputs` of a loop's entry in the Python loop: its members have read theirs."""


def _gather(
    system: System,
    consumer: Component,
    producers: set[str] | None = None,
    delayed: Mapping[str, np.ndarray] | None = None,
) -> Callable[[], None] | None:
    """A function copying the consumer's connected inputs from its producers' output buffers.

    Generated as straight-line code (one statement per value, or one NumPy copy for many values
    from one producer), because it runs for every component on every step. None when the
    consumer has no connected input (from `producers`, when given). `delayed` maps producers
    whose values come from a copy of their outputs taken before the step (`System.delayed_links`).
    """
    groups: dict[str, list[tuple[int, int, float, float]]] = {}
    for connection, producer, source_index, target_index in system.links().get(consumer.name, ()):
        if producers is not None and producer not in producers:
            continue
        link = (source_index, target_index, connection.scale, connection.offset)
        groups.setdefault(producer, []).append(link)
    if not groups:
        return None
    names: dict[str, object] = {"target": consumer.input_cbuffer, "target_array": consumer.input_buffer}
    lines = ["def gather():"]
    for number, (producer_name, links) in enumerate(groups.items()):
        producer = system.components[producer_name]
        if delayed is not None and producer_name in delayed:
            names[f"source{number}"] = names[f"source_array{number}"] = delayed[producer_name]
        else:
            names[f"source{number}"] = producer.output_cbuffer
            names[f"source_array{number}"] = producer.output_buffer
        if len(links) <= _SCALAR_COPY_LIMIT:
            for source_index, target_index, scale, offset in links:
                value = fast_loop.transfer_expression(f"source{number}[{source_index}]", scale, offset)
                lines.append(f"    target[{target_index}] = {value}")
            continue
        # One NumPy copy per kind of link, each with exactly the arithmetic of the scalar path (a
        # plain copy stays a copy: adding 0.0 would turn -0.0 into 0.0).
        kinds = {
            "copy": [link for link in links if link[2] == 1.0 and link[3] == 0.0],
            "scaled": [link for link in links if link[2] != 1.0 and link[3] == 0.0],
            "affine": [link for link in links if link[3] != 0.0],
        }
        for kind, chosen in kinds.items():
            if not chosen:
                continue
            key = f"{number}_{kind}"
            names[f"sources{key}"] = np.array([link[0] for link in chosen], dtype=np.intp)
            names[f"targets{key}"] = np.array([link[1] for link in chosen], dtype=np.intp)
            names[f"scales{key}"] = np.array([link[2] for link in chosen])
            names[f"offsets{key}"] = np.array([link[3] for link in chosen])
            value = f"source_array{number}[sources{key}]"
            if kind != "copy":
                value += f" * scales{key}" + (f" + offsets{key}" if kind == "affine" else "")
            lines.append(f"    target_array[targets{key}] = {value}")
    exec("\n".join(lines), names)  # noqa: S102 - generated from our own templates
    return names["gather"]


class Master:
    """Runs a `System`: initialise, step (one macro step per call) or run many, close.

    Use as a context manager, or call `close()` in a `finally`.
    """

    def __init__(
        self,
        system: System,
        start_time: float = 0.0,
        parameters: Mapping[str, Mapping[str, float]] | None = None,
        stop_time: float | None = None,
    ) -> None:
        self.system = system
        self.start_time_ns = seconds_to_ns(start_time, "start time")
        # The components are told the stop time, and no step of theirs ends after it (`steps_to_stop`).
        self.stop_time = None if stop_time is None else float(stop_time)
        self.stop_time_ns = None if stop_time is None else seconds_to_ns(stop_time, "stop time")
        if self.stop_time_ns is not None and self.stop_time_ns <= self.start_time_ns:
            raise CosimError(f"stop time {stop_time} s is not after the start time {start_time} s")
        self.parameters = {name: dict(values) for name, values in (parameters or {}).items()}
        for name in self.parameters:
            system.component(name)
        # Algebraic loops iterated within the macro step (`cosim.core.loops`): their members must
        # roll back, and the iteration counts go on /signals/master.
        self._loop_groups = system.loop_groups() if system.loops == "iterate" else []
        self._signals: MasterSignals | None = None
        if self._loop_groups:
            self._check_loop_states()
            known = system.components.get(MASTER_SIGNALS)
            if known is not None and not isinstance(known, MasterSignals):
                raise CosimError(
                    f"a component is named '{MASTER_SIGNALS}', the name of the master's own signals "
                    '(loop_iterations) under simulation.algebraic_loops = "iterate"; rename it'
                )
            self._signals = known or system.add(MasterSignals([]))
        self.order = system.order()
        if self._signals is not None:  # stepped last: it takes the iteration counts of the step
            self.order = [c for c in self.order if c is not self._signals] + [self._signals]
        self.step_index = 0
        self.failure: CosimError | None = None
        self._initialized = False
        self._closed = False
        self._kernels: dict[tuple[bool, int], fast_loop.KernelTables | None] = {}
        delayed = system.delayed_links()
        # Loop members' outputs as they were before the step (copied at its start, `_advance`).
        self._previous = {
            producer: np.array(system.components[producer].output_buffer) for producer, _ in delayed
        }
        if delayed:
            loop = " -> ".join(system.algebraic_loop() or [])
            members = ", ".join(system.loop_components())
            print(
                f"note: algebraic loop {loop}: {members} step with their inputs from the previous "
                'communication point (simulation.algebraic_loops = "delay")',
                file=sys.stderr,
            )
        if self._loop_groups:
            loop = " -> ".join(system.algebraic_loop() or [])
            members = ", ".join(system.loop_components())
            print(
                f"note: algebraic loop {loop}: {members} iterate to a fixed point within each macro "
                f'step (simulation.algebraic_loops = "iterate", loop_tolerance = '
                f"{system.loop_tolerance:g}, loop_max_iterations = {system.loop_max_iterations}); "
                "the system steps in the Python master loop, not the compiled kernel",
                file=sys.stderr,
            )
        self._step_now = [0] if self._loop_groups else None  # the step `_advance` is in, for the loops
        self._solvers: list[LoopSolver] = []
        self._plan = [
            (
                component,
                system.period_steps(component),
                _gather(
                    system,
                    component,
                    delayed={p: self._previous[p] for p, c in delayed if c == component.name} or None,
                ),
            )
            for component in self.order
        ]
        self._steppers: list[tuple] = []
        self._check_cut_steps()
        self._tail_from = self._first_short_step()

    def _check_loop_states(self) -> None:
        """Every member of an iterated loop must save and restore its state: one-line error otherwise."""
        for names, _ in self._loop_groups:
            for name in names:
                problem = self.system.components[name].state_support()
                if problem is not None:
                    loop = " -> ".join(self.system.algebraic_loop() or names)
                    raise CosimError(
                        f'simulation.algebraic_loops = "iterate" rolls back the components of algebraic '
                        f"loop {loop}, but component '{name}' cannot: {problem}; use "
                        'simulation.algebraic_loops = "delay" (inputs from the previous communication point)'
                    )

    def _loop_solvers(self) -> list[LoopSolver]:
        """One `LoopSolver` per iterated loop, with the plan's gathers (after initialisation)."""
        plan = {entry[0].name: entry for entry in self._plan}
        solvers = []
        for names, connections in self._loop_groups:
            members = [plan[component.name] for component in self.order if component.name in names]
            links = []
            for c in connections:
                producer, output = self.system.resolve(c.source, "output")
                consumer, input_ = self.system.resolve(c.target, "input")
                name = f"{c.source} -> {c.target}"
                links.append(LoopLink(name, producer, output, consumer, input_, c.scale, c.offset))
            label = ", ".join(link.name for link in links)
            solvers.append(
                LoopSolver(
                    f"({label})",
                    members,
                    links,
                    self.system.loop_tolerance,
                    self.system.loop_max_iterations,
                    self.step_seconds,
                )
            )
        return solvers

    def _initial_loop_passes(self, order: list[Component]) -> int:
        """Exchange the loops' connected values until they agree (initialisation, `loops="iterate"`);
        then the components outside the loops take their connected inputs once more (those fed by
        a loop see its settled values). Returns the passes over the loops, the first one included
        (the pass every mode makes: `System.initialized_early`)."""
        solvers = self._loop_solvers()
        members = {name for names, _ in self._loop_groups for name in names}
        looped = [(c, _gather(self.system, c)) for c in order if c.name in members]
        passes = 1
        while True:
            unsettled = [(solver, worst) for solver in solvers if (worst := solver.worst(solver.links))]
            if not unsettled:
                break
            if passes >= self.system.loop_max_iterations:
                solver, worst = unsettled[0]
                raise solver.not_converged(worst, "at initialisation")
            for component, gather in looped:
                if gather is not None:
                    gather()
                    component.push_inputs()
                component.get_outputs()
            passes += 1
        if passes > 1:
            for component in order:
                gather = None if component.name in members else _gather(self.system, component)
                if gather is not None:
                    gather()
                    component.push_inputs()
                    component.get_outputs()
        return passes

    # ---- time --------------------------------------------------------------------------------

    @property
    def time_ns(self) -> int:
        """Start of the next step (the current simulation time) in integer nanoseconds; the stop
        time after a last step cut short to end there."""
        time_ns = self.start_time_ns + self.step_index * self.system.macro_step_ns
        return time_ns if self.stop_time_ns is None else min(time_ns, self.stop_time_ns)

    @property
    def time(self) -> float:
        """Current simulation time [s], exact up to one float rounding of `time_ns`."""
        return self.time_ns / NS_PER_S

    @property
    def steps_to_stop(self) -> int | None:
        """Macro steps from the start to the stop time (None without one); where the stop time is no
        whole number of macro steps after the start the last is shorter, ending at the stop time."""
        if self.stop_time_ns is None:
            return None
        return -(-(self.stop_time_ns - self.start_time_ns) // self.system.macro_step_ns)

    def _check_cut_steps(self) -> None:
        """`CosimError` when the stop time cuts the last step of a component that cannot take a
        shorter step (module docstring, "Stop time")."""
        if self.stop_time_ns is None:
            return
        span_ns = self.stop_time_ns - self.start_time_ns
        for component, period, _ in self._plan:
            step_ns = period * self.system.macro_step_ns
            if span_ns % step_ns == 0 or component.constant_outputs or component.can_vary_step():
                continue
            whole = span_ns // step_ns
            before, after = ((self.start_time_ns + n * step_ns) / NS_PER_S for n in (whole, whole + 1))
            raise CosimError(
                f"stop time {self.stop_time:g} s is not a whole number of steps of component "
                f"'{component.name}' ({step_ns / NS_PER_S:g} s) after the start time "
                f"{self.start_time_ns / NS_PER_S:g} s, and it cannot take the shorter last step that "
                "would end there (no canHandleVariableCommunicationStepSize); give a stop time of "
                f"{before:g} or {after:g} s"
            )

    def _first_short_step(self) -> int | None:
        """The first step at which a component's step would end after the stop time, so is cut to
        end at it (None: none would). Component of period P due at k passes the stop when
        (k + P) h > stop - start, that is k >= floor((stop - start) / h) - P + 1."""
        if self.stop_time_ns is None:
            return None
        whole = (self.stop_time_ns - self.start_time_ns) // self.system.macro_step_ns
        firsts = [due_from(max(0, whole - period + 1), period) for _, period, _ in self._plan]
        return min(firsts, default=None)

    def _check_steps(self, steps: int) -> None:
        if steps < 0:
            raise CosimError(f"number of steps must be >= 0, got {steps}")
        last = self.steps_to_stop
        if last is not None and self.step_index + steps > last:
            raise CosimError(
                f"{steps} steps from t = {self.time:g} s pass the stop time {self.stop_time:g} s "
                f"({last - self.step_index} steps remain)"
            )

    def step_seconds(self, k: int, period: int) -> float:
        """The step [s] of a component of `period` macro steps due at step k: a whole period, or up
        to the stop time when that comes first."""
        h_ns = period * self.system.macro_step_ns
        if self.stop_time_ns is not None:
            h_ns = min(h_ns, self.stop_time_ns - self.start_time_ns - k * self.system.macro_step_ns)
        return h_ns / NS_PER_S

    # ---- lifecycle ---------------------------------------------------------------------------

    def initialize(self) -> None:
        """Instantiate, set up (parameters), and initialise every component (see module doc)."""
        if self._initialized:
            raise CosimError("the master is already initialised")
        t0 = self.start_time_ns / NS_PER_S
        try:
            for component in self.order:
                component.instantiate()
            for component in self.order:
                component.setup(t0, self.parameters.get(component.name, {}), self.stop_time)
            for component in self.order:
                component.enter_initialization()
            ready: set[str] = set()
            order = self.system.initialization_order()
            for component in order:
                gather = _gather(self.system, component, producers=ready)
                if gather is not None:
                    gather()
                component.push_inputs()
                component.push_text()
                component.initialize()
                component.get_outputs()
                ready.add(component.name)
            for component in self.system.initialized_early(order):
                gather = _gather(self.system, component)
                if gather is not None:
                    gather()
                component.push_inputs()
                component.push_text()
                component.get_outputs()
            if self._loop_groups:
                self._signals.output_buffer[0] = self._initial_loop_passes(order)
        except BaseException:
            try:
                self.close()
            except CosimError:
                pass  # terminating the others failed too; the error that stopped initialisation is the news
            raise
        self._initialized = True
        self._skip_constant_producers()
        # Bound once, after initialisation installed the components' fast paths.
        h_ns = self.system.macro_step_ns
        self._solvers = self._loop_solvers() if self._loop_groups else []
        if self._signals is not None:
            self._signals.solvers = self._solvers
        solver_of = {component.name: solver for solver in self._solvers for component, _, _ in solver.members}
        placed: set[int] = set()
        self._steppers = []
        for c, period, gather in self._plan:
            solver = solver_of.get(c.name)
            if solver is None:
                if not c.constant_outputs:
                    self._steppers.append(
                        (period, period * h_ns / NS_PER_S, gather, c.push_inputs, c.do_step, c.get_outputs)
                    )
            elif id(solver) not in placed:  # a loop steps as one entry, at its first member's place
                placed.add(id(solver))
                self._steppers.append((1, h_ns / NS_PER_S, None, None, self._loop_step(solver), _no_outputs))

    def _loop_step(self, solver: LoopSolver) -> Callable[[float, float], None]:
        """The `do_step` of a loop's entry in the Python loop: the loop's macro step (`_advance` keeps
        the step number in `_step_now`)."""
        now = self._step_now

        def do_step(t: float, h: float) -> None:
            solver.step(now[0], t)

        return do_step

    def _skip_constant_producers(self) -> None:
        """Components with constant outputs were copied from at initialisation: from now on their
        connections are not copied again, and an FMU consumer pushes only its other inputs."""
        constant = {name for name, c in self.system.components.items() if c.constant_outputs}
        if not constant:
            return
        dynamic = set(self.system.components) - constant
        plan = []
        for component, period, gather in self._plan:
            fed = self.system.links().get(component.name, ())
            if any(producer in constant for _, producer, _, _ in fed):
                gather = _gather(self.system, component, producers=dynamic)
                static = {index for _, producer, _, index in fed if producer in constant}
                if hasattr(component, "restrict_push"):
                    component.restrict_push([i for i in range(len(component.inputs)) if i not in static])
            plan.append((component, period, gather))
        self._plan = plan

    def _check_running(self) -> None:
        if self.failure is not None:
            raise CosimError(f"the master stopped after a failure: {self.failure}")
        if not self._initialized or self._closed:
            raise CosimError("the master is not running (call initialize() first; not after close())")

    def step(self) -> None:
        """Advance one macro step, from `time` to `time + macro_step` (or to the stop time)."""
        self._check_running()
        self._check_steps(1)
        self._advance(1)

    def run(
        self,
        steps: int,
        callback: Callable[[Master], bool | None] | None = None,
        compiled: bool | None = None,
    ) -> int:
        """Advance `steps` macro steps; return the number done.

        With `callback`, it is called after every step and a true return stops early. Without
        it the loop has no per-step Python callback, and a system whose stepped components are
        all FMUs stepped by C calls runs in the compiled kernel (`cosim.core.kernel`):
        `compiled=None` chooses it for runs of at least `COMPILED_MIN_STEPS`, True forces it where
        possible, False never.
        """
        self._check_running()
        self._check_steps(steps)
        if callback is None:
            wanted = steps >= COMPILED_MIN_STEPS if compiled is None else compiled
            tables = self._kernel(record=False, block=KERNEL_BLOCK) if wanted else None
            if tables is not None:
                self.run_blocks(steps, tables, block=_RUN_BLOCK)
            else:
                self._advance(steps)
            return steps
        return self._advance(steps, callback)

    def run_recorded(
        self,
        steps: int,
        on_block: Callable[[int, int, list[np.ndarray]], None],
        block: int = 1000,
        compiled: bool | None = None,
    ) -> int:
        """Advance `steps` macro steps, keeping every component's inputs and outputs after each of
        its steps; after each block of at most `block` steps call `on_block(first_step, count,
        histories)`, where `histories[i]` (component i of `order`) has one row per step of that
        component in the block, k = first_step .. first_step + count - 1 with k % period == 0:
        its inputs, then its outputs. Returns the steps done.

        A system whose stepped components are all FMUs stepped by C calls runs the blocks in the
        compiled kernel, which fills the rows itself (`compiled` as in `run`); otherwise the Python
        loop copies them.
        """
        self._check_running()
        self._check_steps(steps)
        if block < 1:
            raise CosimError(f"block must be >= 1 step, got {block}")
        wanted = steps >= COMPILED_MIN_STEPS if compiled is None else compiled
        tables = self._kernel(record=True, block=block) if wanted else None
        if tables is not None:
            # Components never stepped (constant outputs) have no rows, as in the Python loop.
            empty = [np.empty((0, len(c.inputs) + len(c.outputs))) for c, _, _ in self._plan]

            def forward(first: int, end: int, delivered: list, clean: bool) -> None:
                kept = [empty[i] if rows is None else rows for i, rows in enumerate(delivered)]
                on_block(first, end - first, kept)

            # All components are stepped by the kernel: its stretches are the blocks.
            self.run_blocks(steps, tables, forward, block=block)
            return steps
        histories = [
            np.empty((block // period + 1, len(c.inputs) + len(c.outputs))) for c, period, _ in self._plan
        ]
        rows = np.zeros(len(histories), dtype=np.int64)
        done = 0
        while done < steps:
            count = min(block, steps - done)
            first = self.step_index
            rows[:] = 0
            try:
                for k in range(first, first + count):
                    self._advance(1)
                    for i, (component, period, _) in enumerate(self._plan):
                        if not component.constant_outputs and (period == 1 or k % period == 0):
                            row = histories[i][rows[i]]
                            row[: len(component.inputs)] = component.input_buffer
                            row[len(component.inputs) :] = component.output_buffer
                            rows[i] += 1
            finally:
                self._deliver(first, on_block, histories, rows)
            done += count
        return steps

    def kernel_tables(self, record: bool = False, block: int = KERNEL_BLOCK) -> fast_loop.KernelTables | None:
        """The tables of `run_blocks` (`cosim.core.kernel`), or None when the kernel cannot run this
        system: no component steps by C calls, or Jacobi mode with a component that needs Python."""
        self._check_running()
        skip = {c.name for c, _, _ in self._plan if c.constant_outputs}
        tables = fast_loop.KernelTables(self._plan, self.system, skip, record, block)
        stepped = [
            native for native, (c, _, _) in zip(tables.native, self._plan, strict=True) if c.name not in skip
        ]
        if not any(native is not None for native in stepped):
            return None
        if self.system.mode == "jacobi" and any(native is None for native in stepped):
            return None
        if self._previous or self._loop_groups:
            return None  # a delayed or iterated loop steps in Python (`_advance`)
        return tables

    def run_blocks(
        self,
        steps: int,
        tables: fast_loop.KernelTables,
        on_block: Callable[[int, int, list, bool], bool | None] | None = None,
        block: int = KERNEL_BLOCK,
        before_block: Callable[[], None] | None = None,
        cut_after_python: Callable[[int], bool] | None = None,
    ) -> int:
        """Advance up to `steps` macro steps through the compiled kernel (`cosim.core.kernel`);
        components that need Python are stepped here where they are due. Returns the steps done.

        After each stretch of complete steps [first, end) -- at most `block` steps, cut where a
        Python component is due (before it steps), at the end of a step in which one stepped, and
        after a step whose watched position (`tables.watch_*`) needs a look -- `on_block(first,
        end, histories, clean)` is called: `histories[i]` holds component i's buffers (inputs,
        then outputs) after each of its steps in the stretch when the tables record it, else None.
        `clean` is True when no component has stepped yet in step `end`: then a true return
        stops the run at `end` (the same place as the Python loop's callback would); otherwise
        the return is ignored. `before_block()` is called before each call of the kernel.

        `cut_after_python(k)`, when given, is asked after the Python components of step k have
        stepped: False lets the stretch go on past step k (so Python components step only in the
        first step of a stretch, and hold their buffers to its end); True, or no callable, ends
        the stretch with step k.
        """
        self._check_running()
        self._check_steps(steps)
        most = tables.record_block or block  # recorded: the rows the tables hold
        if not 1 <= block <= most:
            raise CosimError(f"block must be 1 to {max(1, most)} steps, got {block}")
        from cosim.core import kernel

        h_ns, start_ns = self.system.macro_step_ns, self.start_time_ns
        jacobi = self.system.mode == "jacobi"
        periods = [period for _, period, _ in self._plan]
        stepping = [i for i in range(len(periods)) if tables.components[i, kernel.C_KIND] != kernel.KIND_IDLE]
        end = self.step_index + steps
        first = k = self.step_index
        position = 0
        tables.rows[:] = 0
        finish_step = False  # a Python component stepped: the kernel ends this step, then returns
        while True:
            if k >= end and position == 0:
                break
            if before_block is not None:
                before_block()
            count = 1 if finish_step else min(block, end - k)
            tail = self._tail_from is not None and k >= self._tail_from
            if tail:  # steps cut at the stop time go one at a time, with their step sizes
                count = 1
                for i in stepping:
                    tables.step_sizes[i] = self.step_seconds(k, periods[i])
            elif self._tail_from is not None:
                count = min(count, self._tail_from - k)
            code, k, position, failed, call, status, kind = tables.run(
                k, count, position, start_ns, h_ns, jacobi
            )
            finish_step = False
            clean = position == 0 or not any(k % periods[i] == 0 for i in stepping if i < position)
            if k > first:
                histories = tables.histories()
                delivered = []
                for i, history in enumerate(histories):
                    if history is None:
                        delivered.append(None)
                        continue
                    period = periods[i]
                    n = (k + period - 1) // period - (first + period - 1) // period
                    delivered.append(history[:n])
                self.step_index = k
                stop = on_block(first, k, delivered, clean) if on_block is not None else False
                # Rows of step k already taken (components before `position`) move to the front.
                for i, history in enumerate(histories):
                    if history is not None:
                        n = len(delivered[i])
                        extra = len(history) - n
                        if extra:
                            history[:extra] = history[n:].copy()
                        tables.rows[i] = extra
                first = k
                if stop and clean:
                    break
            self.step_index = k
            if code == kernel.FAILED:
                try:
                    native = tables.native[failed]
                    kind_name = kernel.KINDS[kind]
                    native.fail(
                        call, status, None if call in (0, 2) else (start_ns + k * h_ns) / NS_PER_S, kind_name
                    )
                except CosimError as error:
                    self.failure = error
                    raise
                raise CosimError(f"component '{self._plan[failed][0].name}' failed at step {k}")
            if code == kernel.HAND_BACK:
                # This component, and the next ones due in this step while they need Python too.
                while True:
                    component, period, gather = self._plan[position]
                    try:
                        if gather is not None:
                            gather()
                            component.push_inputs()
                        component.do_step((start_ns + k * h_ns) / NS_PER_S, self.step_seconds(k, period))
                        component.get_outputs()
                    except CosimError as error:
                        self.failure = error
                        raise
                    position += 1
                    following = next((i for i in stepping if i >= position and k % periods[i] == 0), None)
                    if following is None or tables.native[following] is not None:
                        break
                    position = following
                finish_step = cut_after_python is None or cut_after_python(k)
        return self.step_index - (end - steps)

    def _deliver(self, first: int, on_block, histories: list[np.ndarray], rows: np.ndarray) -> None:
        """Hand the rows of the steps that ran (all of them, or up to a failure) to `on_block`."""
        end = self.step_index
        if end <= first:
            return
        # Steps of each component in [first, end): rows of a step cut short by a failure are dropped.
        kept = [
            history[: min(int(n), (end + period - 1) // period - (first + period - 1) // period)]
            for history, n, (_, period, _) in zip(histories, rows, self._plan, strict=True)
        ]
        on_block(first, end - first, kept)

    def _kernel(self, record: bool, block: int) -> fast_loop.KernelTables | None:
        """Tables for `run`/`run_recorded` (kept for the next call), or None when a component that
        is stepped needs Python (or none is stepped by C calls)."""
        key = (record, block)
        if key not in self._kernels:
            tables = self.kernel_tables(record=record, block=block)
            if tables is not None and any(
                native is None and not component.constant_outputs
                for native, (component, _, _) in zip(tables.native, self._plan, strict=True)
            ):
                tables = None
            self._kernels[key] = tables
        return self._kernels[key]

    def _advance(self, steps: int, callback: Callable[[Master], bool | None] | None = None) -> int:
        """Step `steps` times (or until `callback`, called after each step, returns true); return
        the number of steps done. On a failure `step_index` is the step that failed."""
        steppers = self._steppers
        h_ns = self.system.macro_step_ns
        start_ns = self.start_time_ns
        jacobi = self.system.mode == "jacobi"
        tail_from = self._tail_from
        components = self.system.components
        previous = [(copy, components[name].output_buffer) for name, copy in self._previous.items()]
        now = self._step_now
        first = k = self.step_index
        try:
            for k in range(first, first + steps):
                t = (start_ns + k * h_ns) / NS_PER_S
                tail = tail_from is not None and k >= tail_from  # steps cut at the stop time
                for copy, outputs in previous:
                    copy[:] = outputs
                if now is not None:
                    now[0] = k
                if jacobi:
                    due = [entry for entry in steppers if k % entry[0] == 0]
                    for _, _, gather, push, _, _ in due:
                        if gather is not None:
                            gather()
                            push()
                    for period, h, _, _, do_step, get_outputs in due:
                        do_step(t, self.step_seconds(k, period) if tail else h)
                        get_outputs()
                else:
                    for period, h, gather, push, do_step, get_outputs in steppers:
                        if period == 1 or k % period == 0:
                            if gather is not None:
                                gather()
                                push()
                            do_step(t, self.step_seconds(k, period) if tail else h)
                            get_outputs()
                if callback is not None:
                    self.step_index = k + 1
                    if callback(self):
                        return k + 1 - first
        except CosimError as error:
            self.step_index = k
            self.failure = error
            raise
        self.step_index = first + steps
        return steps

    def close(self) -> None:
        """Terminate healthy components and free all; idempotent. Raises the first terminate error."""
        if self._closed:
            return
        self._closed = True
        first_error: CosimError | None = None
        for component in self.order:
            if component.state in (State.SET_UP, State.STEPPING):
                try:
                    component.terminate()
                except CosimError as error:
                    first_error = first_error or error
        for component in self.order:
            component.free()
        if first_error is not None and self.failure is None:
            raise first_error

    def __enter__(self) -> Master:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
