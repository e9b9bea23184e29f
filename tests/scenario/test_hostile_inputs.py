"""Hostile input to `cosim run` (issue 10): each gets one line naming the file and the key (or the
FMU and its variable), exit 2, no traceback, no log, and quoted values cut to 80 characters."""

from __future__ import annotations

import os
import re
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.errors import CosimError
from cosim.scenario import limits
from cosim.scenario.load import load_scenario
from cosim.world.lidar import MAX_BEAMS, Lidar
from planner.errors import PlannerError
from planner.mapio import MAX_MAP_CELLS, load_map

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "scenarios" / "example_commented.toml"
WAREHOUSE = REPO / "scenarios" / "maps" / "warehouse.yaml"
MESSAGE_LIMIT = 400  # characters: a file name, a key and a value cut to 80 characters fit easily


def example_text(**replace: str) -> str:
    """The commented example with its map as an absolute path and `old=new` text replacements."""
    text = EXAMPLE.read_text().replace('"maps/warehouse.yaml"', f'"{WAREHOUSE}"')
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


def reject(tmp_path: Path, capsys, text: str | None = None, args: tuple[str, ...] = ()) -> str:
    """Run the CLI on `text` (or the example); assert the bad-input contract; return the message."""
    scenario = tmp_path / "hostile.toml"
    if text is not None:
        scenario.write_text(text)
    else:
        scenario = EXAMPLE
    log = tmp_path / "logs" / "run.mcap"
    code = main(["run", str(scenario), "--out", str(log), "--quiet", "--no-plot", *args])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1, err[:2000]
    assert lines[0].startswith(f"cosim: error: {scenario}: "), lines[0][:2000]
    assert "Traceback" not in err
    assert len(lines[0]) < MESSAGE_LIMIT + len(str(scenario)), lines[0][:2000]
    assert not log.parent.exists() or not list(log.parent.iterdir()), "no log for bad input"
    return lines[0]


def test_boolean_where_a_real_is_expected(tmp_path, capsys):
    message = reject(tmp_path, capsys, args=("--set", "pure_pursuit.max_angular_velocity=true"))
    assert "[pure_pursuit].max_angular_velocity: must be a number (the FMU's Real), got true" in message


def test_boolean_for_a_real_parameter_of_a_foreign_fmu(tmp_path, capsys):
    # AvoidanceMixer.avoid_speed_factor is a Real the schema does not list: the FMU's own type decides.
    message = reject(tmp_path, capsys, args=("--set", "mixer.avoid_speed_factor=true"))
    assert "[mixer].avoid_speed_factor: must be a number (the FMU's Real), got true" in message


@pytest.mark.parametrize(
    "overrides, expect",
    [
        (
            ["pure_pursuit.desired_linear_velocity=1e20"],
            "[pure_pursuit].desired_linear_velocity: must be at most 100 m/s in magnitude, got 1e+20",
        ),
        (
            ["pure_pursuit.desired_linear_velocity=-1e20"],
            "[pure_pursuit].desired_linear_velocity: must be at most 100 m/s in magnitude, got -1e+20",
        ),
        (
            ["pure_pursuit.max_angular_velocity=1e20"],
            "[pure_pursuit].max_angular_velocity: must be at most 100 rad/s in magnitude",
        ),
        (
            ["mixer.recovery_linear_velocity=1e20"],
            "[mixer].recovery_linear_velocity: must be at most 100 m/s in magnitude",
        ),
        (
            ["mixer.recovery_angular_velocity=1e20"],
            "[mixer].recovery_angular_velocity: must be at most 100 rad/s in magnitude",
        ),
        (
            ["mixer.recovery_angular_velocity=" + "9" * 400],
            "[mixer].recovery_angular_velocity: must be at most 100 rad/s in magnitude, got an integer of",
        ),
        (
            ["obstacles.0.velocity=[1e20, 0.0]"],
            "[[obstacles]][0].velocity: a speed of at most 100 m/s, got 1e+20",
        ),
        (
            ["obstacles.0.path=[[25.0, 10.5], [30.0, 10.5]]", "obstacles.0.speed=1e20"],
            "[[obstacles]][0].speed: must be <= 100, got 1e+20",
        ),
    ],
)
def test_absurd_velocities(overrides, expect, tmp_path, capsys):
    args = [arg for override in overrides for arg in ("--set", override)]
    assert expect in reject(tmp_path, capsys, args=tuple(args))


def test_tiny_macro_step_hits_the_step_limit(tmp_path, capsys):
    message = reject(tmp_path, capsys, args=("--set", "simulation.macro_step=1e-9"))
    # 200 s / 1 ns: two hundred billion steps, against the documented default of 10^8.
    assert "[simulation].stop_time: 200 s at macro_step 1e-09 s is 2e+11 steps" in message
    assert f"above max_steps = {limits.MAX_STEPS:.3g}" in message and "--max-steps" in message


