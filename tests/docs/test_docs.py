"""Every command and example in README.md, docs/*.md and scenarios/README.md, run as written.

Each fenced block of those files is in `BLOCKS`, keyed by its file and first line, with what this
module does with it: a test that runs it as written (bash with `cosim` meaning `python -m cosim` of
this tree; a Python block as a script; a TOML fragment in the scenario it is written for) and
checks the outcome the text states, or the reason it is not run (a block that needs another
machine, or is a diagram). A block that is in the docs but not in `BLOCKS`, or in `BLOCKS` but no
longer in the docs, fails `test_every_block_is_known`: nothing is skipped silently.

Outside the fenced blocks: the README's command table (every command and option exists), its
inline `cosim log animate` and `--set obstacles.0.center` examples, and scenarios/README's outcome
tables and replan-horizon note (each scenario rerun with the command the page gives).

The numbers a text quotes are read from the text (regular expressions next to each test) and
compared with the run at the precision quoted. Commands run in a scratch folder holding a copy of
`scenarios/` and `tests/data/movingai/` (the files the docs name, relative to the repository root,
where they are to be run), so `logs/` and `docs/` of the checkout are never written.
"""

from __future__ import annotations

import ast
import csv
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu
from PIL import Image

REPO = Path(__file__).resolve().parents[2]
DOC_FILES = [
    "README.md",
    *sorted(p.relative_to(REPO).as_posix() for p in (REPO / "docs").glob("*.md")),
    "scenarios/README.md",
]
QUICK = "scenarios/warehouse_diff_drive_one_obstacle.toml"


@dataclass(frozen=True)
class Block:
    file: str
    line: int  # of the opening fence, from 1
    lang: str
    text: str

    @property
    def key(self) -> tuple[str, str]:
        return (self.file, first_words(self.text))


def first_words(text: str) -> str:
    """A block's name: the start of its first line, spaces collapsed."""
    return " ".join(text.split("\n", 1)[0].split())[:60].rstrip()


def fenced_blocks(file: str) -> list[Block]:
    """The ``` blocks of a Markdown file."""
    lines = (REPO / file).read_text(encoding="utf-8").split("\n")
    blocks, i = [], 0
    while i < len(lines):
        opening = re.match(r"^```(\S*)\s*$", lines[i])
        if opening is None:
            i += 1
            continue
        j = i + 1
        while not lines[j].startswith("```"):
            j += 1
        blocks.append(Block(file, i + 1, opening.group(1), "\n".join(lines[i + 1 : j]) + "\n"))
        i = j + 1
    return blocks


def all_blocks() -> list[Block]:
    return [block for file in DOC_FILES for block in fenced_blocks(file)]


def block(file: str, first_line: str) -> Block:
    (found,) = [b for b in fenced_blocks(file) if b.key == (file, first_words(first_line))]
    return found


# What happens to each block: the name of the test that runs it, or why it is not run.
RUN = "run by "
BLOCKS: dict[tuple[str, str], str] = {
    (
        "README.md",
        "python3 -m pip install -e . && cosim run scenarios/warehouse",
    ): RUN + "test_quick_start (the `cosim run` of line 1; the pip installs are not run: an editable install "
    "repoints the interpreter's `cosim` at this checkout for every other checkout, and line 2's "
    "`pytest` is this suite)",
    (
        "README.md",
        "scenario.toml ──load/validate──► navigation template + [comp",
    ): ("a diagram of the data flow, not a command"),
    ("README.md", "[vehicle]"): RUN + "test_swapped_vehicle_fragment",
    ("README.md", "[components.lag]"): (
        "names first_order_lag.fmu, which the repository does not have (a user's FMU); adding and wiring "
        "a component is run with fixture FMUs in tests/scenario/test_compose.py"
    ),
    ("README.md", "[system]"): RUN + "test_go_to_goal_fragment",
    ("README.md", "[components.ball]"): RUN + "test_model_exchange_fragment",
    (
        "README.md",
        "cosim fmu simulate $(cosim fmu path DifferentialDrive) --sto",
    ): RUN + "test_fmu_simulate",
    ("README.md", "cosim sweep scenarios/warehouse_diff_drive_one_obstacle.toml \\"): RUN
    + "test_readme_sweeps",
    (
        "README.md",
        "dask scheduler --host 10.0.0.5 --port 8786 # on one machine ",
    ): (
        "needs a Dask scheduler at 10.0.0.5 and workers on other machines; a sweep against a running "
        "scheduler is run in tests/sweep/test_sweep_cluster.py"
    ),
    ("README.md", "import cosim"): RUN + "test_python_api_script",
    ("README.md", "cosim/ the orchestrator, one sub-package per stage of the da"): (
        "a listing of the repository's folders (tests/test_layout.py checks the stages)"
    ),
    (
        "README.md",
        "cosim/core/ Component interface (component.py); the integer",
    ): ("a listing of cosim's stages (tests/test_layout.py checks them)"),
    (
        "docs/logs.md",
        "cosim log info LOG # duration, topics (counts, rates), scena",
    ): RUN + "test_log_commands (a synopsis: LOG, OUT, DIR, IN are placeholders, filled in there)",
    ("docs/logs.md", "from cosim.logs import open_log"): RUN + "test_logs_python_block",
    ("docs/logs.md", "ros2 bag info logs/run.mcap -s mcap"): RUN
    + "test_ros2_bag (needs ROS 2 with rosbag2_storage_mcap: skipped, saying so, "
    "where `ros2` is not installed)",
    ("docs/sweeps.md", "cosim sweep scenarios/warehouse_diff_drive_obstacles.toml \\"): RUN
    + "test_sweeps_md_example",
    ("docs/sweeps.md", "sweep      warehouse_diff_drive_obstacles (grid, 9 runs)"): (
        "the output of the block before: compared with that run's output in test_sweeps_md_example"
    ),
    (
        "docs/sweeps.md",
        "cosim sweep scenarios/warehouse_diff_drive_obstacles.toml --",
    ): RUN + "test_sweeps_md_replicates",
    (
        "docs/sweeps.md",
        "cosim sweep: interrupted: kept 12 of 40 rows in logs/s/resul",
    ): (
        "the output of an interrupted sweep, whose counts depend on when Ctrl-C comes; the interrupt and "
        "these lines are checked in tests/sweep/test_sweep_cluster.py"
    ),
}


