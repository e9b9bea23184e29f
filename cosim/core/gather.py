"""The copy of a consumer's connected inputs from its producers' outputs, generated per consumer
(`make_gather`): the Python master loop runs it for every due component on every step.

A generated gather is straight-line code, one statement per value (the connection's arithmetic as
`cosim.core.fast_loop.transfer_expression` writes it, which the compiled kernel copies), or for many
values from one producer one NumPy copy per kind of link (plain copies of a few stretches of
consecutive inputs from evenly spaced outputs, an array port, as slice copies). For two values
from a vehicle it reads:

    def gather():
        target[0] = source0[0]
        target[1] = source0[2] * -1.0
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

import numpy as np

from cosim.core import fast_loop
from cosim.core.component import Component

if TYPE_CHECKING:
    from cosim.core.system import Link, System

# Below this many values from one producer, per-value ctypes copies beat one NumPy fancy-index copy.
_SCALAR_COPY_LIMIT = 4
# Up to this many stretches of consecutive values, slice copies beat one NumPy fancy-index copy (a
# 2000-value path: ~1 us per slice against ~8 us).
_SLICE_COPY_LIMIT = 4


def _runs(sources: np.ndarray, targets: np.ndarray) -> list[tuple[int, int, int, int]] | None:
    """The copies as (source start, source stride, target start, length) stretches of consecutive
    inputs from evenly spaced outputs (an array port, or two interleaved); None when there are more
    than `_SLICE_COPY_LIMIT`, or an input is written twice (then the links' order decides)."""
    order = np.argsort(targets, kind="stable")
    sources, targets = sources[order], targets[order]
    count = len(targets)
    steps = np.diff(sources)
    # Per pair of neighbours: the outputs' stride when the inputs are consecutive, else 0.
    link = np.where((np.diff(targets) == 1) & (steps >= 1), steps, 0)
    if (np.diff(targets) == 0).any():
        return None
    changes = np.flatnonzero(np.diff(link)) + 1  # where a stretch of equal strides starts
    runs = []
    first = 0
    while first < count:
        if len(runs) == _SLICE_COPY_LIMIT:
            return None
        if first < count - 1 and link[first]:  # on while the stride stays the same
            stride = int(link[first])
            later = np.searchsorted(changes, first, side="right")
            end = (int(changes[later]) if later < len(changes) else count - 1) + 1
        else:
            stride, end = 1, first + 1
        runs.append((int(sources[first]), stride, int(targets[first]), end - first))
        first = end
    return runs


def make_gather(
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
    The code and its index arrays depend on the links alone: they are worked out once for the
    system's graph (`System._cached`, shared by the systems of one structure), the buffers bound
    at each call.
    """
    key = ("gather", consumer.name, None if producers is None else frozenset(producers))
    plan = system._cached(key)
    if plan is None:
        plan = system._keep(key, _gather_plan(system, consumer, producers))
    if not plan:
        return None
    code, producer_names, arrays = plan
    names: dict[str, object] = {"target": consumer.input_cbuffer, "target_array": consumer.input_buffer}
    for number, producer_name in enumerate(producer_names):
        if delayed is not None and producer_name in delayed:
            names[f"source{number}"] = names[f"source_array{number}"] = delayed[producer_name]
        else:
            producer = system.components[producer_name]
            names[f"source{number}"] = producer.output_cbuffer
            names[f"source_array{number}"] = producer.output_buffer
    names.update(arrays)
    exec(code, names)  # noqa: S102 - generated from our own templates
    return names["gather"]


def _gather_plan(system: System, consumer: Component, producers: set[str] | None) -> tuple:
    """What `make_gather` generates for the consumer's links: (the compiled `gather`, the producer
    bound to each `source<n>`, the index and scale arrays it reads, read-only); () without links."""
    groups: dict[str, list[Link]] = {}
    for link in system.links().get(consumer.name, ()):
        if producers is None or link.producer in producers:
            groups.setdefault(link.producer, []).append(link)
    if not groups:
        return ()
    arrays: dict[str, np.ndarray] = {}
    lines = ["def gather():"]
    for number, links in enumerate(groups.values()):
        if len(links) <= _SCALAR_COPY_LIMIT:
            for link in links:
                scale, offset = link.connection.scale, link.connection.offset
                value = fast_loop.transfer_expression(f"source{number}[{link.output}]", scale, offset)
                lines.append(f"    target[{link.input}] = {value}")
            continue
        # One NumPy copy per kind of link, each with exactly the arithmetic of the scalar path (a
        # plain copy stays a copy: adding 0.0 would turn -0.0 into 0.0).
        count = len(links)
        sources = np.fromiter((link.output for link in links), np.intp, count)
        targets = np.fromiter((link.input for link in links), np.intp, count)
        scales = np.fromiter((link.connection.scale for link in links), np.float64, count)
        offsets = np.fromiter((link.connection.offset for link in links), np.float64, count)
        plain = (scales == 1.0) & (offsets == 0.0)
        kinds = {"copy": plain, "scaled": ~plain & (offsets == 0.0), "affine": offsets != 0.0}
        for kind, chosen in kinds.items():  # (a mask keeps the links' order)
            if not chosen.any():
                continue
            key = f"{number}_{kind}"
            if kind == "copy":
                runs = _runs(sources[chosen], targets[chosen])
                if runs is not None:  # a few stretches (an array port): slice copies, no index arrays
                    for source, stride, target, length in runs:
                        step = "" if stride == 1 else f":{stride}"
                        lines.append(
                            f"    target_array[{target}:{target + length}] = "
                            f"source_array{number}[{source}:{source + (length - 1) * stride + 1}{step}]"
                        )
                    continue
            arrays[f"sources{key}"] = sources[chosen]
            arrays[f"targets{key}"] = targets[chosen]
            arrays[f"scales{key}"] = scales[chosen]
            arrays[f"offsets{key}"] = offsets[chosen]
            value = f"source_array{number}[sources{key}]"
            if kind != "copy":
                value += f" * scales{key}" + (f" + offsets{key}" if kind == "affine" else "")
            lines.append(f"    target_array[targets{key}] = {value}")
    for array in arrays.values():
        array.flags.writeable = False  # shared by the gathers of every system of this graph
    return compile("\n".join(lines), "<string>", "exec"), tuple(groups), arrays


class Snapshot:
    """One flat copy of several producers' outputs (`take`: one NumPy call), from which a consumer's
    plain links from many of them are copied in one index copy (`gather`): a fleet's lidar reading
    two values from each of 50 vehicles, rather than 100 per-value copies. Only for producers whose
    outputs do not change between `take` and the gathers."""

    def __init__(self, producers: list[Component]) -> None:
        self.buffers = [producer.output_buffer for producer in producers]
        starts = np.cumsum([0] + [len(buffer) for buffer in self.buffers]).tolist()
        self.start = {producer.name: start for producer, start in zip(producers, starts, strict=False)}
        self.values = np.empty(starts[-1])

    def take(self) -> None:
        """Copy the producers' outputs now."""
        if self.buffers:
            np.concatenate(self.buffers, out=self.values)

    def gather(self, consumer: Component, links: list[Link]) -> Callable[[], None]:
        """A function copying `links` (plain copies, from producers of the snapshot) into the
        consumer's inputs from the last `take`."""
        if any(not link.connection.is_plain for link in links):
            raise ValueError("a snapshot gathers plain copies only")
        sources = np.array([self.start[link.producer] + link.output for link in links], np.intp)
        targets = np.array([link.input for link in links], np.intp)
        values, target = self.values, consumer.input_buffer

        def gather() -> None:
            target[targets] = values[sources]

        return gather
