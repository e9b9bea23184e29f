"""FMU components (FMI 2.0 and 3.0) against closed-form kinematics; port mapping; load errors;
the lifecycle; an FMU failing mid-run."""

import math
import os

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.core.component import State
from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.component import FmuComponent


def arc(x0, y0, theta0, v, omega, t):
    """Closed-form unicycle pose after time t at constant v, omega (a circle of radius v/omega)."""
    theta = theta0 + omega * t
    return (
        x0 + v / omega * (math.sin(theta) - math.sin(theta0)),
        y0 - v / omega * (math.cos(theta) - math.cos(theta0)),
        theta,
    )


def drive(component, parameters, v, omega, steps, h):
    component.instantiate()
    component.setup(0.0, parameters)
    component.set_inputs([component.input_index["v"], component.input_index["omega"]], [v, omega])
    component.initialize()
    for k in range(steps):
        component.do_step(k * h, h)
    outputs = component.get_outputs()
    return {p.name: outputs[i] for i, p in enumerate(component.outputs)}


def test_fmi3_fixture_follows_the_closed_form_circle():
    vehicle = FmuComponent(fixture_fmu("diffdrive_fmi3"), "vehicle")
    assert vehicle.fmi_version == 3
    assert [p.name for p in vehicle.inputs] == ["v", "omega"]
    assert [(p.name, p.type) for p in vehicle.outputs][-2:] == [("steps", "integer"), ("moving", "boolean")]
    assert vehicle.feedthrough["x"] == []  # from <ModelStructure>
    try:
        result = drive(vehicle, {"x0": 1.0, "y0": -2.0, "theta0": 0.4}, 0.8, 0.5, 250, 0.01)
    finally:
        vehicle.free()
    expected = arc(1.0, -2.0, 0.4, 0.8, 0.5, 2.5)
    assert [result["x"], result["y"], result["theta"]] == pytest.approx(expected, abs=1e-9)
    assert result["steps"] == 250.0
    assert result["moving"] == 1.0


def test_fmi2_fixture_with_other_names_mapped_with_a_scale():
    port_map = {
        "v": "speed_cmd",
        "omega": {"name": "yaw_rate_cmd", "scale": -1},
        "x": "pos_x",
        "y": "pos_y",
        "theta": "heading",
        "theta0": "start_heading",
    }
    vehicle = FmuComponent(fixture_fmu("diffdrive_fmi2_renamed"), "vehicle", port_map=port_map)
    assert {"v", "omega", "x", "y", "theta", "step_count", "is_moving"} <= set(vehicle.input_index) | set(
        vehicle.output_index
    )
    try:
        result = drive(vehicle, {"theta0": 0.2}, 1.0, 0.3, 100, 0.02)
    finally:
        vehicle.free()
    # The FMU receives -omega, so it turns clockwise.
    expected = arc(0.0, 0.0, 0.2, 1.0, -0.3, 2.0)
    assert [result["x"], result["y"], result["theta"]] == pytest.approx(expected, abs=1e-9)


def test_wrong_variable_name_lists_the_variables_closest_first():
    with pytest.raises(CosimError) as error:
        FmuComponent(fixture_fmu("diffdrive_fmi2_renamed"), "vehicle", port_map={"v": "speed_cmnd"})
    message = str(error.value)
    assert "no variable 'speed_cmnd'" in message
    assert message.index("speed_cmd") < message.index("pos_x")
    assert "\n" not in message
    with pytest.raises(CosimError, match="must be a name or"):
        FmuComponent(fixture_fmu("diffdrive_fmi2"), "vehicle", port_map={"v": {"name": "v", "gain": 2}})


def test_unknown_parameter_is_named():
    vehicle = FmuComponent(fixture_fmu("diffdrive_fmi2"), "vehicle", {"theta_0": 1.0})
    vehicle.instantiate()
    try:
        with pytest.raises(CosimError, match="no parameter 'theta_0'; parameters: theta0"):
            vehicle.setup(0.0, {})
    finally:
        vehicle.free()


@pytest.mark.parametrize(
    ("kind", "message"),
    [
        ("corrupt", "is not a zip archive"),
        ("no_model_description", "has no modelDescription.xml"),
        ("model_exchange_only", "supports model exchange only"),
        ("no_binary", r"has no binary for this platform \(linux64\); it has: win64"),
    ],
)
def test_bad_fmus_give_one_line_errors(kind, message):
    with pytest.raises(CosimError, match=message) as error:
        FmuComponent(fixture_fmu(kind), "vehicle")
    assert "\n" not in str(error.value)


def test_missing_file_and_failed_load_restore_the_working_directory(tmp_path):
    with pytest.raises(CosimError, match="not found"):
        FmuComponent(tmp_path / "absent.fmu", "vehicle")
    before = os.getcwd()
    component = FmuComponent(fixture_fmu("broken_binary"), "vehicle")
    with pytest.raises(CosimError, match="failed to instantiate") as error:
        component.instantiate()
    assert "\n" not in str(error.value)
    assert os.getcwd() == before
    component.free()