BLOCKS = {(file, first_words(first)): what for (file, first), what in BLOCKS.items()}


def test_every_block_is_known():
    """Each fenced block is run by a test or has a reason not to be; no entry names a block gone."""
    blocks = all_blocks()
    keys = [b.key for b in blocks]
    assert len(keys) == len(set(keys)), "two blocks of one file share a first line: make the key unique"
    unknown = [f"{b.file}:{b.line}: {b.key[1]!r}" for b in blocks if b.key not in BLOCKS]
    assert not unknown, "blocks this test neither runs nor lists with a reason:\n" + "\n".join(unknown)
    gone = [f"{file}: {first!r}" for file, first in BLOCKS if (file, first) not in keys]
    assert not gone, "BLOCKS names blocks the docs no longer have:\n" + "\n".join(gone)
    for reason in BLOCKS.values():
        if reason.startswith(RUN):
            assert reason.removeprefix(RUN).split()[0] in globals()


# ---------------------------------------------------------------------------------------------
# Running blocks


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    """A scratch folder laid out as the repository root for the files the docs name."""
    root = tmp_path_factory.mktemp("docs")
    shutil.copytree(REPO / "scenarios", root / "scenarios")
    shutil.copytree(REPO / "tests" / "data" / "movingai", root / "tests" / "data" / "movingai")
    (root / "docs").mkdir()
    return root


def bash(script: str, cwd: Path) -> subprocess.CompletedProcess:
    """Run `script` with bash -e, `cosim` being `python -m cosim` of the tree under test."""
    prelude = (
        f'set -e\ncosim() {{ "{sys.executable}" -m cosim "$@"; }}\npython3() {{ "{sys.executable}" "$@"; }}\n'
    )
    env = {**os.environ, "PYTHONPATH": str(REPO), "COLUMNS": "120"}
    return subprocess.run(["bash", "-c", prelude + script], cwd=cwd, env=env, capture_output=True, text=True)


def check(result: subprocess.CompletedProcess, code: int = 0) -> str:
    assert result.returncode == code, f"exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    return result.stdout + result.stderr


@pytest.fixture(scope="module")
def run_log(workspace) -> Path:
    """logs/run.mcap, as the Python blocks say it was made."""
    python = block("README.md", "import cosim").text
    (command,) = re.findall(r"# the Quick start's run: (cosim run .*)", python)
    assert command == f"cosim run {QUICK} --out logs/run.mcap"
    check(bash(command + " --no-plot", workspace))  # the log is the same, drawn or not
    return workspace / "logs" / "run.mcap"


def box_of(scenario: dict) -> tuple[float, float, float, float]:
    (obstacle,) = scenario["obstacles"]
    assert obstacle["type"] == "rectangle"
    (cx, cy), (sx, sy) = obstacle["center"], obstacle["size"]
    return cx, cy, sx / 2.0, sy / 2.0


def footprint_distance(x, y, box, radius):
    """Distance [m] from a disc of `radius` at (x, y) to an axis-aligned box (cx, cy, hx, hy)."""
    cx, cy, hx, hy = box
    return np.hypot(np.maximum(np.abs(x - cx) - hx, 0.0), np.maximum(np.abs(y - cy) - hy, 0.0)) - radius


def quoted(text: str, pattern: str) -> tuple[str, ...]:
    found = re.search(pattern, text, re.S)
    assert found, f"the docs no longer say {pattern!r}"
    return found.groups()


def same_at_precision(quoted_number: str, value: float) -> bool:
    """`value` written with the decimals of `quoted_number` is `quoted_number`."""
    decimals = len(quoted_number.split(".")[1]) if "." in quoted_number else 0
    return f"{value:.{decimals}f}" == quoted_number


# ---------------------------------------------------------------------------------------------
# README


