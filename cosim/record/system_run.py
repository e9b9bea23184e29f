"""Run any `System` and record every signal: the base of every run.

`cosim run SYSTEM.ssp` (`cosim.ssp.run`) and `cosim fmu simulate` (`cosim.ssp.simulate`) are this
run with their own header and outcome metadata; the robot run (`cosim.navigation.run`) adds its
topics, its loop and its outcome on top of the same pieces.

The log is claimed (`open_recorder`) only after the system is initialised, so bad input never
leaves a log behind. `SystemRun.record_steps` steps an initialised master from its current step to `total`
steps (`Master.run_recorded`: the compiled kernel for a system of FMUs and at least
`COMPILED_MIN_STEPS` steps, which keeps each step's inputs and outputs in blocks for the log),
with every scalar input and output of each component on `/signals/<component>` at each of its
steps, each value stamped at the time it holds (inputs applied at t, outputs at t, a last record
with the final outputs at the end: `cosim.record.recorder`), and String and Binary ones on
`/text_signals/<component>` (`cosim.record.text_signals`). An interrupt (SIGINT/SIGTERM, checked
every `CHUNK_STEPS` steps), an FMU's request to end the run (`SimulationEnded`) and a failed FMU
end the loop; `run_guarded` tells which, the same way for every run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

from cosim.core import interrupt
from cosim.core.master import COMPILED_MIN_STEPS, Master
from cosim.core.timebase import NS_PER_S, due_from
from cosim.errors import PATH_LIMIT, CosimError, SimulationEnded, shorten
from cosim.record.logfile import claim_default_log, claim_log, default_log_path, navcosim_version
from cosim.record.text_signals import TextRecording
from cosim.scenario.load import DEFAULT_LOG_PATTERN

CHUNK_STEPS = 20_000  # steps between checks for an interrupt
PROGRESS_INTERVAL = 0.1  # [s] wall time between progress-bar updates


def open_recorder(
    out_path: Path | None, force: bool, name: str, pattern: str = DEFAULT_LOG_PATTERN, **options
):
    """The run's `Recorder` (`options` are its keywords) on a new log at `out_path` (an existing
    file is refused unless `force`), or, without one, at `pattern` ([output].log) filled in with
    `name` and a timestamp, numbered when that name is taken (`cosim.record.logfile`)."""
    from cosim.record.recorder import Recorder

    if out_path is not None:
        log_path, stream = Path(out_path), claim_log(Path(out_path), force)
    else:
        log_path, stream = claim_default_log(default_log_path(pattern, name))
    return Recorder(log_path, stream=stream, **options)


def close_quietly(master: Master, recorder=None, outcome: dict[str, str] | None = None) -> None:
    """Close the master (the FMUs, their child processes) and the recorder (with `outcome`) on a
    run's way out with an error that matters more than theirs."""
    try:
        master.close()
    except Exception:  # noqa: BLE001 (already failing: the first error is the one to report)
        pass
    if recorder is not None:
        try:
            recorder.close(outcome)
        except Exception:  # noqa: BLE001
            pass


def initialize_or_close(master: Master, source, describe: Callable[[str], str] = str) -> None:
    """Initialise `master`; when that fails, free what it made (its FMUs, their child processes)
    and raise the one line "`source`: initialising the system failed: ..." (`describe` rewords the
    error's text, e.g. with an SSP's own component names). Every run starts this way."""
    try:
        master.initialize()
    except CosimError as error:
        close_quietly(master)
        raise CosimError(f"{source}: initialising the system failed: {describe(str(error))}") from None
    except BaseException:
        close_quietly(master)
        raise


def writing_failed(error: OSError, log_path: Path) -> str:
    """The one line saying the log could not be written (no space, an I/O error); what reached
    the file stays."""
    where = shorten(error.filename or log_path, PATH_LIMIT)
    return f"{where}: writing the log failed ({error.strerror or error})"


