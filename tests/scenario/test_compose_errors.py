"""A badly composed scenario: every problem at once, one line each, naming the file and the key,
with a "did you mean" where a name is close; `cosim run` prints each line and exits 2 with no log.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from fixtures.conftest_helpers import fixture_fmu
from fixtures.pythonfmu_fixtures import pythonfmu_fmu
from test_compose import write_scenario

from cosim.cli import main
from cosim.errors import CosimError
from cosim.scenario.compose import describe_system
from cosim.scenario.load import load_scenario

BROKEN = """
[components.lag]
fmu = "{lag}"
T = 0.5
y_0 = 1.0
rate = 7.0

[components.c1]
fmu = "{controller}"
y = 0.0
theta = 0.0

[components.c2]
fmu = "{controller}"
y = 0.0
theta = 0.0

[components.c3]
fmu = "{controller}"

[[connections]]
from = "c1.v"
to = "c2.x"

[[connections]]
from = "c2.v"
to = "c1.x"

[[connections]]
from = "vehicel.x"
to = "lag.u"

[[connections]]
from = "mixer.v"
to = "vehicle.x"

[[connections]]
from = "lag.y"
to = "vehicle.v"

[[connections]]
from = "mixer.v"
to = "vehicle.v"

[[connections]]
from = "lag.yy"
to = "vehicle.omega"

[[connections]]
from = "vehicle.x"
to = "c3.x"

[[connections]]
from = "vehicle.y"
to = "c3.y"

