"""`cosim.ssp.simulate` (`cosim fmu simulate`): one FMU alone, checked against fmpy's own
`simulate_fmu` of the same FMU with the same start values (an independent engine), the CSV against
the log and against fmpy's CSV writer, and the errors a user can cause."""

from __future__ import annotations

import fmpy
import fmpy.util
import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.core.master import Master
from cosim.errors import CosimError
from cosim.fmi.builtin import builtin_fmu
from cosim.logs.reader import open_log
from cosim.ssp.simulate import parse_start_values, prepare, simulate

DIFFDRIVE_START = {"x0": 1.0, "y0": -2.0, "theta0": 0.3, "v": 0.8, "omega": -0.4}


def _fmpy(path, stop, step, start_values):
    """fmpy's result with a communication point at every step (its default samples 1000 at most)."""
    return fmpy.simulate_fmu(str(path), stop_time=stop, output_interval=step, start_values=start_values)


def _read_csv(path):
    return np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8")


@pytest.mark.parametrize("kind", ["diffdrive_fmi2", "diffdrive_fmi3"])
def test_outputs_match_fmpy_simulate_fmu(kind, tmp_path):
    path = fixture_fmu(kind)
    simulation = prepare(path, stop_time=3.0, step=0.01, start_values=DIFFDRIVE_START)
    result = simulate(simulation, tmp_path / "run.mcap", tmp_path / "run.csv")
    assert (result.reason, result.exit_code, result.steps, result.end_time) == ("stop_time", 0, 300, 3.0)
    reference = _fmpy(path, 3.0, 0.01, DIFFDRIVE_START)
    ours = _read_csv(tmp_path / "run.csv")
    assert len(ours) == len(reference) == 301
    np.testing.assert_allclose(ours["time"], reference["time"], rtol=0, atol=1e-12)
    for name in ("x", "y", "theta"):
        np.testing.assert_allclose(ours[name], reference[name], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ours["steps"], reference["steps"])
    np.testing.assert_array_equal(ours["moving"], reference["moving"])
    assert ours["x"][0] == 1.0 and ours["y"][0] == -2.0  # the parameters reached the FMU


def test_csv_is_fmpy_form_and_holds_the_logs_values(tmp_path):
    path = fixture_fmu("diffdrive_fmi2")
    simulate(
        prepare(path, stop_time=0.5, step=0.05, start_values=DIFFDRIVE_START),
        tmp_path / "a.mcap",
        tmp_path / "a.csv",
    )
    fmpy.util.write_csv(tmp_path / "fmpy.csv", _fmpy(path, 0.5, 0.05, DIFFDRIVE_START))
    ours_lines = (tmp_path / "a.csv").read_text().splitlines()
    fmpy_lines = (tmp_path / "fmpy.csv").read_text().splitlines()
    assert ours_lines[0] == fmpy_lines[0] == '"time","x","y","theta","steps","moving"'
    # Integers and Booleans are written as fmpy writes them.
    assert [line.split(",")[4:] for line in ours_lines[1:]] == [
        line.split(",")[4:] for line in fmpy_lines[1:]
    ]
    ours = _read_csv(tmp_path / "a.csv")
    with open_log(tmp_path / "a.mcap") as log:
        (component,) = log.components
        signals = log.signals(component)
        np.testing.assert_array_equal(signals.t, ours["time"])  # the same times, to the bit
        for name in ("x", "y", "theta", "steps"):
            np.testing.assert_array_equal(signals[name], ours[name])
        np.testing.assert_array_equal(signals["moving"], ours["moving"].astype(float))
        np.testing.assert_array_equal(signals["v"], 0.8)  # an input holds its start value
        assert log.scenario_name == "fixture_diffdrive_fmi2"
        assert log.outcome["reason"] == "stop_time"
        assert "modelDescription.xml" in log.attachments


