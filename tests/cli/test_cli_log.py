"""`cosim log info|plot|export|diff` through the CLI entry point (exit codes, output, files)."""

from __future__ import annotations

import numpy as np
import pytest
from log_synthetic import COMPONENTS, METADATA, STEP_NS, write_log
from mcap_ros2.writer import Writer as Ros2Writer

from cosim.cli import main
from cosim.logs.export import read_csv


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli")
    return {
        "a": write_log(folder / "a.mcap"),
        "same": write_log(folder / "same.mcap"),
        "vfh_changed": write_log(folder / "vfh_changed.mcap", change={"vfh": 1e-3}),
        "failed": write_log(folder / "failed.mcap", outcome={"reached": "false", "reason": "collision"}),
    }


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    """An MCAP written by another tool: a ROS 2 String topic, no navcosim signals."""
    target = tmp_path_factory.mktemp("foreign") / "chatter.mcap"
    with open(target, "wb") as handle:
        writer = Ros2Writer(handle)
        schema = writer.register_msgdef("std_msgs/msg/String", "string data")
        for k in range(5):
            writer.write_message("/chatter", schema, {"data": "hi"}, log_time=k * 10**8, publish_time=k)
        writer.finish()
    return target


def test_info_reports_what_ran(runs, capsys):
    assert main(["log", "info", str(runs["a"].path)]) == 0
    out = capsys.readouterr().out
    assert "synthetic_quarter_circle" in out and "complete" in out
    assert "reached true" in out and "reason goal" in out
    fmu = METADATA["fmu/vehicle"]
    assert fmu["guid"] in out and fmu["model_name"] in out and fmu["generation_tool"] in out
    odom_line = next(line for line in out.splitlines() if line.strip().startswith("/odom "))
    assert "120 msgs" in odom_line and f"{1e9 / STEP_NS:.2f} Hz" in odom_line
    assert "5.950 s" in out  # duration of 120 steps of 50 ms


