"""Shared pytest configuration."""

import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
DATA = Path(__file__).resolve().parent / "data"

# Subprocesses (`python -m cosim ...` with another working directory) import the tree under test,
# not whichever checkout an editable install points at.
os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO


# Test modules that share helpers import each other by basename (unique across tests/), so every
# package folder of tests/ is on sys.path, as tests/ itself is.
sys.path[:0] = [
    str(folder)
    for folder in sorted(Path(__file__).resolve().parent.iterdir())
    if folder.is_dir() and any(folder.glob("test_*.py"))
]
