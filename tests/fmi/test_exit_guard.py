"""An FMU in the run's own process (isolation = "none") that calls exit(): the process ends with exit
status 2 and one line naming that FMU and the FMI call it was in, with the log finalised
(`cosim.fmi.exit_guard`), not with the FMU's "successful" exit 0. A process that ends by itself
while an FMU is loaded keeps its own status.

Truths: the exit status and stderr as the operating system hands them to the parent, the log as
rosbags (a second MCAP/CDR reader) reads it, and the fault fixture's documented fault step.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from fixtures.build_fixtures import FAULTS
from fixtures.conftest_helpers import fixture_fmu
from rosbags.highlevel import AnyReader

from cosim.logs import open_log

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
FAULT_TIME = 2.0  # [s]
PATHS = [str(REPO), str(REPO / "tests")]


def python(code: str, **options) -> subprocess.CompletedProcess:
    """`code` in a new interpreter that imports this tree and the test fixtures."""
    prelude = f"import sys\nsys.path[:0] = {PATHS!r}\n"
    return subprocess.run(
        [sys.executable, "-c", prelude + textwrap.dedent(code)], capture_output=True, text=True, **options
    )


STEPPED = """
from fixtures.build_fixtures import FAULTS
from fixtures.conftest_helpers import fixture_fmu
from cosim.fmi.component import FmuComponent
components = []
for kind, name, fault in {faults!r}:
    c = FmuComponent(fixture_fmu(kind), name)
    c.instantiate()
    c.setup(0.0, {{"fault": FAULTS.index(fault), "fault_time": 0.3}} if fault else {{}})
    c.initialize()
    components.append(c)
for k in range(10):
    for c in components:
        c.do_step(round(k * 0.1, 9), 0.1)
print("all steps done", flush=True)
"""


@pytest.mark.slow
def test_exit_inside_an_fmu_in_this_process_is_a_failed_fmu():
    """Two FMUs of other libraries in the process, the fault FMU calls exit(0) in its doStep at
    t = 0.3 s: the line names it and the FMI function."""
    completed = python(
        STEPPED.format(
            faults=[
                ("gain_fmi2", "before", None),
                ("fault_fmi2", "vehicle", "exit"),
                ("gain_fmi3", "after", None),
            ]
        )
    )
    assert completed.returncode == 2
    assert completed.stdout == ""
    assert completed.stderr == (
        "cosim: error: FMU 'vehicle' (model fixture_fault_fmi2) ended the process with exit status 0 "
        '(exit() inside the FMU; isolation = "none") in fmi2DoStep\n'
    )


@pytest.mark.slow
@pytest.mark.parametrize("order", [("vehicle", "healthy"), ("healthy", "vehicle")])
def test_instances_sharing_a_library_are_all_named(order):
    """Two instances of one FMU that may be instantiated more than once per process share one
    unpacked library, so the call stack cannot tell which called exit(): the line names both (in
    the order they were instantiated) and says so, whichever one exits, never the other alone."""
    faults = {"vehicle": "exit", "healthy": "none"}
    completed = python(STEPPED.format(faults=[("fault_fmi2", name, faults[name]) for name in order]))
    assert completed.returncode == 2
    names = ", ".join(repr(name) for name in order)
    assert completed.stderr == (
        "cosim: error: one of the 2 instances of FMU model fixture_fault_fmi2 sharing one library "
        f"({names}; the stack does not tell which) ended the process with exit status 0 "
        '(exit() inside the FMU; isolation = "none") in fmi2DoStep\n'
    )


@pytest.mark.slow
def test_a_process_that_ends_by_itself_keeps_its_status():
    """No FMU called exit(): the interpreter's own end (sys.exit while an FMU is instantiated, and a
    normal end after it was freed) is neither reported nor changed."""
    healthy = [("fault_fmi2", "vehicle", "none")]
    completed = python(STEPPED.format(faults=healthy) + "sys.exit(3)\n")
    assert (completed.returncode, completed.stderr) == (3, "")
    assert completed.stdout == "all steps done\n"
    freed = python(STEPPED.format(faults=healthy) + "components[0].free()\n")
    assert (freed.returncode, freed.stderr) == (0, "")


def scenario(tmp_path: Path) -> Path:
    """The shipped one-obstacle scenario, 4 s, with the fault FMU (exit() at 2 s) as its vehicle in
    this process."""
    text = SHIPPED.read_text()
    map_file = (SHIPPED.parent / "maps" / "warehouse.yaml").resolve()
    text = re.sub(r'(?m)^file = "maps/warehouse.yaml"', f'file = "{map_file}"', text)
    start = text.index("[vehicle]")
    end = text.index("\n[", start + 1)
    section = (
        f'[vehicle]\nfmu = "{fixture_fmu("fault_fmi2")}"\ntype = "differential"\nradius = 0.5\n'
        f'isolation = "none"\nfault = {FAULTS.index("exit")}\nfault_time = {FAULT_TIME}\n'
    )
    text = text[:start] + section + text[end:]
    text = re.sub(r"(?m)^stop_time = .*$", "stop_time = 4.0", text)
    path = tmp_path / "exit.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
@pytest.mark.parametrize("loop", ["kernel", "python"])
def test_cosim_run_with_an_exiting_fmu_in_process_exits_2_with_its_log_finalised(tmp_path, loop):
    log_path = tmp_path / "exit.mcap"
    environment = dict(os.environ)
    if loop == "python":
        environment["NAVCOSIM_LOOP"] = "python"
    completed = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(scenario(tmp_path)), "--out", str(log_path), "--quiet"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=environment,
    )
    assert completed.returncode == 2
    lines = completed.stderr.splitlines()
    assert len(lines) == 1, completed.stderr
    failure = (
        "FMU 'vehicle' (model fixture_fault_fmi2) ended the process with exit status 0 "
        '(exit() inside the FMU; isolation = "none") in fmi2DoStep (after t = 2.000 s)'
    )
    assert lines[0] == f"cosim: error: {failure}; log (up to the failure): {log_path}"
    log = open_log(log_path)  # finalised: its summary and metadata are there
    assert log.outcome["reason"] == "fmu_failed" and log.outcome["failure"] == failure
    assert float(log.outcome["time"]) == pytest.approx(FAULT_TIME, abs=1e-9)
    assert "isolation" not in log.metadata["fmu/vehicle"]  # in-process (a child would say "process")
    stamps = []
    with AnyReader([log_path]) as reader:  # a second reader: the file is complete MCAP
        connections = [c for c in reader.connections if c.topic == "/odom"]
        for _, timestamp, _ in reader.messages(connections=connections):
            stamps.append(timestamp * 1e-9)
    assert np.all(np.diff(stamps) > 0) and stamps[-1] == pytest.approx(FAULT_TIME, abs=1e-9)
    assert not (tmp_path / "exit.png").exists()  # the run failed: no plot
