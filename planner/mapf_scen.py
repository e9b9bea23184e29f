"""Moving AI MAPF scenario files (`.scen`): the agents' starts and goals as grid cells.

Format: a `version 1` line, then one agent per line, tab-separated: bucket, map file, map width,
map height, start x, start y, goal x, goal y, optimal length. x is the column, y the row (row 0 at
the top, as in the `.map` file).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from planner.errors import PlannerError


def read_scen(path: str | Path, agents: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(starts, goals): (N, 2) int arrays of (row, col) from the first `agents` lines (all if None)."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as error:
        raise PlannerError(f"{path}: cannot read the scenario: {error.strerror or error}") from None
    if agents is not None and agents < 1:
        raise PlannerError(f"{path}: agents must be >= 1, got {agents}")
    starts, goals = [], []
    for number, line in enumerate(lines, start=1):
        if not line.strip() or line.lower().startswith("version"):
            continue
        fields = line.split("\t") if "\t" in line else line.split()
        if len(fields) < 8:
            raise PlannerError(f"{path}:{number}: expected 9 columns (bucket, map, width, height, "
                               f"start x, start y, goal x, goal y, length), got {len(fields)}")  # fmt: skip
        try:
            sx, sy, gx, gy = (int(value) for value in fields[4:8])
        except ValueError:
            raise PlannerError(f"{path}:{number}: start/goal coordinates must be integers") from None
        starts.append((sy, sx))
        goals.append((gy, gx))
        if agents is not None and len(starts) == agents:
            break
    if agents is not None and len(starts) < agents:
        raise PlannerError(f"{path}: {agents} agents asked for, the scenario has {len(starts)}")
    if not starts:
        raise PlannerError(f"{path}: no agents in the scenario")
    return np.array(starts, dtype=np.int64), np.array(goals, dtype=np.int64)
