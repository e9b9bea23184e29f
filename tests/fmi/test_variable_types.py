"""Every numeric FMI variable type in parameters, inputs, outputs and connections, checked against
fmpy's own simulation of the same every-type feedthrough FMU (`fixtures.types_fixture`)."""

from __future__ import annotations

import fmpy
import pytest
from fixtures.build_fixtures import build_fixture_fmu
from fixtures.types_fixture import INPUT_STARTS, TYPES

from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.component import FmuComponent

NUMERIC = {version: [t for t in TYPES[version] if t not in ("String", "Binary")] for version in (2, 3)}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("types")
    return {version: build_fixture_fmu(f"types_fmi{version}", folder) for version in (2, 3)}


@pytest.fixture(scope="module")
def numeric(tmp_path_factory):
    """The builds without String and Binary, which step in the compiled kernel."""
    folder = tmp_path_factory.mktemp("numeric")
    return {version: build_fixture_fmu(f"types_numeric_fmi{version}", folder) for version in (2, 3)}


# Parameter values of each type that the FMU adds to the input (within each type's range).
PARAMETERS = {
    "Real": -0.75, "Float32": 0.25, "Float64": -0.75, "Int8": 7, "UInt8": 55, "Int16": 16, "UInt16": 5535,
    "Int32": 2, "Integer": 2, "UInt32": 294967295, "Int64": 2**45, "UInt64": 2**52, "Boolean": True,
    "Enumeration": 2,
}  # fmt: skip


def _fmpy_outputs(path, version: int, start_values: dict) -> dict[str, float]:
    """The outputs at t = 1 s of fmpy's simulation of the FMU (an independent FMI importer)."""
    result = fmpy.simulate_fmu(str(path), stop_time=1.0, output_interval=0.5, start_values=start_values)
    return {f"{t}_output": float(result[f"{t}_output"][-1]) for t in NUMERIC[version]}


@pytest.mark.parametrize("version", [2, 3])
def test_every_numeric_type_matches_fmpy(fmus, version):
    """Parameters and held inputs of every numeric type reach the FMU, and its outputs come back, as
    fmpy gives them; the unset inputs keep their start values."""
    held = {"Int8_input": -100, "UInt16_input": 1} if version == 3 else {"Integer_input": 41}
    parameters = {f"{t}_parameter": PARAMETERS[t] for t in NUMERIC[version]}
    expected = _fmpy_outputs(fmus[version], version, {**parameters, **held})
    component = FmuComponent(fmus[version], "types", parameters=parameters)
    component.input_buffer[[component.input_index[name] for name in held]] = list(held.values())
    system = System(0.5)
    system.add(component)
    with Master(system) as master:
        master.initialize()
        master.run(2)
    inputs = dict(zip([p.name for p in component.inputs], component.input_buffer.tolist(), strict=True))
    outputs = dict(zip([p.name for p in component.outputs], component.output_buffer.tolist(), strict=True))
    assert {name: outputs[name] for name in expected} == expected
    for t in NUMERIC[version]:
        name = f"{t}_input"
        assert inputs[name] == held.get(name, float(INPUT_STARTS[t])), name
    if version == 3:  # FMI 3.0 Enumerations move as Int64: green (2) + blue (2) - 1 = blue + 1 = 3
        assert outputs["Enumeration_output"] == 3.0


def _chain(fmus, version: int, compiled: bool) -> tuple[list[float], list[float]]:
    """Outputs of two every-type FMUs, the first's outputs feeding the second's inputs of each
    numeric type, after 4 steps (the first's inputs held at values off their starts)."""
    system = System(0.25)
    first = system.add(
        FmuComponent(
            fmus[version], "first", parameters={f"{t}_parameter": PARAMETERS[t] for t in NUMERIC[version]}
        )
    )
    second = system.add(FmuComponent(fmus[version], "second"))
    for t in NUMERIC[version]:
        system.connect(f"first.{t}_output", f"second.{t}_input")
    with Master(system) as master:
        master.initialize()
        master.run(4, compiled=compiled)
    names = [f"{t}_output" for t in NUMERIC[version]]
    return tuple([c.output_buffer[c.output_index[name]] for name in names] for c in (first, second))


@pytest.mark.parametrize("version", [2, 3])
def test_connections_of_every_numeric_type_give_the_same_values_in_the_kernel_and_in_python(numeric, version):
    """Connected through the compiled kernel or the Python loop: the same values, and those the FMU
    computes (the second adds its neutral parameters to what the first gives)."""
    fmus = numeric
    compiled, python = _chain(fmus, version, True), _chain(fmus, version, False)
    assert compiled == python
    first, second = python
    names = [f"{t}_output" for t in NUMERIC[version]]
    expected = _fmpy_outputs(
        fmus[version], version, {f"{t}_parameter": PARAMETERS[t] for t in NUMERIC[version]}
    )
    assert dict(zip(names, first, strict=True)) == expected
    assert second == first


