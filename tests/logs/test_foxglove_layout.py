"""`cosim log layout`: a Foxglove layout made from a log shows every robot. Truth: the log read by
the mcap package and its own ROS 2 decoder (its topics, the /tf frames, the /map's size), the
camera geometry (the height seen is 2 d tan(fovy / 2)) and the shipped robot layout."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from cosim.logs.layout import foxglove_layout
from cosim.logs.reader import open_log
from cosim.navigation.fleet import run_fleet
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def fleet_log(tmp_path_factory) -> Path:
    """Four robots crossing (stopped after 2 s: every topic is there by then)."""
    path = tmp_path_factory.mktemp("layout") / "intersection.mcap"
    fleet = load_scenario(
        REPO / "scenarios" / "fleet_intersection.toml", ["simulation.stop_time=2.0"], fleet=True
    )
    run_fleet(fleet, log_path=path)
    return path


def _topics_and_frames(path: Path) -> tuple[set[str], set[str], tuple[float, float, float, float]]:
    """The log's topics, every frame named on /tf, and the map's (x0, y0, width, height) [m]."""
    frames: set[str] = set()
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        topics = {channel.topic for channel in reader.get_summary().channels.values()}
        for _, _, _, message in reader.iter_decoded_messages(topics=["/tf"]):
            for transform in message.transforms:
                frames |= {transform.header.frame_id, transform.child_frame_id}
        (_, _, _, grid), *_ = reader.iter_decoded_messages(topics=["/map"])
    info = grid.info
    size = (
        info.origin.position.x,
        info.origin.position.y,
        info.width * info.resolution,
        info.height * info.resolution,
    )
    return topics, frames, size


def _check(layout: dict, path: Path) -> dict:
    """Every topic the layout names is in the log, its frames are the log's /tf frames, and its
    camera looks at the map's centre with the whole map in a 16:9 view; the 3D panel."""
    topics, frames, (x0, y0, width, height) = _topics_and_frames(path)
    panel = layout["configById"]["3D!navcosim"]
    assert set(panel["topics"]) <= topics
    assert {name.removeprefix("frame:") for name in panel["transforms"]} == frames
    plotted = {p["value"].rpartition(".")[0] for k, v in layout["configById"].items() if k.startswith("Plot!")
               for p in v["paths"]}  # fmt: skip
    assert plotted <= topics
    camera = panel["cameraState"]
    assert tuple(camera["target"][:2]) == pytest.approx((x0 + width / 2, y0 + height / 2))
    seen = 2 * camera["distance"] * math.tan(math.radians(camera["fovy"]) / 2)
    assert seen >= height and seen * 16 / 9 >= width
    assert seen < 1.2 * max(height, width * 9 / 16)
    return panel


def test_a_fleet_layout_shows_every_robot_in_its_colour(fleet_log):
    layout = foxglove_layout(open_log(fleet_log))
    panel = _check(layout, fleet_log)
    robots = [f"robot{k}" for k in range(1, 5)]
    colours = set()
    for name in robots:
        for what in ("scan", "plan", "pose", "goal"):
            assert panel["topics"][f"/{name}/{what}"]["visible"]
        colours.add(panel["topics"][f"/{name}/scan"]["flatColor"])
        assert (
            panel["topics"][f"/{name}/plan"]["gradient"][0] == panel["topics"][f"/{name}/scan"]["flatColor"]
        )
    assert len(colours) == len(robots)
    speed = layout["configById"]["Plot!speed"]["paths"]
    assert {p["value"] for p in speed} == {
        f"/{n}/signals/vehicle.{s}" for n in robots for s in ("v", "v_actual")
    }
    json.dumps(layout)  # plain JSON


def test_a_robot_run_gets_the_shipped_layouts_topics(tmp_path):
    from cosim.navigation.run import run_scenario

    path = tmp_path / "run.mcap"
    scenario = load_scenario(
        REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml", ["simulation.stop_time=1.0"]
    )
    run_scenario(scenario, path, trace=False)
    panel = _check(foxglove_layout(open_log(path)), path)
    shipped = json.loads((REPO / "foxglove" / "navcosim-layout.json").read_text())["configById"][
        "3D!navcosim"
    ]
    assert set(panel["topics"]) == set(shipped["topics"])
    assert set(panel["transforms"]) == set(shipped["transforms"])


@pytest.mark.slow
def test_cosim_log_layout_writes_the_file(fleet_log, tmp_path):
    out = tmp_path / "fleet.layout.json"
    command = [sys.executable, "-m", "cosim", "log", "layout", str(fleet_log), "--out", str(out)]
    done = subprocess.run(command, capture_output=True, text=True, cwd=REPO, check=False)
    assert done.returncode == 0, done.stderr
    assert "4 robots" in done.stdout
    assert json.loads(out.read_text()) == foxglove_layout(open_log(fleet_log))
    again = subprocess.run(command, capture_output=True, text=True, cwd=REPO, check=False)
    assert again.returncode == 2 and "already exists" in again.stderr


def test_a_log_without_map_is_refused_in_one_line(tmp_path):
    from cosim.errors import CosimError
    from cosim.record.recorder import Recorder

    path = tmp_path / "bare.mcap"
    Recorder(path).close({"reason": "none"})
    with pytest.raises(CosimError, match=r"no /map in the log"):
        foxglove_layout(open_log(path))
