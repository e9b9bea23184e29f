"""String and Binary signals of a run: `/text_signals/<component>`, beside `/signals/<component>`.

The float64 struct of `/signals/<component>` cannot hold text, so a component with String or Binary
inputs or outputs (an FMU's, `cosim.fmi.text`) also gets `/text_signals/<component>`: a generated
`navcosim_msgs/msg/<Component>Text` with a `string` field per String and a `uint8[]` field per
Binary variable, inputs first (channel metadata `navcosim.text_names`, `navcosim.text_types`,
`navcosim.text_inputs`). Its records are stamped as the numeric ones: the record at t holds the
inputs applied at t and the outputs at t, the first one the values after initialisation, a last one
at the end time; in between, a record is written only when a value differs from the previous one
(text changes seldom), so each value holds from its record's time to the next record.
"""

from __future__ import annotations

NS_PER_S = 1_000_000_000


class TextRecording:
    """Installs a listener on each component of `system` with text ports, which writes its records."""

    def __init__(self, recorder, system) -> None:
        self._tracks = []
        for component in system.components.values():
            inputs = tuple(getattr(component, "text_inputs", ()))
            outputs = tuple(getattr(component, "text_outputs", ()))
            if not inputs and not outputs:
                continue
            ports = inputs + outputs
            channel = recorder.text_channel(
                component.name, [p.name for p in ports], [p.fmi_type for p in ports], len(inputs)
            )
            track = _Track(recorder, channel, component, inputs, outputs)
            component.text_listener = track.stepped
            self._tracks.append(track)

    def finish(self, end_ns: int) -> None:
        """The last records, at the end time (the final outputs, the inputs last applied)."""
        for track in self._tracks:
            track.component.text_listener = None
            track.write(end_ns, track.outputs(), always=True)


class _Track:
    def __init__(self, recorder, channel: int, component, inputs, outputs) -> None:
        self.recorder, self.channel, self.component = recorder, channel, component
        self.inputs, self.output_ports = inputs, outputs
        self.last: list | None = None
        self.previous: list = self.outputs()  # the outputs at the start of the next step

    def outputs(self) -> list:
        return [self.component.text_values[p.name] for p in self.output_ports]

    def write(self, t_ns: int, outputs: list, always: bool = False) -> None:
        values = [self.component.text_values[p.name] for p in self.inputs] + outputs
        if always or values != self.last:
            self.recorder.write_text(self.channel, t_ns, values)
            self.last = values

    def stepped(self, t: float) -> None:
        """After the step that started at t [s]: the record at t (inputs applied, outputs before)."""
        self.write(round(t * NS_PER_S), self.previous)
        self.previous = self.outputs()
