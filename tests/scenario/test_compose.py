"""Scenario composition: `[components.NAME]` and `[[connections]]` on top of the navigation template.

- A third-party first-order lag (made with PythonFMU, tests/fixtures/pythonfmu_src) between the
  mixer and the vehicle: the run reaches the goal and the logged `vehicle.v` is the exact
  first-order response to the logged mixer command (closed form while the command is constant,
  the exact held-input recursion over the whole run).
- A go-to-goal FMU (the `controller_fmi2` C fixture) replaces Pure Pursuit (`[components.pure_pursuit]`):
  PurePursuit is gone from the system and the log, the robot drives the straight corridor at the
  controller's 1 m/s, so the goal is reached at the analytic time and distance.
- With Pure Pursuit, VFH and the mixer removed (`[system] remove`), the go-to-goal FMU drives the
  vehicle directly along a curve: the logged pose matches an independent integration of the law
  (numpy, exact arcs) to 1e-9, and the run ends when that integration enters the goal tolerance.
- A connection's scale and offset reach the FMU input exactly; an added component's input can be
  held at a value.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu
from fixtures.pythonfmu_fixtures import pythonfmu_fmu

from cosim.logs import open_log
from cosim.navigation.build import build_run
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = REPO / "scenarios"
MACRO_STEP = 0.01  # [s] of the shipped scenarios
LAG_T = 0.5  # [s] time constant of the lag


def write_scenario(tmp_path: Path, name: str, base: str, extra: str, replace: dict | None = None) -> Path:
    """A shipped scenario with an absolute map path, `replace` applied (regex -> text), `extra` added."""
    text = (SCENARIOS / base).read_text()
    text = re.sub(r'(?m)^file = "maps/', f'file = "{SCENARIOS}/maps/', text)
    for pattern, substitute in (replace or {}).items():
        text, count = re.subn(pattern, substitute, text, flags=re.MULTILINE)
        assert count == 1, pattern
    path = tmp_path / f"{name}.toml"
    path.write_text(text + "\n" + extra)
    return path


def held(source_t_ns: np.ndarray, values: np.ndarray, at_t_ns: np.ndarray) -> np.ndarray:
    """Sample and hold: the value of the most recent sample at or before each time."""
    return values[np.searchsorted(source_t_ns, at_t_ns, side="right") - 1]


LAG = """
[components.lag]
fmu = "{fmu}"
T = {T}

[[connections]]
from = "mixer.v"
to = "lag.u"