@pytest.mark.parametrize("compiled", [True, False])
def test_a_64_bit_output_beyond_2_53_stops_the_run_by_name(numeric, compiled):
    """2^53 + 1 as an Int64 output cannot be a float64 signal: the step that makes it stops the
    run naming it, in the compiled kernel (which steps every numeric type) and in Python alike."""
    system = System(0.5)
    first = system.add(FmuComponent(numeric[3], "first", parameters={"Int64_parameter": 2**53}))
    system.add(FmuComponent(numeric[3], "second", parameters={"Int64_parameter": 2**40}))
    system.connect("first.Int64_output", "second.Int64_input")  # 2^53 - 2^40 + 2^40: exact
    with Master(system) as master:
        master.initialize()
        if compiled:
            assert all(native is not None for native in master.kernel_tables().native)
        master.run(2, compiled=compiled)
        first.set_inputs([first.input_index["Int64_input"]], [-(2**40) + 1])
        with pytest.raises(
            CosimError, match="'second' output 'Int64_output' = 9007199254740993 [(]Int64[)] is beyond 2\\^53"
        ):
            master.run(2, compiled=compiled)


def test_a_64_bit_parameter_is_exact_as_an_int_and_refused_as_a_float_beyond_2_53(fmus):
    component = FmuComponent(fmus[3], "wide", parameters={"Int64_parameter": 2**53 + 1 + 2**40})
    system = System(0.5)
    system.add(component)
    with pytest.raises(
        CosimError, match="output 'Int64_output' = 9007199254740993 [(]Int64[)] is beyond 2\\^53"
    ):
        with Master(system) as master:
            master.initialize()
    component = FmuComponent(fmus[3], "wide", parameters={"Int64_parameter": float(2**60)})
    component.instantiate()
    try:
        with pytest.raises(
            CosimError, match="parameter 'Int64_parameter': 1152921504606846976 is beyond 2\\^53"
        ):
            component.setup(0.0, {})
    finally:
        component.free()


@pytest.mark.parametrize(
    ("source", "target", "problem"),
    [
        ("Float64_output", "Int32_input", "a float cannot feed an integer"),
        ("Float32_output", "Enumeration_input", "a float cannot feed an integer"),
        ("Int32_output", "Boolean_input", "only a Boolean feeds a Boolean"),
        ("Float64_output", "Boolean_input", "only a Boolean feeds a Boolean"),
        ("Int64_output", "Int32_input", "Int32 [-2147483648, 2147483647] does not hold every Int64"),
        ("Int8_output", "UInt8_input", "UInt8 [0, 255] does not hold every Int8"),
        ("UInt64_output", "Int64_input", "does not hold every UInt64"),
    ],
)
def test_a_connection_that_cannot_convert_names_both_ends(fmus, source, target, problem):
    system = System(0.25)
    system.add(FmuComponent(fmus[3], "a"))
    system.add(FmuComponent(fmus[3], "b"))
    with pytest.raises(CosimError, match="connection a[.]" + source + r" [(].*[)] -> b[.]" + target) as error:
        system.connect(f"a.{source}", f"b.{target}")
    assert problem in str(error.value)


@pytest.mark.parametrize(
    ("source", "target"),
    [
        ("Int8_output", "Int16_input"),
        ("UInt8_output", "Int16_input"),
        ("UInt32_output", "Int64_input"),
        ("Int32_output", "Float32_input"),
        ("UInt64_output", "Float64_input"),
        ("Float64_output", "Float32_input"),
        ("Enumeration_output", "Int64_input"),
        ("Int32_output", "Enumeration_input"),
        ("Boolean_output", "Float64_input"),
        ("Boolean_output", "UInt8_input"),
    ],
)
def test_connections_that_convert_are_accepted(fmus, source, target):
    system = System(0.25)
    system.add(FmuComponent(fmus[3], "a"))
    system.add(FmuComponent(fmus[3], "b"))
    system.connect(f"a.{source}", f"b.{target}")


def test_an_integer_parameter_outside_its_type_is_refused(fmus):
    component = FmuComponent(fmus[3], "narrow", parameters={"UInt8_parameter": 256})
    component.instantiate()
    try:
        with pytest.raises(
            CosimError, match=r"'UInt8_parameter': 256 is outside the range of the FMU's UInt8 \[0, 255\]"
        ):
            component.setup(0.0, {})
    finally:
        component.free()


def test_an_array_sized_by_a_tunable_structural_parameter_is_logged_whole(fmus):
    """`y` (Float64[n], n a tunable structural parameter, start 3) has one port per element, and a
    run gives what fmpy gives (y = 2 u); n may be given its start value, not another."""
    component = FmuComponent(fmus[3], "space", parameters={"n": 3})
    assert [p.name for p in component.outputs if p.array_name == "y"] == ["y[1]", "y[2]", "y[3]"]
    assert [p.start for p in component.inputs if p.array_name == "u"] == [1.0, 2.0, 3.0]
    component.input_buffer[[component.input_index[f"u[{k}]"] for k in (1, 2, 3)]] = [0.5, -1.0, 4.0]
    system = System(0.5)
    system.add(component)
    with Master(system) as master:
        master.initialize()
        master.run(2)
    y = [component.output_buffer[component.output_index[f"y[{k}]"]] for k in (1, 2, 3)]
    result = fmpy.simulate_fmu(
        str(fmus[3]), stop_time=1.0, output_interval=0.5, start_values={"u": [0.5, -1.0, 4.0]}
    )
    assert y == result["y"][-1].tolist() == [1.0, -2.0, 8.0]
    resized = FmuComponent(fmus[3], "resized", parameters={"n": 4})
    resized.instantiate()
    try:
        with pytest.raises(CosimError, match="structural parameter 'n' sizes array variables.*start value 3"):
            resized.setup(0.0, {})
    finally:
        resized.free()


