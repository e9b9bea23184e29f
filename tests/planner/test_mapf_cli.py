"""`cosim plan mapf MAP --scen FILE --agents N`: the printed figures agree with the solution the
checker validates, the PNG is a PNG of the documented size, user errors exit 2 with one line."""

from __future__ import annotations

import re
import struct

import pytest
from test_mapf_checker import lower_bound

from cosim.cli import main
from cosim.cli.plan_mapf import FIGURE_PX

MAP = "type octile\nheight 4\nwidth 6\nmap\n......\n.@@@@.\n......\n.@..@.\n"
# x = column, y = row; the last column is the optimal length (unused)
SCEN = "version 1\n" + "".join(
    f"0\tm.map\t6\t4\t{sx}\t{sy}\t{gx}\t{gy}\t0\n"
    for sx, sy, gx, gy in [(0, 0, 5, 2), (5, 0, 0, 2), (2, 3, 3, 0)]
)
OCCUPIED = [[char == "@" for char in row] for row in MAP.splitlines()[4:]]


@pytest.fixture
def instance(tmp_path):
    (tmp_path / "m.map").write_text(MAP)
    (tmp_path / "m.scen").write_text(SCEN)
    return tmp_path


def test_prints_the_solution(instance, capsys):
    code = main(["plan", "mapf", str(instance / "m.map"), "--scen", str(instance / "m.scen"), "--agents", "3",
                 "--time-limit", "2", "--png", str(instance / "paths.png")])  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0
    assert "3 agents" in out and re.search(r"solved +yes \(optimal\)", out)
    cost, bound = map(int, re.search(r"sum of costs +(\d+) / lower bound (\d+)", out).groups())
    starts, goals = [(0, 0), (0, 5), (3, 2)], [(2, 5), (2, 0), (0, 3)]
    assert bound == lower_bound(OCCUPIED, starts, goals) == 7 + 7 + 8  # the third goes round the wall
    assert cost >= bound
    assert re.search(r"first solution +\d+\.\d+ s", out) and re.search(r"total time +\d+\.\d+ s", out)
    data = (instance / "paths.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and struct.unpack(">II", data[16:24]) == FIGURE_PX


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--scen", "{d}/m.scen", "--agents", "4"], "4 agents asked for, the scenario has 3"),
        (["--scen", "{d}/none.scen", "--agents", "2"], "none.scen: scenario not found"),
        (["--agents", "2"], "needs --scen FILE and --agents N"),
        (["--scen", "{d}/m.scen", "--agents", "2", "--time-limit", "-1"], "time_limit"),
    ],
)
def test_user_errors_exit_2_with_one_line(instance, capsys, arguments, message):
    arguments = [argument.replace("{d}", str(instance)) for argument in arguments]
    assert main(["plan", "mapf", str(instance / "m.map"), *arguments]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("cosim: error: ") and message in error


def test_missing_map(instance, capsys):
    assert (
        main(
            ["plan", "mapf", str(instance / "none.map"), "--scen", str(instance / "m.scen"), "--agents", "1"]
        )
        == 2
    )
    assert "none.map: map not found" in capsys.readouterr().err
