"""Limits of an FMU in a child process: its memory (`max_memory`, [simulation] fmu_max_memory: the
child's RLIMIT_DATA), the unpacking of its archive (a call of its own, not charged to fmu_timeout),
and the folder it unpacks into (removed by the host however the child ended).

Truths: the kernel's accounting of the child (VmHWM in /proc, the wait status), the leaking
fixture's own arithmetic (leak_mib MiB per step, written and never freed), and the file system
(what is left in the TMPDIR the run was given).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.errors import CosimError
from cosim.fmi import isolated
from cosim.fmi.component import FmuComponent
from cosim.fmi.isolated import IsolatedFmuComponent
from cosim.logs import open_log
from cosim.navigation.build import build_run
from cosim.scenario.load import Scenario, load_scenario

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
MIB = 1 << 20
PATHS = [str(REPO), str(REPO / "tests")]
LIMIT = 300 * MIB  # [bytes] well above an idle child (~40 MiB resident, ~100 MiB of data)
LEAK = 16.0  # [MiB] per step
STEP = 0.1  # [s]


def peak_resident(pid: int) -> int:
    """VmHWM of a running process [bytes]."""
    with open(f"/proc/{pid}/status") as status:
        line = next(line for line in status if line.startswith("VmHWM:"))
    return int(line.split()[1]) * 1024


def leaking_vehicle(max_memory: int | None, steps: int):
    """The leaking fixture in a child, stepped `steps` times or until it fails; returns
    (component, steps done, error or None)."""
    vehicle = IsolatedFmuComponent(fixture_fmu("leaking_fmi2"), "vehicle", max_memory=max_memory)
    vehicle.instantiate()
    vehicle.setup(0.0, {"leak_mib": LEAK})
    vehicle.initialize()
    for k in range(steps):
        try:
            vehicle.do_step(round(k * STEP, 9), STEP)
        except CosimError as error:
            return vehicle, k, error
    return vehicle, steps, None


SMALL_HOST = """
import json, sys
sys.path[:0] = {paths!r}
sys.path.insert(0, {tests!r})
from test_isolation_limits import leaking_vehicle
vehicle, done, error = leaking_vehicle({limit}, 100)
print(json.dumps({{"pid": vehicle.pid, "done": done, "state": vehicle.state.name, "error": str(error)}}))
vehicle.free()
"""


@pytest.mark.slow
def test_fmu_max_memory_stops_a_leaking_fmu():
    """In a host of its own: Linux keeps ru_maxrss across execve, so a child's peak is measurable
    only above its host's size (this test process may be larger than the limit)."""
    code = SMALL_HOST.format(paths=PATHS, tests=str(Path(__file__).parent), limit=LIMIT)
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    result = json.loads(completed.stdout)
    done, message = result["done"], result["error"]  # 100 steps would leak 1.6 GiB
    assert result["state"] == "FAILED"
    assert message.startswith(
        f"FMU 'vehicle' (model fixture_leaking_fmi2, process {result['pid']}) exceeded fmu_max_memory "
        f"(300 MiB) in fmi2DoStep at t = {round(done * STEP, 9):g} s: its peak resident memory "
    ), message
    # The fixture does not check malloc: the failed allocation is a write to address 0.
    assert message.endswith(f"crashed with signal {int(signal.SIGSEGV)} (SIGSEGV, Segmentation fault)")
    peak = float(re.search(r"its peak resident memory ([\d.]+) MiB", message).group(1)) * MIB
    # What it leaked before the step that failed is resident; the limit held it below LIMIT.
    assert done * LEAK * MIB < peak <= LIMIT
    assert done < LIMIT / (LEAK * MIB)


def test_without_the_limit_the_same_fmu_grows_past_it():
    """The control: no max_memory, and the same leak passes 300 MiB resident without failing."""
    steps = round(1.25 * LIMIT / (LEAK * MIB))
    vehicle, done, error = leaking_vehicle(None, steps)
    try:
        assert error is None and done == steps
        assert peak_resident(vehicle.pid) > LIMIT
    finally:
        vehicle.terminate()
        vehicle.free()