def test_step_limit_can_be_raised():
    overrides = ["simulation.macro_step=0.0001", "simulation.stop_time=20000"]  # 2e8 steps
    with pytest.raises(CosimError, match=r"\[simulation\].stop_time: .* is 2e\+08 steps"):
        load_scenario(EXAMPLE, overrides)
    assert load_scenario(EXAMPLE, [*overrides, "simulation.max_steps=200000000"]).stop_time == 20000


def test_max_steps_flag_is_the_same_key(tmp_path, capsys):
    message = reject(tmp_path, capsys, args=("--set", "simulation.macro_step=1e-6", "--max-steps", "1000"))
    assert "is 2e+08 steps, above max_steps = 1e+03" in message


def test_sub_nanosecond_macro_step(tmp_path, capsys):
    message = reject(tmp_path, capsys, args=("--set", "simulation.macro_step=1e-300"))
    assert "[simulation].macro_step: must be at least 1 ns (1e-09 s, the time base), got 1e-300" in message


def test_macro_step_of_a_fraction_of_a_nanosecond(tmp_path, capsys):
    message = reject(tmp_path, capsys, args=("--set", "simulation.macro_step=1.5e-9"))
    assert "[simulation].macro_step: must be a whole number of nanoseconds, got 1.5e-09 s" in message


def test_stop_time_overflowing_the_time_base(tmp_path, capsys):
    message = reject(tmp_path, capsys, args=("--set", "simulation.stop_time=1e300"))
    assert "[simulation].stop_time: must be <= 1e+09, got 1e+300" in message


def test_rate_with_a_period_beyond_the_time_base(tmp_path, capsys):
    message = reject(tmp_path, capsys, args=("--set", "lidar.rate=1e-300"))
    assert "[lidar].rate: must be >= 1e-09 Hz" in message


def test_too_many_obstacles(tmp_path, capsys):
    obstacle = '\n[[obstacles]]\ntype = "circle"\ncenter = [40.0, 30.0]\nradius = 0.1\n'
    message = reject(tmp_path, capsys, example_text() + obstacle * 20_000)
    assert f"[obstacles]: at most {limits.MAX_OBSTACLES} obstacles, got 20001" in message


def test_huge_lidar_count(tmp_path, capsys):
    message = reject(tmp_path, capsys, args=("--set", f"lidar.count={2**63 - 1}"))
    assert "[lidar].count: at most 720 beams (the VFH input size), got 9223372036854775807" in message


def test_lidar_range_beyond_what_a_laser_scan_holds(tmp_path, capsys):
    # sensor_msgs/LaserScan's range_max is a float32: 1e308 m broke the /scan packing with a traceback.
    message = reject(tmp_path, capsys, args=("--set", "lidar.range=[0, 1e308]"))
    assert f"[lidar].range: max must be at most {limits.MAX_LIDAR_RANGE:g} m, got 1e+308" in message


def test_lidar_component_beam_limits():
    with pytest.raises(CosimError, match=rf"lidar 'l': count must be an integer in 1..{MAX_BEAMS}, got 9223"):
        Lidar("l", count=2**63 - 1)
    with pytest.raises(CosimError, match=r"lidar 'l': capacity .* must be in 3..100000 for 3 beams, got 2"):
        Lidar("l", angles=[0.0, 0.1, 0.2], capacity=2)
    with pytest.raises(
        CosimError, match=r"lidar 'l': needs a flat list of 1..100000 beam angles, got shape \(0,\)"
    ):
        Lidar("l", angles=[])
    with pytest.raises(CosimError, match="beam angles must be finite"):
        Lidar("l", angles=[0.0, float("nan")])


def test_toml_nested_1000_deep(tmp_path, capsys):
    text = example_text() + "\n[output.deep]\nvalue = " + "[" * 1000 + "]" * 1000 + "\n"
    assert "TOML nested too deeply" in reject(tmp_path, capsys, text)


def test_integer_of_5000_digits(tmp_path, capsys):
    text = example_text(**{"seed = 0 ": "seed = " + "9" * 5000 + " "})
    assert "TOML value not readable" in reject(tmp_path, capsys, text)


def test_50_mb_value_is_quoted_short(tmp_path, capsys):
    big = "x" * (50 * 1024 * 1024)  # a literal string: tomllib reads it in a second
    text = example_text(**{'master = "gauss-seidel"': f"master = '{big}'"})
    message = reject(tmp_path, capsys, text)
    quoted = re.search(r"got '(x+)…", message)
    assert "[simulation].master: must be one of 'gauss-seidel', 'jacobi'" in message
    assert quoted is not None and len(quoted.group(0)) - len("got ") == 80  # with its quote and ellipsis