@pytest.mark.parametrize("version", [2, 3])
def test_string_and_binary_parameters_inputs_outputs_and_connections(fmus, version):
    """Text moves beside the numbers: parameters at setup, a held input, a connection from one FMU's
    String output to another's input, read before each step; unconnected text inputs keep their
    start values; outputs as the fixture defines them (input then parameter: fmpy records no text)."""
    system = System(0.5)
    first = system.add(FmuComponent(fmus[version], "first", parameters={"String_parameter": " world"}))
    second = system.add(FmuComponent(fmus[version], "second", parameters={"String_parameter": "!"}))
    if version == 3:
        first.default_parameters["Binary_parameter"] = b"\x0c"
        second.set_text("Binary_input", "ff")
    for t in ("String",):
        system.connect(f"first.{t}_output", f"second.{t}_input")
    real = "Float64" if version == 3 else "Real"
    with pytest.raises(
        CosimError, match=f"first.String_output [(]String[)] -> second.{real}_input [(]a number"
    ):
        system.connect("first.String_output", f"second.{real}_input")
    with Master(system) as master:
        master.initialize()
        assert master.kernel_tables() is None  # text moves in Python
        master.run(2)
    assert first.text_values["String_input"] == "hello"  # its start value
    assert first.text_values["String_output"] == "hello world"
    assert second.text_values["String_input"] == "hello world"
    assert second.text_values["String_output"] == "hello world!"
    if version == 3:
        assert first.text_values["Binary_output"] == b"\x0a\x0b\x0c"
        assert second.text_values["Binary_output"] == b"\xff"


@pytest.mark.slow
@pytest.mark.parametrize("version", [2, 3])
def test_every_type_in_the_log_of_fmu_simulate(fmus, version, tmp_path):
    """`cosim fmu simulate` of the every-type FMU, one parameter of each numeric type given: the
    log's /signals hold each input at its start value and each output as fmpy computes it."""
    import subprocess
    import sys
    from pathlib import Path

    from cosim.logs.reader import open_log

    given = {"Integer": 2, "Int16": 16, "UInt32": 294967295, "Boolean": True, "Float32": 0.25}
    start_values = {f"{t}_parameter": v for t, v in given.items() if t in NUMERIC[version]}
    command = [sys.executable, "-m", "cosim", "fmu", "simulate", str(fmus[version]), "--stop-time", "1"]
    command += ["--step", "0.5", "--out", str(tmp_path / "run.mcap"), "--quiet", "--start-values"]
    command += [f"{k}={str(v).lower()}" for k, v in start_values.items()]
    root = Path(__file__).resolve().parents[2]
    completed = subprocess.run(command, capture_output=True, text=True, cwd=root, timeout=300)
    assert completed.returncode == 0, completed.stderr
    expected = _fmpy_outputs(fmus[version], version, start_values)
    with open_log(tmp_path / "run.mcap") as log:
        (component,) = log.components
        signals = log.signals(component)
        for t in NUMERIC[version]:
            assert signals[f"{t}_input"].tolist() == [float(INPUT_STARTS[t])] * 3, t
            assert signals[f"{t}_output"][-1] == expected[f"{t}_output"], t


@pytest.mark.parametrize("version", [2, 3])
def test_unconnected_inputs_keep_their_start_values_in_the_kernel_and_in_python(numeric, version):
    """One input wired, the others unconnected: the compiled kernel (which sends every input before
    each step) and the Python loop (which sends them at initialisation and with a gathered one) give
    the outputs fmpy gives from the start values and the one input."""
    wired = "Int32" if version == 3 else "Integer"
    runs = []
    for compiled in (True, False):
        system = System(0.25)
        system.add(FmuComponent(numeric[version], "first", parameters={f"{wired}_parameter": 5}))
        second = system.add(FmuComponent(numeric[version], "second"))
        system.connect(f"first.{wired}_output", f"second.{wired}_input")
        with Master(system) as master:
            master.initialize()
            master.run(4, compiled=compiled)
        outputs = [second.output_buffer[second.output_index[f"{t}_output"]] for t in NUMERIC[version]]
        runs.append((second.input_buffer.tolist(), outputs))
    assert runs[0] == runs[1]
    names = [f"{t}_output" for t in NUMERIC[version]]
    given = {f"{wired}_input": INPUT_STARTS[wired] + 5}
    expected = fmpy.simulate_fmu(
        str(numeric[version]), stop_time=1.0, output_interval=0.25, start_values=given
    )
    assert dict(zip(names, runs[0][1], strict=True)) == {n: float(expected[n][-1]) for n in names}