@pytest.mark.slow
def test_quick_start(workspace):
    """The Quick start's run and everything the README says it shows, read from its log."""
    from cosim.logs import open_log

    first, second = block("README.md", "python3 -m pip install -e . && cosim run " + QUICK).text.splitlines()
    install, command = first.split(" && ")
    assert install == "python3 -m pip install -e ."
    assert second == "python3 -m pip install -e '.[test]' && python3 -m pytest"
    output = check(bash(command, workspace))
    assert re.search(r"goal reached\s+yes", output)
    (log_path,) = (workspace / "logs").glob("warehouse_diff_drive_one_obstacle-*.mcap")
    assert log_path.with_suffix(".png").is_file()

    readme = (REPO / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("## Quick start") : readme.index("## What runs")]
    prose = " ".join(section.split())
    log = open_log(log_path)
    outcome = log.outcome
    scenario = tomllib.loads((REPO / QUICK).read_text(encoding="utf-8"))
    box, radius = box_of(scenario), scenario["vehicle"]["radius"]
    trajectory = log.trajectory()
    distance = footprint_distance(trajectory.x, trajectory.y, box, radius)
    plans = [
        (item.t, np.array([[p.pose.position.x, p.pose.position.y] for p in item.message.poses]))
        for item in log.messages("/plan")
    ]
    mixer = log.signals("mixer")
    avoid = mixer["mode"] == 1  # the mixer's modes: 0 follow, 1 avoid (VFH), 2 recover

    # "a box that is not on the map stands on the path": the first plan runs through it.
    first_plan = plans[0][1]
    assert footprint_distance(first_plan[:, 0], first_plan[:, 1], box, radius).min() < 0

    # "From t = 30 s VFH steers the robot off the path and below the box": the avoid spell that
    # starts then ends with the robot below the box's lower edge.
    (start,) = quoted(prose, r"From t = ([\d.]+) s VFH steers the robot off the path and below the box")
    entries = np.flatnonzero(avoid[1:] & ~avoid[:-1]) + 1
    exits = np.flatnonzero(~avoid[1:] & avoid[:-1]) + 1
    spell = [k for k in entries if same_at_precision(start, mixer.t[k])]
    assert spell, f"no entry into avoid mode at t = {start} s: {mixer.t[entries]}"
    end = mixer.t[exits[exits > spell[0]][0]]
    at_end = np.searchsorted(trajectory.t, end)
    assert trajectory.y[at_end] < box[1] - box[3]
    assert distance[at_end] < 5.0

    # "at t = 37.5 s, beside the box, the planner replans round it": the second plan, made then,
    # keeps the footprint off the box.
    (replan,) = quoted(prose, r"at t = ([\d.]+) s, beside the box, the planner replans round it")
    assert len(plans) == 2 and same_at_precision(replan, plans[1][0])
    assert distance[np.searchsorted(trajectory.t, plans[1][0])] < 5.0
    assert footprint_distance(plans[1][1][:, 0], plans[1][1][:, 1], box, radius).min() > 0

    # "passes it with its footprint 1.6 m away (t = 40.4 s) and reaches the goal at t = 72.9 s"
    gap, when, goal_time = quoted(
        prose, r"footprint ([\d.]+) m away \(t = ([\d.]+) s\) and reaches the goal at t = ([\d.]+) s"
    )
    closest = int(np.argmin(distance))
    assert same_at_precision(gap, distance[closest]) and same_at_precision(when, trajectory.t[closest])
    assert same_at_precision(goal_time, outcome["time"])
    interventions, replans = quoted(prose, r"goal reached, (\d+) VFH interventions, (\d+) replan, exit 0")
    assert outcome["reached"] and outcome["reason"] == "goal_reached"
    assert (outcome["vfh_interventions"], outcome["replans"]) == (int(interventions), int(replans))

    # The GIF: "`cosim log animate logs/<run>.mcap --out docs/quickstart.gif` drew this (10x speed,
    # 20 fps)" from this run: the command as written, then the committed GIF against it.
    from PIL import Image

    (animate,) = quoted(
        prose,
        r"`(cosim log animate logs/<run>\.mcap --out docs/quickstart\.gif)` drew this from the log alone "
        r"\(10x speed, 20 fps\)",
    )
    check(bash(animate.replace("<run>", log_path.stem), workspace))
    with (
        Image.open(workspace / "docs" / "quickstart.gif") as drawn,
        Image.open(REPO / "docs" / "quickstart.gif") as committed,
    ):
        assert drawn.info["duration"] == 1000 / 20
        frames = drawn.n_frames
        # A frame every 0.5 s of the run from t = 0 (and one at its end, if it ends between two).
        assert frames in (
            math.floor(outcome["time"] / (10 / 20)) + 1,
            math.ceil(outcome["time"] / (10 / 20)) + 1,
        )
        assert (committed.n_frames, committed.size) == (frames, drawn.size)


@pytest.mark.slow
def test_swapped_vehicle_fragment(workspace, run_log):
    """The `[vehicle]` fragment with an FMU of other variable names (a second implementation of the
    differential drive, the fixture `diffdrive_fmi2_renamed`), in the Quick start's scenario, and the
    README's `cosim log diff A.mcap B.mcap --tolerance 1e-6` that tells whether it behaves alike."""
    fragment = block("README.md", "[vehicle]").text
    scenarios = workspace / "scenarios"
    shutil.copy(fixture_fmu("diffdrive_fmi2_renamed"), scenarios / "my_vehicle.fmu")
    text = without_tables((REPO / QUICK).read_text(encoding="utf-8"), {"vehicle"}) + "\n" + fragment
    (scenarios / "my_vehicle.toml").write_text(text, encoding="utf-8")
    output = check(
        bash("cosim run scenarios/my_vehicle.toml --out logs/my_vehicle.mcap --no-plot", workspace)
    )
    assert re.search(r"goal reached\s+yes", output)
    readme = " ".join((REPO / "README.md").read_text(encoding="utf-8").split())
    (diff,) = quoted(
        readme,
        r"`(cosim log diff A\.mcap B\.mcap --tolerance 1e-6)` then tells you whether the swapped FMU "
        r"behaves like the original \(exit 1 when not\)",
    )
    output = check(
        bash(diff.replace("A.mcap", "logs/run.mcap").replace("B.mcap", "logs/my_vehicle.mcap"), workspace)
    )
    assert "EQUAL" in output


def without_tables(text: str, names: set[str]) -> str:
    """A TOML text less the tables (and their comments) named."""
    kept, skipping = [], False
    for line in text.split("\n"):
        header = re.match(r"^\[\[?([\w.]+)\]\]?", line)
        if header:
            skipping = header.group(1) in names
        if not skipping:
            kept.append(line)
    return "\n".join(kept)


