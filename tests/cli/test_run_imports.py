"""What a `cosim run` with its progress bar imports: tqdm without importlib.metadata (its package asks
importlib.metadata for its version, ~8 ms; the run gives it the version its dist-info names), and the
version tqdm reports is importlib.metadata's."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


def _python(code: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, env=env)


@pytest.mark.slow
def test_a_run_with_its_bar_imports_tqdm_without_importlib_metadata(tmp_path):
    code = (
        "import sys\n"
        "from cosim.cli import main\n"
        f"code = main(['run', {str(SCENARIO)!r}, '--out', {str(tmp_path / 'run.mcap')!r}, '--no-plot',"
        " '--set', 'simulation.stop_time=1.0'])\n"
        "print('tqdm' in sys.modules, 'importlib.metadata' in sys.modules)\n"
        "import tqdm, importlib.metadata\n"
        "print(tqdm.__version__ == importlib.metadata.version('tqdm'))\n"
        "sys.exit(code)\n"
    )
    done = _python(code)
    assert done.returncode == 1, done.stderr  # the goal is not reached in 1 s
    assert done.stdout.split()[-3:] == ["True", "False", "True"]


@pytest.mark.slow
def test_tqdm_finds_its_version_itself_when_it_was_imported_first():
    code = (
        "import sys, tqdm\n"
        "from cosim.cli.run import _tqdm_version_without_metadata\n"
        "module = sys.modules['tqdm.version']\n"
        "_tqdm_version_without_metadata()\n"
        "print(sys.modules['tqdm.version'] is module)\n"
    )
    done = _python(code)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["True"]