def test_plot_run_writes_a_png(runs, tmp_path):
    """The run loop's entry point: default signals, folders created."""
    from cosim.logs.plot import plot_run

    png = plot_run(runs["a"].path, tmp_path / "x" / "run.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_plot_command_with_chosen_signals(runs, tmp_path, capsys):
    chosen = tmp_path / "chosen.png"
    args = ["log", "plot", str(runs["a"].path), "--png", str(chosen), "--signals"]
    assert main([*args, "vfh.ranges[1]", "mixer.mode"]) == 0
    assert chosen.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main([*args, "vfh.ranges[1]"]) == 2  # the picture is kept: drawing again needs --force
    assert "already exists; give --force" in capsys.readouterr().err
    args.insert(-1, "--force")
    assert main([*args, "vfh.nope"]) == 2
    assert "no signal 'nope'" in capsys.readouterr().err
    assert main([*args, "novariable"]) == 2
    assert "expected COMPONENT.VARIABLE" in capsys.readouterr().err


def test_export_csv_and_npz_equal_the_recording_to_the_bit(runs, tmp_path):
    run = runs["a"]
    assert main(["log", "export", str(run.path), "--to", "csv", "--out", str(tmp_path)]) == 0
    for component, names in COMPONENTS.items():
        read_names, t_ns, values = read_csv(tmp_path / f"a-{component}.csv")
        assert read_names == names
        np.testing.assert_array_equal(t_ns, run.t_ns)
        assert values.tobytes() == run.signals[component].tobytes()
    assert (
        main(
            [
                "log",
                "export",
                str(run.path),
                "--to",
                "npz",
                "--component",
                "vfh",
                "mixer",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    data = np.load(tmp_path / "a-signals.npz")
    assert sorted(data.files) == sorted(
        f"{c}.{k}" for c in ("vfh", "mixer") for k in ("t", "t_ns", "values", "names")
    )
    assert data["vfh.values"].tobytes() == run.signals["vfh"].tobytes()
    assert list(data["vfh.names"]) == COMPONENTS["vfh"]
    np.testing.assert_array_equal(data["mixer.t_ns"], run.t_ns)


def test_diff_of_a_run_against_itself_is_zero(runs, capsys):
    assert main(["log", "diff", str(runs["a"].path), str(runs["same"].path), "--tolerance", "0"]) == 0
    out = capsys.readouterr().out
    assert "largest deviation 0" in out and "EQUAL" in out


def test_diff_names_the_changed_component(runs, capsys):
    assert main(["log", "diff", str(runs["a"].path), str(runs["vfh_changed"].path)]) == 1
    out = capsys.readouterr().out
    flagged = [
        line.split()[0] for line in out.splitlines() if line.startswith("vfh.") or line.startswith("mixer.")
    ]
    before, after = runs["a"].signals["vfh"], runs["vfh_changed"].signals["vfh"]
    changed = [
        f"vfh.{name}"
        for column, name in enumerate(COMPONENTS["vfh"])
        if not np.array_equal(before[:, column], after[:, column], equal_nan=True)  # inf + 1e-3 is inf
    ]
    assert len(changed) == 3 and sorted(flagged) == sorted(changed)
    assert "DIFFERENT (vfh)" in out
    # within a tolerance above the change: equal
    assert (
        main(["log", "diff", str(runs["a"].path), str(runs["vfh_changed"].path), "--tolerance", "0.002"]) == 0
    )


def test_diff_reports_outcome_differences(runs, capsys):
    assert main(["log", "diff", str(runs["a"].path), str(runs["failed"].path)]) == 1
    out = capsys.readouterr().out
    assert "outcome reached: A true  B false" in out and "outcome reason: A goal  B collision" in out


def test_diff_interpolates_different_time_bases(runs, tmp_path, capsys):
    """A run cut at half time: B is interpolated onto A's times where both exist; equal there."""
    shorter = write_log(tmp_path / "short.mcap", steps=60)
    assert main(["log", "diff", str(runs["a"].path), str(shorter.path), "--tolerance", "0"]) == 0
    out = capsys.readouterr().out
    assert "B interpolated linearly onto A's times" in out and "largest deviation 0" in out


@pytest.mark.parametrize("action", ["info", "plot", "export", "diff"])
def test_bad_inputs_give_one_line_and_exit_2(tmp_path, capsys, action):
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("just some text\n")
    args = {
        "info": [str(not_mcap)],
        "plot": [str(not_mcap)],
        "export": [str(not_mcap), "--to", "csv"],
        "diff": [str(not_mcap), str(not_mcap)],
    }[action]
    assert main(["log", action, *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("cosim: error:") and "not an MCAP file" in err
    assert (
        main(["log", action, *[str(tmp_path / "missing.mcap") if a == str(not_mcap) else a for a in args]])
        == 2
    )
    assert "no such log file" in capsys.readouterr().err


def test_foreign_mcap_partial_output_or_one_line(foreign, tmp_path, capsys):
    assert main(["log", "info", str(foreign)]) == 0
    out = capsys.readouterr().out
    assert "/chatter" in out and "not a navcosim run log" in out
    assert main(["log", "plot", str(foreign), "--png", str(tmp_path / "f.png")]) == 0
    assert (tmp_path / "f.png").exists()
    assert main(["log", "export", str(foreign), "--to", "csv", "--out", str(tmp_path)]) == 2
    assert "no navcosim signal channels" in capsys.readouterr().err


def test_info_shows_the_overrides_the_run_applied(tmp_path, capsys):
    """A real run with two --set overrides: log info names them (the attached scenario.toml is the
    file as given, so without them the log would not say what ran)."""
    from pathlib import Path

    scenario = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_no_obstacle.toml"
    log = tmp_path / "over.mcap"
    sets = ["--set", "simulation.stop_time=0.3", "--set", "vfh.safety_distance=0.6"]
    assert main(["run", str(scenario), "--out", str(log), "--no-plot", *sets]) == 1
    capsys.readouterr()
    assert main(["log", "info", str(log)]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("--set"))
    assert "simulation.stop_time=0.3" in line and "vfh.safety_distance=0.6" in line
    assert (
        main(["run", str(scenario), "--out", str(tmp_path / "plain.mcap"), "--no-plot", sets[0], sets[1]])
        == 1
    )
    capsys.readouterr()
    assert main(["log", "info", str(tmp_path / "plain.mcap")]) == 0
    assert "vfh.safety_distance" not in capsys.readouterr().out
