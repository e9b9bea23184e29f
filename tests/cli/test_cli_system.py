"""`cosim system SCENARIO [--png FILE]`: the expanded system as text and as a block diagram."""

from __future__ import annotations

import re

import numpy as np
import pytest
from fixtures.pythonfmu_fixtures import pythonfmu_fmu
from test_compose import LAG, write_scenario

from cosim.cli import main
from cosim.navigation.build import build_run
from cosim.scenario.load import load_scenario

BEAMS = 360  # lidar beams of the shipped differential-drive scenarios
WAYPOINTS = 1000  # rows of the planner's output


@pytest.fixture(scope="module")
def lag_scenario(tmp_path_factory):
    extra = LAG.format(fmu=pythonfmu_fmu("first_order_lag"), T=0.5)
    extra = extra.replace('to = "lag.u"', 'to = "lag.u"\nscale = 0.5\noffset = 0.25')
    tmp_path = tmp_path_factory.mktemp("system")
    return write_scenario(tmp_path, "lag", "warehouse_diff_drive_one_obstacle.toml", extra)


def test_system_prints_components_connections_and_step_order(lag_scenario, capsys):
    assert main(["system", str(lag_scenario)]) == 0
    out = capsys.readouterr().out
    sections = dict(re.findall(r"(?ms)^(components|connections|step order)\b[^\n]*\n(.*?)(?:\n\n|\Z)", out))
    rows = {line.split()[0]: line for line in sections["components"].splitlines()[1:]}
    assert list(rows) == ["planner", "pure_pursuit", "lidar", "vfh", "mixer", "vehicle", "lag"]
    assert re.search(
        r"FirstOrderLag \(.*FirstOrderLag\.fmu\)\s+2\.0\s+100 Hz \(every step\)\s+\[components\.lag\]",
        rows["lag"],
    )
    assert re.search(
        r"PurePursuit .*\s2\.0\s+20 Hz \(every 5 steps\)\s+\[pure_pursuit\]", rows["pure_pursuit"]
    )
    assert re.search(r"Python lidar .*\s-\s+10 Hz \(every 10 steps\)", rows["lidar"])
    # The template's connections (pose to Pure Pursuit and lidar, waypoints, beams, commands, the
    # two vehicle inputs, and the replanning planner's pose, ranges and VFH direction), one
    # replaced by the scenario's, plus the scenario's two.
    template = 6 + 2 * WAYPOINTS + 2 * BEAMS + 6 + 2 + (3 + BEAMS + 1)
    assert f"connections ({template - 1 + 2}; input = output * scale + offset)" in out
    lines = sections["connections"].splitlines()
    assert re.search(
        rf"planner\.waypoints\[1\.\.{WAYPOINTS},1\.\.2\]\s+pure_pursuit\.waypoints\[1\.\.{WAYPOINTS},1\.\.2\]"
        rf"\s+1\s+0\s+navigation template \({2 * WAYPOINTS} connections\)",
        "\n".join(lines),
    )
    assert any(
        re.fullmatch(r"\s*mixer\.v\s+lag\.u\s+0\.5\s+0\.25\s+\[\[connections\]\]\[0\]", line)
        for line in lines
    )
    assert any(
        re.fullmatch(r"\s*lag\.y\s+vehicle\.v\s+1\s+0\s+\[\[connections\]\]\[1\]", line) for line in lines
    )
    assert re.search(
        r"mixer\.v\s+->\s+vehicle\.v\s+replaced by\s+\[\[connections\]\]\[1\]\s+\(from lag\.y\)", out
    )
    order = [line.split(". ", 1)[1].split()[0] for line in sections["step order"].splitlines()]
    assert sorted(order) == sorted(rows)
    # Replanning (the default): the planner steps with the lidar, after it (it reads the scan).
    assert re.search(r"Python planner .*\s-\s+10 Hz \(every 10 steps\)", rows["planner"])
    assert order.index("lidar") < order.index("planner") < order.index("pure_pursuit")


def test_step_order_puts_every_direct_producer_first(lag_scenario, capsys):
    """Gauss-Seidel: a producer whose output depends directly on its inputs steps before a consumer
    whose outputs depend directly on that connection's input (the replanning planner reads VFH's
    direction of the step before: its waypoints do not depend on it, else VFH -> planner -> Pure
    Pursuit -> VFH would be a loop)."""
    assert main(["system", str(lag_scenario)]) == 0
    out = capsys.readouterr().out
    order = re.findall(r"(?m)^  \d+\. (\w+)", out)
    description = build_run(load_scenario(lag_scenario)).description
    for connection in description.connections:
        producer = description.components[connection.source_component]
        output = connection.source.split(".", 1)[1]
        consumer = description.components[connection.target_component]
        used = connection.target.split(".", 1)[1]
        direct_use = any(used in consumer.feedthrough.get(o, consumer.inputs) for o in consumer.outputs)
        if producer.feedthrough.get(output, producer.inputs) and direct_use:  # a Python output lists none
            assert order.index(producer.name) < order.index(connection.target_component), connection


