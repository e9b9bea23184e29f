"""Model Exchange FMUs inside the co-simulation (`cosim.fmi.model_exchange`), checked against fmpy's
own CVode run of the same FMU, the analytic bouncing ball and scipy's `solve_ivp`."""

from __future__ import annotations

import math

import fmpy
import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu
from scipy.integrate import solve_ivp

from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.model_exchange import ModelExchangeComponent

G, E = 9.81, 0.7


def analytic_bounces(h0: float, count: int) -> list[float]:
    """Bounce times of a ball dropped from rest at h0: t1 = sqrt(2 h0 / g), then 2 e^k v1 / g apart."""
    v1 = math.sqrt(2 * G * h0)
    times = [v1 / G]
    for k in range(1, count):
        times.append(times[-1] + 2 * E**k * v1 / G)
    return times


def run(component, macro_step: float, stop: float, on_step=None) -> dict[str, list[float]]:
    """Step `component` alone to `stop` [s]; each output's value at every communication point."""
    system = System(macro_step)
    system.add(component)
    master = Master(system)
    master.initialize()
    names = [port.name for port in component.outputs]
    series = {name: [value] for name, value in zip(names, component.output_buffer.tolist(), strict=True)}
    try:
        for k in range(round(stop / macro_step)):
            if on_step is not None:
                on_step(k * macro_step, component)
            master.step()
            for name, value in zip(names, component.output_buffer.tolist(), strict=True):
                series[name].append(value)
    finally:
        master.close()
    return series


def bounce_times(t_bounce) -> list[float]:
    return [float(t) for t in dict.fromkeys(np.asarray(t_bounce, dtype=float)) if t > 0]


@pytest.mark.parametrize("version", [1, 2, 3])
def test_bouncing_ball_bounces_when_fmpy_and_the_analytic_ball_do(version):
    path = fixture_fmu(f"bouncing_ball_me_fmi{version}")
    ball = ModelExchangeComponent(path, "ball", solver="cvode", tolerance=1e-10)
    ours = bounce_times(run(ball, 0.01, 2.0)["t_bounce"])
    reference = fmpy.simulate_fmu(str(path), stop_time=2.0, relative_tolerance=1e-10, output=["t_bounce"])
    theirs = bounce_times(reference["t_bounce"])
    assert len(ours) == len(theirs) == 4
    assert np.max(np.abs(np.subtract(ours, theirs))) < 1e-6
    assert np.max(np.abs(np.subtract(ours, analytic_bounces(1.0, 4)))) < 1e-6
    assert ball.events == 4


@pytest.mark.parametrize("solver", ["rk4", "euler"])
def test_fixed_step_solvers_locate_the_bounces(solver):
    ball = ModelExchangeComponent(fixture_fmu("bouncing_ball_me_fmi2"), "ball", solver=solver, max_step=1e-4)
    ours = bounce_times(run(ball, 0.01, 2.0)["t_bounce"])
    # Euler's height error is O(step): its bounces drift by ~g t step / v per bounce.
    allowed = 1e-6 if solver == "rk4" else 5e-3
    assert np.max(np.abs(np.subtract(ours, analytic_bounces(1.0, 4)))) < allowed


def test_time_event_kicks_the_ball_at_its_time():
    """nextEventTime: at kick_time the FMU adds kick_dv to v, between communication points."""
    kick_time, kick_dv, h0 = 0.555, 3.0, 100.0
    parameters = {"h0": h0, "kick_time": kick_time, "kick_dv": kick_dv}
    for version, solver in ((3, "cvode"), (3, "rk4"), (3, "euler"), (1, "cvode"), (2, "rk4")):
        ball = ModelExchangeComponent(
            fixture_fmu(f"bouncing_ball_me_fmi{version}"), "ball", parameters, solver=solver, tolerance=1e-10
        )
        series = run(ball, 0.1, 1.0)
        v_end = -G * 1.0 + kick_dv
        h_end = h0 - G / 2 + kick_dv * (1.0 - kick_time)
        # Euler on a linear v and quadratic h: v exact, h off by g t h / 2 with one step per 0.1 s.
        allowed = 1e-6 if solver != "euler" else 0.6
        assert series["v"][-1] == pytest.approx(v_end, abs=1e-9)
        assert series["h"][-1] == pytest.approx(h_end, abs=allowed)


def _van_der_pol(mu: float, u: float):
    def f(t, x):
        return [x[1], mu * (1 - x[0] ** 2) * x[1] - x[0] + u]

    return f


@pytest.mark.parametrize("version", [2, 3])
def test_van_der_pol_matches_solve_ivp(version):
    mu = 1.5
    component = ModelExchangeComponent(
        fixture_fmu(f"van_der_pol_me_fmi{version}"), "vdp", {"mu": mu}, solver="cvode", tolerance=1e-10
    )
    series = run(component, 0.1, 10.0)
    times = np.arange(101) * 0.1
    exact = solve_ivp(_van_der_pol(mu, 0.0), (0, 10), [2.0, 0.0], t_eval=times, rtol=1e-8, atol=1e-10)
    ours = np.array([series["x0"], series["x1"]])
    assert np.max(np.abs(ours - exact.y)) < 1e-6 * np.max(np.abs(exact.y))


