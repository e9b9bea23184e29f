"""Connections folded for people: runs of element-to-same-element array connections as one line.

`fold` turns the 720 connections `lidar.ranges[k] -> vfh.ranges[k]` into one
`lidar.ranges[1..360] -> vfh.ranges[1..360]` (for `cosim system` and its block diagram).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from cosim.scenario.description import ConnectionDescription

_ELEMENT = re.compile(r"^(?P<base>[^\[]+)\[(?P<index>\d+(?:,\d+)*)\]$")


@dataclass(frozen=True)
class Link:
    """One connection, or connections between matching elements of two arrays folded into one."""

    source: str  # "component.port" or "component.array[1..n]"
    target: str
    scale: float
    offset: float
    where: str
    count: int = 1


def _element(reference: str) -> tuple[str, tuple[int, ...]] | None:
    """("component.array", indices) of an array element reference, else None."""
    name, _, port = reference.partition(".")
    match = _ELEMENT.match(port)
    if match is None:
        return None
    return f"{name}.{match['base']}", tuple(int(i) for i in match["index"].split(","))


def _ranges(indices: list[tuple[int, ...]]) -> str:
    """`[1..1000,1..2]` for the index tuples of a full block, else the first and last element."""
    columns = list(zip(*indices, strict=True))
    lows, highs = [min(c) for c in columns], [max(c) for c in columns]
    size = 1
    for low, high in zip(lows, highs, strict=True):
        size *= high - low + 1
    if size == len(set(indices)):
        return (
            "["
            + ",".join(
                f"{low}..{high}" if high > low else f"{low}" for low, high in zip(lows, highs, strict=True)
            )
            + "]"
        )
    first, last = indices[0], indices[-1]
    return f"[{','.join(map(str, first))}]..[{','.join(map(str, last))}]"


def fold(connections: tuple[ConnectionDescription, ...] | list[ConnectionDescription]) -> list[Link]:
    """The connections with runs of element-to-same-element array connections folded."""
    links: list[Link] = []
    groups: dict[tuple, list[tuple[int, ...]]] = {}
    for connection in connections:
        source, target = _element(connection.source), _element(connection.target)
        if source is None or target is None or source[1] != target[1]:
            links.append(
                Link(
                    connection.source,
                    connection.target,
                    connection.scale,
                    connection.offset,
                    connection.where,
                )
            )
            continue
        key = (source[0], target[0], connection.scale, connection.offset, connection.where)
        if key not in groups:
            groups[key] = []
            links.append(Link(*key[:2], *key[2:], count=0))  # placeholder, filled in below
        groups[key].append(source[1])
    folded = []
    for link in links:
        if link.count:
            folded.append(link)
            continue
        indices = groups[(link.source, link.target, link.scale, link.offset, link.where)]
        ranges = _ranges(indices)
        folded.append(
            Link(
                link.source + ranges, link.target + ranges, link.scale, link.offset, link.where, len(indices)
            )
        )
    return folded


def number_text(value: float) -> str:
    return f"{value:g}"


def table_lines(rows: list[tuple[str, ...]], indent: str = "  ") -> list[str]:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return [
        indent + "  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)).rstrip()
        for row in rows
    ]


def unconnected_lines(system, description=None) -> list[str]:
    """The inputs that no connection feeds, each with the value it keeps for the run (its start
    value, or the one the scenario holds it at), folded to 12 a component; none: no lines."""
    from cosim.record.inputs import unconnected_inputs, value_text

    kept = unconnected_inputs(system)
    if not kept:
        return []
    count = sum(len(values) for values in kept.values())
    lines = ["", f"unconnected inputs ({count}; each keeps its value for the run)"]
    rows = [("input", "value", "from")]
    for name, values in kept.items():
        held = (
            description.components[name].held_inputs if description and name in description.components else {}
        )
        runs = _runs(
            [
                (port, value_text(value), "held by the scenario" if port in held else "start")
                for port, value in values.items()
            ]
        )
        for position, (port, value, source) in enumerate(runs):
            if position == _LISTED:
                rows.append((f"{name}: ... and {len(runs) - _LISTED} more", "", ""))
                break
            rows.append((f"{name}.{port}", value, source))
    return lines + table_lines(rows)


def _runs(rows: list[tuple[str, str, str]]) -> list[tuple[str, str, str]]:
    """Consecutive elements of one array with the same value and source as one row, `a[3..9]`."""
    folded: list[list] = []
    for port, value, source in rows:
        array, _, index = port[:-1].partition("[") if port.endswith("]") else (port, "", "")
        last = folded[-1] if folded else None
        if (
            last is not None
            and index.isdigit()
            and last[0] == array
            and last[2] + 1 == int(index)
            and last[3:] == [value, source]
        ):
            last[2] = int(index)
            continue
        number = int(index) if index.isdigit() else None
        folded.append([array if number is not None else port, number, number, value, source])
    return [
        (
            name if first is None else f"{name}[{first}]" if first == last else f"{name}[{first}..{last}]",
            value,
            source,
        )
        for name, first, last, value, source in folded
    ]


_LISTED = 12
