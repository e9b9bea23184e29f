"""The inputs of a system that no connection feeds, with the values they keep.

FMI gives every input a start value, and an input that no connection feeds keeps it for the whole
run (or the value a scenario, an SSP binding or `--start-values` holds it at): the value staged in
the component's input buffer (`FmuComponent.text_values` for a String or Binary), which the master
sends at initialisation and the compiled kernel again before each step. `cosim system` lists them;
a run's log keeps them in the metadata record `unconnected_inputs` ("component.port" -> the value
as text: a number in Python's shortest round-trip form, an integer as an integer, a Boolean as
true/false, a String as itself, a Binary as hex), written only when there is one.
"""

from __future__ import annotations

METADATA_NAME = "unconnected_inputs"


def unconnected_inputs(system) -> dict[str, dict[str, object]]:
    """Component name -> {input port -> the value it keeps} of every input (numeric and text) that
    no connection of `system` (a `cosim.core.system.System`) feeds, in the components' order."""
    unfed = system.unfed_inputs()  # (the numeric ones: worked out once for the graph)
    fed = None
    kept: dict[str, dict[str, object]] = {}
    for name, component in system.components.items():
        values: dict[str, object] = {}
        inputs, buffer = component.inputs, component.input_buffer
        for index in unfed[name]:
            port = inputs[index]
            values[port.name] = _typed(port.type, buffer.item(index))
        for port in getattr(component, "text_inputs", ()):
            if fed is None:
                fed = {connection.target for connection in (*system.connections, *system.text_connections)}
            if f"{name}.{port.name}" not in fed:
                values[port.name] = component.text_values.get(port.name, port.start)
        if values:
            kept[name] = values
    return kept


def value_text(value: object) -> str:
    """A kept value as the metadata and `cosim system` write it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, bytes):
        return value.hex()
    return repr(value) if isinstance(value, float) else str(value)


def unconnected_metadata(system) -> dict[str, str]:
    """The `unconnected_inputs` metadata record of `system` (empty when every input is fed)."""
    return {
        f"{name}.{port}": value_text(value)
        for name, values in unconnected_inputs(system).items()
        for port, value in values.items()
    }


def _typed(kind: str, value: float) -> object:
    if kind == "boolean":
        return value != 0.0
    if kind == "integer" and value == value and abs(value) != float("inf"):
        return int(value)
    return value