def test_unconnected_input_keeps_its_start_value(tmp_path):
    """failing_fmi2 integrates its input u, whose start value is 1: y(t) = t, as fmpy has it."""
    path = fixture_fmu("failing_fmi2")
    simulate(
        prepare(path, stop_time=2.0, step=0.1, start_values={"fail_time": 10.0}),
        tmp_path / "u.mcap",
        tmp_path / "u.csv",
    )
    ours = _read_csv(tmp_path / "u.csv")
    reference = _fmpy(path, 2.0, 0.1, {"fail_time": 10.0})
    np.testing.assert_allclose(ours["y"], reference["y"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours["y"], ours["time"], rtol=0, atol=1e-12)


def test_defaults_follow_default_experiment_then_fmpy(tmp_path):
    # The project FMU declares <DefaultExperiment startTime="0" stopTime="10" stepSize="0.01"/>.
    described = fmpy.read_model_description(str(builtin_fmu("DifferentialDrive", 2))).defaultExperiment
    project = prepare(builtin_fmu("DifferentialDrive", 2))
    assert (project.start_time, project.stop_time, project.step) == (
        float(described.startTime),
        float(described.stopTime),
        float(described.stepSize),
    )
    assert project.steps == 1000
    # The fixture declares none: 1 s, and fmpy's step rule 10 ** (round(log10(1)) - 3).
    fixture = prepare(fixture_fmu("diffdrive_fmi2"))
    assert (fixture.start_time, fixture.stop_time, fixture.step, fixture.steps) == (0.0, 1.0, 0.001, 1000)
    assert prepare(fixture_fmu("diffdrive_fmi2"), stop_time=50.0).step == 0.1


def test_long_run_steps_through_the_compiled_kernel(tmp_path, monkeypatch):
    kernel_calls = []
    run_blocks = Master.run_blocks

    def counting(self, *args, **kwargs):
        kernel_calls.append(args[0])
        return run_blocks(self, *args, **kwargs)

    monkeypatch.setattr(Master, "run_blocks", counting)
    simulation = prepare(
        fixture_fmu("diffdrive_fmi2"), stop_time=20.0, step=0.001, start_values=DIFFDRIVE_START
    )
    result = simulate(simulation, tmp_path / "k.mcap")
    assert result.steps == 20_000 and sum(kernel_calls) == 20_000


def test_failing_fmu_ends_the_run_with_its_failure_and_a_finalised_log(tmp_path):
    path = fixture_fmu("failing_fmi2")
    result = simulate(
        prepare(path, stop_time=2.0, step=0.1, start_values={"fail_time": 0.5}), tmp_path / "f.mcap"
    )
    assert result.exit_code == 2 and result.reason == "fmu_failed"
    assert "\n" not in result.failure and "fmi2DoStep" in result.failure
    with open_log(tmp_path / "f.mcap") as log:
        assert log.is_complete and log.outcome["reason"] == "fmu_failed"
        assert log.end_time == pytest.approx(0.5)


@pytest.mark.parametrize(
    ("kind", "options", "message"),
    [
        (
            "diffdrive_fmi2",
            {"start_values": {"omegaa": 1.0}},
            "has no parameter or input 'omegaa'; closest: omega",
        ),
        ("diffdrive_fmi2", {"start_values": {"x": 1.0}}, "has no parameter or input 'x'"),  # an output
        ("diffdrive_fmi2", {"start_values": {"v": True}}, "'v' is a Real: give a number, not true"),
        (
            "failing_fmi2",
            {"start_values": {"fail_status": 1.5}},
            "'fail_status' is an Integer: give a whole number",
        ),
        ("diffdrive_fmi2", {"stop_time": -1.0}, "--stop-time -1 s is not after the start time 0 s"),
        ("diffdrive_fmi2", {"step": 0.0}, "--step must be > 0 s"),
        ("diffdrive_fmi2", {"interface": "me"}, "the FMU has no <ModelExchange> interface; --interface me"),
        ("diffdrive_fmi2", {"solver": "cvode"}, "--solver cvode: a solver integrates a Model Exchange FMU"),
        ("model_exchange_only", {"interface": "cs"}, "the FMU has no <CoSimulation> interface"),
        ("corrupt", {}, "not an FMU"),
    ],
)
def test_bad_input_is_one_line(kind, options, message):
    with pytest.raises(CosimError) as error:
        prepare(fixture_fmu(kind), **options)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_start_value_outside_the_declared_range():
    with pytest.raises(CosimError, match=r"'wheel_radius' must be >= 1e-09$"):
        prepare(builtin_fmu("DifferentialDrive", 2), start_values={"wheel_radius": -1.0})


@pytest.mark.parametrize("text", ["x0", "=1", " = 2"])
def test_start_value_without_name_or_equals(text):
    with pytest.raises(CosimError, match=r"^--start-values .*: expected NAME=VALUE"):
        parse_start_values([text])


@pytest.mark.parametrize("text", ["x0=abc", "x0=nan", "x0=[1, 2]", "x0="])
def test_a_numeric_variable_takes_only_a_number(text):
    with pytest.raises(
        CosimError, match=r"^--start-values x0=.*: the value must be a finite number or true/false$"
    ):
        prepare(fixture_fmu("diffdrive_fmi2"), start_values=parse_start_values([text]))


def test_start_value_texts_are_read_as_the_variable_takes_them():
    assert parse_start_values(["x0=1.5", "s = a b", "e="]) == {"x0": "1.5", "s": "a b", "e": ""}
    texts = parse_start_values(["x0=1.5", "theta0=-2e-3", "v=3"])
    simulation = prepare(fixture_fmu("diffdrive_fmi2"), start_values=texts)
    assert simulation.component.parameters == {"x0": 1.5, "theta0": -0.002}
    assert simulation.component.held_inputs == {"v": 3}


def test_string_start_values_reach_the_fmu(tmp_path, monkeypatch):
    """The every-type fixture's String_output is String_input followed by String_parameter."""
    import cosim.navigation.build

    made = []
    make_fmu = cosim.navigation.build.make_fmu
    monkeypatch.setattr(
        cosim.navigation.build, "make_fmu", lambda *a, **k: made.append(make_fmu(*a, **k)) or made[-1]
    )
    texts = parse_start_values(['String_input="ab "', "String_parameter=cd"])
    simulation = prepare(fixture_fmu("types_fmi2"), stop_time=0.2, step=0.1, start_values=texts)
    assert simulation.held_text == {"String_input": "ab "}
    assert simulate(simulation, tmp_path / "s.mcap").reason == "stop_time"
    assert made[0].text_values["String_output"] == "ab cd"


def test_an_integer_start_value_stays_exact(tmp_path):
    """2^53 + 1 is no float: it reaches the FMU's setter as given, whose Integer range refuses it."""
    texts = parse_start_values(["Integer_parameter=9007199254740993"])
    simulation = prepare(fixture_fmu("types_fmi2"), stop_time=0.2, step=0.1, start_values=texts)
    assert simulation.component.parameters["Integer_parameter"] == 2**53 + 1
    with pytest.raises(CosimError, match="Integer_parameter.*9007199254740993"):
        simulate(simulation, tmp_path / "i.mcap")


def test_csv_and_log_end_together_where_the_fmu_ends_the_run(tmp_path):
    """The every-type fixture asks to end in its step from 0.5 s (end_time = 0.55): both stop at 0.5 s,
    where fmpy's simulate_fmu stops too."""
    path = fixture_fmu("types_fmi2")
    start = {"end_time": 0.55}
    result = simulate(
        prepare(path, stop_time=2.0, step=0.1, start_values=start), tmp_path / "e.mcap", tmp_path / "e.csv"
    )
    assert (result.reason, result.exit_code) == ("fmu_terminated", 0)
    ours = _read_csv(tmp_path / "e.csv")
    reference = _fmpy(path, 2.0, 0.1, start)
    # fmpy repeats its last communication point (a row at termination); the points are the same.
    np.testing.assert_allclose(ours["time"], np.unique(reference["time"]), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ours["Real_output"], reference["Real_output"][: len(ours)])
    with open_log(tmp_path / "e.mcap") as log:
        signals = log.signals(log.components[0])
        np.testing.assert_array_equal(signals.t, ours["time"])
        for name in ours.dtype.names[1:]:
            np.testing.assert_array_equal(signals[name], ours[name].astype(float))


def _van_der_pol_end(tmp_path, **options):
    simulation = prepare(fixture_fmu("van_der_pol_me_fmi2"), stop_time=2.0, step=0.5, **options)
    log = tmp_path / f"vdp-{len(list(tmp_path.glob('*.mcap')))}.mcap"
    simulate(simulation, log)
    with open_log(log) as opened:
        signals = opened.signals(opened.components[0])
        return np.array([signals["x0"][-1], signals["x1"][-1]])


def test_solver_tolerance_and_max_step_reach_the_model_exchange_solver(tmp_path):
    """Van der Pol (mu = 1, x = (2, 0), u = 0) to t = 2 s in steps of 0.5 s against scipy's
    solve_ivp at rtol 1e-12: CVode at rtol 1e-10 and RK4 in 1 ms steps agree; RK4 in one 0.5 s step
    per communication step and CVode at rtol 1e-2 do not."""
    from scipy.integrate import solve_ivp

    def van_der_pol(t, x):
        return [x[1], (1 - x[0] ** 2) * x[1] - x[0]]

    exact = solve_ivp(van_der_pol, (0.0, 2.0), [2.0, 0.0], rtol=1e-12, atol=1e-12).y[:, -1]
    tight = _van_der_pol_end(tmp_path, interface="me", solver="cvode", tolerance=1e-10)
    fine = _van_der_pol_end(tmp_path, interface="me", solver="rk4", max_step=1e-3)
    coarse = _van_der_pol_end(tmp_path, interface="me", solver="rk4")
    loose = _van_der_pol_end(tmp_path, interface="me", solver="cvode", tolerance=1e-2)
    assert np.max(np.abs(fine - exact)) < 1e-9 and np.max(np.abs(tight - exact)) < 1e-7
    assert np.max(np.abs(coarse - exact)) > 1e-4 and np.max(np.abs(loose - exact)) > 1e-5
    simulation = prepare(fixture_fmu("van_der_pol_me_fmi2"), solver="euler", max_step=0.01, tolerance=1e-6)
    assert (simulation.interface, simulation.solver) == ("me", "euler")  # ME-only: no --interface needed
    assert simulation.component.integration.max_step == 0.01


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            {"tolerance": 1e-6},
            "--tolerance 1e-06: a solver integrates a Model Exchange FMU; give --interface me",
        ),
        ({"max_step": 0.01}, "--max-step 0.01: a solver integrates a Model Exchange FMU"),
    ],
)
def test_solver_options_on_a_co_simulation_fmu_are_one_line(options, message):
    with pytest.raises(CosimError) as error:
        prepare(fixture_fmu("diffdrive_fmi2"), **options)
    assert message in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize("options", [{"tolerance": 0.0}, {"max_step": -1.0}, {"tolerance": float("nan")}])
