"""`cosim plan` and `cosim plan compare` end to end: metrics, PNGs, the comparison table, bad input.

Truths: an independent Dijkstra length (the optimal 8-connected length printed by the map README and
re-derived in test_thesis_direction), PNG headers read byte by byte, and the CLI contract (user errors
exit 2 with one `cosim: error:` line and no traceback).
"""

from __future__ import annotations

import importlib.util
import re
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.cli.plan_plot import figure_size_px

REPO = Path(__file__).resolve().parents[2]
WAREHOUSE = REPO / "scenarios" / "maps" / "warehouse.yaml"
# Optimal 8-connected length without corner cutting of query thesis_table_3_1 [m]: 104 straight
# half-metre steps and 73 diagonal ones (the scipy Dijkstra of test_thesis_direction gives it; as
# sqrt(2) is irrational, every optimal path has exactly these steps, so 178 path nodes).
TABLE_3_1_OPTIMAL = 0.5 * (104 + 73 * np.sqrt(2.0))
HYBRID = importlib.util.find_spec("planner.hybrid") is not None


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) [px] from a PNG's IHDR chunk."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def metric(output: str, name: str, column: int = 0) -> str:
    line = next(line for line in output.splitlines() if line.startswith(name))
    return line[len(name) :].split()[column]


def test_plan_prints_metrics_and_draws_png(tmp_path, capsys):
    png = tmp_path / "plan.png"
    code = main(
        ["plan", str(WAREHOUSE), "--start", "6,6", "--goal", "84,53", "--repeat", "2", "--png", str(png)]
    )
    output = capsys.readouterr().out
    assert code == 0
    assert float(metric(output, "path length [m]")) == pytest.approx(TABLE_3_1_OPTIMAL, abs=0.006)
    assert int(metric(output, "path nodes")) == 104 + 73 + 1
    assert int(metric(output, "searched nodes")) > 177
    # A measured time, so only its sign is a behaviour; the machine sets its size.
    assert float(metric(output, "elapsed time [s]")) > 0.0
    assert "median of 2 runs" in output and "untimed run that loads" in output
    assert png.stat().st_size > 10_000
    assert png_size(png) == figure_size_px(1)


def test_named_query_gives_the_same_plan(capsys):
    assert main(["plan", str(WAREHOUSE), "--query", "thesis_table_3_1", "--repeat", "1"]) == 0
    output = capsys.readouterr().out
    assert float(metric(output, "path length [m]")) == pytest.approx(TABLE_3_1_OPTIMAL, abs=0.006)


def test_options_reach_the_planner(capsys):
    arguments = ["plan", str(WAREHOUSE), "--query", "thesis_table_3_1", "--repeat", "1"]
    assert main([*arguments, "--connectivity", "4"]) == 0
    four = capsys.readouterr().out
    # 4-connected: the Manhattan distance is a lower bound, reached when the detours are monotone.
    assert float(metric(four, "path length [m]")) >= (84 - 6) + (53 - 6) - 1e-9
    assert main([*arguments, "--expansion-distance", "0.8", "--heuristic", "thesis"]) == 0
    inflated = capsys.readouterr().out
    assert float(metric(inflated, "path length [m]")) > TABLE_3_1_OPTIMAL
    assert "expansion_distance 0.8" in inflated


@pytest.mark.skipif(not HYBRID, reason="planner.hybrid not available")
def test_hybrid_takes_poses(capsys):
    arguments = ["plan", str(WAREHOUSE), "--start", "6,6,0", "--goal", "84,53,0", "--planner", "hybrid"]
    assert (
        main([*arguments, "--expansion-distance", "2.25", "--min-turning-radius", "3.5", "--repeat", "1"])
        == 0
    )
    output = capsys.readouterr().out
    assert float(metric(output, "path length [m]")) >= np.hypot(84 - 6, 53 - 6)


