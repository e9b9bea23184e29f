"""Fixtures of the FMU tests."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from cosim.fmi.builtin import builtin_fmu


@pytest.fixture
def fmu_cache(tmp_path: Path, monkeypatch) -> Path:
    """A project FMU build cache (NAVCOSIM_FMU_CACHE) holding a built PurePursuit: its many
    variables, 2000 waypoint inputs among them."""
    folder = tmp_path / "fmus"
    folder.mkdir()
    shutil.copy2(builtin_fmu("PurePursuit"), folder / "PurePursuit.fmu")
    monkeypatch.setenv("NAVCOSIM_FMU_CACHE", str(folder))
    return folder
