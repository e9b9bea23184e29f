"""What a run's plot shows, as arrays (`PlotData`): what `cosim.logs.plot.collect` gathers from a log
or a run's trace and `cosim.logs.plot.draw` turns into pixels (and what `cosim run` hands to the
child process that draws), with the colours and names of the mixer's modes."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MODE_AVOID, MODE_RECOVER = 1, 2
MODE_COLORS = {MODE_AVOID: "#ff9f1c", MODE_RECOVER: "#d62828"}
MODE_NAMES = {MODE_AVOID: "{avoider} avoiding (mode 1)", MODE_RECOVER: "recovering (mode 2)"}
ZONE_RGBA = (0.55, 0.7, 0.95, 0.55)  # the inflated zone over free cells


def mode_name(mode: int, avoider: str) -> str:
    return MODE_NAMES[mode].format(avoider=avoider)


@dataclass
class Series:
    label: str  # legend text
    unit: str  # y axis unit
    t: np.ndarray  # [s]
    values: np.ndarray
    panel: str  # series with the same panel share an axis


@dataclass
class PlotData:
    """Everything the figure shows, as arrays: what `draw` turns into pixels."""

    title: str
    image: np.ndarray | None = (
        None  # RGBA bytes of the map: occupied cells, free cells, inflated zone; row 0 at the top
    )
    extent: tuple[float, float, float, float] | None = None  # the image's (x0, x1, y0, y1) [m]
    has_zone: bool = False
    obstacles: list[np.ndarray] = field(default_factory=list)  # polygons, N x 2 [m]
    tracks: list[np.ndarray] = field(default_factory=list)  # moving obstacles' centres, N x 2 [m]
    plans: list[tuple[float, np.ndarray]] = field(default_factory=list)  # (t [s], N x 2 [m]) oldest first
    reverse: list[np.ndarray] = field(default_factory=list)  # per plan, per segment: the car reverses
    trajectory: np.ndarray | None = None  # N x 2 [m]
    end: tuple[float, float, str] | None = None  # where a run that missed its goal ended, and why
    mode_points: dict[int, np.ndarray] = field(default_factory=dict)  # mode -> trajectory points in it
    start: tuple[float, float, float] | None = None
    goal: tuple[float, float] | None = None  # in force at the end (the outcome's)
    goals: list[tuple[float, float, float]] = field(default_factory=list)  # (t [s], x, y [m]) given
    tolerance: float | None = None
    limits: tuple[float, float, float, float] | None = None  # x0, x1, y0, y1 of the map view
    series: list[Series] = field(default_factory=list)
    modes: tuple[np.ndarray, np.ndarray] | None = None  # (t [s], mode) of the mixer
    label: str = ""  # the run's name in an overlay (its log's stem)
    avoider: str = "VFH"  # the avoider that ran (`avoider_name`)

    @property
    def plan(self) -> np.ndarray | None:
        """The plan in force at the end, N x 2 [m], or None."""
        return self.plans[-1][1] if self.plans else None
