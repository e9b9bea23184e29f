"""`cosim fmu simulate X.fmu`: one FMU alone, as `fmpy simulate` and `fmusim` run it.

The FMU becomes a component as a scenario's `[components.NAME]` does: a `ComponentDescription`
(its interface read from modelDescription.xml, the start values split into parameters and held
inputs) made into a component by `cosim.navigation.build.make_fmu`. It is the one component of a
`System` without connections, run by the master as an SSP's FMUs are (`cosim.ssp.run`): a
co-simulation FMU steps through the compiled kernel, which keeps each step's inputs and outputs in
blocks for the log (a Model Exchange FMU, `cosim.fmi.model_exchange`, steps in the Python loop).
An input keeps its value for the whole run: the one given in `start_values`, else its start value.
The run ends at the stop time, or where the FMU asks to end it (`SimulationEnded`: reason
"fmu_terminated", exit code 0), or at a failure (the log finalised up to it).

Defaults are fmpy's: the start time is the DefaultExperiment's startTime, else 0; the stop time its
stopTime, else 1 s after the start; the step its stepSize, else the power of ten nearest to a
thousandth of the run (10 ** (round(log10(stop - start)) - 3) s, fmpy's rule). A stop time that
is no whole number of steps after the start ends with a shorter step, as fmpy does, for an FMU that
can take variable steps (canHandleVariableCommunicationStepSize; a Model Exchange FMU always can);
the FMU is told the stop time.

The log (`/signals/<name>`, every input and output, stamped as `cosim.record.recorder` says: the
record at t holds the outputs at t, the first the outputs after initialisation) names the FMU's
model as the system (`navcosim` metadata `scenario_name`) and keeps the FMU's description
(metadata `fmu/<name>`) and its modelDescription.xml (an attachment).

The CSV is fmpy's (`fmpy.util.write_csv`): a header of the quoted names, "time" then every output
in the FMU's order, and a row per communication point t0, t0 + h, ..., stop: reals in Python's
shortest round-trip form, integers as integers, Booleans as True / False. Its values are those of
the log's records at the same times.
"""

from __future__ import annotations

import math
import re
import tomllib
import zipfile
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from cosim.core import interrupt
from cosim.core.component import closest_names
from cosim.core.master import Master
from cosim.core.system import System
from cosim.core.timebase import NS_PER_S, seconds_to_ns
from cosim.errors import CosimError
from cosim.record.output import atomic_output, checked_output
from cosim.record.system_run import SystemRun, open_recorder
from cosim.scenario.description import ComponentDescription
from cosim.scenario.limits import MAX_STEPS
from cosim.scenario.load import Integration
from cosim.scenario.params import unstarted_inputs, unstarted_problem

INTERFACES = ("cs", "me")  # co-simulation, Model Exchange
_INTEGER_TYPES = {"Integer", "Enumeration", *(f"{s}Int{n}" for s in ("", "U") for n in (8, 16, 32, 64))}