@pytest.mark.slow
def test_go_to_goal_fragment(workspace):
    """The go-to-goal fragment, with what its comments ask: the sections of the removed components
    deleted, `[planner] replan = false`, and its `[goal]` for the scenario's; the FMU is the fixture
    go-to-goal controller (parameters goal_x, goal_y; inputs x, y, theta; outputs v, omega)."""
    fragment = block("README.md", "[system]").text
    assert (
        'remove = ["pure_pursuit", "vfh", "mixer"]' in fragment and "set [planner] replan = false" in fragment
    )
    scenarios = workspace / "scenarios"
    shutil.copy(fixture_fmu("controller_fmi2"), scenarios / "go_to_goal.fmu")
    base = without_tables(
        (REPO / QUICK).read_text(encoding="utf-8"), {"pure_pursuit", "vfh", "mixer", "goal"}
    )
    base = base.replace("[planner]", "[planner]\nreplan = false", 1)
    (scenarios / "go_to_goal.toml").write_text(base + "\n" + fragment, encoding="utf-8")
    output = check(
        bash("cosim run scenarios/go_to_goal.toml --out logs/go_to_goal.mcap --no-plot", workspace)
    )
    # "the same point as the FMU's (else the run can only end at the stop time)": it ends at the goal.
    assert re.search(r"goal reached\s+yes", output)


@pytest.mark.slow
def test_model_exchange_fragment(workspace):
    """The `[components.ball]` fragment (the fixture bouncing ball, Model Exchange only) added to the
    Quick start's scenario: `cosim system` shows "the solver in the FMI column (`2.0 ME cvode`)"."""
    fragment = block("README.md", "[components.ball]").text
    shutil.copy(fixture_fmu("bouncing_ball_me_fmi2"), workspace / "scenarios" / "bouncing_ball.fmu")
    text = (REPO / QUICK).read_text(encoding="utf-8") + "\n" + fragment
    (workspace / "scenarios" / "ball.toml").write_text(text, encoding="utf-8")
    readme = " ".join((REPO / "README.md").read_text(encoding="utf-8").split())
    (column,) = quoted(readme, r"`cosim system` shows the solver in the FMI column \(`([^`]+)`\)")
    output = check(bash("cosim system scenarios/ball.toml", workspace))
    (row,) = [line for line in output.splitlines() if line.strip().startswith("ball ")]
    assert column in row


@pytest.mark.slow
def test_fmu_simulate(workspace):
    """`cosim fmu simulate` of the differential drive: x.csv ends at t = 10 with x = 1 + 0.5 * 10."""
    text = block(
        "README.md",
        "cosim fmu simulate $(cosim fmu path DifferentialDrive) --sto",
    ).text
    check(bash(text, workspace))
    readme = " ".join((REPO / "README.md").read_text(encoding="utf-8").split())
    t_end, x_end = quoted(readme, r"x\.csv ends at t = ([\d.]+) with x = ([\d.]+), 1 m plus 10 s at 0\.5 m/s")
    with open(workspace / "x.csv", newline="") as file:
        rows = list(csv.reader(file))
    header, last = rows[0], rows[-1]
    assert header[0] == "time" and len(rows) == 1 + 1001  # t = 0 and 1000 steps of 0.01 s
    assert float(last[0]) == pytest.approx(float(t_end), abs=1e-12)
    assert float(last[header.index("x")]) == pytest.approx(1.0 + 0.5 * 10.0, abs=1e-9) == float(x_end)


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as file:
        return list(csv.DictReader(file))


def sweep_dirs(workspace: Path, scenario: str) -> list[Path]:
    return sorted((workspace / "logs").glob(f"sweep-{scenario}-*"))


@pytest.mark.slow
def test_readme_sweeps(workspace):
    """The README's five sweep commands, as written, and what their comments say."""
    text = block("README.md", "cosim sweep scenarios/warehouse_diff_drive_one_obstacle.toml \\").text
    before = {
        name: set(sweep_dirs(workspace, name))
        for name in ("warehouse_diff_drive_one_obstacle", "warehouse_diff_drive_obstacles")
    }
    check(bash(text, workspace))
    logs = workspace / "logs"

    # "# 4 x 2 = 8 runs"
    noise = read_rows(logs / "noise" / "results.csv")
    assert len(noise) == 8 and {(r["lidar.seed"], r["lidar.noise"]) for r in noise} == {
        (str(seed), noise_level) for seed in range(4) for noise_level in ("0.02", "0.05")
    }
    # "# the same sweep, described in a file": the same runs (ids hash the scenario and overrides)
    # with the same outcomes.
    (from_file,) = (
        set(sweep_dirs(workspace, "warehouse_diff_drive_one_obstacle"))
        - before["warehouse_diff_drive_one_obstacle"]
    )
    outcome_columns = [
        "run_id",
        "reason",
        "time",
        "distance",
        "min_clearance",
        "vfh_interventions",
        "replans",
    ]

    def outcomes(rows):
        return sorted(tuple(r[c] for c in outcome_columns) for r in rows)

    assert outcomes(read_rows(from_file / "results.csv")) == outcomes(noise)

    # The three sweeps of the several-obstacle scenario, told apart by their columns and sizes.
    by_kind = {}
    for folder in (
        set(sweep_dirs(workspace, "warehouse_diff_drive_obstacles"))
        - before["warehouse_diff_drive_obstacles"]
    ):
        rows = read_rows(folder / "results.csv")
        kind = (
            "replicates"
            if "replicate" in rows[0]
            else ("lhs" if "pure_pursuit.lookahead_distance" in rows[0] else "grid")
        )
        by_kind[kind] = (folder, rows)
    assert sorted(by_kind) == ["grid", "lhs", "replicates"]
    folder, rows = by_kind["lhs"]  # --method lhs --samples 20 ... --set simulation.stop_time=120
    assert len(rows) == 20 and all(float(r["time"]) <= 120.0 for r in rows)
    assert all(
        0.1 <= float(r["vfh.safety_distance"]) <= 0.5
        and 4 <= float(r["pure_pursuit.lookahead_distance"]) <= 12
        for r in rows
    )
    folder, rows = by_kind["grid"]  # 3 x 3 with --keep-logs failed
    assert len(rows) == 9
    kept = {p.name for p in (folder / "runs").iterdir()}
    for row in rows:
        assert (f"{row['run_id']}.mcap" in kept) == (row["reason"] != "goal_reached")
    folder, rows = by_kind["replicates"]  # "# 2 points x 10 seeds = 20 runs"
    assert len(rows) == 20
    for value in ("0.1", "0.3"):
        seeds = [r["lidar.seed"] for r in rows if r["vfh.safety_distance"] == value]
        assert len(seeds) == len(set(seeds)) == 10