def test_an_fmu_that_fails_far_below_the_limit_is_a_plain_crash():
    """A segfault at 40 MiB under a 300 MiB limit is not blamed on the limit, even from a host
    larger than the limit (whose size the child's ru_maxrss starts from: Linux keeps it across
    execve)."""
    from fixtures.build_fixtures import FAULTS

    ballast = bytearray(b"\x01") * LIMIT  # resident in this process while the child starts
    vehicle = IsolatedFmuComponent(fixture_fmu("fault_fmi2"), "vehicle", max_memory=LIMIT)
    vehicle.instantiate()
    vehicle.setup(0.0, {"fault": FAULTS.index("segfault"), "fault_time": 0.0})
    vehicle.initialize()
    with pytest.raises(CosimError) as error:
        vehicle.do_step(0.0, STEP)
    vehicle.free()
    assert len(ballast) == LIMIT
    assert "fmu_max_memory" not in str(error.value) and "crashed with signal 11" in str(error.value)


def test_a_limit_below_what_the_child_needs_to_load_the_fmu_is_named():
    """16 MiB: less data than the child's Python already has mapped (about 95 MiB, or 54 MiB when
    OPENBLAS_NUM_THREADS=1 leaves numpy one thread: Dask's nanny sets it in the process that starts
    its workers, a sweep test before this one in the same process), so loading the description's
    parser fails; the failure says which limit it was."""
    vehicle = IsolatedFmuComponent(fixture_fmu("diffdrive_fmi2"), "vehicle", max_memory=16 * MIB)
    with pytest.raises(CosimError) as error:
        vehicle.instantiate()
    vehicle.free()
    assert re.match(
        r"FMU 'vehicle' \(model fixture_diffdrive_fmi2, process \d+\) exceeded fmu_max_memory \(16 MiB\) in ",
        str(error.value),
    ), str(error.value)


def test_a_bad_memory_limit_is_refused():
    with pytest.raises(CosimError, match=r"component 'vehicle': FMU memory limit must be > 0 bytes, got 0"):
        IsolatedFmuComponent(fixture_fmu("diffdrive_fmi2"), "vehicle", max_memory=0)


# ---- unpacking, timed apart -----------------------------------------------------------------


@pytest.mark.slow
def test_unpacking_is_not_charged_to_the_fmi_call_timeout():
    """The padded fixture unpacks 256 MiB: give each FMI call a quarter of what unpacking it took
    here in-process. Charged to fmi2Instantiate (as before), that limit would fail it."""
    path = fixture_fmu("padded_fmi2")
    local = FmuComponent(path, "vehicle")
    started = time.perf_counter()
    local.unpack()
    unpacking = time.perf_counter() - started
    local.free()
    vehicle = IsolatedFmuComponent(path, "vehicle", timeout=unpacking / 4)
    try:
        vehicle.instantiate()
        vehicle.setup(0.0, {})
        vehicle.set_inputs([0], [1.0])
        vehicle.initialize()
        vehicle.do_step(0.0, 0.5)
        assert vehicle.get_outputs()[0] == 0.5  # x = v h
        vehicle.terminate()
    finally:
        vehicle.free()


def test_unpacking_has_its_own_limit_and_message(monkeypatch):
    monkeypatch.setattr(isolated, "UNPACK_TIMEOUT", 1e-6)
    vehicle = IsolatedFmuComponent(fixture_fmu("padded_fmi2"), "vehicle")
    with pytest.raises(CosimError) as error:
        vehicle.instantiate()
    assert re.fullmatch(
        r"FMU 'vehicle' \(model fixture_padded_fmi2, process \d+\) did not return from unpacking the FMU "
        r"archive within 1e-06 s \(its own limit, not fmu_timeout\); its process was killed",
        str(error.value),
    ), str(error.value)
    vehicle.free()


# ---- the folder a child unpacks into ----------------------------------------------------------


def test_a_killed_childs_folder_is_removed(tmp_path, monkeypatch):
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)  # read TMPDIR again
    vehicle = IsolatedFmuComponent(fixture_fmu("diffdrive_fmi2"), "vehicle")
    vehicle.instantiate()
    vehicle.setup(0.0, {})
    vehicle.initialize()
    vehicle.do_step(0.0, STEP)
    [folder] = tmp_path.iterdir()
    assert folder.name.startswith("navcosim-vehicle-process-")
    assert any(path.suffix == ".so" for path in folder.rglob("*"))  # the unpacked binary
    os.kill(vehicle.pid, signal.SIGKILL)
    with pytest.raises(CosimError, match=r"crashed with signal 9 \(SIGKILL"):
        vehicle.do_step(STEP, STEP)
    assert list(tmp_path.iterdir()) == []  # removed at the failure, before free()
    vehicle.free()