@dataclass(frozen=True)
class Simulation:
    """What `simulate` runs: the FMU's component, the interface, and the experiment [s]."""

    component: ComponentDescription
    interface: str  # "cs" | "me"
    solver: str | None  # Model Exchange integrator; None for co-simulation
    start_time: float
    stop_time: float
    step: float
    start_values: dict[str, object] = field(default_factory=dict)  # as given, by variable name
    held_text: dict[str, str | bytes] = field(default_factory=dict)  # String / Binary inputs' values

    @property
    def steps(self) -> int:
        """Steps to the stop time, the last shorter where the stop is no whole number of steps."""
        span_ns = seconds_to_ns(self.stop_time, "stop time") - seconds_to_ns(self.start_time, "start time")
        return -(-span_ns // seconds_to_ns(self.step, "step"))


@dataclass
class SimulationResult:
    log_path: Path
    csv_path: Path | None
    steps: int
    end_time: float  # [s]
    wall_time: float  # [s]
    reason: str  # stop_time, fmu_terminated (an FMU asked to end), interrupted, fmu_failed
    failure: str | None = None
    ended: str | None = None  # which FMU asked to end the run, and when

    @property
    def exit_code(self) -> int:
        """0 the run reached its stop time or the FMU ended it, 1 interrupted, 2 a failed FMU."""
        if self.failure is not None:
            return 2
        return 0 if self.reason in ("stop_time", "fmu_terminated") else 1


def parse_start_values(texts: list[str] | tuple[str, ...]) -> dict[str, str]:
    """`name=value` texts as name -> value text (read by `prepare` as the variable's type takes it);
    `CosimError` on one without a name or `=`."""
    values: dict[str, str] = {}
    for text in texts:
        name, separator, literal = text.partition("=")
        name = name.strip()
        if not separator or not name:
            raise CosimError(f"--start-values {text}: expected NAME=VALUE, e.g. x0=1.5")
        values[name] = literal.strip()
    return values


def _number(name: str, literal: str) -> int | float | bool:
    """A numeric variable's value text: a TOML number or true/false (an integer stays exact)."""
    try:
        value = tomllib.loads(f"value = {literal}")["value"]
    except tomllib.TOMLDecodeError:
        value = None
    if not isinstance(value, bool) and (not isinstance(value, int | float) or not math.isfinite(value)):
        raise CosimError(f"--start-values {name}={literal}: the value must be a finite number or true/false")
    return value


def _text(literal: str) -> str:
    """A String (or Binary, as hex) variable's value text: as written, or a TOML string unquoted."""
    try:
        value = tomllib.loads(f"value = {literal}")["value"]
    except tomllib.TOMLDecodeError:
        return literal
    return value if isinstance(value, str) else literal


def prepare(
    path: str | Path,
    *,
    stop_time: float | None = None,
    step: float | None = None,
    start_time: float | None = None,
    start_values: dict[str, object] | None = None,
    interface: str | None = None,
    solver: str | None = None,
    tolerance: float | None = None,
    max_step: float | None = None,
) -> Simulation:
    """Read the FMU at `path` and check the options against it; `CosimError` (one line) otherwise.
    None takes the default (module docstring); `interface` None: co-simulation when the FMU has it.
    `start_values`: variable name -> value, or its text (`parse_start_values`)."""
    from cosim.fmi.inspect import read_description
    from cosim.fmi.layout import fmu_layout

    path = Path(path)
    if not path.is_file():
        raise CosimError(f"{path}: no such FMU file")
    description = read_description(path)
    interface = interface or ("cs" if description.coSimulation is not None else "me")
    if interface not in INTERFACES:
        raise CosimError(f"--interface {interface}: must be one of {', '.join(INTERFACES)}")
    for option, value in (("--solver", solver), ("--tolerance", tolerance), ("--max-step", max_step)):
        if value is not None and interface != "me":
            raise CosimError(
                f"{option} {value}: a solver integrates a Model Exchange FMU; give --interface me"
            )
        if option != "--solver" and value is not None and not (math.isfinite(value) and value > 0):
            raise CosimError(f"{option} must be > 0, got {value:g}")
    if interface == "me" and description.modelExchange is None:
        raise CosimError(f"{path}: the FMU has no <ModelExchange> interface; --interface me cannot run it")
    if interface == "cs" and description.coSimulation is None:
        raise CosimError(f"{path}: the FMU has no <CoSimulation> interface; --interface cs cannot run it")
    name = component_name(description.modelName or path.stem)
    layout = fmu_layout(path, name)
    variable_step = interface == "me" or description.coSimulation.canHandleVariableCommunicationStepSize
    start, stop, h = _experiment(description, start_time, stop_time, step, variable_step)
    parameters, held, held_text = _split_start_values(path, description, layout, start_values or {})
    for port in unstarted_inputs(layout):
        if port not in held and port not in held_text:
            raise CosimError(
                f"{path}: " + unstarted_problem(port, f"give it a value with --start-values {port}=<value>")
            )
    inputs = tuple(port.name for port in layout.inputs)
    feedthrough = {port.name: layout.feedthrough.get(port.name, inputs) for port in layout.outputs}
    component = ComponentDescription(
        name,
        "fmu",
        str(path),
        fmu=path,
        fmi_version=layout.fmi_version,
        model_name=description.modelName or "",
        parameters=parameters,
        held_inputs=held,
        inputs=inputs,
        outputs=tuple(port.name for port in layout.outputs),
        parameter_names=tuple(port.name for port in layout.parameters),
        feedthrough=feedthrough,
        integration=Integration("me", solver or "cvode", tolerance, max_step)
        if interface == "me"
        else Integration("cs"),
    )
    given = dict(start_values or {})
    return Simulation(component, interface, component.integration.solver, start, stop, h, given, held_text)


def component_name(model_name: str) -> str:
    """The component (and `/signals/<name>`) name of a model: its word characters, `_` for the rest."""
    name = re.sub(r"\W", "_", model_name)
    return name if name and not name[0].isdigit() else f"fmu_{name}"


def _experiment(description, start_time, stop_time, step, variable_step: bool) -> tuple[float, float, float]:
    """Start, stop and step [s]: the options, else the DefaultExperiment, else fmpy's defaults. A
    stop time that is no whole number of steps after the start takes a shorter last step, which an
    FMU without canHandleVariableCommunicationStepSize cannot take."""
    experiment = description.defaultExperiment

    def default(option, attribute: str):
        if option is not None:
            return float(option)
        value = getattr(experiment, attribute, None) if experiment is not None else None
        return None if value is None else float(value)

    start = default(start_time, "startTime") or 0.0
    stop = default(stop_time, "stopTime")
    stop = start + 1.0 if stop is None else stop
    for option, value in (("--start-time", start), ("--stop-time", stop)):
        if not math.isfinite(value):
            raise CosimError(f"{option} must be finite, got {value}")
    if not stop > start:
        raise CosimError(f"--stop-time {stop:g} s is not after the start time {start:g} s")
    h = default(step, "stepSize")
    if h is None:
        h = 10.0 ** (round(math.log10(stop - start)) - 3)
    if not (math.isfinite(h) and h > 0):
        raise CosimError(f"--step must be > 0 s, got {h:g}")
    h_ns = seconds_to_ns(h, "--step")
    span_ns = seconds_to_ns(stop, "--stop-time") - seconds_to_ns(start, "--start-time")
    steps, rest = divmod(span_ns, h_ns)
    if rest and not variable_step:
        raise CosimError(
            f"--stop-time {stop:g} s is not a whole number of --step {h:g} s steps after the start "
            f"time {start:g} s ({span_ns / h_ns:.6g} steps), and the FMU cannot take a shorter last "
            "step (no canHandleVariableCommunicationStepSize)"
        )
    steps += rest > 0
    if steps > MAX_STEPS:
        raise CosimError(f"{steps} steps of {h:g} s: more than {MAX_STEPS}; give a larger --step")
    return start, stop, h


def _split_start_values(path: Path, description, layout, values: dict) -> tuple[dict, dict, dict]:
    """The start values as parameters, held numeric inputs and held text (String, Binary) inputs,
    each checked against its variable's type and declared min/max; `CosimError` naming the first
    bad one (with the closest names for a typo). A value given as text is read as its variable's
    type takes it (`parse_start_values`)."""
    parameters = {port.name for port in (*layout.parameters, *layout.text.get("parameter", ()))}
    texts = {port.name for causality in ("parameter", "input") for port in layout.text.get(causality, ())}
    variables = {variable.name: variable for variable in description.modelVariables}
    settable = [port.name for port in (*layout.parameters, *layout.inputs)]
    settable += [port.name for causality in ("parameter", "input") for port in layout.text.get(causality, ())]
    split: tuple[dict, dict, dict] = ({}, {}, {})
    for name, value in values.items():
        if name not in settable:
            raise CosimError(
                f"--start-values {name}={_literal(value)}: the FMU ({description.modelName}) has no "
                f"parameter or input '{name}'; "
                f"closest: {closest_names(name, settable) if settable else 'none (it has neither)'}"
            )
        if name in texts:
            value = _text(value) if isinstance(value, str) else value
            split[0 if name in parameters else 2][name] = value  # the FMU checks the type at setup
            continue
        value = _number(name, value) if isinstance(value, str) else value
        variable = variables.get(name)
        problem = _value_problem(variable, value) if variable is not None else None
        if problem:
            raise CosimError(f"--start-values {name}={_literal(value)}: {problem}")
        # An integer stays a Python int: an Int64 beyond 2^53 reaches the FMU exactly.
        value = value if isinstance(value, int) and not isinstance(value, bool) else float(value)
        split[0 if name in parameters else 1][name] = value
    return split


def _value_problem(variable, value: float | bool) -> str | None:
    """Why `value` does not suit the FMU variable (its type, its declared min/max), or None."""
    kind = variable.type
    if kind == "Boolean":
        return None if value in (0, 1) else f"'{variable.name}' is a Boolean: give true or false"
    if isinstance(value, bool):
        return f"'{variable.name}' is a {kind}: give a number, not {str(value).lower()}"
    if kind in _INTEGER_TYPES and value != math.floor(value):
        return f"'{variable.name}' is an {kind}: give a whole number"
    low, high = _bound(variable.min), _bound(variable.max)
    if (low is None or value >= low) and (high is None or value <= high):
        return None
    if low is not None and high is not None:
        return f"'{variable.name}' must be in [{low:g}, {high:g}] (its min and max)"
    return f"'{variable.name}' must be {'>=' if high is None else '<='} {low if high is None else high:g}"


def _bound(text) -> float | None:
    try:
        bound = float(text)
    except (TypeError, ValueError):
        return None
    return bound if math.isfinite(bound) else None


def _literal(value) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    return f"{value:g}" if isinstance(value, float) else str(value)


def simulate(
    simulation: Simulation,
    out_path: Path | None = None,
    csv_path: Path | None = None,
    progress: bool = False,
    force: bool = False,
) -> SimulationResult:
    """Run `simulation`, logging to `out_path` (default logs/<model>-<timestamp>.mcap) and, given
    `csv_path`, writing the outputs as CSV. `CosimError` on bad input, before any file exists;
    an FMU that fails while stepping ends the run with its `failure` (the log finalised up to it).
    Signals are handled as for any run (`cosim.record.system_run`)."""
    from cosim.navigation.build import make_fmu

    described = simulation.component
    for path in (out_path, csv_path):
        if path is not None:
            checked_output(path, force)  # checked again, race-free, when written
    with interrupt.catching_signals(), ExitStack() as outputs:
        # The CSV goes to a temporary beside it, renamed when the run ends (with the rows up to a
        # failure, as the log); an error before that leaves no file.
        csv_temporary = outputs.enter_context(atomic_output(csv_path, force)) if csv_path else None
        # Nothing feeds this FMU: its NaN outputs are its values, recorded as they are.
        real = tuple(port.name for port in _output_ports(described) if port.type == "real")
        try:
            component = make_fmu(described, nan_outputs=real)
            for name, value in simulation.held_text.items():
                component.set_text(name, value)
        except CosimError as error:
            raise CosimError(f"{described.fmu}: {error}") from None
        system = System(simulation.step)
        system.add(component)
        master = Master(
            system,
            start_time=simulation.start_time,
            parameters={described.name: described.parameters},
            stop_time=simulation.stop_time,
        )
        try:
            master.initialize()
        except CosimError as error:
            raise CosimError(f"{described.fmu}: initialising the FMU failed: {error}") from None
        with interrupt.deferred():
            result = _run(simulation, master, out_path, csv_temporary, progress, force)
    return replace(result, csv_path=csv_path)


def _output_ports(described: ComponentDescription):
    from cosim.fmi.layout import fmu_layout

    return fmu_layout(described.fmu, described.name).outputs


def _run(simulation: Simulation, master: Master, out_path, csv_path, progress: bool, force: bool):
    (component,) = master.order
    csv = None
    try:
        csv = _CsvWriter(csv_path, component) if csv_path is not None else None
        # No in-memory trace: the plot of an FMU's run reads the log.
        recorder = open_recorder(out_path, force, component.name, trace=False)
    except BaseException:
        if csv is not None:
            csv.close()
        master.close()
        raise
    h_ns = master.system.macro_step_ns

    def write_csv(first: int, count: int, blocks) -> None:
        ((_, times, rows),) = blocks
        # Outputs at each step's end (the last ends at the stop time).
        csv.write(np.minimum(times + h_ns, master.time_ns), rows[:, len(component.inputs) :])

    steps = SystemRun(
        master,
        recorder,
        progress=simulation.stop_time - simulation.start_time if progress else None,
        on_rows=write_csv if csv is not None else None,
    )
    with recorder:
        _write_header(simulation, steps)
        steps.begin()
        steps.signal_channels()
        if csv is not None:
            csv.write(np.array([master.start_time_ns]), component.output_buffer[None, :])
        try:
            reason, end = steps.record_steps(
                simulation.steps, lambda error: f"{error} (at t = {master.time:.6g} s)"
            )
        finally:
            if csv is not None:
                csv.close()
        failure = steps.finish(reason, end, lambda error: f"terminating the FMU failed: {error}")
    return SimulationResult(
        recorder.path, csv_path, master.step_index, master.time, steps.wall_time, reason, failure, end.ended
    )


def _write_header(simulation: Simulation, steps: SystemRun) -> None:
    described = simulation.component
    details = {
        "fmu": Path(described.fmu).name,
        "interface": simulation.interface,
        "start_time": repr(simulation.start_time),
        "stop_time": repr(simulation.stop_time),
        "macro_step": repr(simulation.step),
        "start_values": " ".join(f"{k}={_literal(v)}" for k, v in simulation.start_values.items()),
    }
    with zipfile.ZipFile(described.fmu) as archive:
        text = archive.read("modelDescription.xml")
    description = ("modelDescription.xml", "application/xml", text)
    steps.write_header(
        described.model_name or described.name, details, steps.master.order, None, [description]
    )


class _CsvWriter:
    """The outputs as fmpy writes a result (module docstring), a block of rows at a time."""

    def __init__(self, path: Path, component) -> None:
        self.path = Path(path)
        kinds = [port.type for port in component.outputs]
        self.formats = [_FORMATS.get(kind, _FORMATS["real"]) for kind in kinds]
        try:
            self.file = open(self.path, "w", encoding="utf-8", newline="")  # noqa: SIM115 (closed by close())
        except OSError as error:
            raise CosimError(f"{self.path}: cannot write the CSV ({error.strerror or error})") from None
        names = ["time", *(port.name for port in component.outputs)]
        self.file.write(",".join(f'"{name}"' for name in names) + "\n")

    def write(self, times_ns: np.ndarray, outputs: np.ndarray) -> None:
        columns = [[repr(t / NS_PER_S) for t in times_ns.tolist()]]
        columns += [fmt(outputs[:, j]) for j, fmt in enumerate(self.formats)]
        self.file.write("".join(",".join(row) + "\n" for row in zip(*columns, strict=True)))

    def close(self) -> None:
        self.file.close()


_FORMATS = {
    "real": lambda column: list(map(repr, column.tolist())),
    "integer": lambda column: list(map(str, column.astype(np.int64).tolist())),
    "boolean": lambda column: ["True" if value else "False" for value in column.tolist()],
}


def summary(result: SimulationResult) -> str:
    rate = result.end_time / result.wall_time if result.wall_time > 0 else math.inf
    csv = f"; csv: {result.csv_path}" if result.csv_path is not None else ""
    ended = f" ({result.ended})" if result.ended else ""
    return (
        f"{result.reason}{ended}: {result.steps} steps to t = {result.end_time:.6g} s in "
        f"{result.wall_time:.2f} s ({rate:.0f}x real time); log: {result.log_path}{csv}"
    )
