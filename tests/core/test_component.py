"""The Component interface: ports, array-element names, feedthrough, lifecycle and misuse."""

import dataclasses

import numpy as np
import pytest

from cosim.core.component import Port, PythonComponent, State, array_ports
from cosim.errors import CosimError


class Scale(PythonComponent):
    """y = gain * u + offset; `gain` a parameter, counts its steps."""

    def __init__(self, name="scale", period=0.0):
        super().__init__(
            name,
            inputs=[Port("u", unit="m"), Port("offset", start=0.5)],
            outputs=[Port("y", unit="m"), Port("steps", "integer")],
            parameters=[Port("gain", start=2.0)],
            period=period,
            feedthrough={"steps": []},
        )

    def on_setup(self, t0, parameters):
        self.gain = parameters["gain"]

    def on_initialize(self):
        self.output_buffer[0] = self.gain * self.input_buffer[0] + self.input_buffer[1]

    def step(self, t, h):
        self.output_buffer[0] = self.gain * self.input_buffer[0] + self.input_buffer[1]
        self.output_buffer[1] += 1


def test_array_element_ports_are_told_apart_from_scalars():
    assert Port("ranges[3]").array_name == "ranges"
    assert Port("ranges[3]").array_index == (3,)
    assert Port("waypoints[12,1]").array_index == (12, 1)
    assert Port("waypoints[12,1]").is_array_element
    assert not Port("x").is_array_element
    assert not Port("ranges3]").is_array_element
    ports = array_ports("waypoints", 2, columns=2)
    assert [p.name for p in ports] == ["waypoints[1,1]", "waypoints[1,2]", "waypoints[2,1]", "waypoints[2,2]"]
    assert all(np.isnan(p.start) for p in ports)


def test_a_port_is_a_frozen_value():
    """Port's own __init__ keeps the dataclass contract: fields, equality, hashing, replace, frozen."""
    port = Port("waypoints[3, 2]", "real", "m", "a corner", 1.5)
    assert port == Port("waypoints[3, 2]", "real", "m", "a corner", 1.5)
    assert hash(port) == hash(
        Port(name="waypoints[3, 2]", type="real", unit="m", description="a corner", start=1.5)
    )
    assert port != Port("waypoints[3, 2]", "real", "m", "a corner", 2.5)
    assert [f.name for f in dataclasses.fields(Port)][:5] == ["name", "type", "unit", "description", "start"]
    moved = dataclasses.replace(port, name="x")
    assert (moved.name, moved.unit, moved.start, moved.array_name, moved.array_index) == (
        "x",
        "m",
        1.5,
        None,
        None,
    )
    assert (port.array_name, port.array_index) == ("waypoints", (3, 2))
    with pytest.raises(dataclasses.FrozenInstanceError):
        port.name = "y"
    assert Port("v").type == "real" and Port("v").start == 0.0


def test_port_type_is_checked():
    with pytest.raises(CosimError, match="type 'float'"):
        Port("x", "float")


def test_feedthrough_defaults_to_all_inputs_and_is_validated():
    component = Scale()
    assert component.feedthrough == {"y": ["u", "offset"], "steps": []}
    with pytest.raises(CosimError, match="unknown output 'z'"):
        PythonComponent.__init__(component, "bad", [Port("u")], [Port("y")], feedthrough={"z": []})
    with pytest.raises(CosimError, match="unknown input 'w'"):
        PythonComponent.__init__(component, "bad", [Port("u")], [Port("y")], feedthrough={"y": ["w"]})


def test_duplicate_ports_and_bad_names_are_errors():
    with pytest.raises(CosimError, match="declared twice"):
        PythonComponent.__init__(Scale(), "bad", [Port("u"), Port("u")], [])
    with pytest.raises(CosimError, match="identifier"):
        Scale(name="my lidar")
    with pytest.raises(CosimError, match="period"):
        Scale(period=-1.0)


def test_lifecycle_and_batched_inputs():
    component = Scale()
    assert component.input_buffer.tolist() == [0.0, 0.5]  # start values
    component.instantiate()
    component.setup(0.0, {"gain": 3.0})
    component.set_inputs([0], [2.0])
    component.initialize()
    assert component.get_outputs()[0] == 3.0 * 2.0 + 0.5
    component.set_inputs(np.array([1, 0]), np.array([1.0, -1.0]))
    component.do_step(0.0, 0.1)
    outputs = component.get_outputs()
    assert outputs.tolist() == [-2.0, 1.0]
    assert outputs is component.get_outputs()  # the same buffer every call
    assert component.signal_names() == ["u", "offset", "y", "steps"]
    assert component.signal_values().tolist() == [-1.0, 1.0, -2.0, 1.0]
    component.terminate()
    component.free()
    component.free()  # safe twice
    assert component.state is State.FREED


def test_misuse_raises_cosim_error():
    component = Scale()
    with pytest.raises(CosimError, match=r"do_step\(\) called in state created"):
        component.do_step(0.0, 0.1)
    component.instantiate()
    with pytest.raises(CosimError, match="instantiate"):
        component.instantiate()
    with pytest.raises(CosimError, match="no parameter 'gian'; parameters: gain"):
        component.setup(0.0, {"gian": 1.0})
    component.setup(0.0, {})
    with pytest.raises(CosimError, match="do_step"):
        component.do_step(0.0, 0.1)
    component.initialize()
    component.terminate()
    with pytest.raises(CosimError, match="state terminated"):
        component.do_step(0.0, 0.1)
    component.free()
    with pytest.raises(CosimError, match="state freed"):
        component.get_outputs()


def test_port_lookup_lists_known_ports():
    with pytest.raises(CosimError, match="no port 'yy'; ports: y"):
        Scale().port("yy")
    assert Scale().port("offset") == ("input", 1)
