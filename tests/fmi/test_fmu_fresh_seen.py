"""A project FMU found up to date is found so again, in the same process, without listing or
reading its sources while no folder listing nor source file changed (`builtin._SEEN_FRESH`: the
times, sizes and inodes of the folders, sources, stamp and FMU); an edit, a new file or a rebuild
makes the full check run again.

Truth: the full check (`_stat_lines` against the stamp) and a rebuild's bytes."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from fmu_harness import copy_sources

from cosim.fmi import builtin as fmus

REPO = Path(__file__).resolve().parents[2]
NAME = "DifferentialDrive"


def _age(path: Path, seconds: float) -> None:
    status = path.stat()
    os.utime(path, ns=(status.st_atime_ns, status.st_mtime_ns - int(seconds * 1e9)))


@pytest.fixture
def built(tmp_path):
    """A copy of the sources built into a cache, the sources a minute older than the stamp."""
    sources = copy_sources(REPO / "fmus", tmp_path / "fmus")
    cache_dir = tmp_path / "cache"
    fmus.build_if_stale(NAME, sources, cache_dir)
    for path in sources.rglob("*"):
        if path.is_file():
            _age(path, 60)
    fmus.build_if_stale(NAME, sources, cache_dir)  # renews the recorded times
    return sources, cache_dir


def _counting(monkeypatch, sources: Path) -> list[int]:
    build = fmus._build_module(sources)
    calls = []
    listing = build.source_files

    def counted(*args, **kwargs):
        calls.append(1)
        return listing(*args, **kwargs)

    monkeypatch.setattr(build, "source_files", counted)
    return calls


def test_a_second_check_reads_no_listing_and_an_edit_is_seen(built, monkeypatch):
    sources, cache_dir = built
    calls = _counting(monkeypatch, sources)
    assert fmus._is_fresh(NAME, sources, cache_dir, 2)  # the first check, as without keeping
    assert fmus._SEEN_FRESH[(NAME, sources, cache_dir, 2)] is None
    assert fmus._is_fresh(NAME, sources, cache_dir, 2)  # asked again: checked, what it read kept
    assert fmus._is_fresh(NAME, sources, cache_dir, 2)
    assert fmus._is_fresh(NAME, sources, cache_dir, 2)
    assert len(calls) == 2  # the third and fourth answers are the second one kept
    first = (cache_dir / f"{NAME}.fmu").read_bytes()
    model = sources / NAME / "model.c"
    text = model.read_text()
    model.write_text(text.replace("m->wheel_radius = 0.05;", "m->wheel_radius = 0.07;"))  # same size
    assert not fmus._is_fresh(NAME, sources, cache_dir, 2)
    rebuilt = fmus.build_if_stale(NAME, sources, cache_dir)
    assert rebuilt.read_bytes() != first


def test_a_new_source_file_is_seen(built, monkeypatch):
    sources, cache_dir = built
    assert fmus._is_fresh(NAME, sources, cache_dir, 2) and fmus._is_fresh(NAME, sources, cache_dir, 2)
    calls = _counting(monkeypatch, sources)
    (sources / NAME / "extra.h").write_text("/* a new header */\n")
    assert not fmus._is_fresh(NAME, sources, cache_dir, 2)  # its line is not in the stamp
    assert calls
    (sources / NAME / "extra.h").unlink()
    assert fmus._is_fresh(NAME, sources, cache_dir, 2)


def test_another_environment_checks_again(built, monkeypatch):
    sources, cache_dir = built
    assert fmus._is_fresh(NAME, sources, cache_dir, 2) and fmus._is_fresh(NAME, sources, cache_dir, 2)
    monkeypatch.setenv("CC", "another-compiler")
    assert not fmus._is_fresh(NAME, sources, cache_dir, 2)  # the stamp names the compiler


OTHER_NAMES = ["Nope", ".hidden", "", "common", "../fmus/Bicycle", "Bi*"]


@pytest.mark.parametrize("name", [*fmus.known_names(), *OTHER_NAMES])
def test_a_known_name_is_told_as_the_listing_tells_it(name):
    assert fmus._is_known(name) == (name in fmus.known_names())
