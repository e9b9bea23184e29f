"""An FMU's request to end the simulation (FMI 2.0 Discard with fmi2Terminated, FMI 3.0
terminateSimulation) ends the run cleanly where fmpy's simulate_fmu ends it, instead of failing."""

from __future__ import annotations

import subprocess
import sys

import fmpy
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError, SimulationEnded
from cosim.fmi.component import FmuComponent
from cosim.logs.reader import open_log


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("version", [2, 3])
def test_the_request_ends_the_run_at_the_step_it_was_made_in(version, compiled):
    """end_time = 0.55 s: the step from 0.5 s asks to end; the run stops there, in the kernel and
    in Python alike, with `SimulationEnded` naming the FMU (FMI 2.0: where fmpy stops too)."""
    system = System(0.1)
    system.add(FmuComponent(fixture_fmu(f"types_fmi{version}"), "stair", parameters={"end_time": 0.55}))
    with Master(system) as master:
        master.initialize()
        with pytest.raises(SimulationEnded, match="FMU 'stair' .* asked to end the simulation") as ended:
            master.run(20, compiled=compiled)
        assert ended.value.component == "stair" and ended.value.time == pytest.approx(0.5)
        assert master.step_index == 5 and master.time == pytest.approx(0.5)
    if version == 2:
        result = fmpy.simulate_fmu(
            str(fixture_fmu("types_fmi2")), stop_time=2, output_interval=0.1, start_values={"end_time": 0.55}
        )
        assert result["time"][-1] == pytest.approx(master.time)


def test_a_discard_without_the_terminated_flag_is_still_a_failure():
    system = System(0.1)
    system.add(FmuComponent(fixture_fmu("fault_fmi2"), "faulty", parameters={"fault": 8, "fault_time": 0.2}))
    with Master(system) as master:
        master.initialize()
        with pytest.raises(CosimError, match="returned fmi2Discard from fmi2DoStep") as failed:
            master.run(10, compiled=False)
        assert not isinstance(failed.value, SimulationEnded)


@pytest.mark.slow
@pytest.mark.parametrize("version", [2, 3])
def test_fmu_simulate_ends_with_exit_0_and_says_why(tmp_path, version):
    command = [sys.executable, "-m", "cosim", "fmu", "simulate", str(fixture_fmu(f"types_fmi{version}"))]
    command += ["--stop-time", "2", "--step", "0.1", "--start-values", "end_time=0.55", "--out", "run.mcap"]
    completed = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert completed.returncode == 0, completed.stderr
    assert "fmu_terminated (FMU 'fixture_types_fmi" in completed.stdout
    assert "asked to end the simulation in its step from t = 0.5 s): 5 steps to t = 0.5 s" in completed.stdout
    with open_log(tmp_path / "run.mcap") as log:
        assert log.is_complete and log.outcome["reason"] == "fmu_terminated"
        assert "asked to end the simulation" in log.outcome["ended_by"]
