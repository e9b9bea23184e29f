"""A Model Exchange FMU in a scenario (`[components.NAME] interface / solver / tolerance / max_step`):
the ball bounces as fmpy's CVode run and the analytic ball do, `cosim system` shows the solver,
and bad settings are one-line errors naming the key."""

from __future__ import annotations

import math
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu
from test_compose import write_scenario

from cosim.errors import CosimError
from cosim.logs import open_log
from cosim.navigation.build import build_run
from cosim.navigation.run import run_scenario
from cosim.scenario.compose import describe_system
from cosim.scenario.load import load_scenario

BASE = "warehouse_diff_drive_no_obstacle.toml"
STOP = ["output.plot=false", "simulation.stop_time=2"]


def analytic_bounces(h0: float, count: int, g: float = 9.81, e: float = 0.7) -> list[float]:
    v1 = math.sqrt(2 * g * h0)
    times = [v1 / g]
    for k in range(1, count):
        times.append(times[-1] + 2 * e**k * v1 / g)
    return times


def bounces(t_bounce) -> list[float]:
    return [float(t) for t in dict.fromkeys(np.asarray(t_bounce, dtype=float)) if t > 0]


def scenario(tmp_path: Path, kind: str, keys: str = ""):
    extra = f'[components.ball]\nfmu = "{fixture_fmu(kind)}"\n{keys}\n'
    return write_scenario(tmp_path, "ball", BASE, extra)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("kind", "isolation"), [("bouncing_ball_me_fmi2", "none"), ("bouncing_ball_me_fmi3", "process")]
)
def test_a_bouncing_ball_in_a_scenario_bounces_as_fmpy_and_the_analytic_ball(tmp_path, kind, isolation):
    path = scenario(tmp_path, kind, f'solver = "cvode"\nisolation = "{isolation}"')
    run_scenario(load_scenario(path, STOP), tmp_path / "ball.mcap")
    ours = bounces(open_log(tmp_path / "ball.mcap").signals("ball")["t_bounce"])
    reference = fmpy.simulate_fmu(str(fixture_fmu(kind)), stop_time=2.0, output=["t_bounce"])
    assert len(ours) == 4
    assert np.max(np.abs(np.subtract(ours, bounces(reference["t_bounce"])))) < 1e-6
    assert np.max(np.abs(np.subtract(ours, analytic_bounces(1.0, 4)))) < 1e-6


def test_the_interface_and_solver_are_described(tmp_path):
    described = describe_system(
        load_scenario(scenario(tmp_path, "bouncing_ball_me_fmi2", 'solver = "rk4"\nmax_step = 0.001'))
    )
    ball = described.components["ball"].integration
    assert (ball.interface, ball.solver, ball.max_step) == ("me", "rk4", 0.001)
    # An ME-only FMU runs as Model Exchange without saying so; CVode is the default solver.
    plain = describe_system(load_scenario(scenario(tmp_path, "bouncing_ball_me_fmi3"))).components["ball"]
    assert (plain.integration.interface, plain.integration.solver) == ("me", "cvode")
    assert described.components["vehicle"].integration.interface == "cs"


def test_cosim_system_shows_the_solver(tmp_path, capsys):
    from cosim.cli import main

    path = scenario(tmp_path, "bouncing_ball_me_fmi2", 'solver = "euler"')
    assert main(["system", str(path)]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if line.strip().startswith("ball "))
    assert "2.0 ME euler" in line


def test_an_fmu_with_both_interfaces_runs_co_simulation_unless_interface_me(tmp_path):
    """The fixture's binary instantiates for Model Exchange only: the default fails to instantiate."""
    default = load_scenario(scenario(tmp_path, "bouncing_ball_both_fmi2", 'isolation = "none"'), STOP)
    assert describe_system(default).components["ball"].integration.interface == "cs"
    with pytest.raises(CosimError, match="failed to instantiate"):
        build_run(default).system.component("ball").instantiate()
    chosen = load_scenario(
        scenario(tmp_path, "bouncing_ball_both_fmi2", 'interface = "me"\nisolation = "none"'), STOP
    )
    component = build_run(chosen).system.component("ball")
    assert type(component).__name__ == "ModelExchangeComponent"


@pytest.mark.parametrize(
    ("kind", "keys", "message"),
    [
        (
            "bouncing_ball_me_fmi2",
            'solver = "dopri"',
            r"\[components.ball\].solver: must be one of 'cvode', 'rk4', 'euler'",
        ),
        ("bouncing_ball_me_fmi2", "tolerance = 0", r"\[components.ball\].tolerance: must be > 0"),
        ("bouncing_ball_me_fmi2", "max_step = -1.0", r"\[components.ball\].max_step: must be > 0"),
        (
            "bouncing_ball_me_fmi2",
            'interface = "fmi"',
            r"\[components.ball\].interface: must be one of 'cs', 'me'",
        ),
        (
            "diffdrive_fmi2",
            'interface = "me"\nv = 0\nomega = 0',
            r'\[components.ball\].interface: interface = "me": the FMU has no Model Exchange',
        ),
        (
            "diffdrive_fmi2",
            'solver = "rk4"\nv = 0\nomega = 0',
            r"\[components.ball\].solver: solver integrates a Model Exchange FMU",
        ),
    ],
)
def test_bad_integration_settings_are_one_line_errors(tmp_path, kind, keys, message):
    with pytest.raises(CosimError, match=message) as error:
        describe_system(load_scenario(scenario(tmp_path, kind, keys)))
    assert "\n" not in str(error.value)