[[connections]]
from = "c3.omega"
to = "mixer.x"
"""

# (key, what the line must say), in the order they are reported.
EXPECTED = [
    ("[components.lag].y_0", "the FMU has no parameter or input 'y_0' (did you mean 'y0'?)"),
    ("[components.lag].rate", "7 Hz is not a whole number of macro steps of 0.01 s"),
    ("[[connections]][2].from", "no component 'vehicel' (did you mean 'vehicle'?)"),
    ("[[connections]][3].to", "'vehicle.x' is an output, and `to` takes an input (an output cannot be wired"),
    ("[[connections]][5].to", "input 'vehicle.v' is already fed by [[connections]][4] (from 'lag.y')"),
    ("[[connections]][6].from", "component 'lag' has no output 'yy' (did you mean 'y'?)"),
    ("[[connections]][9].to", "component 'mixer' has no input 'x'"),
    ("[[connections]][0]", "algebraic loop through components c1, c2: "),
    ("[[connections]][0]", "c1.v -> c2.x -> c2.v -> c1.x"),
]


@pytest.fixture
def broken(tmp_path) -> Path:
    extra = BROKEN.format(lag=pythonfmu_fmu("first_order_lag"), controller=fixture_fmu("controller_fmi2"))
    return write_scenario(tmp_path, "broken", "warehouse_diff_drive_one_obstacle.toml", extra)


def test_every_problem_is_reported_at_once(broken):
    scenario = load_scenario(broken, ["simulation.algebraic_loops=error"])
    with pytest.raises(CosimError) as raised:
        describe_system(scenario)
    lines = str(raised.value).splitlines()
    assert len(lines) == len(EXPECTED) - 1, "\n".join(lines)  # the loop's is two checks
    for key, text in EXPECTED:
        assert any(line.startswith(f"{broken}: {key}: ") and text in line for line in lines), (
            key,
            text,
            lines,
        )
    # c3's unconnected input theta keeps its start value, as FMI defines: no problem.
    assert not any("not connected" in line for line in lines)


def test_cli_prints_every_problem_on_its_own_line(broken, tmp_path, capsys):
    log = tmp_path / "run.mcap"
    code = main(
        [
            "run",
            str(broken),
            "--out",
            str(log),
            "--quiet",
            "--no-plot",
            "--set",
            "simulation.algebraic_loops=error",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == len(EXPECTED) - 1
    assert all(line.startswith(f"cosim: error: {broken}: ") for line in lines), err
    assert "Traceback" not in err and not log.exists()


@pytest.mark.parametrize("settings", [["simulation.master=jacobi"], []])
def test_jacobi_and_the_default_delay_allow_the_loop(broken, settings):
    """The one-step delay of Jacobi (or of the default `algebraic_loops = "delay"`) breaks an
    algebraic loop: not a problem there."""
    scenario = load_scenario(broken, settings)
    with pytest.raises(CosimError) as raised:
        describe_system(scenario)
    assert "algebraic loop" not in str(raised.value)


RENAMED = """[vehicle]
fmu = "{fmu}"
type = "differential"
radius = 0.5
ports = {{ velocity = "speed_cmd", x = "pos_x", theta = "headin" }}
"""


def test_port_map_problems_at_once_with_the_fmus_own_names(tmp_path):
    section = RENAMED.format(fmu=fixture_fmu("diffdrive_fmi2_renamed"))
    vehicle = {r"^\[vehicle\]\n(?:[^\[\n].*\n|\n)*?(?=\[)": section + "\n"}
    path = write_scenario(tmp_path, "renamed", "warehouse_diff_drive_one_obstacle.toml", "", vehicle)
    with pytest.raises(CosimError) as raised:
        describe_system(load_scenario(path))
    lines = str(raised.value).splitlines()
    assert len(lines) == 3, lines
    unknown, misspelt, missing = lines
    # A key that is no port of the role is unknown (not "an input that exists").
    assert unknown.startswith(f"{path}: [vehicle].ports.velocity: unknown port 'velocity'")
    assert "the ports of [vehicle]: " in unknown and " v," in unknown
    assert misspelt.startswith(f"{path}: [vehicle].ports.theta: the FMU has no variable 'headin' (mapped to")
    assert "(did you mean 'heading'?)" in misspelt
    # Every port the template needs and the FMU lacks, at once, with the FMU's own variable names.
    assert missing.startswith(f"{path}: [vehicle].ports: the FMU (fixture_diffdrive_fmi2_renamed) has no ")
    ports = missing.split("for the ports ")[1].split(" that the")[0]
    assert sorted(ports.split(", ")) == sorted(["y", "theta", "v", "omega", "x0", "y0", "theta0"])
    own = missing.split("the FMU's variables: ")[1]
    assert "inputs " in own and "speed_cmd" in own and "yaw_rate_cmd" in own
    assert "outputs " in own and "pos_y" in own and "heading" in own
    assert "parameters " in own and "start_x" in own
    assert "(the run needs the robot pose vehicle.x, vehicle.y, vehicle.theta)" in missing


def _without(*sections: str) -> dict:
    """`write_scenario` replacements deleting whole sections."""
    return {rf"^\[{name}\][^\n]*\n(?:[^\[\n].*\n|\n)*": "" for name in sections}


REMOVED = """
[system]
remove = ["vfh", "mixr", "vehicle", "vfh"]

[[connections]]
from = "lidar.ranges[1]"
to = "vfh.ranges[1]"
"""


def test_removal_problems_at_once(tmp_path):
    path = write_scenario(
        tmp_path, "removed", "warehouse_diff_drive_one_obstacle.toml", REMOVED, _without("vfh")
    )
    with pytest.raises(CosimError) as raised:
        describe_system(load_scenario(path))
    lines = str(raised.value).splitlines()
    expected = [
        ("[system].remove", "'vfh' is listed twice"),
        ("[system].remove", "no template component 'mixr' (did you mean 'mixer'?); removable: planner, "),
        (
            "[system].remove",
            "'vehicle' cannot be removed: the run needs the robot pose (vehicle.x, vehicle.y, ",
        ),
        ("[[connections]][0].to", "'vfh' is removed by [system].remove"),
        # Inputs the removed component fed: the planner's (replanning) and the mixer's.
        (
            "[planner]",
            "input steering_dir of planner is not connected: the template's connection into it "
            "was dropped (from vfh.steering_dir: vfh is removed by [system].remove); set [planner] replan "
            "= false",
        ),
        ("[mixer]", "input steering_dir of mixer is not connected"),
        ("[mixer]", 'add [[connections]] to = "mixer.steering_dir", or hold it at a value in [mixer]'),
    ]
    assert len(lines) == len(expected) - 1, "\n".join(lines)
    for key, text in expected:
        assert any(line.startswith(f"{path}: {key}: ") and text in line for line in lines), (key, text, lines)


REPLACED = """
[components.pure_pursuit]
fmu = "{controller}"
goal_x = 80.0
goal_y = 6.0
rate = 7.0

