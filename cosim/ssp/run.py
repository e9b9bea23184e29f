"""`cosim run SYSTEM.ssp`: run an SSP 1.0 or 2.0 archive and log every component's variables.

An SSP that navcosim exported runs as the scenario it came from (`cosim.ssp.export`).
In any other, the FMU components and connections of the SSD are stepped by the master from the
start to the stop time (which the FMUs are told; a stop time that is no whole number of macro
steps after the start ends with a shorter step), with every scalar input and output of each
component on `/signals/<component>` at each of its steps, each value stamped at the time it holds
(inputs applied at t, outputs at t, a last record with the final outputs at the end; the
convention of every run: `cosim.record.system_run`).

Overrides: `--set simulation.stop_time=S`, `simulation.macro_step=S`, `simulation.start_time=S`,
`simulation.master=gauss-seidel|jacobi` take precedence over the file (for the macro step, over
the annotations and the FMUs' step sizes: `cosim.ssp.read`); the summary and the log's metadata
say where the macro step came from. `simulation.algebraic_loops=delay|iterate|error`,
`loop_tolerance` and `loop_max_iterations` say how an algebraic loop runs, as in a scenario
(`cosim.core.loops`). The log names each FMU by its archive member, so two runs of
one archive write the same bytes.

An archive is untrusted input, held to a scenario's limits: it is not extracted when it has more
than `cosim.fmi.archive.MAX_ENTRIES` entries or would unpack to more than `simulation.fmu_max_size`
MiB (default 1024, as an FMU); a run is at most `simulation.max_steps` macro steps (default
`cosim.scenario.limits.MAX_STEPS`) and its times at most `MAX_TIME`. Its FMUs run where a
scenario's FMUs given by path run (`simulation.fmu_isolation`, default "auto"): in a child process
whose FMI calls may take `simulation.fmu_timeout` seconds, so a crash, an exit() or a hang of an
FMU ends the run with exit code 2 and a finalised log; an FMU whose bytes are the project's own
build of it runs in-process ("auto"), as a scenario's project FMUs do. Every error line starts
with the archive's name.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from cosim.core import interrupt
from cosim.core.loops import DEFAULT_MAX_ITERATIONS, DEFAULT_TOLERANCE
from cosim.core.master import Master
from cosim.core.system import LOOP_HANDLING, MODES
from cosim.errors import PATH_LIMIT, CosimError, shorten
from cosim.record.system_run import (
    SystemRun,
    close_quietly,
    initialize_or_close,
    open_recorder,
    writing_failed,
)
from cosim.scenario.limits import MAX_STEPS, MAX_TIME, MIN_MACRO_STEP
from cosim.ssp.read import DEFAULT_TIMEOUT, SspSystem, build_system, max_unpacked_size, open_ssp

SIMULATION_KEYS = ("stop_time", "macro_step", "start_time", "master")
LOOP_KEYS = ("algebraic_loops", "loop_tolerance", "loop_max_iterations")  # `System.handle_loops`
# The [simulation] keys of a scenario's FMUs and run length, which an SSP run takes too.
GUARD_KEYS = ("fmu_isolation", "fmu_timeout", "fmu_max_size", "max_steps")
ISOLATIONS = ("auto", "process", "none")
MESSAGE_LIMIT = 2000  # characters of an error line


@dataclass
class SspRunResult:
    log_path: Path
    steps: int
    end_time: float  # [s]
    wall_time: float  # [s]
    reason: str  # stop_time, fmu_terminated (an FMU asked to end), interrupted, fmu_failed
    failure: str | None = None
    macro_step: float = 0.0  # [s]
    macro_step_source: str = ""  # where the macro step came from
    ended: str | None = None  # which FMU asked to end the run, and when

    @property
    def exit_code(self) -> int:
        """0 the run completed (or an FMU ended it), 1 interrupted, 2 a failed FMU."""
        if self.failure is not None:
            return 2
        return 0 if self.reason in ("stop_time", "fmu_terminated") else 1


@dataclass(frozen=True)
class Experiment:
    start_time: float
    stop_time: float
    macro_step: float
    master: str
    macro_step_source: str = ""
    isolation: str = "auto"  # where the FMUs run: `cosim.ssp.read.build_system`
    timeout: float = DEFAULT_TIMEOUT  # [s] longest FMI call of an FMU in a child process
    loops: str = "delay"  # how an algebraic loop runs (`System.handle_loops`)
    loop_tolerance: float = DEFAULT_TOLERANCE
    loop_max_iterations: int = DEFAULT_MAX_ITERATIONS


def parse_overrides(overrides: list[str] | tuple[str, ...]) -> dict[str, object]:
    """`simulation.KEY=VALUE` overrides of an SSP run (other keys belong to scenarios only)."""
    values: dict[str, object] = {}
    for override in overrides:
        key, separator, text = override.partition("=")
        section, _, name = key.strip().partition(".")
        override = shorten(override)
        if not separator or section != "simulation" or name not in SIMULATION_KEYS + GUARD_KEYS + LOOP_KEYS:
            known = ", ".join(f"simulation.{k}" for k in SIMULATION_KEYS + GUARD_KEYS + LOOP_KEYS)
            raise CosimError(f"--set {override}: an SSP run takes only {known}")
        try:
            value = tomllib.loads(f"value = {text.strip()}")["value"]
        except tomllib.TOMLDecodeError:
            value = text.strip()
        number = not isinstance(value, bool) and isinstance(value, int | float) and math.isfinite(value)
        if name == "master":
            if value not in MODES:
                raise CosimError(f"--set {override}: master must be one of {', '.join(MODES)}")
        elif name == "algebraic_loops":
            if value not in LOOP_HANDLING:
                raise CosimError(
                    f"--set {override}: algebraic_loops must be one of {', '.join(LOOP_HANDLING)}"
                )
        elif name == "loop_tolerance":
            if not (number and value > 0):
                raise CosimError(f"--set {override}: loop_tolerance must be a number > 0")
            value = float(value)
        elif name == "loop_max_iterations":
            if not (number and value == int(value) and value >= 1):
                raise CosimError(f"--set {override}: loop_max_iterations must be a whole number >= 1")
            value = int(value)
        elif name == "fmu_isolation":
            if value not in ISOLATIONS:
                raise CosimError(f"--set {override}: fmu_isolation must be one of {', '.join(ISOLATIONS)}")
        elif name == "max_steps":
            if not (number and value == int(value) and value >= 1):
                raise CosimError(f"--set {override}: max_steps must be a whole number >= 1")
            value = int(value)
        elif name in ("fmu_timeout", "fmu_max_size"):
            if not (number and value > 0):
                unit = "seconds" if name == "fmu_timeout" else "MiB"
                raise CosimError(f"--set {override}: {name} must be a number of {unit} > 0")
        elif not number:
            raise CosimError(f"--set {override}: {name} must be a number of seconds")
        values[name] = value
    return values


def experiment(ssp: SspSystem, overrides: dict[str, object]) -> Experiment:
    """Start, stop, macro step and master from the overrides, else the file; errors say which is missing."""
    where = f"{ssp.source}: SystemStructure.ssd"
    start = float(overrides.get("start_time", ssp.start_time))
    if not (math.isfinite(start) and start >= 0):  # the log's clock counts nanoseconds from 0
        raise CosimError(f"{where}: start time must be a finite number of seconds >= 0, got {start:g}")
    stop = overrides.get("stop_time", ssp.stop_time)
    if stop is None:
        raise CosimError(
            f"{where}: DefaultExperiment gives no stopTime; pass --set simulation.stop_time=SECONDS"
        )
    step = overrides.get("macro_step", ssp.macro_step)
    source = "--set simulation.macro_step" if "macro_step" in overrides else ssp.macro_step_source
    if step is None:
        raise CosimError(
            f"{where}: no macro step (SSP has none; navcosim reads its own nc:Simulation macroStep, "
            "the OSP osp:FixedStepAlgorithm baseStepSize and OMS oms:FixedStepMaster stepSize "
            "annotations, and the FMUs' DefaultExperiment stepSize: none is there); "
            "pass --set simulation.macro_step=SECONDS"
        )
    master = str(overrides.get("master", ssp.master or "gauss-seidel"))
    if master not in MODES:
        raise CosimError(f"{where}: nc:Simulation master '{master}' is not one of {', '.join(MODES)}")
    for what, value in (("start time", start), ("stop time", stop), ("macro step", step)):
        if not (math.isfinite(float(value)) and abs(float(value)) <= MAX_TIME):
            raise CosimError(
                f"{where}: {what} must be a finite number, at most {MAX_TIME:g} s in magnitude, "
                f"got {float(value):g}"
            )
    if float(step) <= 0:
        raise CosimError(f"{where}: macro step must be > 0 s, got {step}")
    if float(step) < MIN_MACRO_STEP:
        raise CosimError(f"{where}: macro step must be at least 1 ns (the time base), got {step} s")
    if float(stop) <= start:
        raise CosimError(f"{where}: stop time {stop} s is not after the start time {start} s")
    max_steps = int(overrides.get("max_steps", MAX_STEPS))
    steps = (float(stop) - start) / float(step)
    if steps > max_steps + 0.5:
        raise CosimError(
            f"{where}: {float(stop) - start:g} s at macro step {float(step):g} s is {steps:.3g} steps, "
            f"above max_steps = {max_steps:.3g} (give --set simulation.max_steps=N to allow it)"
        )
    isolation = str(overrides.get("fmu_isolation", "auto"))
    timeout = float(overrides.get("fmu_timeout", DEFAULT_TIMEOUT))
    loops = (
        str(overrides.get("algebraic_loops", "delay")),
        float(overrides.get("loop_tolerance", DEFAULT_TOLERANCE)),
        int(overrides.get("loop_max_iterations", DEFAULT_MAX_ITERATIONS)),
    )
    return Experiment(start, float(stop), float(step), master, source, isolation, timeout, *loops)


def run_ssp(
    path: str | Path, out_path: Path | None = None, overrides=(), progress: bool = False, force: bool = False
):
    """Run the SSP archive `path`, logging to `out_path` (default logs/<name>-<timestamp>.mcap).

    Returns an `SspRunResult`; for an SSP that navcosim exported from a scenario (it carries the
    `org.navcosim.scenario` annotation) the scenario's run: (scenario, `RunResult`). Raises
    `CosimError` on bad input, before any log exists. The log is claimed and signals are handled as
    for a scenario (`cosim.record.system_run`).
    """
    source = shorten(path, PATH_LIMIT)
    try:
        values = parse_overrides(overrides)
        with open_ssp(path, max_unpacked_size(values)) as ssp:
            from cosim.ssp import export

            if export.SCENARIO_ANNOTATION in ssp.annotations:
                return export.run_exported(ssp, values, out_path, progress, force)
            with interrupt.catching_signals():
                return _run_fmus(ssp, experiment(ssp, values), out_path, force, max_unpacked_size(values))
    except CosimError as error:
        if out_path is not None and str(error).startswith(f"{out_path}:"):
            raise CosimError(shorten(str(error), MESSAGE_LIMIT)) from None  # the command line's log
        raise named(source, error) from None


def named(source: str, error: CosimError) -> CosimError:
    """`error` as one line of at most `MESSAGE_LIMIT` characters that starts with the archive's name
    `source` (every SSP error does, whatever in the archive it quotes)."""
    message = str(error)
    line = message if message.startswith(f"{source}:") else f"{source}: {message}"
    line = shorten(line, MESSAGE_LIMIT)
    return error if line == message else CosimError(line)


def _run_fmus(
    ssp: SspSystem, run: Experiment, out_path: Path | None, force: bool, max_size: int | None = None
) -> SspRunResult:
    system, parameters = build_system(ssp, run.macro_step, run.master, run.isolation, run.timeout, max_size)
    system.handle_loops(run.loops, run.loop_tolerance, run.loop_max_iterations)
    master = Master(system, start_time=run.start_time, parameters=parameters, stop_time=run.stop_time)
    initialize_or_close(master, ssp.source, ssp.members)
    with interrupt.deferred():
        return _record(ssp, run, master, out_path, force)


def _record(
    ssp: SspSystem, run: Experiment, master: Master, out_path: Path | None, force: bool
) -> SspRunResult:
    """Step and log, with signals deferred: an interrupt ends the run with a finalised log."""
    try:
        # No in-memory trace: the plot of an SSP run reads the log.
        recorder = open_recorder(out_path, force, Path(ssp.source).stem or "ssp", trace=False)
    except BaseException:
        master.close()
        raise
    steps = SystemRun(master, recorder)
    try:
        with recorder:
            _write_header(ssp, run, steps)
            steps.begin()
            steps.signal_channels()
            reason, end = steps.record_steps(
                master.steps_to_stop,  # the last one shorter where the stop is no whole number of steps
                lambda error: f"{ssp.source}: {ssp.members(str(error))} (at t = {master.time:.3f} s)",
            )
            failure = steps.finish(
                reason,
                end,
                lambda error: f"{ssp.source}: terminating the system failed: {ssp.members(str(error))}",
                {"reached": "false"},
            )
    except OSError as error:
        close_quietly(master, recorder)
        raise CosimError(f"{ssp.source}: {writing_failed(error, recorder.path)}") from None
    return SspRunResult(
        recorder.path,
        master.step_index,
        master.time,
        steps.wall_time,
        reason,
        failure,
        run.macro_step,
        run.macro_step_source,
        end.ended,
    )


def _write_header(ssp: SspSystem, run: Experiment, steps: SystemRun) -> None:
    details = {
        "ssp": Path(ssp.source).name,
        "macro_step": repr(run.macro_step),
        "macro_step_source": run.macro_step_source,
        "start_time": repr(run.start_time),
        "stop_time": repr(run.stop_time),
        "master": run.master,
    }
    # Each FMU as its archive member, not the folder this run unpacked it to (new in every run).
    members = {spec.name: spec.member for spec in ssp.components}
    ssd = ("SystemStructure.ssd", "application/x-ssp-definition", ssp.ssd_text)
    steps.write_header(ssp.name, details, steps.master.order, members, [ssd])


def _ended(ended: str | None) -> str:
    return f" ({ended})" if ended else ""


def summary(result: SspRunResult) -> str:
    rate = result.end_time / result.wall_time if result.wall_time > 0 else math.inf
    return (
        f"{result.reason}{_ended(result.ended)}: {result.steps} steps of {result.macro_step:.6g} s "
        "(macro step from "
        f"{result.macro_step_source}) to t = {result.end_time:.6g} s in {result.wall_time:.2f} s "
        f"({rate:.0f}x real time); log: {result.log_path}"
    )
