"""A first `cosim sweep` on a machine says what it builds, as a first `cosim run` does: one line per
kind of build on stderr ("building FMUs ...", from the local cluster's fork server, which builds
them before the workers it forks need them); `--quiet` says nothing, and a second sweep, with
everything built, neither. Truth: the FMU cache the sweep was given, empty before and holding the
scenario's four project FMUs after."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
FMUS = "PurePursuit, VectorFieldHistogram, AvoidanceMixer, DifferentialDrive"  # as the run reads them


def _sweep(tmp_path: Path, cache: str, out: str, *extra: str) -> subprocess.CompletedProcess:
    environment = dict(os.environ, NAVCOSIM_FMU_CACHE=str(tmp_path / cache), PYTHONPATH=str(REPO))
    command = [
        sys.executable, "-m", "cosim", "sweep", str(SCENARIO), "--vary", "lidar.seed=0,1",
        "--set", "simulation.stop_time=1", "--workers", "1", "--no-plot", "--out", str(tmp_path / out),
        *extra,
    ]  # fmt: skip
    return subprocess.run(command, capture_output=True, text=True, env=environment, cwd=tmp_path, timeout=600)


@pytest.mark.slow
def test_a_first_sweep_says_what_it_builds(tmp_path):
    quiet = _sweep(tmp_path, "quiet-fmus", "quiet", "--quiet")
    assert quiet.returncode == 0, quiet.stderr
    assert "first use or changed sources" not in quiet.stderr
    built = sorted(path.name for path in (tmp_path / "quiet-fmus").glob("*.fmu"))
    assert built == sorted(f"{name}.fmu" for name in FMUS.split(", "))
    first = _sweep(tmp_path, "fmus", "first")
    assert first.returncode == 0, first.stderr
    lines = [line for line in first.stderr.splitlines() if "(first use or changed sources)" in line]
    assert lines == [f"cosim sweep: building FMUs {FMUS} (first use or changed sources) ..."]
    again = _sweep(tmp_path, "fmus", "again")
    assert again.returncode == 0 and "first use" not in again.stderr