def test_system_png_is_a_block_diagram(lag_scenario, tmp_path, capsys):
    import matplotlib.image

    png = tmp_path / "system.png"
    assert main(["system", str(lag_scenario), "--png", str(png)]) == 0
    assert f"block diagram: {png}" in capsys.readouterr().out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = matplotlib.image.imread(png)[:, :, :3]
    assert image.shape[0] >= 400 and image.shape[1] >= 1200

    def share(colour: str) -> float:
        rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)]) / 255
        return float(np.mean(np.all(np.abs(image - rgb) < 0.02, axis=2)))

    # Boxes: FMUs, Python components and the added lag in their fills; the scenario's arrows orange.
    assert share("#dbe9f6") > 0.01 and share("#e5f5e0") > 0.005 and share("#fde0c5") > 0.002
    assert share("#d95f02") > 0.0002


def test_system_of_a_broken_scenario_lists_its_problems(tmp_path, capsys):
    extra = '[[connections]]\nfrom = "mixr.v"\nto = "vehicle.vv"\n'
    path = write_scenario(tmp_path, "broken", "warehouse_diff_drive_one_obstacle.toml", extra)
    assert main(["system", str(path)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 2
    assert "[[connections]][0].to: component 'vehicle' has no input 'vv' (did you mean 'v'?)" in lines[0]
    assert "[[connections]][0].from: no component 'mixr' (did you mean 'mixer'?)" in lines[1]


def test_system_lists_removed_and_replaced_components_and_dropped_connections(tmp_path, capsys):
    from test_compose import direct_scenario, replacement_scenario

    replaced = replacement_scenario(tmp_path)
    png = tmp_path / "replaced.png"
    assert main(["system", str(replaced), "--png", str(png)]) == 0
    out = capsys.readouterr().out
    rows = re.findall(r"(?m)^  (\w+)\s+\S", out.split("components (")[1].split("\n\n")[0])[1:]
    assert rows == ["planner", "pure_pursuit", "lidar", "vfh", "mixer", "vehicle"]
    assert re.search(
        r"(?m)^  pure_pursuit\s+fixture_controller_fmi2 .*20 Hz .*\[components\.pure_pursuit\]$", out
    )
    assert "PurePursuit" not in out
    assert "template components replaced: pure_pursuit (by [components.pure_pursuit])" in out
    assert f"template connections dropped with them ({2 * WAYPOINTS + 3})" in out
    dropped = out.split("template connections dropped with them")[1].split("\n\n")[0]
    assert re.search(
        rf"planner\.waypoints\[1\.\.{WAYPOINTS},1\.\.2\]\s+pure_pursuit\.waypoints\[1\.\.{WAYPOINTS},1\.\.2\]\s+"
        rf"\[components\.pure_pursuit\] has no such input \({2 * WAYPOINTS} connections\)",
        dropped,
    )
    for target in ("vfh.target_dir", "mixer.target_dir"):
        assert re.search(
            rf"pure_pursuit\.target_dir\s+{re.escape(target)}\s+\[components\.pure_pursuit\] has no", dropped
        )
    assert re.search(r"pure_pursuit\.goal_reached\s+mixer\.goal_reached\s+", dropped)
    assert "command for /cmd_vel and the /odom twist: mixer.v, mixer.omega" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    removed = direct_scenario(tmp_path)
    assert main(["system", str(removed), "--png", str(tmp_path / "removed.png")]) == 0
    out = capsys.readouterr().out
    assert "components (4)" in out
    assert "template components removed ([system].remove): pure_pursuit, vfh, mixer" in out
    # Every template connection to or from them: pose, waypoints, beams, commands, the vehicle's
    # two inputs; the planner does not replan here (no pose, ranges, direction into it).
    count = 3 + 2 * WAYPOINTS + 2 * BEAMS + 6 + 2
    assert f"template connections dropped with them ({count})" in out
    assert re.search(r"mixer\.v\s+vehicle\.v\s+mixer is removed by \[system\]\.remove", out)
    assert "command for /cmd_vel and the /odom twist: go_to_goal.v, go_to_goal.omega" in out
    assert "avoidance mode for the outcome: none (the VFH counts of the outcome stay 0)" in out
    assert "scan for /scan: lidar.ranges" in out
