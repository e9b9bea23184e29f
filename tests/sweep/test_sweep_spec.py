"""Sweep specifications without a cluster: --vary texts, sampling (grid, random, LHS), run ids,
sweep files, and the one-line errors of `cosim sweep` (exit 2)."""

from __future__ import annotations

import shutil
import socket
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.errors import CosimError
from cosim.sweep import build, engine
from cosim.sweep.engine import plan
from cosim.sweep.spec import make_spec, parse_vary, sample_points

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


def test_vary_lists_and_ranges():
    assert parse_vary("lidar.seed=0,1,5").values == (0, 1, 5)
    assert parse_vary("lidar.seed=0:6:4").values == (0, 2, 4, 6)  # integer ends, whole steps
    assert parse_vary("lidar.noise=0:0.1:3").values == (0.0, 0.05, 0.1)
    # 12 significant digits: the 0.1 steps read as written.
    assert parse_vary("lidar.noise=0:1:11").values[3] == 0.3
    assert parse_vary("lidar.seed=0:1:3").values == (0.0, 0.5, 1.0)  # not whole: floats
    assert parse_vary("simulation.master=gauss-seidel,jacobi").values == ("gauss-seidel", "jacobi")
    # Commas inside brackets belong to one value.
    assert parse_vary("vfh.distance_limits=[3.5, 20.0],[2.0, 15.0]").values == ([3.5, 20.0], [2.0, 15.0])
    interval = parse_vary("lidar.noise=0.01:0.2")
    assert interval.values is None and interval.interval == (0.01, 0.2) and not interval.integer
    assert parse_vary("lidar.seed=0:9").integer


@pytest.mark.parametrize(
    "text, message",
    [
        ("lidar.noise", "expected KEY=V1,V2"),
        ("lidar.noise=0:0.1:0", "COUNT must be an integer >= 1"),
        ("lidar.noise=0:0.1:x", "COUNT must be an integer >= 1"),
        ("lidar.noise=a:0.1:3", "START and STOP must be finite numbers"),
        ("lidar.noise=0:1:2:3", "expected START:STOP:COUNT or START:STOP"),
        ("lidar.noise=0.2:0.1", "START must be < STOP"),
        ("lidar.noise=0.1,,0.2", "an empty value"),
    ],
)
def test_bad_vary_texts(text, message):
    with pytest.raises(CosimError, match=message):
        parse_vary(text)


def test_grid_is_the_product_first_key_slowest():
    spec = make_spec(SCENARIO, [parse_vary("lidar.seed=0,1"), parse_vary("lidar.noise=0.0,0.1,0.2")])
    assert sample_points(spec) == [(0, 0.0), (0, 0.1), (0, 0.2), (1, 0.0), (1, 0.1), (1, 0.2)]


def test_latin_hypercube_puts_one_point_in_every_stratum():
    samples = 10
    dimensions = [
        parse_vary("lidar.noise=0.0:0.5"),
        parse_vary("lidar.seed=0:9"),
        parse_vary("vfh.x=1,2,3,4,5"),
    ]
    spec = make_spec(SCENARIO, dimensions, "lhs", samples, seed=3)
    points = np.array(sample_points(spec), dtype=float)
    # Definition of a Latin hypercube: along each axis every one of the N equal strata holds one point.
    strata = np.floor(points[:, 0] / 0.5 * samples).astype(int)
    assert sorted(strata) == list(range(samples))
    assert sorted(points[:, 1].astype(int)) == list(range(10))  # 10 integers, 10 strata: each once
    assert sorted(np.bincount(points[:, 2].astype(int))[1:]) == [2] * 5  # 5 values, 10 strata: twice each
    assert sample_points(spec) == sample_points(make_spec(SCENARIO, dimensions, "lhs", samples, seed=3))
    assert sample_points(spec) != sample_points(make_spec(SCENARIO, dimensions, "lhs", samples, seed=4))


