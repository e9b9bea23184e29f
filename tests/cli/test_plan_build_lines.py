"""A first `cosim plan` says what it compiles, one line on stderr as a first `cosim run` does, and
compiles exactly the kernels the command then loads; the next call says nothing. Truth: the kernels
the process loaded (`native.load._loaded`) and the native cache's files."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from native import load as native

REPO = Path(__file__).resolve().parents[2]
MAP = str(REPO / "scenarios" / "maps" / "warehouse.yaml")
CODE = (
    "import sys\n"
    "from cosim.cli import main\n"
    "from native import load as native\n"
    "code = main(sys.argv[1:])\n"
    "print('loaded', ' '.join(sorted(str(path) for path in native._loaded)))\n"
    "sys.exit(code)\n"
)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("words", "kernels"),
    [
        (["plan", MAP, "--start", "6,6", "--goal", "40,40"], ["astar", "distance"]),
        (
            ["plan", "compare", MAP, "--start", "6,6", "--goal", "40,40"],
            ["hybrid", "astar_general", "astar", "distance"],
        ),
    ],
)
def test_a_first_plan_says_what_it_compiles(tmp_path, words, kernels):
    cache = tmp_path / "native"
    environment = dict(os.environ, NAVCOSIM_NATIVE_CACHE=str(cache), PYTHONPATH=str(REPO))
    command = [sys.executable, "-c", CODE, *words]
    first = subprocess.run(
        command, capture_output=True, text=True, env=environment, cwd=tmp_path, timeout=600
    )
    assert first.returncode == 0, first.stderr
    lines = [line for line in first.stderr.splitlines() if "(first use or changed sources)" in line]
    assert lines == [f"compiling kernels {', '.join(kernels)} (first use or changed sources) ..."]
    sources = [REPO / "planner" / "native" / f"{name}.c" for name in kernels]
    loaded = first.stdout.splitlines()[-1].split()[1:]
    assert sorted(loaded) == sorted(str(path.resolve()) for path in sources)
    built = sorted(path.name for path in cache.iterdir())
    assert built == sorted(native.library_name(path.resolve()) for path in sources)
    again = subprocess.run(
        command, capture_output=True, text=True, env=environment, cwd=tmp_path, timeout=600
    )
    assert again.returncode == 0 and "first use" not in again.stderr
