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
