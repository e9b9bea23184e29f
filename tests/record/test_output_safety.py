"""Commands write only what the user named and destroy nothing (cosim.record.output): an existing
file needs --force, a device, FIFO or folder is refused, a failed write leaves the target as it was."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import CosimError
from cosim.record.output import atomic_output, checked_output

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("log") / "run.mcap"
    assert (
        main(
            [
                "run",
                str(SCENARIO),
                "--out",
                str(path),
                "--no-plot",
                "--quiet",
                "--set",
                "simulation.stop_time=2",
            ]
        )
        == 1  # the goal is not reached in 2 s: a result, not an error
    )
    return path


def test_a_failed_write_leaves_the_target_and_no_temporary(tmp_path):
    target = tmp_path / "table.csv"
    target.write_text("kept")
    with pytest.raises(CosimError, match="No space left"), atomic_output(target, force=True) as temporary:
        temporary.write_text("half")
        raise OSError(28, "No space left on device")
    assert target.read_text() == "kept"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]


def test_a_whole_write_replaces_the_target_only_with_force(tmp_path):
    target = tmp_path / "table.csv"
    target.write_text("old")
    with pytest.raises(CosimError, match="already exists; give --force"):
        checked_output(target)
    with atomic_output(target, force=True) as temporary:
        temporary.write_text("new")
    assert target.read_text() == "new"
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~_umask()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full here")
@pytest.mark.parametrize(
    "command",
    [
        ["log", "recover", "{log}", "--out", "/dev/full", "--force"],
        ["log", "plot", "{log}", "--png", "/dev/full", "--force"],
        ["log", "animate", "{log}", "--out", "/dev/full", "--force"],
    ],
)
def test_dev_full_is_refused_and_survives(log, command, capsys):
    assert main([part.format(log=log) for part in command]) == 2
    assert "not a regular file" in capsys.readouterr().err
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_existing_outputs_are_kept_without_force(log, tmp_path, capsys):
    kept = tmp_path / "kept.mcap"
    kept.write_bytes(b"mine")
    for command in (
        ["log", "recover", str(log), "--out", str(kept)],
        ["log", "plot", str(log), "--png", str(kept)],
    ):
        assert main(command) == 2
        assert "already exists; give --force" in capsys.readouterr().err
        assert kept.read_bytes() == b"mine"
    assert main(["log", "recover", str(log), "--out", str(kept), "--force"]) == 0
    assert kept.read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_a_folder_is_no_output(log, tmp_path, capsys):
    assert main(["log", "recover", str(log), "--out", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize("action", ["info", "plot", "diff", "export", "animate"])
def test_a_fifo_named_like_a_log_is_refused_without_waiting(tmp_path, action):
    fifo = tmp_path / "run.mcap"
    os.mkfifo(fifo)
    extra = {"diff": [str(fifo)], "export": ["--to", "csv"], "animate": ["--out", str(tmp_path / "a.gif")]}
    command = [sys.executable, "-m", "cosim", "log", action, str(fifo), *extra.get(action, [])]
    # The timeout only guards against a hang (what the bug was); it measures nothing.
    done = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"cosim: error: {fifo}: not a regular file (a folder, device or FIFO), not a log"
    ]