def test_long_unknown_project_fmu_name_is_quoted_short(tmp_path, capsys):
    # Found by the scenario mutator: a 2000-character FMU name that is no path was echoed in full.
    name = "[" * 2000
    text = example_text(**{'fmu = "DifferentialDrive"': f"fmu = '{name}'"})
    message = reject(tmp_path, capsys, text)
    assert "[vehicle].fmu: unknown project FMU '[[[" in message and "or give a path" in message
    assert len(message) < 300 + len(str(tmp_path))


def test_5_mb_unknown_key_is_quoted_short(tmp_path, capsys):
    text = example_text() + f"\n[simulation.x]\n'{'k' * (5 * 1024 * 1024)}' = 1\n"
    assert "[simulation].x: unknown key" in reject(tmp_path, capsys, text)


@pytest.mark.slow
def test_50_mb_map_path(tmp_path, capsys):
    text = example_text(**{f'"{WAREHOUSE}"': "'" + "m" * (50 * 1024 * 1024) + ".yaml'"})
    message = reject(tmp_path, capsys, text)
    assert "[map].file: cannot open the map file 'mmmm" in message and "File name too long" in message


def test_map_path_is_a_symlink_loop(tmp_path, capsys):
    loop = tmp_path / "loop.yaml"
    os.symlink(loop, loop)
    message = reject(tmp_path, capsys, example_text(**{f'"{WAREHOUSE}"': f'"{loop}"'}))
    assert "[map].file: cannot open the map file" in message and "symbolic link loop" in message.lower()


def test_map_path_with_a_nul_byte(tmp_path, capsys):
    message = reject(tmp_path, capsys, example_text(**{f'"{WAREHOUSE}"': '"maps/\\u0000.yaml"'}))
    assert "[map].file: cannot open the map file" in message and "null" in message


def _pgm_header_only(path: Path, width: int, height: int) -> Path:
    path.write_bytes(f"P5\n{width} {height}\n255\n".encode() + bytes(64))
    return path


