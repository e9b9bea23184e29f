"""`cosim fmu simulate` as a user runs it: the command's outputs against fmpy's `simulate_fmu`
of the same FMU with the same start values, the default log name, and one-line errors with
exit 2."""

from __future__ import annotations

import subprocess
import sys

import fmpy
import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.logs.reader import open_log


def _cosim(*arguments, cwd):
    command = [sys.executable, "-m", "cosim", "fmu", "simulate", *map(str, arguments)]
    return subprocess.run(command, capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.mark.slow
def test_simulate_writes_log_and_csv_as_fmpy_computes_them(tmp_path):
    path = fixture_fmu("diffdrive_fmi2")
    start = {"x0": 0.5, "theta0": 1.0, "v": 1.2, "omega": 0.7}
    completed = _cosim(
        path, "--stop-time", 4, "--step", 0.02, "--start-values",
        *(f"{k}={v}" for k, v in start.items()), "--csv", "out.csv", "--out", "out.mcap", "--quiet",
        cwd=tmp_path,
    )  # fmt: skip
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout == "" and completed.stderr == ""
    ours = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True)
    reference = fmpy.simulate_fmu(str(path), stop_time=4, output_interval=0.02, start_values=start)
    assert len(ours) == len(reference) == 201
    for name in ("time", "x", "y", "theta"):
        np.testing.assert_allclose(ours[name], reference[name], rtol=0, atol=1e-12)
    with open_log(tmp_path / "out.mcap") as log:
        assert log.is_complete and log.outcome["reason"] == "stop_time"
        np.testing.assert_array_equal(log.signals("fixture_diffdrive_fmi2")["x"], ours["x"])


@pytest.mark.slow
def test_default_log_goes_under_logs_and_the_summary_names_it(tmp_path):
    completed = _cosim(fixture_fmu("diffdrive_fmi2"), "--stop-time", 0.1, cwd=tmp_path)
    assert completed.returncode == 0, completed.stderr
    (log,) = (tmp_path / "logs").glob("fixture_diffdrive_fmi2-*.mcap")
    assert completed.stdout.startswith("stop_time: 1000 steps to t = 0.1 s")
    assert f"log: {log.relative_to(tmp_path)}" in completed.stdout


@pytest.mark.slow
@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--start-values", "omga=1"], "has no parameter or input 'omga'; closest: omega"),
        (["--start-values", "v"], "--start-values v: expected NAME=VALUE"),
        (["--interface", "me"], "the FMU has no <ModelExchange> interface; --interface me cannot run it"),
        (["--solver", "rk4"], "--solver rk4: a solver integrates a Model Exchange FMU"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, arguments, message):
    completed = _cosim(fixture_fmu("diffdrive_fmi2"), *arguments, cwd=tmp_path)
    assert completed.returncode == 2
    assert completed.stderr.count("\n") == 1 and completed.stderr.startswith("cosim: error: ")
    assert message in completed.stderr
    assert not (tmp_path / "logs").exists()  # refused before any log exists


@pytest.mark.slow
def test_missing_file_is_one_line_and_exit_2(tmp_path):
    completed = _cosim(tmp_path / "nothing.fmu", cwd=tmp_path)
    assert completed.returncode == 2 and completed.stderr.count("\n") == 1
    assert "nothing.fmu: no such file and not a project FMU" in completed.stderr


@pytest.mark.slow
def test_a_cut_last_step_is_refused_only_for_an_fmu_that_cannot_take_it(tmp_path):
    arguments = ["--stop-time", "1.05", "--step", "0.1", "--out", "run.mcap"]
    refused = _cosim(fixture_fmu("gain_fixed_step_fmi2"), *arguments, cwd=tmp_path)
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1
    assert "is not a whole number of --step 0.1 s steps" in refused.stderr
    assert "cannot take a shorter last step" in refused.stderr
    completed = _cosim(fixture_fmu("diffdrive_fmi2"), *arguments, cwd=tmp_path)
    assert completed.returncode == 0, completed.stderr
    with open_log(tmp_path / "run.mcap") as log:
        assert log.end_time == pytest.approx(1.05, abs=1e-12)