[mixer]
v_in = 1.0
"""


def test_replacement_problems_at_once(tmp_path):
    extra = REPLACED.format(controller=fixture_fmu("controller_fmi2"))
    path = write_scenario(
        tmp_path,
        "replaced",
        "warehouse_diff_drive_one_obstacle.toml",
        extra,
        _without("pure_pursuit"),
    )
    with pytest.raises(CosimError) as raised:
        describe_system(load_scenario(path))
    lines = str(raised.value).splitlines()
    expected = [
        ("[components.pure_pursuit].rate", "7 Hz is not a whole number of macro steps of 0.01 s"),
        (
            "[mixer].v_in",
            "input 'v_in' is held at a value and also connected (from 'pure_pursuit.v', "
            "navigation template); drop one of them",
        ),
        # One line per component: the ports the replacement lacks fed VFH's and the mixer's inputs.
        (
            "[vfh]",
            "input target_dir of vfh is not connected: the template's connection into it was dropped "
            "(from pure_pursuit.target_dir: [components.pure_pursuit] has no such output)",
        ),
        (
            "[mixer]",
            "inputs target_dir, goal_reached of mixer are not connected: the template's connections "
            "into them were dropped (from pure_pursuit.target_dir, pure_pursuit.goal_reached: ",
        ),
    ]
    assert len(lines) == len(expected), "\n".join(lines)
    for key, text in expected:
        assert any(line.startswith(f"{path}: {key}: ") and text in line for line in lines), (key, text, lines)


@pytest.mark.parametrize(
    ("extra", "drop", "key", "text"),
    [
        ('[system]\nremove = "vfh"\n', (), "[system].remove", "must be a list of component names"),
        (
            '[system]\nremove = ["vfh"]\n',
            (),
            "[vfh]",
            "'vfh' is removed by [system].remove: this section would set nothing; delete it",
        ),
        (  # every idle section in one line, not one per run
            '[system]\nremove = ["vfh", "pure_pursuit"]\n',
            (),
            "[pure_pursuit] (removed by [system].remove), [vfh] (removed by [system].remove)",
            "these sections would set nothing; delete them",
        ),
        ('[system]\nremove = ["mixer"]\nkeep = 1\n', (), "[system].keep", "unknown key"),
        (
            '[components.pure_pursuit]\nfmu = "PurePursuit"\n',
            (),
            "[pure_pursuit]",
            "'pure_pursuit' is replaced by [components.pure_pursuit]: this section would set nothing",
        ),
        (
            '[system]\nremove = ["vfh"]\n\n[components.vfh]\nfmu = "VectorFieldHistogram"\n',
            ("vfh",),
            "[components.vfh]",
            "'vfh' is also in [system].remove: replace it or remove it, not both",
        ),
        (
            '[components.vehicle]\nfmu = "DifferentialDrive"\n',
            (),
            "[components.vehicle]",
            "swap the vehicle in [vehicle] (fmu, ports): the run reads the robot pose from its x, y, theta",
        ),
        (
            '[components.lidar]\nfmu = "DifferentialDrive"\n',
            (),
            "[components.lidar]",
            "'lidar' is a Python component of the navigation template",
        ),
    ],
)
def test_removal_and_replacement_keys_on_load(tmp_path, capsys, extra, drop, key, text):
    path = write_scenario(tmp_path, "keys", "warehouse_diff_drive_one_obstacle.toml", extra, _without(*drop))
    with pytest.raises(CosimError) as raised:
        load_scenario(path)
    assert str(raised.value).startswith(f"{path}: {key}: ") and text in str(raised.value), str(raised.value)
    # The command line: one line, exit 2, no log.
    log = tmp_path / "run.mcap"
    assert main(["run", str(path), "--out", str(log), "--quiet", "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and not log.exists()
