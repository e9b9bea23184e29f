"""A first `cosim run` of a fleet says what it builds, as a robot's run does: one line for the
project FMUs of all its robots (each named once, built side by side), none when they are built.
Truth: the FMU cache the run was given, empty before and holding exactly those FMUs after."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FMUS = "PurePursuit, VectorFieldHistogram, AvoidanceMixer, DifferentialDrive"  # as the run reads them


@pytest.mark.slow
def test_a_first_fleet_run_says_what_it_builds(tmp_path):
    environment = dict(os.environ, NAVCOSIM_FMU_CACHE=str(tmp_path / "fmus"), PYTHONPATH=str(REPO))
    command = [
        sys.executable, "-m", "cosim", "run", str(REPO / "scenarios" / "fleet_head_on.toml"), "--no-plot",
        "--set", "simulation.stop_time=0.5", "--out", str(tmp_path / "fleet.mcap"), "--force",
    ]  # fmt: skip
    first = subprocess.run(
        command, capture_output=True, text=True, env=environment, cwd=tmp_path, timeout=600
    )
    assert first.returncode == 1, first.stderr  # stopped at 0.5 s, not completed
    lines = [line for line in first.stderr.splitlines() if "(first use or changed sources)" in line]
    assert lines == [f"building FMUs {FMUS} (first use or changed sources) ..."]
    built = sorted(path.name for path in (tmp_path / "fmus").glob("*.fmu"))
    assert built == sorted(f"{name}.fmu" for name in FMUS.split(", "))
    again = subprocess.run(
        command, capture_output=True, text=True, env=environment, cwd=tmp_path, timeout=600
    )
    assert again.returncode == 1 and "first use" not in again.stderr