[[connections]]
from = "lag.y"
to = "vehicle.v"
"""


@pytest.fixture(scope="module")
def lag_run(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("lag")
    extra = LAG.format(fmu=pythonfmu_fmu("first_order_lag"), T=LAG_T)
    path = write_scenario(tmp_path, "lag", "warehouse_diff_drive_one_obstacle.toml", extra)
    scenario = load_scenario(path, ["output.plot=false"])
    built = build_run(scenario)
    order = [component.name for component in built.system.order()]
    result = run_scenario(scenario, tmp_path / "lag.mcap")
    return built, order, result, open_log(tmp_path / "lag.mcap")


def test_lag_sits_between_mixer_and_vehicle(lag_run):
    built, order, _, log = lag_run
    description = built.description
    assert description.components["lag"].model_name == "FirstOrderLag"
    assert log.metadata["fmu/lag"]["generation_tool"].startswith("PythonFMU")
    targets = {c.target: c for c in description.connections}
    assert targets["vehicle.v"].source == "lag.y" and targets["lag.u"].source == "mixer.v"
    assert [(old.source, new.where) for old, new in description.replaced] == [
        ("mixer.v", "[[connections]][1]")
    ]
    # PythonFMU declares no dependencies: y depends on u directly, so the lag steps after the
    # mixer and before the vehicle (Gauss-Seidel), though it was added last.
    assert order.index("mixer") < order.index("lag") < order.index("vehicle")


def test_lag_run_reaches_the_goal_with_the_first_order_response_on_vehicle_v(lag_run):
    _, _, result, log = lag_run
    assert result.failure is None
    assert result.outcome.reached and result.outcome.reason == "goal_reached"
    vehicle, mixer, lag = log.signals("vehicle"), log.signals("mixer"), log.signals("lag")
    # Each record holds values at its stamp: inputs applied at t, outputs at t (the last record is
    # the end of the run). Gauss-Seidel: an input applied at t_k is its producer's output after the
    # producer's step at t_k, i.e. the producer's record at its next stamp.
    steps = vehicle.t_ns[:-1]
    command = mixer["v"][np.searchsorted(mixer.t_ns, steps, side="right")]  # mixer output after its step
    np.testing.assert_array_equal(lag["u"][:-1], command)  # the lag saw exactly the mixer's command
    assert lag["y"][0] == 0.0
    np.testing.assert_array_equal(lag["y"][1:], vehicle["v"][:-1])
    vehicle_v = vehicle["v"][:-1]
    # Closed form while the mixer holds its first command: y(t_k + h) = v (1 - exp(-(k + 1) h / T)).
    first = command[0]
    steady = int(np.argmax(command != first)) if np.any(command != first) else len(command)
    assert steady * MACRO_STEP > 4 * LAG_T and first == pytest.approx(1.5)
    k = np.arange(steady)
    np.testing.assert_allclose(
        vehicle_v[:steady], first * (1 - np.exp(-(k + 1) * MACRO_STEP / LAG_T)), rtol=0, atol=1e-12
    )
    # The whole run: each step exact for the held command, y' = u + (y - u) exp(-h / T).
    decay = math.exp(-MACRO_STEP / LAG_T)
    expected, y = np.empty(len(command)), 0.0
    for index, u in enumerate(command):
        y = u + (y - u) * decay
        expected[index] = y
    np.testing.assert_allclose(vehicle_v, expected, rtol=0, atol=1e-12)
    # The lag shows: where VFH changes the command the vehicle's speed trails it.
    assert np.max(np.abs(vehicle_v - command)) > 0.1


def remove_section(name: str) -> dict:
    """A `write_scenario` replacement deleting the section `[name]` (up to the next section)."""
    return {rf"^\[{name}\][^\n]*\n(?:[^\[\n].*\n|\n)*": ""}


GO_TO_GOAL_X, GO_TO_GOAL_Y = 80.0, 6.0
# The go-to-goal FMU (the `controller_fmi2` C fixture) in Pure Pursuit's place: the template keeps
# the connections to the ports it has (vehicle.x/y/theta -> x/y/theta, v/omega -> mixer.v_in/omega_in)
# and drops the others (waypoints, target_dir, goal_reached): those inputs of VFH and the mixer are
# held (straight ahead along the corridor, goal not reached: the outcome decides arrival).
REPLACE_PURE_PURSUIT = f"""
[components.pure_pursuit]
fmu = "{{fmu}}"
goal_x = {GO_TO_GOAL_X}
goal_y = {GO_TO_GOAL_Y}
v_max = 1.0

[vfh]
target_dir = 0.0
robot_radius = 0.5