def test_compare_prints_the_thesis_columns_and_draws_panels(tmp_path, capsys):
    png = tmp_path / "compare.png"
    code = main(
        ["plan", "compare", str(WAREHOUSE), "--query", "thesis_table_3_1", "--repeat", "1", "--png", str(png)]
    )
    output = capsys.readouterr().out
    assert code == 0
    header = next(line for line in output.splitlines() if "basic" in line and "modified" in line)
    columns = ["basic", "modified", "inflated", "inflated + new h"] + (["hybrid"] if HYBRID else [])
    assert re.split(r"\s{2,}", header.strip()) == columns
    for name in ("path length [m]", "path nodes", "searched nodes", "elapsed time [s]"):
        assert len(metric(output, name, slice(None))) == len(columns)
    lengths = [float(value) for value in metric(output, "path length [m]", slice(None))]
    searched = [int(value) for value in metric(output, "searched nodes", slice(None))]
    assert lengths[2] > lengths[1]  # inflation keeps away from the racks: a longer path
    assert searched[3] < searched[0]  # eq 3.6 searches far fewer nodes than the basic A*
    if not HYBRID:
        assert "hybrid column omitted" in output
    assert png_size(png) == figure_size_px(len(columns))


@pytest.mark.slow
def test_subprocess_run_and_error(tmp_path):
    command = [
        sys.executable,
        "-m",
        "cosim",
        "plan",
        str(WAREHOUSE),
        "--query",
        "thesis_table_3_3",
        "--repeat",
        "1",
    ]
    completed = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert completed.returncode == 0, completed.stderr
    assert "path length [m]" in completed.stdout
    completed = subprocess.run(
        [*command[:-4], "--start=-5,6", "--goal", "84,53"], capture_output=True, text=True, timeout=120
    )
    assert completed.returncode == 2
    assert completed.stderr.startswith("cosim: error:") and completed.stderr.count("\n") == 1
    assert "Traceback" not in completed.stderr


def _write_map(folder: Path, name: str, pgm: bytes, **yaml_keys) -> Path:
    (folder / f"{name}.pgm").write_bytes(pgm)
    keys = {"image": f"{name}.pgm", "resolution": 1.0, "origin": "[0.0, 0.0, 0.0]", "negate": 0}
    keys.update({"occupied_thresh": 0.65, "free_thresh": 0.196, **yaml_keys})
    path = folder / f"{name}.yaml"
    path.write_text("".join(f"{key}: {value}\n" for key, value in keys.items()))
    return path


def _pgm(pixels: np.ndarray, header: str | None = None) -> bytes:
    rows, cols = pixels.shape
    return (header or f"P5\n{cols} {rows}\n255\n").encode() + pixels.astype(np.uint8).tobytes()


@pytest.fixture
def bad_maps(tmp_path) -> dict[str, Path]:
    walled = np.full((10, 10), 254)
    walled[:, 5] = 0  # a wall from top to bottom: left and right halves never meet
    pixels = np.full((10, 10), 254)
    maps = {
        "no_path": _write_map(tmp_path, "walled", _pgm(walled)),
        "bad_header": _write_map(tmp_path, "header", _pgm(pixels, "P7\n10 10\n255\n")),
        "sizes_disagree": _write_map(tmp_path, "sizes", _pgm(pixels, "P5\n12 10\n255\n")),
        "zero_resolution": _write_map(tmp_path, "zero", _pgm(pixels), resolution=0.0),
        "negative_resolution": _write_map(tmp_path, "negative", _pgm(pixels), resolution=-0.5),
    }
    (tmp_path / "garbage.png").write_bytes(b"this is not an image")
    maps["unreadable_image"] = tmp_path / "garbage.png"
    np.save(tmp_path / "free.npy", np.zeros((10, 10), dtype=bool))
    maps["npy"] = tmp_path / "free.npy"
    return maps


