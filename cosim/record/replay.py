"""The kernel's blocks of steps handed to the recording: from their rows, or replayed step by step.

`Master.run_blocks` steps the FMUs in the compiled kernel and keeps their buffers after each step
(a block's rows). `BlockReplay.replay` records and checks a block from those rows
(`cosim.record.blocks.BlockRecording`) when they describe it; a block they cannot describe (a
topic's first message, a Python component due after the block's first step) is replayed step by
step: each recorded component's buffers are set to each step's values in turn and the run's
per-step callback `finish_step(k)` (recording, mode, outcome, planner) is called for it, as the
Python loop calls it. Either way the log and the outcome are the same bytes and numbers.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cosim.core.timebase import due_from
from cosim.record.blocks import BlockRecording


class HeldPart(NamedTuple):
    """One component's buffers as the recording reads them, and their values after the last step
    replayed (at first: after initialisation)."""

    period: int  # [steps]
    inputs: np.ndarray  # its scalar inputs: a view of the input buffer (array inputs unrecorded)
    row_inputs: slice  # where they sit in a row
    outputs: np.ndarray  # its output buffer
    held_inputs: np.ndarray
    held_outputs: np.ndarray


class BlockReplay:
    """The recording's side of `Master.run_blocks` (module docstring). `fast`: the block recording
    (None: every block step by step)."""

    def __init__(self, master, finish_step, fast: BlockRecording | None) -> None:
        self.finish_step = finish_step
        self.fast = fast
        self.parts: list[HeldPart] = []
        for component in master.order:  # as the kernel's rows (`histories`) are ordered
            period = master.system.period_steps(component)
            slots = [i for i, port in enumerate(component.inputs) if not port.is_array_element]
            if not slots:
                where = slice(0, 0)
            elif slots == list(range(slots[0], slots[-1] + 1)):
                where = slice(slots[0], slots[-1] + 1)
            else:  # scalars between arrays: the whole buffer
                where = slice(0, len(component.inputs))
            inputs = component.input_buffer[where]
            outputs = component.output_buffer
            self.parts.append(HeldPart(period, inputs, where, outputs, inputs.copy(), outputs.copy()))

    def replay(self, first: int, end: int, histories, clean: bool) -> str | None:
        """Steps [first, end): recorded and checked from their rows, or, for a block that needs it,
        step by step (`replay_steps`); why the run ends after them, or None."""
        fast = self.fast
        if fast is None:
            return self.replay_steps(first, end, histories, clean)
        if fast.accepts(first, end, histories):
            return fast.block(first, end, histories, clean)
        if not fast.usable:
            return self.replay_steps(first, end, histories, clean)
        fast.flush()
        rows = {}
        for i, part in enumerate(self.parts):
            if i in fast.buffers:
                row = fast.held(i)
                part.held_inputs[:] = row[part.row_inputs]
                part.held_outputs[:] = row[len(row) - len(part.outputs) :]
                rows[i] = row
        try:
            return self.replay_steps(first, end, histories, clean)
        finally:
            for i, row in rows.items():
                part = self.parts[i]
                row[part.row_inputs] = part.held_inputs
                row[len(row) - len(part.outputs) :] = part.held_outputs

    def replay_steps(self, first: int, end: int, histories, clean: bool) -> str | None:
        """Steps [first, end) as the Python loop's callback sees them: each recorded component's
        buffers (its scalar inputs and its outputs, what the recording reads) are set to what they
        held after each step (its rows, held between its steps), then put back as they are now."""
        live = []
        views = []
        for i, history in enumerate(histories):
            if history is None:
                continue
            part = self.parts[i]
            inputs, outputs = part.inputs, part.outputs
            live.append((inputs.copy(), outputs.copy(), part))
            inputs[:] = part.held_inputs
            outputs[:] = part.held_outputs
            if len(history):
                # Rows of the block as two 2-D views: the scalar inputs, the outputs.
                input_rows = history[:, part.row_inputs]
                output_rows = history[:, history.shape[1] - len(outputs) :]
                period = part.period
                views.append((period, due_from(first, period), input_rows, output_rows, inputs, outputs))
        reason = None
        try:
            for k in range(first, end):
                for period, first_k, input_rows, output_rows, inputs, outputs in views:
                    if period == 1:
                        inputs[:] = input_rows[k - first_k]
                        outputs[:] = output_rows[k - first_k]
                    elif k % period == 0:
                        j = (k - first_k) // period
                        inputs[:] = input_rows[j]
                        outputs[:] = output_rows[j]
                reason = self.finish_step(k)
                if reason is not None:
                    if k != end - 1 or not clean:
                        raise RuntimeError(
                            f"the compiled loop ran past step {k}, where the run ends ({reason})"
                        )
                    break
        finally:
            for live_inputs, live_outputs, part in live:
                part.held_inputs[:] = part.inputs
                part.held_outputs[:] = part.outputs
                part.inputs[:] = live_inputs
                part.outputs[:] = live_outputs
        return reason