@pytest.mark.slow
def test_python_api_script(workspace, run_log):
    """The README's Python API block saved as example.py and run as a script from the root."""
    from cosim.logs import open_log

    script = block("README.md", "import cosim").text
    (workspace / "example.py").write_text(script, encoding="utf-8")
    output = check(bash("python3 example.py", workspace))
    assert "Traceback" not in output
    reached, time = quoted(
        script, r'log\.outcome\["reached"\], log\.outcome\["time"\]  # (True|False), ([\d.]+)'
    )
    outcome = open_log(run_log).outcome
    assert outcome["reached"] is (reached == "True") and same_at_precision(time, outcome["time"])


# ---------------------------------------------------------------------------------------------
# docs/logs.md

# The synopsis lines of `cosim log`, each with the commands that fill its placeholders (LOG the
# Quick start's log; OUT, DIR, IN files of the scratch folder) and choose each alternative.
PLOT = (
    "cosim log plot LOG [LOG ...] [--png OUT] [--signals vehicle.v_actual vfh.steering_dir ...] "
    "[--dpi N] [--size WxH]"
)
ANIMATE = "cosim log animate LOG --out run.gif|run.mp4 [--fps 20] [--speed 10] [--dpi N] [--size WxH]"
DIFF = "cosim log diff LOG_A LOG_B [--tolerance 1e-9] [--png OUT [--dpi N] [--size WxH]]"
LOG_COMMANDS = {
    "cosim log info LOG": ["cosim log info logs/run.mcap"],
    PLOT: [
        "cosim log plot logs/run.mcap --png plot.png --signals vehicle.v_actual vfh.steering_dir",
        "cosim log plot logs/run.mcap logs/radius.mcap --png both.png --dpi 50 --size 800x500",
    ],
    ANIMATE: ["cosim log animate logs/run.mcap --out run.gif --fps 5 --speed 40 --dpi 40 --size 320x240"],
    "cosim log export LOG --to csv|npz [--component vehicle mixer] [--out DIR]": [
        "cosim log export logs/run.mcap --to csv --component vehicle mixer --out csv",
        "cosim log export logs/run.mcap --to npz --out npz",
    ],
    DIFF: [
        "cosim log diff logs/run.mcap logs/run.mcap --tolerance 1e-9",
        "cosim log diff logs/run.mcap logs/radius.mcap --tolerance 1e-9 --png diff.png --dpi 50 "
        "--size 800x600",
    ],
    "cosim log recover IN [--out OUT]": [
        "cosim log recover cut.mcap --out recovered.mcap",
        "cosim log recover cut.mcap",
    ],
    "cosim log layout LOG [--out OUT]": [
        "cosim log layout logs/run.mcap --out run.layout.json",
        "cosim log layout logs/radius.mcap",
    ],
}