def test_an_input_change_restarts_the_integration():
    """u held at 0, then 1 from t = 5 s: the solution is solve_ivp's piecewise one."""

    def step_input(t, component):
        component.input_buffer[component.input_index["u"]] = 1.0 if t >= 5.0 - 1e-9 else 0.0
        component.push_inputs()  # (as the master does for a connected input)

    component = ModelExchangeComponent(fixture_fmu("van_der_pol_me_fmi2"), "vdp", tolerance=1e-10)
    series = run(component, 0.1, 10.0, on_step=step_input)
    first = solve_ivp(_van_der_pol(1.0, 0.0), (0, 5), [2.0, 0.0], rtol=1e-10, atol=1e-12)
    second = solve_ivp(_van_der_pol(1.0, 1.0), (5, 10), first.y[:, -1], rtol=1e-10, atol=1e-12)
    assert series["x0"][-1] == pytest.approx(second.y[0, -1], abs=1e-6)
    assert series["x1"][-1] == pytest.approx(second.y[1, -1], abs=1e-6)


@pytest.mark.parametrize(("solver", "order"), [("euler", 1), ("rk4", 4)])
def test_fixed_step_solvers_converge_at_their_order(solver, order):
    exact = solve_ivp(_van_der_pol(1.0, 0.0), (0, 2), [2.0, 0.0], rtol=1e-12, atol=1e-14).y[:, -1]
    errors = []
    for max_step in (0.02, 0.01, 0.005):
        component = ModelExchangeComponent(
            fixture_fmu("van_der_pol_me_fmi2"), "vdp", solver=solver, max_step=max_step
        )
        series = run(component, 0.1, 2.0)
        errors.append(np.max(np.abs([series["x0"][-1] - exact[0], series["x1"][-1] - exact[1]])))
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    for ratio in ratios:
        assert ratio == pytest.approx(2**order, rel=0.15)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"solver": "dopri"}, "unknown solver 'dopri'; solvers: cvode, rk4, euler"),
        ({"tolerance": 0.0}, "tolerance must be a number > 0, got 0"),
        ({"max_step": -1.0}, "max_step must be a number > 0, got -1"),
    ],
)
def test_bad_settings_are_one_line_errors(options, message):
    with pytest.raises(CosimError, match=message) as error:
        ModelExchangeComponent(fixture_fmu("bouncing_ball_me_fmi2"), "ball", **options)
    assert "\n" not in str(error.value)


def test_a_co_simulation_only_fmu_has_no_model_exchange():
    with pytest.raises(CosimError, match='has no model exchange interface; interface = "me" needs one'):
        ModelExchangeComponent(fixture_fmu("diffdrive_fmi2"), "vehicle")


@pytest.mark.slow
@pytest.mark.parametrize("version", [2, 3])
def test_cosim_fmu_simulate_bounces_the_ball_as_fmpy(tmp_path, version, capsys):
    """`cosim fmu simulate --interface me --solver cvode`; both take the FMU's DefaultExperiment
    (stop 2 s, step 0.01 s, tolerance 1e-10)."""
    from cosim.cli import main

    path = fixture_fmu(f"bouncing_ball_me_fmi{version}")
    csv = tmp_path / "ball.csv"
    argv = ["fmu", "simulate", str(path), "--interface", "me", "--solver", "cvode"]
    assert main([*argv, "--out", str(tmp_path / "ball.mcap"), "--csv", str(csv)]) == 0
    table = np.genfromtxt(csv, delimiter=",", names=True)
    ours = bounce_times(table["t_bounce"])
    theirs = bounce_times(fmpy.simulate_fmu(str(path), output=["t_bounce"])["t_bounce"])
    assert len(ours) == len(theirs) == 4
    assert np.max(np.abs(np.subtract(ours, theirs))) < 1e-6
    assert np.max(np.abs(np.subtract(ours, analytic_bounces(1.0, 4)))) < 1e-6


@pytest.mark.parametrize("version", [1, 2, 3])
def test_step_events_update_the_discrete_states_after_each_step(version):
    """A model that asks for an event after every completed integrator step: rk4 with 0.01 s
    substeps over 1 s makes 100 step events, CVode one per communication point (10); each is
    one discrete-state update (plus the initial one), and the fall stays exact (rk4 integrates
    the quadratic h exactly; CVode restarts at first order after each event)."""
    parameters = {"h0": 100.0, "step_events": 1.0}
    for solver, max_step, steps, allowed in (("rk4", 0.01, 100, 1e-9), ("cvode", None, 10, 1e-6)):
        ball = ModelExchangeComponent(
            fixture_fmu(f"bouncing_ball_me_fmi{version}"),
            "ball",
            parameters,
            solver=solver,
            max_step=max_step,
        )
        series = run(ball, 0.1, 1.0)
        assert series["event_updates"][-1] == 1 + steps
        assert ball.events == steps
        assert series["h"][-1] == pytest.approx(100.0 - G / 2, abs=allowed)