@pytest.mark.slow
def test_cosim_run_leaves_nothing_behind_when_its_child_is_killed(tmp_path):
    """The whole command: its child killed with SIGKILL mid-run; exit 2, one line, and the run's
    TMPDIR holds nothing afterwards (no unpacked FMU)."""
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    path = scenario(tmp_path, fixture_fmu("diffdrive_fmi2"), "", stop_time=100.0)
    log_path = tmp_path / "killed.mcap"
    host = subprocess.Popen(
        [sys.executable, "-m", "cosim", "run", str(path), "--out", str(log_path), "--quiet", "--no-plot"],
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "TMPDIR": str(scratch)},
    )
    child = None
    for _ in range(6000):  # until the run is stepping: its log exists and the child is up
        children = Path(f"/proc/{host.pid}/task/{host.pid}/children").read_text().split()
        child = next((int(pid) for pid in children if _is_isolated_child(int(pid))), None)
        if child is not None and log_path.exists() and host.poll() is None:
            break
        time.sleep(0.01)
    assert child is not None and host.poll() is None
    assert any(scratch.iterdir())  # the child's folder, while it runs
    os.kill(child, signal.SIGKILL)
    _, stderr = host.communicate()
    assert host.returncode == 2, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and "crashed with signal 9 (SIGKILL" in lines[0], stderr
    assert list(scratch.iterdir()) == []
    assert open_log(log_path).outcome["reason"] == "fmu_failed"


def _is_isolated_child(pid: int) -> bool:
    try:
        return b"cosim.fmi.isolated_child" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except FileNotFoundError:
        return False


# ---- the scenario key -----------------------------------------------------------------------


def scenario(tmp_path: Path, fmu: Path, vehicle_extra: str, simulation: str = "", stop_time: float = 4.0):
    """The shipped one-obstacle scenario with a fixture FMU (the project's port names) as vehicle."""
    text = SHIPPED.read_text()
    map_file = (SHIPPED.parent / "maps" / "warehouse.yaml").resolve()
    text = re.sub(r'(?m)^file = "maps/warehouse.yaml"', f'file = "{map_file}"', text)
    start = text.index("[vehicle]")
    end = text.index("\n[", start + 1)
    section = f'[vehicle]\nfmu = "{fmu}"\ntype = "differential"\nradius = 0.5\n{vehicle_extra}\n'
    text = text[:start] + section + text[end:]
    text = re.sub(r"(?m)^stop_time = .*$", f"stop_time = {stop_time}", text)
    text = text.replace("[simulation]", f"[simulation]\n{simulation}", 1)
    path = tmp_path / "s.toml"
    path.write_text(text)
    return path


def test_fmu_max_memory_defaults_to_2_gib_and_reaches_the_child(tmp_path):
    assert Scenario.fmu_max_memory == 2048.0
    loaded = load_scenario(scenario(tmp_path, fixture_fmu("diffdrive_fmi2"), ""))
    assert loaded.fmu_max_memory == 2048.0
    assert build_run(loaded).system.component("vehicle").max_memory == 2 << 30
    chosen = load_scenario(
        scenario(tmp_path, fixture_fmu("diffdrive_fmi2"), ""), ["simulation.fmu_max_memory=300"]
    )
    assert build_run(chosen).system.component("vehicle").max_memory == LIMIT
    with pytest.raises(CosimError, match=r"\[simulation\]\.fmu_max_memory: must be > 0, got 0"):
        load_scenario(scenario(tmp_path, fixture_fmu("diffdrive_fmi2"), ""), ["simulation.fmu_max_memory=0"])


@pytest.mark.slow
def test_a_leaking_vehicle_ends_the_run_with_one_line(tmp_path):
    path = scenario(tmp_path, fixture_fmu("leaking_fmi2"), "leak_mib = 8.0", "fmu_max_memory = 300")
    log_path = tmp_path / "leak.mcap"
    completed = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(path), "--out", str(log_path), "--quiet", "--no-plot"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    lines = completed.stderr.splitlines()
    assert completed.returncode == 2 and len(lines) == 1, completed.stderr
    assert re.match(
        r"cosim: error: FMU 'vehicle' \(model fixture_leaking_fmi2, process \d+\) exceeded fmu_max_memory "
        r"\(300 MiB\) in fmi2DoStep at t = [\d.]+ s: its peak resident memory [\d.]+ MiB; "
        r"crashed with signal 11",
        lines[0],
    ), lines[0]
    log = open_log(log_path)
    assert log.outcome["reason"] == "fmu_failed"
    # 8 MiB leaked per 10 ms step: it failed before 300 MiB were leaked, after 150 (the child's own
    # data is about 100 MiB).
    assert 150 / 8 * 0.01 < float(log.outcome["time"]) < 300 / 8 * 0.01