def scenario_attachments(text: str, map_file: Path) -> list[tuple[str, str, bytes]]:
    """What a scenario's log attaches, (name, media type, bytes) each: `scenario.toml` (the file as
    given), the map file and, for a ROS map (.yaml), the image it names."""
    attachments = [
        ("scenario.toml", "application/toml", text.encode()),
        (map_file.name, "application/octet-stream", map_file.read_bytes()),
    ]
    if map_file.suffix in (".yaml", ".yml"):
        for line in map_file.read_text().splitlines():
            key, _, value = line.partition(":")
            image = map_file.parent / value.strip().strip("'\"")
            if key.strip() == "image" and image.is_file():
                attachments.append((image.name, "image/x-portable-graymap", image.read_bytes()))
    return attachments


class RunEnd(NamedTuple):
    """How a run's loop ended, besides reaching its end."""

    failure: str | None = None  # the message of a failed FMU
    ended: str | None = None  # an FMU's request to end the run (FMI terminateSimulation)
    interrupted: bool = False  # a signal while an FMU in a child process did not answer


def run_guarded(loop: Callable[[], None], describe: Callable[[CosimError], str]) -> RunEnd:
    """Call `loop()`; a failed FMU (`describe(error)` is its message), an FMU's request to end the
    run and an interrupt while a child process did not answer end it cleanly, each as a `RunEnd`."""
    try:
        loop()
    except SimulationEnded as request:  # the run ends cleanly; the outcome rules judge it
        return RunEnd(ended=str(request))
    except CosimError as error:
        return RunEnd(failure=describe(error))
    except interrupt.Interrupted:
        interrupt.take()
        return RunEnd(interrupted=True)
    return RunEnd()


def progress_bar(stop_time: float):
    """The run's progress bar on stderr (tqdm, erased at the end), counting simulated seconds up to
    `stop_time` [s]; `update_bar` moves it."""
    from tqdm import tqdm

    return tqdm(
        total=round(stop_time, 3),
        unit="s",
        desc="simulated",
        leave=False,
        dynamic_ncols=True,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s [{elapsed}{postfix}]",
    )


def update_bar(bar, sim_time: float, wall: float, last_update: list) -> None:
    """Move `bar` to `sim_time` [s] simulated in `wall` [s] of wall time; `last_update[1]` holds
    the simulated time it showed last."""
    bar.update(round(sim_time - last_update[1], 3))
    last_update[1] = sim_time
    if wall > 0:
        bar.set_postfix_str(f"{sim_time / wall:.0f}x real time", refresh=False)