W = str(WAREHOUSE)
BAD_INPUT = {
    "start outside the map": [W, "--start=-5,6", "--goal", "84,53"],
    "goal outside the map": [W, "--start", "6,6", "--goal", "84,75"],
    "start on an obstacle": [W, "--start", "20,13.5", "--goal", "84,53"],
    "goal inside the inflation": [W, "--start", "6,6", "--goal", "20,16.5", "--expansion-distance", "2.25"],
    "bad X,Y syntax": [W, "--start", "6;6", "--goal", "84,53"],
    "X,Y not numbers": [W, "--start", "six,6", "--goal", "84,53"],
    "too many values": [W, "--start", "6,6,0,1", "--goal", "84,53"],
    "hybrid needs a heading": [W, "--start", "6,6", "--goal", "84,53", "--planner", "hybrid"],
    "unknown query": [W, "--query", "nope"],
    "grid option with hybrid": [
        W,
        "--query",
        "thesis_table_3_1",
        "--planner",
        "hybrid",
        "--heuristic",
        "octile",
    ],
    "hybrid option with A*": [W, "--query", "thesis_table_3_1", "--min-turning-radius", "3.5"],
    "missing start": [W, "--goal", "84,53"],
    "missing map": ["/nonexistent/map.yaml", "--start", "1,1", "--goal", "2,2"],
    "negative expansion": [W, "--query", "thesis_table_3_1", "--expansion-distance", "-1"],
    "no path": ["{no_path}", "--start", "1.5,5", "--goal", "8.5,5"],
    "wrong PGM header": ["{bad_header}", "--start", "1.5,5", "--goal", "8.5,5"],
    "PGM sizes disagree": ["{sizes_disagree}", "--start", "1.5,5", "--goal", "8.5,5"],
    "resolution zero": ["{zero_resolution}", "--start", "1.5,5", "--goal", "8.5,5"],
    "resolution negative": ["{negative_resolution}", "--start", "1.5,5", "--goal", "8.5,5"],
    "unreadable image": ["{unreadable_image}", "--start", "1.5,5", "--goal", "8.5,5"],
    "npy resolution <= 0": ["{npy}", "--resolution", "0", "--start", "1.5,5", "--goal", "8.5,5"],
    "compare: start outside": ["compare", W, "--start=-5,6", "--goal", "84,53"],
}


@pytest.mark.parametrize("case", sorted(BAD_INPUT))
def test_bad_input_exits_2_with_one_line(case, bad_maps, capsys):
    arguments = [word.format(**bad_maps) if word.startswith("{") else word for word in BAD_INPUT[case]]
    code = main(["plan", *arguments, "--repeat", "1"])
    captured = capsys.readouterr()
    assert code == 2, captured
    assert captured.err.startswith("cosim: error: ")
    assert captured.err.count("\n") == 1, captured.err
    assert "Traceback" not in captured.err


def test_plan_prints_every_option_it_ran_with(capsys):
    """The defaults are said, not only the given options: resolved as `planner.options.resolve`
    resolves them, the given ones marked."""
    from planner.options import PRESETS

    assert main(["plan", str(WAREHOUSE), "--query", "thesis_table_3_1", "--repeat", "1"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("options"))
    assert "planner astar*" in line and "connectivity 8," in line and "heuristic octile," in line
    assert "expansion_distance 0," in line and "untrusted_points False," in line
    arguments = ["--configuration", "modified", "--heuristic", "euclidean"]
    assert main(["plan", str(WAREHOUSE), "--query", "thesis_table_3_1", "--repeat", "1", *arguments]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("options"))
    assert "configuration modified*" in line and "heuristic euclidean*" in line
    assert f"untrusted_points {PRESETS['modified']['untrusted_points']}," in line  # from the preset


def test_each_compare_column_is_reproduced_by_the_plan_command_it_prints(capsys):
    """`plan compare` names, per column, the `cosim plan` command with the same options; run as
    printed, each gives the column's path length, path nodes and searched nodes."""
    import shlex

    assert (
        main(["plan", "compare", str(WAREHOUSE), "--start", "6,6", "--goal", "84,53", "--repeat", "1"]) == 0
    )
    output = capsys.readouterr().out
    header = next(line for line in output.splitlines() if line.strip().startswith("basic"))
    labels = re.split(r"\s{2,}", header.strip())
    commands = dict(
        line.strip().split(": ", 1)
        for line in output.split("each column alone")[1].splitlines()[1:]
        if line.startswith("  ")
    )
    assert list(commands) == labels
    for column, label in enumerate(labels):
        words = shlex.split(commands[label])
        assert words[:2] == ["cosim", "plan"]
        assert main([*words[1:], "--repeat", "1"]) == 0
        alone = capsys.readouterr().out
        for name in ("path length [m]", "path nodes", "searched nodes"):
            assert metric(alone, name) == metric(output, name, column), (label, name)