def test_non_positive_solver_options_are_refused(options):
    with pytest.raises(CosimError, match=r"must be > 0"):
        prepare(fixture_fmu("van_der_pol_me_fmi2"), interface="me", **options)


def test_outputs_destroy_nothing(tmp_path):
    """An existing CSV is refused without force, a folder always, before anything is written; a
    run that fails keeps its CSV up to the failure, as its log."""
    simulation = prepare(
        fixture_fmu("failing_fmi2"), stop_time=2.0, step=0.1, start_values={"fail_time": 0.5}
    )
    taken = tmp_path / "taken.csv"
    taken.write_text("mine\n")
    with pytest.raises(CosimError, match="taken.csv: already exists; give --force"):
        simulate(simulation, tmp_path / "a.mcap", taken)
    with pytest.raises(CosimError, match="is a folder"):
        simulate(simulation, tmp_path / "a.mcap", tmp_path)
    assert taken.read_text() == "mine\n" and not (tmp_path / "a.mcap").exists()
    result = simulate(simulation, tmp_path / "a.mcap", taken, force=True)
    assert result.reason == "fmu_failed" and result.csv_path == taken
    rows = _read_csv(taken)
    with open_log(tmp_path / "a.mcap") as log:
        np.testing.assert_array_equal(log.signals(log.components[0]).t, rows["time"])
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary left