def test_lifecycle_misuse_is_an_error_not_a_crash():
    vehicle = FmuComponent(fixture_fmu("diffdrive_fmi2"), "vehicle")
    with pytest.raises(CosimError, match="do_step"):
        vehicle.do_step(0.0, 0.1)
    vehicle.instantiate()
    vehicle.setup(0.0, {})
    vehicle.initialize()
    vehicle.do_step(0.0, 0.1)
    vehicle.terminate()
    with pytest.raises(CosimError, match="state terminated"):
        vehicle.do_step(0.1, 0.1)
    vehicle.free()
    # fmpy would segfault on a call after freeInstance; the component refuses it.
    with pytest.raises(CosimError, match="state freed"):
        vehicle.get_outputs()
    with pytest.raises(CosimError, match="state freed"):
        vehicle.push_inputs()
    vehicle.free()


def test_two_instances_of_one_fmu_are_independent():
    path = fixture_fmu("diffdrive_fmi3")
    first, second = FmuComponent(path, "first"), FmuComponent(path, "second")
    try:
        a = drive(first, {}, 1.0, 0.0, 10, 0.1)
        b = drive(second, {"y0": 5.0}, 2.0, 0.0, 10, 0.1)
        assert (a["x"], a["y"]) == pytest.approx((1.0, 0.0))
        assert (b["x"], b["y"]) == pytest.approx((2.0, 5.0))
        # The fixture may be instantiated more than once per process (FMI's
        # canBeInstantiatedOnlyOncePerProcess false): its instances share one unpacked folder.
        assert not first.model_description.coSimulation.canBeInstantiatedOnlyOncePerProcess
        assert first._unzip_dir == second._unzip_dir
    finally:
        first.free()
        second.free()


def test_controller_declares_its_direct_dependencies():
    controller = FmuComponent(fixture_fmu("controller_fmi2"), "controller")
    assert controller.feedthrough == {"v": ["x", "y", "theta"], "omega": ["x", "y", "theta"]}
    assert controller.describe()["generation_tool"] == "navcosim test fixtures"


@pytest.mark.parametrize(("status", "name"), [(3, "fmi2Error"), (4, "fmi2Fatal")])
def test_fmu_failing_mid_run_stops_the_master_with_name_and_time(status, name):
    system = System(0.1)
    failing = system.add(
        FmuComponent(fixture_fmu("failing_fmi2"), "faulty", {"fail_time": 0.5, "fail_status": status})
    )
    vehicle = system.add(FmuComponent(fixture_fmu("diffdrive_fmi2"), "vehicle"))
    system.connect("faulty.y", "vehicle.v")
    master = Master(system)
    master.initialize()
    with pytest.raises(CosimError) as error:
        master.run(10)
    message = str(error.value)
    assert (
        f"FMU 'faulty' (model fixture_failing_fmi2) returned {name} from fmi2DoStep at t = 0.5 s" in message
    )
    assert "fixture failure requested" in message  # the FMU's own log message
    assert master.time == 0.5
    assert failing.output_buffer[0] == pytest.approx(0.5)  # y integrated up to the failure
    assert failing.state is State.FAILED
    with pytest.raises(CosimError, match="stopped after a failure"):
        master.step()
    master.close()  # terminates the healthy vehicle only; freeing the failed FMU is safe
    assert vehicle.state is State.FREED and failing.state is State.FREED


def test_fmu_failing_in_the_compiled_loop_reports_the_same():
    system = System(0.1)
    system.add(FmuComponent(fixture_fmu("failing_fmi2"), "faulty", {"fail_time": 0.3}))
    system.add(FmuComponent(fixture_fmu("diffdrive_plain_fmi2"), "vehicle"))
    system.connect("faulty.y", "vehicle.v")
    with Master(system) as master:
        master.initialize()
        with pytest.raises(CosimError, match=r"returned fmi2Error from fmi2DoStep at t = 0.3 s"):
            master.run(10, compiled=True)
        assert master.time == pytest.approx(0.3)


def test_fmu_in_a_closed_loop_reaches_the_goal():
    system = System(0.01)
    vehicle = system.add(FmuComponent(fixture_fmu("diffdrive_fmi3"), "vehicle"))
    system.add(FmuComponent(fixture_fmu("controller_fmi2"), "controller", {"goal_x": 3.0, "goal_y": -2.0}))
    for port in ("x", "y", "theta"):
        system.connect(f"vehicle.{port}", f"controller.{port}")
    system.connect("controller.v", "vehicle.v")
    system.connect("controller.omega", "vehicle.omega")
    with Master(system) as master:
        master.initialize()
        master.run(2000)
        assert np.hypot(vehicle.output_buffer[0] - 3.0, vehicle.output_buffer[1] + 2.0) < 1e-3
