"""planner.mapf_scen.read_scen on .scen files the tests write; the Moving AI data the tests ship
(tests/data/movingai) solved and checked; the kernel builds from the sources alone."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from test_mapf_checker import check

from native import load as native
from planner import OccupancyGrid, PlannerError
from planner.mapf import solve
from planner.mapf_scen import read_scen

DATA = Path(__file__).resolve().parents[1] / "data" / "movingai"
SCEN = (
    "version 1\n0\tm.map\t4\t3\t0\t1\t3\t2\t4.0\n1\tm.map\t4\t3\t2\t0\t1\t1\t1.4\n"
    "2\tm.map\t4\t3\t3\t0\t0\t0\t3\n"
)


def test_reads_x_as_column_and_y_as_row(tmp_path):
    path = tmp_path / "m.scen"
    path.write_text(SCEN)
    starts, goals = read_scen(path)
    assert starts.tolist() == [[1, 0], [0, 2], [0, 3]]
    assert goals.tolist() == [[2, 3], [1, 1], [0, 0]]
    starts, goals = read_scen(path, agents=2)
    assert starts.tolist() == [[1, 0], [0, 2]] and goals.tolist() == [[2, 3], [1, 1]]


@pytest.mark.parametrize(
    "text, agents, message",
    [
        (SCEN, 4, "4 agents asked for, the scenario has 3"),
        (SCEN, 0, "agents must be >= 1"),
        ("version 1\n0\tm.map\t4\t3\t0\t1\t3\n", None, r"m.scen:2: expected 9 columns"),
        (
            "version 1\n0\tm.map\t4\t3\ta\t1\t3\t2\t4\n",
            None,
            r"m.scen:2: start/goal coordinates must be integers",
        ),
        ("version 1\n", None, "no agents in the scenario"),
    ],
)
def test_bad_scenarios(tmp_path, text, agents, message):
    path = tmp_path / "m.scen"
    path.write_text(text)
    with pytest.raises(PlannerError, match=message) as error:
        read_scen(path, agents)
    assert "\n" not in str(error.value)


def test_missing_file(tmp_path):
    with pytest.raises(PlannerError, match="missing.scen: cannot read the scenario"):
        read_scen(tmp_path / "missing.scen")


@pytest.mark.slow
@pytest.mark.parametrize("name, agents", [("room-64-64-8", 60), ("warehouse-10-20-10-2-1", 100)])
def test_moving_ai_instances_are_solved_and_valid(name, agents):
    grid = OccupancyGrid.from_file(DATA / f"{name}.map")
    starts, goals = read_scen(DATA / f"{name}-random-1.scen", agents)
    result = solve(grid, starts, goals, time_limit=1.0)
    check(grid.occupied.tolist(), starts, goals, result)
    assert result.sum_of_costs >= result.lower_bound


def test_kernel_hash_covers_its_header():
    source = Path(__file__).resolve().parents[2] / "planner" / "native" / "mapf.c"
    assert {path.name for path in native._sources(source)} == {"mapf.c", "mapf_lns.h"}


@pytest.mark.slow
def test_builds_from_a_clean_checkout(tmp_path, repo_root):
    """The tracked files alone (git archive) and an empty kernel cache: the first solve compiles the
    kernel the way the grid A* kernels are built, with the project's warning flags, and runs."""
    tree = tmp_path / "tree"
    tree.mkdir()
    archive = subprocess.run(["git", "-C", str(repo_root), "stash", "create"], capture_output=True, text=True)
    commit = archive.stdout.strip() or "HEAD"
    tracked = ["native", "planner", "pyproject.toml"]
    tar = subprocess.run(["git", "-C", str(repo_root), "archive", commit, *tracked],
                         capture_output=True, check=True)  # fmt: skip
    subprocess.run(["tar", "-x", "-C", str(tree)], input=tar.stdout, check=True)
    script = textwrap.dedent(
        """
        import numpy as np
        from planner import OccupancyGrid
        from planner.mapf import solve
        open_room = OccupancyGrid(np.zeros((3, 3), bool))
        result = solve(open_room, [(0, 0), (2, 2)], [(2, 2), (0, 0)], time_limit=1)
        print(result.sum_of_costs, result.optimal)
        """
    )
    cache = tmp_path / "cache"
    environment = {"PATH": "/usr/bin:/bin", "NAVCOSIM_NATIVE_CACHE": str(cache), "HOME": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=tree, env=environment, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["8", "True"]
    assert [path.name.split("-")[0] for path in cache.glob("*.so")] == ["mapf"]
    compiled = subprocess.run(
        [native.compiler(), *native.FLAGS, "-Werror", "-o", str(tmp_path / "m.so"),
         str(tree / "planner" / "native" / "mapf.c"), *native.LINK],
        capture_output=True, text=True,
    )  # fmt: skip
    assert compiled.returncode == 0, compiled.stderr