@pytest.mark.slow
def test_log_commands(workspace, run_log):
    """Every line of docs/logs.md's `cosim log` synopsis, filled in, and what its comment says."""
    from cosim.logs import open_log

    text = block(
        "docs/logs.md",
        "cosim log info LOG # duration, topics (counts, rates), scena",
    ).text
    synopsis = {line.split("#")[0].strip(): line.partition("#")[2].strip() for line in text.splitlines()}
    assert sorted(synopsis) == sorted(LOG_COMMANDS)
    # A second log that differs (the README's `--set vfh.robot_radius=0.6`) and a cut one.
    check(bash(f"cosim run {QUICK} --set vfh.robot_radius=0.6 --out logs/radius.mcap --no-plot", workspace))
    data = run_log.read_bytes()
    (workspace / "cut.mcap").write_bytes(data[: len(data) // 2])

    info = check(bash(LOG_COMMANDS["cosim log info LOG"][0], workspace))
    for word in ("/odom", "goal_reached", "DifferentialDrive"):  # "duration, topics ..., outcome, FMUs"
        assert word in info
    one, overlay = LOG_COMMANDS[PLOT]
    check(bash(one, workspace))
    assert (workspace / "plot.png").stat().st_size > 0
    check(bash(overlay, workspace))
    assert Image.open(workspace / "both.png").size == (800, 500)
    check(bash(LOG_COMMANDS[ANIMATE][0], workspace))
    assert Image.open(workspace / "run.gif").size == (320, 240)
    csv_command, npz_command = LOG_COMMANDS[
        "cosim log export LOG --to csv|npz [--component vehicle mixer] [--out DIR]"
    ]
    check(bash(csv_command, workspace))
    vehicle = read_rows(workspace / "csv" / "run-vehicle.csv")
    signals = open_log(run_log).signals("vehicle")
    assert len(vehicle) == len(signals.t) and float(vehicle[-1]["x"]) == signals["x"][-1]
    assert (workspace / "csv" / "run-mixer.csv").is_file()
    check(bash(npz_command, workspace))
    assert "vehicle.values" in np.load(workspace / "npz" / "run-signals.npz").files
    # "exit 0 equal, 1 different, 2 bad input"
    equal, different = LOG_COMMANDS[DIFF]
    assert synopsis[DIFF] == "exit 0 equal, 1 different, 2 bad input"
    check(bash(equal, workspace), 0)
    check(bash(different, workspace), 1)
    assert Image.open(workspace / "diff.png").size == (800, 600)
    check(bash("cosim log diff logs/run.mcap scenarios/README.md", workspace), 2)
    # "a cut log as a complete, indexed MCAP": the default OUT is IN with .recovered.mcap.
    # "a Foxglove layout for this log": its 3D panel shows the log's /scan; the default OUT is
    # LOG with .layout.json.
    for command, out in zip(LOG_COMMANDS["cosim log layout LOG [--out OUT]"],
                            ("run.layout.json", "logs/radius.layout.json"), strict=True):  # fmt: skip
        check(bash(command, workspace))
        layout = json.loads((workspace / out).read_text())
        assert layout["configById"]["3D!navcosim"]["topics"]["/scan"]["visible"]
    with_out, default = LOG_COMMANDS["cosim log recover IN [--out OUT]"]
    for command, out in ((with_out, "recovered.mcap"), (default, "cut.recovered.mcap")):
        check(bash(command, workspace))
        recovered = open_log(workspace / out)
        assert recovered.is_complete and 0 < len(recovered.signals("vehicle").t) < len(signals.t)


@pytest.mark.slow
def test_logs_python_block(workspace, run_log):
    """docs/logs.md's Python block as a script; its comments' outcome values are the log's."""
    script = block("docs/logs.md", "from cosim.logs import open_log").text
    assert 'open_log("logs/run.mcap")' in script
    (workspace / "logs_example.py").write_text(script, encoding="utf-8")
    check(bash("python3 logs_example.py", workspace))
    from cosim.logs import open_log

    log = open_log(run_log)
    (typed,) = quoted(script, r"log\.outcome  # (\{.*?), \.\.\.\}")
    (text,) = quoted(script, r'log\.metadata\["outcome"\]  # .*?: (\{.*?), \.\.\.\}')
    for claimed, actual in ((typed, log.outcome), (text, log.metadata["outcome"])):
        claimed = ast.literal_eval(claimed + "}")
        assert {key: actual[key] for key in claimed} == claimed


@pytest.mark.slow
def test_ros2_bag(workspace, run_log):
    if shutil.which("ros2") is None:
        pytest.skip("docs/logs.md's `ros2 bag info/play` needs ROS 2 (not installed here)")
    text = block("docs/logs.md", "ros2 bag info logs/run.mcap -s mcap").text
    info, _play = text.splitlines()
    assert "/odom" in check(bash(info, workspace))


# ---------------------------------------------------------------------------------------------
# docs/sweeps.md


@pytest.mark.slow
def test_sweeps_md_example(workspace):
    """The example sweep as written; its summary is the one the page quotes, line for line, but for
    the wall time (which is the machine's)."""
    command = block("docs/sweeps.md", "cosim sweep scenarios/warehouse_diff_drive_obstacles.toml \\").text
    output = check(bash(command, workspace))
    quoted_summary = block("docs/sweeps.md", "sweep      warehouse_diff_drive_obstacles (grid, 9 runs)").text
    printed = [line.rstrip() for line in output.splitlines()]
    rows = read_rows(workspace / "logs" / "sweep-example" / "results.csv")
    for line in quoted_summary.splitlines():
        if line.startswith("wall time"):  # the machine's
            assert any(p.startswith("wall time") for p in printed)
            continue
        run = re.match(r"^  ([0-9a-f]{16})  (.*)$", line)
        if run:
            # A run id hashes the path of the map's image as this checkout resolves it (not only
            # the files' contents), so it differs between checkouts: the line's run id must be
            # the run's own in results.csv, the rest as quoted.
            (row,) = [r for r in rows if r["reason"] == "collision"]
            assert f"  {row['run_id']}  {run.group(2)}" in printed, (
                f"the summary has no line {line!r}:\n{output}"
            )
            continue
        assert line.rstrip() in printed, f"the summary has no line {line!r}:\n{output}"


@pytest.mark.slow
def test_sweeps_md_replicates(workspace):
    """The replicates command: 4 runs per point, each with its own seed, and aggregate.csv."""
    command = block(
        "docs/sweeps.md",
        "cosim sweep scenarios/warehouse_diff_drive_obstacles.toml --",
    ).text
    before = set(sweep_dirs(workspace, "warehouse_diff_drive_obstacles"))
    check(bash(command, workspace))
    (folder,) = set(sweep_dirs(workspace, "warehouse_diff_drive_obstacles")) - before
    rows = read_rows(folder / "results.csv")
    columns = list(rows[0])
    key = "pure_pursuit.desired_linear_velocity"
    assert (
        columns.index("replicate") == columns.index(key) + 1
        and columns.index("lidar.seed") == columns.index(key) + 2
    )
    for value in ("1.5", "1.9"):
        point = [r for r in rows if r[key] == value]
        assert sorted(int(r["replicate"]) for r in point) == [0, 1, 2, 3]
        seeds = {int(r["lidar.seed"]) for r in point}
        assert len(seeds) == 4 and all(0 <= s < 2**31 for s in seeds)
    aggregate = read_rows(folder / "aggregate.csv")
    assert [r["runs"] for r in aggregate] == ["4", "4"]
    for row in aggregate:
        times = [float(r["time"]) for r in rows if r[key] == row[key] and r["reason"] == "goal_reached"]
        if not times:  # "They are empty where no run of the point reached the goal"
            assert row["time_mean"] == row["time_std"] == ""
            continue
        assert float(row["time_mean"]) == pytest.approx(np.mean(times), rel=1e-5)  # %g: 6 digits
        if len(times) > 1:
            assert float(row["time_std"]) == pytest.approx(np.std(times, ddof=1), rel=1e-5)


# ---------------------------------------------------------------------------------------------
# scenarios/README.md: the outcome tables (no fenced blocks; its numbers are claims)


def table_rows(text: str, header_start: str) -> list[list[str]]:
    """The cells of the Markdown table whose header line starts with `header_start`."""
    lines = text[text.index(header_start) :].splitlines()
    rows = []
    for line in lines[2:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip("|").split("|")])
    return rows


def parse_outcome(cell: str) -> dict:
    """'goal, 72.90 s, 0.641 m, 1' / '**stop time** 200 s (0.133 m), recovering' /
    'yes, 73.70 s, 0.651 m, 6' / '**no (stop time 200 s)**, -, 0.382 m, 60' -> the quoted values."""
    cell = cell.replace("**", "")
    patterns = [
        (r"^goal, ([\d.]+) s, ([\d.]+) m(?:, (\d+))?$", ("goal_reached", "time", "min_clearance", "replans")),
        (r"^stop time ([\d.]+) s \(([\d.]+) m\)(?:, recovering)?$", ("stop_time", "time", "min_clearance")),
        (
            r"^yes, ([\d.]+) s, ([\d.]+) m, (\d+)$",
            ("goal_reached", "time", "min_clearance", "vfh_interventions"),
        ),
        (
            r"^no \(stop time ([\d.]+) s\), -, ([\d.]+) m, (\d+)$",
            ("stop_time", "time", "min_clearance", "vfh_interventions"),
        ),
    ]
    for pattern, (reason, *names) in patterns:
        found = re.match(pattern, cell)
        if found:
            return {"reason": reason} | {
                n: v for n, v in zip(names, found.groups(), strict=True) if v is not None
            }
    raise AssertionError(f"an outcome cell this test cannot read: {cell!r}")


def assert_outcome(claimed: dict, outcome: dict, what: str) -> None:
    assert outcome["reason"] == claimed["reason"], what
    for name, number in claimed.items():
        if name != "reason":
            assert same_at_precision(number, outcome[name]), f"{what}: {name} {outcome[name]} is not {number}"


def apf_variant(scenario: str) -> str:
    """`scenario` with the avoider and mixer of warehouse_apf.toml ("the same obstacles with [vfh]
    fmu = "ArtificialPotentialField" and the parameters of warehouse_apf.toml")."""
    apf = (REPO / "scenarios" / "warehouse_apf.toml").read_text(encoding="utf-8")
    own = without_tables(
        (REPO / "scenarios" / f"{scenario}.toml").read_text(encoding="utf-8"), {"vfh", "mixer"}
    )
    avoider = apf[apf.index("[vfh]") : apf.index("[lidar]")]
    assert "[mixer]" not in (REPO / "scenarios" / f"{scenario}.toml").read_text(encoding="utf-8")
    return own + "\n" + avoider


@pytest.mark.slow
def test_scenarios_readme_outcomes(workspace):
    """Both outcome tables of scenarios/README.md, run with the command it gives (`S` each
    scenario, `false|true` each value; `--out` into the scratch folder and `--no-plot` added: the
    outcome is the log's, drawn or not)."""
    from cosim.logs import open_log

    text = (REPO / "scenarios" / "README.md").read_text(encoding="utf-8")
    (command,) = quoted(
        " ".join(text.split()),
        r"`(python3 -m cosim run S --set simulation\.macro_step=0\.05 --set output\.pose_rate=20 "
        r"--set planner\.replan=false\|true)`",
    )
    replanning = table_rows(text, "| scenario | replan = false")
    shipped = sorted(p.stem for p in (REPO / "scenarios").glob("*.toml") if not p.stem.startswith("fleet_"))
    assert sorted(row[0].strip("`") for row in replanning) == shipped
    avoiders = table_rows(text, "| obstacles | avoider |")
    for name in ("warehouse_diff_drive_obstacles", "warehouse_diff_drive_large_obstacles"):
        (workspace / "scenarios" / f"apf_{name}.toml").write_text(apf_variant(name), encoding="utf-8")
    runs = [*shipped, "apf_warehouse_diff_drive_obstacles", "apf_warehouse_diff_drive_large_obstacles"]
    # Exit 1 is a run that did not reach the goal (stop time); the two values in parallel.
    halves = [
        "\n".join(
            command.replace(" S ", f" scenarios/{name}.toml ").replace("false|true", replan)
            + f" --out logs/table/{name}-{replan}.mcap --no-plot || test $? = 1"
            for name in runs
        )
        for replan in ("false", "true")
    ]
    check(bash(f"({halves[0]}) & first=$!\n({halves[1]}) & second=$!\nwait $first\nwait $second", workspace))

    def outcome(name: str, replan: str) -> dict:
        return open_log(workspace / "logs" / "table" / f"{name}-{replan}.mcap").outcome

    for name, without, with_replan in replanning:
        name = name.strip("`")
        assert_outcome(parse_outcome(without), outcome(name, "false"), f"{name} replan = false")
        assert_outcome(parse_outcome(with_replan), outcome(name, "true"), f"{name} replan = true")
    scenario = None
    for obstacles, avoider, without, with_replan in avoiders:
        if obstacles:
            (scenario,) = re.findall(r"`\.\.\.(_\w+)`", obstacles)
            scenario = "warehouse_diff_drive" + scenario
        # The one-box run with the potential field is warehouse_apf.toml.
        name = {
            "VFH": scenario,
            "APF": "warehouse_apf" if scenario.endswith("one_obstacle") else f"apf_{scenario}",
        }[avoider]
        assert_outcome(parse_outcome(without), outcome(name, "false"), f"{avoider} {name} replan = false")
        assert_outcome(parse_outcome(with_replan), outcome(name, "true"), f"{avoider} {name} replan = true")


# ---------------------------------------------------------------------------------------------
# README "Command line": each synopsis names a command that exists, with options it has


def subcommand_parsers(parser) -> dict:
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices
    return {}


def test_command_line_table():
    """Every row of the README's command table: its (sub-)commands exist and every option it shows
    is one of theirs (`cosim X --help` lists it)."""
    from cosim.cli import build_parser

    readme = (REPO / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("## Command line") :]
    rows = table_rows(section, "| command | what it does |")
    assert len(rows) >= 15
    checked = 0
    for row in rows:
        for synopsis in re.findall(r"`(cosim [^`]+)`", row[0]):
            words = synopsis.replace("\\|", "|").split()[1:]
            parsers = [build_parser()]
            while words and all(name in subcommand_parsers(parsers[0]) for name in words[0].split("|")):
                parsers = [subcommand_parsers(p)[name] for p in parsers for name in words.pop(0).split("|")]
            assert parsers[0].prog != "cosim", f"no command in {synopsis!r}"
            for option in re.findall(r"(?<![\w-])(--[a-z][a-z-]*)", synopsis):
                for parser in parsers:
                    known = {s for action in parser._actions for s in action.option_strings}
                    assert option in known, f"{parser.prog} has no {option} ({synopsis!r})"
                    checked += 1
    assert checked >= 25  # the table shows about 30 options: the parsing found them


@pytest.mark.slow
def test_set_array_of_tables(workspace):
    """README: "`--set obstacles.0.center=[X,Y]` moves the first `[[obstacles]]`", in the Quick
    start's scenario: the log's /obstacles marker stands at (X, Y)."""
    from cosim.logs import open_log

    readme = " ".join((REPO / "README.md").read_text(encoding="utf-8").split())
    override, x, y = quoted(
        readme, r"`--set (obstacles\.0\.center=\[([\d.]+),([\d.]+)\])` moves the first `\[\[obstacles\]\]`"
    )
    check(bash(f"cosim run {QUICK} --set {override} --out logs/moved.mcap --no-plot", workspace))
    scenario = tomllib.loads((REPO / QUICK).read_text(encoding="utf-8"))
    assert scenario["obstacles"][0]["center"] != [float(x), float(y)]  # it does move
    marker = next(iter(open_log(workspace / "logs" / "moved.mcap").messages("/obstacles"))).message.markers[0]
    assert (marker.pose.position.x, marker.pose.position.y) == (float(x), float(y))


@pytest.mark.slow
def test_replan_horizon_note(workspace, run_log):
    """scenarios/README's note on the Quick start's `replan_horizon`: with the default (20 m) the
    replan comes far from the box and the robot keeps away from it; with 2 m (the scenario's) VFH
    acts first, the replan comes beside the box, and the closest approach is the one quoted."""
    from cosim.logs import open_log

    text = " ".join((REPO / "scenarios" / "README.md").read_text(encoding="utf-8").split())
    horizon, default = quoted(
        text, r"`replan_horizon = ([\d.]+)`; the default, ([\d.]+) m, is the lidar's range"
    )
    scenario = tomllib.loads((REPO / QUICK).read_text(encoding="utf-8"))
    assert scenario["planner"]["replan_horizon"] == float(horizon)
    assert scenario["lidar"]["range"][1] == float(default)
    box, radius = box_of(scenario), scenario["vehicle"]["radius"]
    ahead, far = quoted(
        text,
        r"With 20 m the box, seen on the plan ([\d.]+) m ahead, made a replan into another aisle and the "
        r"robot's footprint never came within ([\d.]+) m of it",
    )
    check(
        bash(
            f"cosim run {QUICK} --set planner.replan_horizon={default} --out logs/h20.mcap --no-plot",
            workspace,
        )
    )
    for path, replan_distance, closest in (
        (workspace / "logs" / "h20.mcap", ahead, far),
        (run_log, None, None),
    ):
        log = open_log(path)
        trajectory = log.trajectory()
        distance = footprint_distance(trajectory.x, trajectory.y, box, radius)
        plans = [item.t for item in log.messages("/plan")]
        assert len(plans) == 2 and log.outcome["replans"] == 1
        at_replan = distance[np.searchsorted(trajectory.t, plans[1])]
        if replan_distance is not None:
            assert same_at_precision(replan_distance, at_replan)
            assert same_at_precision(closest, distance.min())
    start, replan, gap, clearance = quoted(
        text,
        r"With 2 m VFH steers the robot off the plan and below the box from t = ([\d.]+) s, the planner "
        r"replans beside it at ([\d.]+) s, and the footprint passes ([\d.]+) m from it \(the minimum "
        r"clearance, ([\d.]+) m, is to a rack corner\)",
    )
    readme = " ".join((REPO / "README.md").read_text(encoding="utf-8").split())
    # The same numbers as the README's Quick start, which test_quick_start checks against the run.
    assert f"From t = {start} s VFH steers" in readme and f"at t = {replan} s, beside the box" in readme
    assert f"footprint {gap} m away" in readme
    log = open_log(run_log)
    assert same_at_precision(clearance, log.outcome["min_clearance"])
    trajectory = log.trajectory()
    assert footprint_distance(trajectory.x, trajectory.y, box, radius).min() > log.outcome["min_clearance"]