class SystemRun:
    """One run of an initialised `master`, recording to `recorder` (module docstring).

    `progress`: the simulated time [s] a progress bar counts up to (None: no bar). Call `begin()`
    after the header's metadata, then `record_steps(total, describe)` (or a loop of one's own through
    `run_guarded`), then `end_steps()` before the outcome and `recorder.close(outcome)`. `on_rows`
    (first step, count, [(channel, times [ns], rows)]) sees each block as it is recorded."""

    def __init__(self, master: Master, recorder, progress: float | None = None, on_rows=None) -> None:
        self.master = master
        self.recorder = recorder
        self.system = master.system
        self.on_rows = on_rows
        self.text: TextRecording | None = None
        self.start_clock(progress)

    def start_clock(self, progress: float | None) -> None:
        """The run's wall clock starts now (again), with a progress bar up to `progress` [s]."""
        self.bar = progress_bar(progress) if progress is not None else None
        self.wall_start = time.perf_counter()
        self.last_update = [self.wall_start, 0.0]  # wall time and simulated time [s] the bar last showed

    @property
    def wall_time(self) -> float:
        """[s] since the run started."""
        return time.perf_counter() - self.wall_start

    def write_header(
        self,
        name: str,
        details: dict[str, str],
        components,
        fmu_labels: dict[str, str] | None = None,
        attachments=(),
    ) -> None:
        """The metadata every log starts with: `navcosim` (the run's `name`, this version, then
        `details`), `fmu/<component>` for each of `components` that describes itself (its `fmu`
        as `fmu_labels` names it, when it does), the unconnected inputs, then `attachments`
        ((name, media type, bytes) each)."""
        recorder = self.recorder
        recorder.add_metadata(
            "navcosim", {"scenario_name": name, "navcosim_version": navcosim_version(), **details}
        )
        labels = fmu_labels or {}
        for component in components:
            description = component.describe()
            if description:
                if component.name in labels:
                    description["fmu"] = labels[component.name]
                recorder.add_metadata(f"fmu/{component.name}", description)
        recorder.add_unconnected_inputs(self.system)
        for attachment, media_type, data in attachments:
            recorder.add_attachment(attachment, media_type, data)

    def begin(self) -> None:
        """The channels of the text signals (after the header's metadata, as the log lists them)."""
        self.text = TextRecording(self.recorder, self.system)

    def signal_channels(self) -> None:
        """`/signals/<component>` of every component with all its ports, in the master's order."""
        recorder, system = self.recorder, self.system
        self.channels, self.periods = [], []
        for component in self.master.order:
            self.periods.append(system.period_steps(component))
            self.channels.append(
                recorder.signal_channel(
                    component.name,
                    component.signal_names(),
                    units=[port.unit for port in (*component.inputs, *component.outputs)],
                    inputs=len(component.inputs),
                    initial=component.signal_values(),
                    period_ns=self.periods[-1] * system.macro_step_ns,
                )
            )

    def record(self, first: int, count: int, histories: list[np.ndarray]) -> None:
        """`Master.run_recorded`'s callback: the block's rows onto the components' channels."""
        master = self.master
        h_ns = self.system.macro_step_ns
        blocks = []
        for channel, period, rows in zip(self.channels, self.periods, histories, strict=True):
            first_k = due_from(first, period)  # row j is step first_k + j * period
            times = master.start_time_ns + (first_k + period * np.arange(len(rows))) * h_ns
            blocks.append((channel, times, rows))
        self.recorder.hold_signal_rows(blocks)
        if self.on_rows is not None:
            self.on_rows(first, count, blocks)
        self.show_progress((first + count) * h_ns / NS_PER_S)

    def show_progress(self, sim_time: float) -> None:
        """Move the progress bar to `sim_time` [s] simulated (at most every `PROGRESS_INTERVAL`)."""
        if self.bar is not None:
            now = time.perf_counter()
            if now - self.last_update[0] >= PROGRESS_INTERVAL:
                self.last_update[0] = now
                update_bar(self.bar, sim_time, now - self.wall_start, self.last_update)

    def record_steps(self, total: int, describe: Callable[[CosimError], str]) -> tuple[str, RunEnd]:
        """Step to `total` steps, recording every signal; (reason, how it ended): reason
        stop_time, fmu_terminated, interrupted or fmu_failed (`describe(error)` its message)."""
        master = self.master
        compiled = total >= COMPILED_MIN_STEPS

        def loop() -> None:
            while master.step_index < total and interrupt.take() is None:
                master.run_recorded(
                    min(CHUNK_STEPS, total - master.step_index), self.record, compiled=compiled
                )

        try:
            end = run_guarded(loop, describe)
        finally:
            if self.bar is not None:
                self.bar.close()
        reason = (
            "fmu_failed" if end.failure else ("stop_time" if master.step_index >= total else "interrupted")
        )
        return ("fmu_terminated" if end.ended else reason), end

    def close_master(self, failure: str | None, describe: Callable[[CosimError], str]) -> str | None:
        """Free the system (its FMUs, their child processes); the run's failure, or
        `describe(error)` when terminating it failed."""
        try:
            self.master.close()
        except CosimError as error:
            return failure or describe(error)
        return failure

    def finish(
        self, reason: str, end: RunEnd, describe: Callable[[CosimError], str], first: dict | None = None
    ) -> str | None:
        """The end of the run: the system freed (`describe(error)` when that fails), the last
        records, the log closed with the outcome metadata (`first`, then reason, time, failure,
        ended_by); returns the run's failure."""
        failure = self.close_master(end.failure, describe)
        outcome = {**(first or {}), "reason": reason, "time": repr(self.master.time)}
        if failure:
            outcome["failure"] = failure
        if end.ended:
            outcome["ended_by"] = end.ended
        self.end_steps()
        self.recorder.close(outcome)
        return failure

    def end_steps(self) -> None:
        """The last records of the signals, at the time the run ended."""
        end_ns = self.master.time_ns
        self.text.finish(end_ns)
        self.recorder.end_steps(end_ns)
