"""A Foxglove layout made for one log: `cosim log layout LOG` (docs/logs.md, docs/fleet.md).

`foxglove/navcosim-layout.json` is the shipped layout of a robot run: fixed topic names (/scan,
/plan, ...) and a camera over the shipped 100 m x 60 m warehouse. A fleet's log puts each robot's
topics under its namespace (/robot1/scan, TF frames robot1/odom, robot1/base_link) and may lie on
any map, so its layout is made from the log itself:

- one 3D panel, looking straight down at the centre of the log's /map from far enough that the
  whole map fits a 16:9 view (the height seen is 2 d tan(fovy / 2)); the map, the obstacles, /tf,
  and per robot its scan, plan, pose and goal in the robot's colour (the colours of `cosim log plot`
  and the run's PNG, in the log's robot order), each robot's frames shown with their names;
- plots of every robot's commanded and actual speed and its mixer mode, one line per robot
  (the signals that exist in the log: a robot without a mixer has no mode line).

A robot run's log gets the same layout with one robot and no namespace. The layout is the JSON
that Foxglove's "Layouts -> Import from file..." reads.
"""

from __future__ import annotations

import math

from cosim.errors import CosimError
from cosim.logs.plot_map import PLAN_COLOR, run_colour
from cosim.logs.reader import Log

FOVY = 45.0  # [deg] the 3D panel's vertical field of view
ASPECT = 16 / 9  # the view the camera distance is chosen for
MARGIN = 1.05  # the map fills the view but for this
GRID_LAYER = {  # a 1 m grid on the map frame, as the shipped layout has
    "visible": True,
    "layerId": "foxglove.Grid",
    "frameId": "map",
    "size": 50,
    "divisions": 50,
    "lineWidth": 1,
    "color": "#248eff40",
    "position": [0, 0, -0.01],
    "rotation": [0, 0, 0],
    "order": 1,
}


def robot_namespaces(log: Log) -> list[tuple[str, str]]:
    """(name, topic prefix) of each robot of the log: ("robot1", "/robot1") ... for a fleet,
    ("robot", "") for a robot run."""
    robots = log.robots
    return [(name, f"/{name}") for name in robots] if robots else [("robot", "")]


def camera(log: Log) -> dict:
    """The 3D panel's camera: straight down at the map's centre, the whole map in a 16:9 view."""
    grid = log.map()
    if grid is None:
        raise CosimError(f"{log.path}: no /map in the log: a layout needs the map to frame")
    rows, cols = grid.shape
    width, height = cols * grid.resolution, rows * grid.resolution
    centre = (grid.origin[0] + width / 2, grid.origin[1] + height / 2)
    seen = max(height, width / ASPECT) * MARGIN  # the view's height that holds the whole map
    distance = seen / (2 * math.tan(math.radians(FOVY) / 2))
    return {
        "perspective": False,
        "distance": round(distance, 3),
        "phi": 0,
        "thetaOffset": 90,
        "target": [round(centre[0], 6), round(centre[1], 6), 0],
        "targetOffset": [0, 0, 0],
        "targetOrientation": [0, 0, 0, 1],
        "fovy": FOVY,
        "near": 0.5,
        "far": 5000,
    }


def foxglove_layout(log: Log) -> dict:
    """The layout of `log` (module docstring)."""
    topics = {info.name for info in log.topics}
    robots = robot_namespaces(log)
    fleet = bool(log.robots)
    panel_topics: dict[str, dict] = {"/map": {"visible": True, "colorMode": "map", "alpha": 1}}
    transforms = {"frame:map": {"visible": True}}
    for index, (name, prefix) in enumerate(robots):
        colour = run_colour(index) if fleet else PLAN_COLOR
        frames = (f"{name}/odom", f"{name}/base_link") if fleet else ("odom", "base_link")
        transforms.update({f"frame:{frame}": {"visible": True} for frame in frames})
        solid = [f"{colour}ff", f"{colour}ff"]
        wanted = {
            f"{prefix}/map_inflated": {"visible": not fleet, "colorMode": "costmap", "alpha": 0.35},
            f"{prefix}/plan": {"visible": True, "lineWidth": 0.08, "gradient": solid},
            f"{prefix}/scan": {"visible": True, "pointSize": 4, "colorMode": "flat", "flatColor": solid[0]},
            f"{prefix}/pose": {"visible": True, "type": "arrow", "color": solid[0]},
            f"{prefix}/goal": {"visible": True, "type": "arrow", "color": solid[0]},
        }
        panel_topics.update({topic: style for topic, style in wanted.items() if topic in topics})
    for topic in ("/obstacles", "/tf"):
        if topic in topics:
            panel_topics[topic] = {"visible": True}
    three_d = {
        "followTf": "map",
        "followMode": "follow-none",
        "cameraState": camera(log),
        "scene": {"transforms": {"showLabel": True, "axisScale": 0.5}},
        "transforms": transforms,
        "topics": panel_topics,
        "layers": {"grid": GRID_LAYER},
        "foxglovePanelTitle": f"map, {'robots' if fleet else 'robot'}: plan, scan, pose, goal (/tf)",
    }
    components = set(log.components)
    speed, mode = [], []
    for index, (name, prefix) in enumerate(robots):
        colour = run_colour(index) if fleet else PLAN_COLOR
        vehicle, mixer = (f"{name}:vehicle", f"{name}:mixer") if fleet else ("vehicle", "mixer")
        label = f"{name} " if fleet else ""
        if vehicle in components:
            names = log.signal_names(vehicle)
            for signal, what in (("v", "commanded"), ("v_actual", "actual")):
                if signal in names:
                    speed.append(_path(f"{prefix}/signals/vehicle.{signal}", f"{label}v {what}", colour))
        if mixer in components and "mode" in log.signal_names(mixer):
            mode.append(_path(f"{prefix}/signals/mixer.mode", f"{label}mode", colour))
    config = {"3D!navcosim": three_d}
    plots = []
    if speed:
        config["Plot!speed"] = _plot("vehicle speed [m/s]", speed)
        plots.append("Plot!speed")
    if mode:
        config["Plot!mode"] = _plot("mixer mode (0 follow, 1 avoid, 2 recover, 3 stopped)", mode)
        plots.append("Plot!mode")
    layout: str | dict = "3D!navcosim"
    if plots:
        side = plots[0] if len(plots) == 1 else {
            "direction": "column", "first": plots[0], "second": plots[1], "splitPercentage": 60,
        }  # fmt: skip
        layout = {"direction": "row", "first": "3D!navcosim", "second": side, "splitPercentage": 62}
    return {
        "configById": config,
        "globalVariables": {},
        "userNodes": {},
        "linkedGlobalVariables": [],
        "playbackConfig": {"speed": 1},
        "layout": layout,
    }


def _path(value: str, label: str, colour: str) -> dict:
    return {
        "value": value,
        "enabled": True,
        "timestampMethod": "receiveTime",
        "label": label,
        "color": colour,
    }


def _plot(title: str, paths: list[dict]) -> dict:
    return {
        "title": title,
        "paths": paths,
        "showXAxisLabels": True,
        "showYAxisLabels": True,
        "showLegend": True,
        "legendDisplay": "floating",
        "isSynced": True,
        "xAxisVal": "timestamp",
    }