def test_random_sampling_is_seeded_and_stays_in_range():
    dimensions = [parse_vary("lidar.noise=0.0:0.5"), parse_vary("lidar.seed=3:5")]
    points = sample_points(make_spec(SCENARIO, dimensions, "random", 200, seed=1))
    assert points == sample_points(make_spec(SCENARIO, dimensions, "random", 200, seed=1))
    assert all(0.0 <= noise <= 0.5 for noise, _ in points)
    assert {seed for _, seed in points} == {3, 4, 5} and all(isinstance(s, int) for _, s in points)


@pytest.mark.parametrize(
    "arguments, message",
    [
        (dict(method="grid", samples=4), "--samples applies to --method random and lhs"),
        (dict(method="lhs"), "needs --samples N"),
        (dict(method="sobol"), "expected grid, random or lhs"),
    ],
)
def test_bad_method_options(arguments, message):
    with pytest.raises(CosimError, match=message):
        make_spec(SCENARIO, [parse_vary("lidar.seed=0,1")], **arguments)


def test_a_grid_needs_values_not_an_interval():
    with pytest.raises(CosimError, match="a grid needs a list or START:STOP:COUNT"):
        make_spec(SCENARIO, [parse_vary("lidar.noise=0.0:0.1")])


def _copy_scenario(folder: Path) -> Path:
    shutil.copytree(REPO / "scenarios" / "maps", folder / "maps")
    target = folder / SCENARIO.name
    shutil.copy(SCENARIO, target)
    return target


def test_run_ids_follow_the_scenario_its_files_and_overrides(tmp_path):
    scenario = _copy_scenario(tmp_path)
    spec = make_spec(scenario, [parse_vary("lidar.seed=0,1")], overrides=["simulation.stop_time=5"])
    bundle, runs, _ = plan(spec)
    again = [run.run_id for run in plan(spec)[1]]
    assert [run.run_id for run in runs] == again and len(set(again)) == 2
    assert runs[0].overrides == ("simulation.stop_time=5", "lidar.seed=0")
    # The bundle holds the scenario, the map YAML and the image the YAML names, by relative path.
    assert set(bundle.files) == {SCENARIO.name, "maps/warehouse.yaml", "maps/warehouse.pgm"}
    other_base = make_spec(scenario, [parse_vary("lidar.seed=0,1")], overrides=["simulation.stop_time=6"])
    assert {run.run_id for run in plan(other_base)[1]}.isdisjoint(again)
    image = tmp_path / "maps" / "warehouse.pgm"
    data = bytearray(image.read_bytes())
    data[-1] ^= 0xFF  # one map cell changes: the runs are not the same runs any more
    image.write_bytes(bytes(data))
    assert {run.run_id for run in plan(spec)[1]}.isdisjoint(again)


def test_run_ids_do_not_depend_on_the_folder_the_sweep_lies_in(tmp_path):
    """The same scenario and map in two folders: the same runs (a map YAML's image is found by its
    resolved path, which must not enter the run id), so `--resume` after moving a sweep's folder
    redoes nothing."""
    ids = []
    for name in ("first", "second/deeper"):
        folder = tmp_path / name
        folder.mkdir(parents=True)
        spec = make_spec(_copy_scenario(folder), [parse_vary("lidar.seed=0,1")], overrides=[])
        ids.append([run.run_id for run in plan(spec)[1]])
    assert ids[0] == ids[1] and len(set(ids[0])) == 2


def test_sweep_file_merges_with_arguments(tmp_path):
    sweep_file = tmp_path / "sweep.toml"
    sweep_file.write_text(
        f"""
[sweep]
scenario = "{SCENARIO}"
method = "lhs"
samples = 3
seed = 7
set = ["simulation.stop_time=5"]
out = "out"
workers = 1

[vary]
"lidar.noise" = {{ start = 0.0, stop = 0.1 }}
lidar.seed = [0, 1, 2]
"""
    )
    spec, options = build(
        sweep_file, ["lidar.seed=4,5"], None, None, None, ["lidar.rate=20"], None, None, None, False
    )
    assert spec.method == "lhs" and spec.samples == 3 and spec.seed == 7
    assert spec.keys == ("lidar.noise", "lidar.seed")
    assert spec.dimensions[1].values == (4, 5)  # the command line replaces the file's values
    assert spec.overrides == ("simulation.stop_time=5", "lidar.rate=20")
    assert options.out == tmp_path / "out" and options.workers == 1
    shipped = REPO / "scenarios" / "sweeps" / "warehouse_lidar_noise.toml"
    spec, _ = build(shipped, None, None, None, None, (), None, None, None, False)
    assert spec.scenario.resolve() == SCENARIO and len(sample_points(spec)) == 8


