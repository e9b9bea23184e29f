"""The sweep's fork server (`cosim.sweep.warm`, imported with a warm-up request in the environment)
leaves without the interpreter's teardown, yet with what it printed written out, and hands its
workers a frozen heap and cosim's collector thresholds, the collector on again after its first
import (`cosim.sweep.hold`) switched it off. Observed from outside, in a fresh Python
process: an `atexit` handler registered before the import must not run, the lines printed before
the exit must arrive, and `gc` must report its state as Python's own API reads it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.sweep.warm import WARM_ENV

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"

PROGRAM = """
import atexit, gc, sys
atexit.register(lambda: print("teardown ran"))
before = gc.get_threshold()
import cosim.sweep.hold
print("held", not gc.isenabled())
import cosim.sweep.warm
print("collecting", gc.isenabled())
print("threshold", *gc.get_threshold())
print("frozen", gc.get_freeze_count() > 0)
print("default before", before == (700, 10, 10))
sys.stderr.write("unflushed stderr line")
print("last line", end="")
"""


def _fork_server_import(request: str | None, tmp_path: Path) -> subprocess.CompletedProcess:
    environment = {**os.environ, "TMPDIR": str(tmp_path)}
    environment.pop(WARM_ENV, None)
    if request is not None:
        environment[WARM_ENV] = request
    return subprocess.run(
        [sys.executable, "-c", PROGRAM], capture_output=True, text=True, env=environment, timeout=300
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    "request_text",
    [json.dumps({"scenario": str(SCENARIO), "overrides": ["lidar.seed=1"]}), "not json"],
    ids=["warm-up", "failed warm-up"],
)
def test_the_fork_server_exits_at_once_with_its_output_written(request_text, tmp_path):
    result = _fork_server_import(request_text, tmp_path)
    assert result.returncode == 0, result
    lines = result.stdout.splitlines()
    assert "teardown ran" not in lines  # the teardown was skipped: the handler before ours never ran
    assert lines == [
        "held True",
        "collecting True",
        "threshold 20000 20 10",
        "frozen True",
        "default before True",
        "last line",
    ]
    assert result.stderr == "unflushed stderr line"
    assert list(tmp_path.iterdir()) == []  # the warm-up's scratch folder is gone


@pytest.mark.slow
def test_without_a_request_the_import_changes_nothing(tmp_path):
    result = _fork_server_import(None, tmp_path)
    assert result.returncode == 0, result
    lines = result.stdout.splitlines()
    assert lines[:5] == [
        "held False",
        "collecting True",
        "threshold 700 10 10",
        "frozen False",
        "default before True",
    ]
    assert lines[5:] == ["last line", "teardown ran"] or lines[5:] == ["last lineteardown ran"]


@pytest.mark.slow
def test_a_sweep_file_warms_up_its_scenario_with_its_overrides_first(tmp_path, monkeypatch):
    """`cosim sweep FILE` starts the fork server before it parses FILE: the warm-up reads the
    scenario and the `set` overrides the file names, the command line's after them (as
    `cosim.sweep.build` merges them). A misspelt key shows which overrides it ran with."""
    import shutil
    import tempfile

    from cosim.errors import CosimError
    from cosim.sweep.warm import warm_up

    folder = tmp_path / "sweeps"
    folder.mkdir()
    shutil.copy(SCENARIO, folder / "scenario.toml")
    shutil.copytree(SCENARIO.parent / "maps", folder / "maps")
    sweep_file = folder / "noise.toml"
    sweep_file.write_text(
        '[sweep]\nscenario = "scenario.toml"\nset = ["lidar.seed=3", "vfh.robot_radus=0.5"]\n'
        '[vary]\n"lidar.noise" = [0.0, 0.1]\n'
    )
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    with pytest.raises(CosimError, match="robot_radus"):  # the file's own override was applied
        warm_up(str(sweep_file), ["simulation.stop_time=2"])
    sweep_file.write_text(sweep_file.read_text().replace(', "vfh.robot_radus=0.5"', ""))
    warm_up(str(sweep_file), ["simulation.stop_time=2"])  # raises if the short run fails
    with pytest.raises(CosimError, match="stop_tme"):  # and the command line's
        warm_up(str(sweep_file), ["simulation.stop_tme=2"])
    assert list(scratch.iterdir()) == []


@pytest.mark.slow
@pytest.mark.parametrize(
    "vary, code, built",
    [
        # the fork server builds the 4 FMUs of its warm-up run
        ("lidar.seed=0,1", 0, {"AvoidanceMixer", "DifferentialDrive", "PurePursuit", "VectorFieldHistogram"}),
        # and a worker the vehicle of the second run (which fails: the scenario sets the parameters
        # of the differential drive)
        ("vehicle.fmu=DifferentialDrive,Bicycle", 1, {"Bicycle"}),
    ],
    ids=["fork server", "worker"],
)
def test_a_sweep_that_builds_its_fmus_leaves_no_build_folder(vary, code, built, tmp_path):
    """Building FMUs compiles their shared C code in a temporary folder, which an exit handler
    removes; the sweep's fork server and its workers end with `os._exit`, so they remove it
    themselves (the server as it leaves, a worker as its sweep's plugin is torn down). With a fresh
    FMU cache, nothing of navcosim's stays in TMPDIR."""
    import shutil
    import tempfile

    scratch = Path(tempfile.mkdtemp(prefix="nc-"))  # (short: the fork server's socket is in there)
    environment = {**os.environ, "TMPDIR": str(scratch), "NAVCOSIM_FMU_CACHE": str(tmp_path / "fmus")}
    environment.pop(WARM_ENV, None)
    try:
        result = subprocess.run(
            [sys.executable, "-m", "cosim", "sweep", str(SCENARIO), "--vary", vary, "--set",
             "simulation.stop_time=2", "--out", str(tmp_path / "out"), "--quiet", "--no-plot"],
            capture_output=True, text=True, env=environment, timeout=300, cwd=SCENARIO.parents[1],
        )  # fmt: skip
        assert result.returncode == code, result.stderr
        assert built <= {path.stem for path in (tmp_path / "fmus").glob("*.fmu")}
        assert [path.name for path in scratch.iterdir() if path.name.startswith("navcosim")] == []
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