def test_pgm_of_40000_by_40000(tmp_path, capsys):
    image = _pgm_header_only(tmp_path / "huge.pgm", 40_000, 40_000)
    (tmp_path / "huge.yaml").write_text(
        "image: huge.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    message = reject(tmp_path, capsys, example_text(**{f'"{WAREHOUSE}"': f'"{tmp_path / "huge.yaml"}"'}))
    assert f"[map].file: {image}: image larger than the map limit of {MAX_MAP_CELLS} pixels" in message


@pytest.mark.parametrize("width, height", [(8193, 8192), (9000, 9000)])
def test_image_just_over_the_cell_limit_is_refused_before_decoding(width, height, tmp_path):
    # Between our limit and PIL's own bomb check: our header check refuses it, and PIL says nothing.
    image = _pgm_header_only(tmp_path / "big.pgm", width, height)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(PlannerError, match=f"map of {height} x {width} cells is larger than the limit"):
            load_map(image)


def test_movingai_and_npy_headers_over_the_cell_limit(tmp_path):
    movingai = tmp_path / "huge.map"
    movingai.write_text("type octile\nheight 40000\nwidth 40000\nmap\n....\n")
    with pytest.raises(PlannerError, match="map of 40000 x 40000 cells is larger than the limit"):
        load_map(movingai)
    npy = tmp_path / "huge.npy"
    with open(npy, "wb") as stream:  # a header that promises 1.6e9 cells, and no data
        np.lib.format.write_array_header_1_0(
            stream, {"descr": "|b1", "fortran_order": False, "shape": (40_000, 40_000)}
        )
    with pytest.raises(PlannerError, match="map of 40000 x 40000 cells is larger than the limit"):
        load_map(npy)


def test_yaml_image_name_of_5_mb(tmp_path):
    yaml = tmp_path / "map.yaml"
    yaml.write_text(f"image: {'i' * (5 * 1024 * 1024)}.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(PlannerError) as caught:
        load_map(yaml)
    assert len(str(caught.value)) < MESSAGE_LIMIT and "cannot open (File name too long)" in str(caught.value)


def _rewrite_fmu(source: Path, target: Path, edit) -> Path:
    with zipfile.ZipFile(source) as original, zipfile.ZipFile(target, "w") as copy:
        for item in original.infolist():
            data = original.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = edit(data.decode()).encode()
            copy.writestr(item, data)
    return target


def _drop_third_variable(xml: str) -> str:
    start = [m.start() for m in re.finditer("<ScalarVariable", xml)][2]
    end = xml.index("</ScalarVariable>", start) + len("</ScalarVariable>")
    return xml[:start] + xml[end:]


def _vehicle_fmu_scenario(tmp_path: Path, fmu: Path) -> str:
    return example_text(**{'fmu = "DifferentialDrive"': f'fmu = "{fmu}"\ntype = "differential"'})


def test_wrong_model_identifier(tmp_path, capsys):
    from cosim.fmi.builtin import builtin_fmu

    fmu = _rewrite_fmu(
        builtin_fmu("DifferentialDrive"),
        tmp_path / "wrongid.fmu",
        lambda xml: xml.replace('modelIdentifier="DifferentialDrive"', 'modelIdentifier="Wrong"'),
    )
    message = reject(tmp_path, capsys, _vehicle_fmu_scenario(tmp_path, fmu))
    assert f"[vehicle].fmu: FMU '{fmu}': <CoSimulation modelIdentifier=\"Wrong\"> needs binaries/" in message
    assert "/Wrong.so, which is missing;" in message and "holds: DifferentialDrive.so" in message


def test_deleted_scalar_variable(tmp_path, capsys):
    from cosim.fmi.builtin import builtin_fmu

    fmu = _rewrite_fmu(builtin_fmu("DifferentialDrive"), tmp_path / "dropped.fmu", _drop_third_variable)
    count = zipfile.ZipFile(fmu).read("modelDescription.xml").decode().count("<ScalarVariable")
    message = reject(tmp_path, capsys, _vehicle_fmu_scenario(tmp_path, fmu))
    assert f"[vehicle].fmu: FMU '{fmu}': invalid modelDescription.xml: <ModelStructure> <Outputs>" in message
    assert f"refers to ScalarVariable {count + 1}, but <ModelVariables> holds {count}" in message


def test_deleted_variable_of_an_fmi3_fmu(tmp_path):
    from fixtures.conftest_helpers import fixture_fmu

    from cosim.fmi.component import FmuComponent

    def drop_x(xml: str) -> str:
        return "\n".join(line for line in xml.splitlines() if '<Float64 name="x" ' not in line)

    fmu = _rewrite_fmu(fixture_fmu("diffdrive_fmi3"), tmp_path / "dropped3.fmu", drop_x)
    with pytest.raises(CosimError) as caught:
        FmuComponent(fmu, "vehicle")
    assert str(caught.value) == (
        f"FMU '{fmu}': invalid modelDescription.xml: <ModelStructure> <Output valueReference=\"5\"> "
        "refers to valueReference 5, which no variable of <ModelVariables> has"
    )


# Found by the scenario mutator (tests/scenario/test_scenario_mutants.py).


def test_component_name_of_3000_characters(tmp_path, capsys):
    name = "x" * 3000
    message = reject(tmp_path, capsys, example_text() + f'\n[components.{name}]\nfmu = "DifferentialDrive"\n')
    assert "[components].xxxx" in message
    assert "a component name must be an identifier (letters, digits, _) of at most 100 characters" in message


def test_component_that_is_not_a_table_names_its_section(tmp_path, capsys):
    message = reject(tmp_path, capsys, example_text() + "\n[components]\nghost = 1.5\n")
    assert message.endswith(": [components].ghost: must be a table [components.ghost], got 1.5")


def test_connection_endpoint_of_7000_characters_is_cut(tmp_path, capsys):
    # Composition problems quote the user's names; each line stays short however long they are.
    extra = "\n[[connections]]\nfrom = 'mixer." + "v" * 7000 + "'\nto = 'vehicle.v'\n"
    message = reject(tmp_path, capsys, example_text() + extra)
    assert "[[connections]][0].from: component 'mixer' has no output 'vvvv" in message and "…" in message


def test_parameter_name_of_3000_characters_is_cut(tmp_path, capsys):
    text = example_text(**{"[vfh] ": "[vfh]\n" + "z" * 3000 + " = 1.0\n"})
    message = reject(tmp_path, capsys, text)
    assert "[vfh].zzzz" in message and "the FMU has no parameter 'zzzz" in message


def test_toml_date_is_quoted_as_written(tmp_path, capsys):
    message = reject(tmp_path, capsys, example_text(**{"stop_time = 200.0": "stop_time = 2026-01-01"}))
    assert message.endswith("[simulation].stop_time: must be a number, got 2026-01-01")


def test_empty_key_is_named(tmp_path, capsys):
    message = reject(tmp_path, capsys, example_text(**{"[vfh] ": '[vfh]\n"" = "x"\n'}))
    # A string is a String variable's value: the empty name is then no parameter of the FMU.
    assert message.endswith("""[vfh].: the FMU has no parameter ''""")


@pytest.mark.parametrize("kind", ["directory", "device"])
def test_map_file_that_is_not_a_regular_file(kind, tmp_path, capsys):
    target = tmp_path / "a_map.yaml" if kind == "directory" else Path("/dev/null")
    if kind == "directory":
        target.mkdir()
    message = reject(tmp_path, capsys, example_text(**{f'"{WAREHOUSE}"': f'"{target}"'}))
    what = "is a directory" if kind == "directory" else "is not a regular file"
    assert message.endswith(f"[map].file: the map file {what}: {target}")
