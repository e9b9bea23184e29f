"""An FMU that fails mid-run: `cosim run` exits 2 with one line naming the FMU and the time, and
the log is finalised and readable up to that time.

The `failing_fmi2` fixture (y = integral of u; the doStep that would pass `fail_time` returns
fmi2Error or fmi2Fatal) takes the mixer's place: its one input and one output fill the mixer's
ports through the scenario's port map (several ports may name one FMU variable).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.logs import open_log

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
MIXER_RATE = 20.0  # [Hz] the scenario's default controller rate


def _scenario(tmp_path: Path, fail_time: float, fail_status: int) -> Path:
    text = SHIPPED.read_text()
    map_file = (SHIPPED.parent / "maps" / "warehouse.yaml").resolve()
    text = re.sub(r'(?m)^file = "maps/warehouse.yaml"', f'file = "{map_file}"', text)
    inputs = ", ".join(
        f'{port} = "u"' for port in ("v_in", "omega_in", "target_dir", "steering_dir", "goal_reached")
    )
    outputs = ", ".join(f'{port} = "y"' for port in ("v", "omega", "steering_angle", "mode"))
    text += f"""
[mixer]
fmu = "{fixture_fmu("failing_fmi2")}"
fail_time = {fail_time}
fail_status = {fail_status}
ports = {{ {inputs}, {outputs} }}
"""
    path = tmp_path / "failing.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
@pytest.mark.parametrize("fail_status, status_name", [(3, "fmi2Error"), (4, "fmi2Fatal")])
def test_failing_fmu_stops_the_run_with_one_line_and_a_readable_log(tmp_path, fail_status, status_name):
    fail_time = 3.0  # [s]
    log_path = tmp_path / "failing.mcap"
    completed = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(_scenario(tmp_path, fail_time, fail_status))]
        + ["--out", str(log_path), "--no-plot", "--quiet"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert completed.returncode == 2, completed.stderr
    assert "Traceback" not in completed.stderr
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1, completed.stderr
    # The doStep that would go past fail_time fails: the one starting at fail_time (a mixer step).
    failed_at = fail_time
    match = re.search(
        r"FMU 'mixer' \(model fixture_failing_fmi2\) returned (\w+) from fmi2DoStep at t = ([0-9.]+) s",
        lines[0],
    )
    assert match, lines[0]
    assert match[1] == status_name
    assert float(match[2]) == pytest.approx(failed_at, abs=1e-9)
    assert str(log_path) in lines[0]

    log = open_log(log_path)
    assert log.outcome is not None and log.outcome["reason"] == "fmu_failed"
    assert "mixer" in log.outcome.get("failure", "")
    vehicle = log.signals("vehicle")
    # Every vehicle step up to the failure is in the log, none after it.
    assert vehicle.t[-1] <= failed_at + 1e-9
    assert vehicle.t[-1] >= failed_at - 1.0 / MIXER_RATE
    assert np.all(np.diff(vehicle.t) > 0)
    mixer = log.signals("mixer")
    assert mixer.t[-1] <= failed_at + 1e-9
    trajectory = log.trajectory()
    assert trajectory is not None and len(trajectory.t) == len(vehicle.t)