def _one_line_error(capsys, argv) -> str:
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cosim: error: "), captured.err
    return lines[0]


@pytest.mark.parametrize(
    "vary, message",
    [
        ("vfh.robot_radus=0.4,0.5", "no parameter 'robot_radus' (did you mean 'robot_radius'?)"),
        ("lidar.cont=90,180", "unknown key (did you mean 'count'?)"),
        ("lidr.seed=0,1", "unknown section 'lidr' (did you mean 'lidar'?)"),
        ("lidar.seed=0.5,1", "--vary lidar.seed=0.5,1: .* [lidar].seed: must be an integer, got 0.5"),
        ("lidar.noise=-0.1,0.1", "noise: must be >= 0, got -0.1"),
        ("lidar.noise=0:0.1:zero", "bad range: COUNT must be an integer"),
    ],
)
def test_bad_vary_is_one_line_and_exit_2(capsys, tmp_path, vary, message):
    # One worker: an FMU parameter is checked by a build that overlaps the cluster's start.
    argv = ["sweep", str(SCENARIO), "--vary", vary, "--out", str(tmp_path / "out"), "--workers", "1"]
    line = _one_line_error(capsys, argv)
    assert all(part in line for part in message.split(" .* ")), line
    assert not (tmp_path / "out").exists(), "a refused sweep leaves nothing behind"


def test_unreachable_scheduler_is_exit_2(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", 1.0)
    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    line = _one_line_error(
        capsys,
        ["sweep", str(SCENARIO), "--vary", "lidar.seed=0,1", "--out", str(tmp_path / "out")]
        + ["--scheduler", f"tcp://127.0.0.1:{port}"],
    )
    assert f"--scheduler tcp://127.0.0.1:{port}: cannot reach the Dask scheduler" in line


def test_unwritable_out_dir_is_exit_2(capsys, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    line = _one_line_error(
        capsys, ["sweep", str(SCENARIO), "--vary", "lidar.seed=0,1", "--out", str(blocker / "out")]
    )
    assert f"--out {blocker / 'out'}: not writable" in line


def test_an_earlier_sweep_needs_resume(capsys, tmp_path):
    (tmp_path / "results.csv").write_text("run_id\n")
    line = _one_line_error(
        capsys, ["sweep", str(SCENARIO), "--vary", "lidar.seed=0,1", "--out", str(tmp_path)]
    )
    assert "holds an earlier sweep (results.csv); add --resume" in line


def test_local_cluster_starts_before_the_sweep_is_planned(tmp_path, monkeypatch):
    """The fork server of the local cluster (Dask's start-up: its imports and a warm-up run) starts
    first, so it warms up while the sweep is validated; a sweep on a scheduler starts none."""
    calls = []
    monkeypatch.setattr(engine, "start_fork_server", lambda *args, **named: calls.append("fork server"))
    planned = engine.plan
    monkeypatch.setattr(engine, "plan", lambda spec: calls.append("plan") or planned(spec))
    spec, options = build(
        SCENARIO, ["lidar.noise=-1,0.05"], None, None, None, (), tmp_path / "out", None, None, False
    )
    with pytest.raises(CosimError, match="lidar.noise"):
        engine.run_sweep(spec, options, progress=False, plot=False)
    assert calls == ["fork server", "plan"]
    calls.clear()
    spec, options = build(
        SCENARIO, ["lidar.noise=-1,0.05"], None, None, None, (), tmp_path / "out", None, "tcp://x:1", False
    )
    with pytest.raises(CosimError, match="lidar.noise"):
        engine.run_sweep(spec, options, progress=False, plot=False)
    assert calls == ["plan"]
