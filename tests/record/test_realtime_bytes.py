"""`--realtime` alone paces the run but writes the log an unpaced run writes, byte for byte (the
chunk windows of a live view are for the live view only, as docs/logs.md says)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.cli import main

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "warehouse_diff_drive_no_obstacle.toml"


@pytest.mark.slow
def test_a_paced_run_writes_the_bytes_of_an_unpaced_one(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    common = ["run", str(SCENARIO), "--no-plot", "--quiet", "--set", "simulation.stop_time=6.5"]
    assert main([*common, "--out", str(tmp_path / "plain.mcap")]) == 1  # stop time before the goal
    assert main([*common, "--out", str(tmp_path / "paced.mcap"), "--realtime", "200"]) == 1
    plain, paced = (tmp_path / "plain.mcap").read_bytes(), (tmp_path / "paced.mcap").read_bytes()
    assert len(plain) > 10_000 and paced == plain