[mixer]
target_dir = 0.0
goal_reached = false
"""


def test_go_to_goal_fmu_replaces_pure_pursuit_and_reaches_the_goal(tmp_path):
    path = replacement_scenario(tmp_path)
    scenario = load_scenario(path, ["output.plot=false"])
    built = build_run(scenario)
    description = built.description
    assert "PurePursuit" not in {c.model_name for c in description.components.values()}
    assert description.components["pure_pursuit"].model_name == "fixture_controller_fmi2"
    assert description.replacing == ("pure_pursuit",) and description.removed == ()
    # A replacement without its own rate steps at the controller rate, like the role it replaces.
    assert description.components["pure_pursuit"].rate == scenario.controller_rate == 20.0
    dropped = {(c.source, c.target) for c, _ in description.dropped}
    assert ("pure_pursuit.target_dir", "vfh.target_dir") in dropped
    assert ("planner.waypoints[1,1]", "pure_pursuit.waypoints[1,1]") in dropped
    assert len(dropped) == 2 * 1000 + 3  # waypoints; target_dir twice, goal_reached
    targets = {c.target: c.source for c in description.connections}
    assert targets["mixer.v_in"] == "pure_pursuit.v" and targets["pure_pursuit.x"] == "vehicle.x"
    assert not any(c.target.startswith("pure_pursuit.waypoints") for c in description.connections)
    assert description.components["vfh"].held_inputs == {"target_dir": 0.0}
    result = run_scenario(scenario, tmp_path / "go.mcap")
    assert result.failure is None and result.outcome.reached
    log = open_log(tmp_path / "go.mcap")
    assert log.metadata["fmu/pure_pursuit"]["model_name"] == "fixture_controller_fmi2"
    fmus = {key: value["model_name"] for key, value in log.metadata.items() if key.startswith("fmu/")}
    assert "PurePursuit" not in fmus.values() and len(fmus) == 4
    built_models = {
        c.model_description.modelName
        for c in built.system.components.values()
        if hasattr(c, "model_description")
    }
    assert built_models == {
        "fixture_controller_fmi2",
        "VectorFieldHistogram",
        "AvoidanceMixer",
        "DifferentialDrive",
    }
    vehicle, controller, mixer = (log.signals(name) for name in ("vehicle", "pure_pursuit", "mixer"))
    assert "waypoints[1,1]" not in controller.names and "target_dir" not in controller.names
    signals = {topic.name for topic in log.topics if topic.name.startswith("/signals/")}
    assert signals == {
        f"/signals/{n}" for n in ("planner", "pure_pursuit", "lidar", "vfh", "mixer", "vehicle")
    }
    # The vehicle drives the controller's v = min(gain_v * distance, v_max) = 1 m/s through the
    # mixer (VFH sees a free corridor and follows the held target direction 0).
    np.testing.assert_array_equal(controller["v"], 1.0)
    np.testing.assert_array_equal(vehicle["v"], 1.0)
    np.testing.assert_array_equal(mixer["mode"], 0.0)
    assert result.outcome.vfh_interventions == 0
    # Straight along y = 6 from x = 6 at 1 m/s: within the 1 m tolerance of x = 80 after 73 s.
    np.testing.assert_allclose(vehicle["y"], 6.0, atol=1e-9)
    assert result.outcome.time == pytest.approx(73.0, abs=MACRO_STEP + 1e-9)
    assert result.outcome.distance == pytest.approx(result.outcome.time * 1.0, abs=1e-9)


def go_to_goal_law(x, y, theta, goal, gain_v=1.0, gain_omega=2.0, v_max=1.0):
    """The controller fixture's law, written again: v = min(gain_v d, v_max), omega = gain_omega *
    heading error wrapped to (-pi, pi]."""
    dx, dy = goal[0] - x, goal[1] - y
    error = math.atan2(dy, dx) - theta
    error = math.atan2(math.sin(error), math.cos(error))
    return min(gain_v * math.hypot(dx, dy), v_max), gain_omega * error


def unicycle(start, goal, period_steps, h, steps):
    """Poses after each of `steps` macro steps: the go-to-goal law sampled every `period_steps`
    steps at the pose of that step's start, held in between; each step the exact arc of constant
    v, omega (the differential drive with unlimited wheel speeds)."""
    x, y, theta = start
    poses = np.empty((steps + 1, 3))
    poses[0] = start
    for k in range(steps):
        if k % period_steps == 0:
            v, omega = go_to_goal_law(x, y, theta, goal)
        # The arc's chord, 2 v/omega sin(omega h / 2), along the mean heading: the closed form
        # x += v/omega (sin theta' - sin theta), ... without its cancellation at small omega.
        turn = omega * h
        chord = v * h * float(np.sinc(turn / 2 / math.pi))  # np.sinc(u) = sin(pi u) / (pi u)
        x += chord * math.cos(theta + turn / 2)
        y += chord * math.sin(theta + turn / 2)
        theta += turn
        poses[k + 1] = (x, y, theta)
    return poses


GOAL_CURVED = (30.0, 8.0)
START_HEADING = -0.6  # [rad]: away from the goal, so the law turns the robot round first
DIRECT = f"""
[system]
remove = ["pure_pursuit", "vfh", "mixer"]

[components.go_to_goal]
fmu = "{{fmu}}"
goal_x = {GOAL_CURVED[0]}
goal_y = {GOAL_CURVED[1]}
rate = 20.0

[[connections]]
from = "vehicle.x"
to = "go_to_goal.x"

[[connections]]
from = "vehicle.y"
to = "go_to_goal.y"

[[connections]]
from = "vehicle.theta"
to = "go_to_goal.theta"

[[connections]]
from = "go_to_goal.v"
to = "vehicle.v"

[[connections]]
from = "go_to_goal.omega"
to = "vehicle.omega"
"""


def direct_scenario(tmp_path: Path, extra: str = "", replan: bool = False) -> Path:
    """The no-obstacle warehouse with Pure Pursuit, VFH and the mixer removed and the go-to-goal
    FMU driving the vehicle directly toward GOAL_CURVED (off the start's heading: a curve)."""
    replace = {
        r"^theta = 0.0$": f"theta = {START_HEADING}",
        r"^\[goal\]\nx = 84.0\ny = 53.0": f"[goal]\nx = {GOAL_CURVED[0]}\ny = {GOAL_CURVED[1]}",
        **remove_section("pure_pursuit"),
        **remove_section("vfh"),
    }
    if not replan:
        replace[r"^smoothing = \"none\".*$"] = 'smoothing = "none"\nreplan = false'
    body = DIRECT.format(fmu=fixture_fmu("controller_fmi2")) + extra
    return write_scenario(tmp_path, "direct", "warehouse_diff_drive_no_obstacle.toml", body, replace)


def test_go_to_goal_drives_the_vehicle_with_vfh_and_mixer_removed(tmp_path):
    scenario = load_scenario(direct_scenario(tmp_path), ["output.plot=false"])
    built = build_run(scenario)
    description = built.description
    assert set(description.components) == {"planner", "lidar", "vehicle", "go_to_goal"}
    assert description.removed == ("pure_pursuit", "vfh", "mixer")
    assert description.observed.command == ("go_to_goal.v", "go_to_goal.omega")
    assert description.observed.mode is None and description.observed.scan is not None
    result = run_scenario(scenario, tmp_path / "direct.mcap")
    assert result.failure is None and result.outcome.reached, result.outcome
    assert result.outcome.vfh_interventions == 0 and result.outcome.recovery_time == 0.0
    log = open_log(tmp_path / "direct.mcap")
    signals = {topic.name for topic in log.topics if topic.name.startswith("/signals/")}
    # (The planner, not replanning, has only array outputs: they go to /plan, not /signals.)
    assert signals == {f"/signals/{name}" for name in ("lidar", "vehicle", "go_to_goal")}
    vehicle = log.signals("vehicle")
    # An independent integration of the law: the pose after every macro step, to 1e-9.
    steps = len(vehicle.t) - 1
    expected = unicycle(scenario.start, GOAL_CURVED, 5, MACRO_STEP, steps)
    for column, name in enumerate(("x", "y", "theta")):
        np.testing.assert_allclose(vehicle[name], expected[:, column], rtol=0, atol=1e-9, err_msg=name)
    # It curves (it starts heading 0.68 rad right of the goal), and the run ends at the first pose
    # within the goal tolerance, which the integration says when.
    assert np.ptp(expected[:, 2]) > 0.6
    inside = np.hypot(expected[:, 0] - GOAL_CURVED[0], expected[:, 1] - GOAL_CURVED[1]) <= 1.0
    arrival = int(np.argmax(inside))
    assert arrival == steps and result.outcome.time == pytest.approx(arrival * MACRO_STEP, abs=1e-9)
    travelled = np.sum(np.hypot(np.diff(expected[:, 0]), np.diff(expected[:, 1])))
    assert result.outcome.distance == pytest.approx(travelled, abs=1e-6)
    # /cmd_vel is what feeds the vehicle: the go-to-goal command.
    commands = list(log.messages("/cmd_vel"))
    controller = log.signals("go_to_goal")
    assert commands and commands[0].message.linear.x == controller["v"][1]


def replacement_scenario(tmp_path: Path) -> Path:
    extra = REPLACE_PURE_PURSUIT.format(fmu=fixture_fmu("controller_fmi2"))
    replace = {
        r"^\[goal\]\nx = 84.0\ny = 53.0": f"[goal]\nx = {GO_TO_GOAL_X}\ny = {GO_TO_GOAL_Y}",
        **remove_section("pure_pursuit"),
        **remove_section("vfh"),
    }
    return write_scenario(tmp_path, "go_to_goal", "warehouse_diff_drive_no_obstacle.toml", extra, replace)


@pytest.mark.parametrize("make", [replacement_scenario, direct_scenario], ids=["replaced", "removed"])
def test_ssp_export_of_a_changed_template_reproduces_the_run(tmp_path, capsys, make):
    """The exported archive carries the replacement (its FMU, the held inputs) and the removal."""
    import io
    import zipfile

    import xmlschema

    from cosim.cli import main

    path = make(tmp_path)
    sets = ["--set", "simulation.stop_time=6"]
    archive, direct, again = tmp_path / "x.ssp", tmp_path / "direct.mcap", tmp_path / "again.mcap"
    assert main(["ssp", "export", str(path), "--out", str(archive), *sets]) == 0
    schemas = Path(__file__).resolve().parents[1] / "data" / "ssp-1.0.1"
    with zipfile.ZipFile(archive) as zipped:
        ssd, ssv = zipped.read("SystemStructure.ssd"), zipped.read("resources/parameters.ssv")
        fmus = sorted(name for name in zipped.namelist() if name.endswith(".fmu"))
    xmlschema.XMLSchema(schemas / "SystemStructureDescription.xsd").validate(io.BytesIO(ssd))
    xmlschema.XMLSchema(schemas / "SystemStructureParameterValues.xsd").validate(io.BytesIO(ssv))
    if make is replacement_scenario:
        assert fmus == [f"resources/{n}.fmu" for n in ("mixer", "pure_pursuit", "vehicle", "vfh")]
        assert b'"vfh.target_dir"' in ssv and b'"mixer.goal_reached"' in ssv  # the held inputs
    else:
        assert fmus == ["resources/go_to_goal.fmu", "resources/vehicle.fmu"]
    codes = [main(["run", str(path), "--out", str(direct), "--no-plot", "--quiet", *sets])]
    codes.append(main(["run", str(archive), "--out", str(again), "--no-plot", "--quiet"]))
    assert codes[0] == codes[1]
    capsys.readouterr()
    assert main(["log", "diff", str(direct), str(again), "--tolerance", "0"]) == 0
    assert "(largest deviation 0)" in capsys.readouterr().out


def test_scale_offset_and_held_input_reach_the_fmu(tmp_path):
    extra = f"""
[components.probe]
fmu = "{fixture_fmu("controller_fmi2")}"
goal_x = 10.0
goal_y = 0.0
y = 0.0
theta = 0.0

[[connections]]
from = "mixer.v"
to = "probe.x"
scale = -2.0
offset = 10.5
"""
    path = write_scenario(tmp_path, "probe", "warehouse_diff_drive_one_obstacle.toml", extra)
    scenario = load_scenario(path, ["output.plot=false", "simulation.stop_time=3.0"])
    assert scenario.connections[0].scale == -2.0 and scenario.connections[0].offset == 10.5
    result = run_scenario(scenario, tmp_path / "probe.mcap")
    assert result.failure is None
    log = open_log(tmp_path / "probe.mcap")
    mixer, probe = log.signals("mixer"), log.signals("probe")
    x = held(mixer.t_ns, mixer["v"], probe.t_ns) * -2.0 + 10.5
    np.testing.assert_array_equal(probe["x"], x)  # bit for bit: input = output * scale + offset
    np.testing.assert_array_equal(probe["y"], 0.0)  # held
    # The controller's v from those inputs: min(gain_v * |goal - (x, 0)|, v_max) with gain 1, v_max 1.
    np.testing.assert_allclose(probe["v"], np.minimum(np.abs(10.0 - x), 1.0), rtol=0, atol=1e-12)


def _readme_block(heading: str, index: int = 0) -> str:
    """The `index`-th ```toml block after `heading` in the README."""
    text = (REPO / "README.md").read_text()
    after = text[text.index(heading) :]
    return after.split("```toml\n")[1 + index].split("```", 1)[0]


def test_readme_swap_example_runs_as_written(tmp_path):
    block = _readme_block("### Swapping in your own FMU")
    assert 'fmu = "my_vehicle.fmu"' in block
    section = block.replace("my_vehicle.fmu", str(fixture_fmu("diffdrive_fmi2_renamed")))
    vehicle = {r"^\[vehicle\]\n(?:[^\[\n].*\n|\n)*?(?=\[)": section + "\n"}
    path = write_scenario(tmp_path, "swap", "warehouse_diff_drive_one_obstacle.toml", "", vehicle)
    scenario = load_scenario(path, ["output.plot=false", "simulation.stop_time=10.0"])
    result = run_scenario(scenario, tmp_path / "swap.mcap")
    assert result.failure is None
    trajectory = open_log(tmp_path / "swap.mcap").trajectory()
    assert np.hypot(trajectory.x[-1] - trajectory.x[0], trajectory.y[-1] - trajectory.y[0]) > 10.0


def test_readme_composition_example_runs_as_written(tmp_path):
    block = _readme_block("### Composing a system")
    assert 'fmu = "first_order_lag.fmu"' in block
    extra = block.replace("first_order_lag.fmu", str(pythonfmu_fmu("first_order_lag")))
    path = write_scenario(tmp_path, "readme_lag", "warehouse_diff_drive_one_obstacle.toml", extra)
    scenario = load_scenario(path, ["output.plot=false", "simulation.stop_time=2.0"])
    result = run_scenario(scenario, tmp_path / "readme_lag.mcap")
    assert result.failure is None
    vehicle = open_log(tmp_path / "readme_lag.mcap").signals("vehicle")
    k = np.arange(len(vehicle.t) - 1)  # the steps; the last record (the end) holds the last input
    applied = vehicle["v"][:-1]  # at t_k: the lag's output after its step at t_k (Gauss-Seidel)
    np.testing.assert_allclose(applied, 1.5 * (1 - np.exp(-(k + 1) * MACRO_STEP / 0.5)), atol=1e-12)


def test_readme_removal_example_runs_as_written(tmp_path):
    block = _readme_block("### Composing a system", 1)
    assert 'fmu = "go_to_goal.fmu"' in block and 'remove = ["pure_pursuit", "vfh", "mixer"]' in block
    extra = block.replace("go_to_goal.fmu", str(fixture_fmu("controller_fmi2")))
    # As the block says: the [pure_pursuit] and [vfh] sections go, [planner] gets replan = false.
    replace = {
        **remove_section("pure_pursuit"),
        **remove_section("vfh"),
        **remove_section("goal"),  # the block's own [goal] takes its place
        r"^smoothing = \"none\".*$": 'smoothing = "none"\nreplan = false',
    }
    path = write_scenario(tmp_path, "readme_direct", "warehouse_diff_drive_no_obstacle.toml", extra, replace)
    scenario = load_scenario(path, ["output.plot=false", "simulation.stop_time=5.0"])
    result = run_scenario(scenario, tmp_path / "readme_direct.mcap")
    assert result.failure is None
    vehicle = open_log(tmp_path / "readme_direct.mcap").signals("vehicle")
    # Heading straight for (80, 6) from (6, 6) at the controller's 1 m/s.
    assert vehicle["x"][-1] == pytest.approx(6.0 + 5.0, abs=1e-9) and np.all(vehicle["y"] == 6.0)


def test_example_commented_composition_block_is_valid_when_uncommented(tmp_path):
    """The commented-out example in scenarios/example_commented.toml is a working composition."""
    text = (SCENARIOS / "example_commented.toml").read_text()
    start = text.index("# [components.lag]")
    block = "\n".join(
        line[2:] for line in text[start:].split("\n\n", 1)[0].splitlines() if line.startswith("#")
    )
    block = block.replace("first_order_lag.fmu", str(pythonfmu_fmu("first_order_lag")))
    path = write_scenario(tmp_path, "example_lag", "example_commented.toml", block)
    description = build_run(load_scenario(path, ["output.plot=false"])).description
    assert description.components["lag"].parameters == {"T": 0.5}
    assert [(old.target, new.source) for old, new in description.replaced] == [("vehicle.v", "lag.y")]


def test_example_commented_removal_block_reports_what_must_follow(tmp_path):
    """The commented-out [system] example: removing VFH and the mixer leaves the planner's
    steering_dir and the vehicle's v, omega unfed, as its comment says; all reported at once."""
    from cosim.errors import CosimError
    from cosim.scenario.compose import describe_system

    text = (SCENARIOS / "example_commented.toml").read_text()
    start = text.index("# [system]")
    block = "\n".join(line[2:] for line in text[start:].split("\n\n", 1)[0].splitlines())
    assert block == '[system]\nremove = ["vfh", "mixer"]'
    path = write_scenario(tmp_path, "example_removed", "example_commented.toml", block, remove_section("vfh"))
    path.write_text(re.sub(r"(?ms)^\[mixer\].*?(?=^# More components)", "", path.read_text()))
    with pytest.raises(CosimError) as raised:
        describe_system(load_scenario(path))
    lines = str(raised.value).splitlines()
    assert len(lines) == 2, lines
    assert lines[0].startswith(f"{path}: [planner]: input steering_dir of planner is not connected")
    assert "set [planner] replan = false" in lines[0]
    assert lines[1].startswith(f"{path}: [vehicle]: inputs v, omega of vehicle are not connected")
    assert "(from mixer.v, mixer.omega: mixer is removed by [system].remove)" in lines[1]
