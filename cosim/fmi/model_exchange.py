"""Model Exchange FMUs (FMI 1.0, 2.0 and 3.0) as co-simulation components, integrated by a solver.

`ModelExchangeComponent` is an `FmuComponent` (the same ports, port map, parameters, batched
input/output transfers and checks) whose `do_step(t, h)` integrates the FMU's continuous states
from t to t + h with a solver of `cosim.fmi.solvers` (`cvode`, `rk4`, `euler`), the inputs held at
the values pushed for the step (zero-order hold, as a co-simulation FMU sees them):

- a state event (an event indicator crosses zero) stops the solver at the crossing (CVode's root
  finding; bisection for the fixed-step solvers), a time event (the FMU's nextEventTime) is a stop
  time of the solver, and a step event (fmi*CompletedIntegratorStep asking for event mode, after
  each accepted step when the FMU declares it needs the call) stops it where it is. At each event the
  FMU enters event mode and its discrete states are updated until it needs no more
  (fmi2NewDiscreteStates / fmi3UpdateDiscreteStates; FMI 1.0, which has no modes: fmiEventUpdate
  until iterationConverged), then the solver restarts from the states the FMU gives back;
- an input that changed since the last step restarts the solver (its derivatives jumped); a change of
  a discrete input (Integer, Boolean, or variability discrete) is pushed in event mode, with the
  event iteration after it, as FMI requires.

Initialisation is `FmuComponent`'s, followed by the event iteration FMI prescribes after
exitInitializationMode and the switch to continuous-time mode (FMI 1.0: fmiSetTime(t0), then
fmiInitialize, which does the initial event iteration itself). The FMU asking to terminate is a
`CosimError`, as for co-simulation FMUs.

Defaults: `tolerance` (CVode's relative tolerance; absolute = tolerance x the states' nominals) is
the FMU's DefaultExperiment tolerance, else 1e-5 (fmpy's); `max_step` [s] is unbounded for CVode
(each call still stops at the communication point) and one communication step for rk4 / euler.

This component steps in the Python master loop only: `native_step()` is None.
"""

from __future__ import annotations

import ctypes
import math
import zipfile
from collections.abc import Collection, Mapping
from pathlib import Path

import fmpy
import numpy as np
from fmpy.fmi1 import FMU1Model
from fmpy.fmi2 import FMU2Model
from fmpy.fmi3 import FMU3Model

from cosim.core.component import NativeStep, State
from cosim.errors import CosimError
from cosim.fmi.component import FmuComponent, functions_bound_once
from cosim.fmi.solvers import SOLVERS, make_solver

DEFAULT_TOLERANCE = 1e-5  # fmpy's relative tolerance when the FMU's DefaultExperiment gives none
_MAX_EVENT_ITERATIONS = 1000  # discrete-state updates at one event before it is an error


def fmu_component(integration: Mapping[str, object] | None = None, **arguments) -> FmuComponent:
    """`FmuComponent(**arguments)`, or with `integration` (solver, tolerance, max_step: None for
    the defaults) `ModelExchangeComponent(**arguments, **integration)`."""
    if integration is None:
        return FmuComponent(**arguments)
    return ModelExchangeComponent(**arguments, **integration)


def integration_problem(solver: str, tolerance: float | None, max_step: float | None) -> str | None:
    """Why these integration settings are invalid (one line), or None."""
    if solver not in SOLVERS:
        return f"unknown solver '{solver}'; solvers: {', '.join(SOLVERS)}"
    for key, value in (("tolerance", tolerance), ("max_step", max_step)):
        if value is not None and not (math.isfinite(value) and value > 0):
            return f"{key} must be a number > 0, got {value:g}"
    return None


class ModelExchangeComponent(FmuComponent):
    """A Model Exchange FMU as a component (module docstring).

    Args: those of `FmuComponent`, and
        solver: "cvode" (default), "rk4" or "euler".
        tolerance: CVode's relative tolerance (None: the FMU's DefaultExperiment's, else 1e-5).
        max_step: the longest solver step [s] (None: unbounded for CVode, h for rk4 / euler).
    """

    _FMPY_CLASSES = {
        version: functions_bound_once(c) for version, c in ((1, FMU1Model), (2, FMU2Model), (3, FMU3Model))
    }

    def __init__(
        self,
        path: str | Path,
        name: str,
        parameters: Mapping[str, float] | None = None,
        port_map: Mapping[str, object] | None = None,
        period: float = 0.0,
        feedthrough_override: Mapping[str, list[str]] | None = None,
        nan_outputs: Collection[str] = (),
        max_unpacked_size: int | None = None,
        solver: str = "cvode",
        tolerance: float | None = None,
        max_step: float | None = None,
    ) -> None:
        problem = integration_problem(solver, tolerance, max_step)
        if problem:
            raise CosimError(f"component '{name}': {problem}")
        super().__init__(
            path, name, parameters, port_map, period, feedthrough_override, nan_outputs, max_unpacked_size
        )
        description = self.model_description
        experiment = description.defaultExperiment
        if tolerance is None and experiment is not None and experiment.tolerance is not None:
            tolerance = float(experiment.tolerance)
        self.solver_name = solver
        self.tolerance = DEFAULT_TOLERANCE if tolerance is None else float(tolerance)
        self.max_step = max_step
        self.nx = int(description.numberOfContinuousStates)
        self.nz = int(description.numberOfEventIndicators)
        # FMI 1.0 has no attribute for it: fmiCompletedIntegratorStep is called after every step.
        needs = description.modelExchange.needsCompletedIntegratorStep or self.fmi_version == 1
        self._needs_completed_step = bool(needs)
        variables = [self._variables[p.name].variable for p in self.inputs]
        self._discrete_inputs = np.array(
            [
                i
                for i, v in enumerate(variables)
                if v.type not in ("Real", "Float64") or v.variability == "discrete"
            ],
            dtype=np.intp,
        )
        self._check_binary()
        self._solver = None
        self._integrated_inputs = self.input_buffer.copy()  # the inputs the solver integrated with
        self._next_event: float | None = None  # the FMU's nextEventTime [s]
        self._time = 0.0
        self.events = 0  # events handled while stepping (state, time, step and input events)

    def _interface(self):
        return self.model_description.modelExchange

    def _check_interface(self) -> None:
        if self._interface() is None:
            raise CosimError(
                f"FMU '{self.path}' (model {self.model_description.modelName}) has no model exchange "
                'interface; interface = "me" needs one'
            )

    def _check_binary(self) -> None:
        platform = fmpy.platform if self.fmi_version < 3 else fmpy.platform_tuple
        identifier = self._interface().modelIdentifier
        binary = f"binaries/{platform}/{identifier}{fmpy.sharedLibraryExtension}"
        with zipfile.ZipFile(self.path) as archive:
            if binary not in archive.namelist():
                raise CosimError(
                    f"FMU '{self.path}' (model {self.model_description.modelName}) has no model exchange "
                    f"binary {binary} for this platform"
                )

    def _bind_do_step(self, dll) -> None:
        """The Model Exchange calls of the integration loop (there is no doStep)."""
        v, d, n, c_int = ctypes.c_void_p, ctypes.c_double, ctypes.c_size_t, ctypes.c_int
        array = ctypes.CFUNCTYPE(c_int, v, v, n)
        version, function = self.fmi_version, self._function
        flag = {1: ctypes.c_uint8, 2: ctypes.c_int, 3: ctypes.c_bool}[
            version
        ]  # fmiBoolean, fmi2Boolean, bool
        derivatives = "GetDerivatives" if version < 3 else "GetContinuousStateDerivatives"
        nominals = "GetNominalContinuousStates" if version == 1 else "GetNominalsOfContinuousStates"
        self._set_time = ctypes.CFUNCTYPE(c_int, v, d)((function("SetTime"), dll))
        self._set_states = array((function("SetContinuousStates"), dll))
        self._get_states = array((function("GetContinuousStates"), dll))
        self._get_nominals = array((function(nominals), dll))
        self._get_derivatives = array((function(derivatives), dll))
        self._get_indicators = array((function("GetEventIndicators"), dll))
        if version == 1:  # (c, *callEventUpdate)
            prototype = ctypes.CFUNCTYPE(c_int, v, ctypes.POINTER(flag))
        else:  # (c, noSetFMUStatePriorToCurrentPoint, *enterEventMode, *terminateSimulation)
            prototype = ctypes.CFUNCTYPE(c_int, v, flag, ctypes.POINTER(flag), ctypes.POINTER(flag))
        self._completed_step = prototype((function("CompletedIntegratorStep"), dll))
        self._completed_flags = (flag(), flag())
        self._raw_do_step, self._do_step_flags = None, ()
        self._step_flags = (ctypes.c_bool * 3)()

    def _compile_fast_path(self) -> None:
        super()._compile_fast_path()
        self._compiled["do_step"] = self._integrate
        if len(self._discrete_inputs):
            self._compiled["push_inputs"] = self._push_in_event_mode(self._compiled["push_inputs"])

    def _push_in_event_mode(self, push):
        """`push` for an FMU with discrete inputs: a change of one is sent in event mode."""
        slots = self._discrete_inputs
        sent = self.input_buffer[slots].copy()

        def push_inputs() -> None:
            if self.state is not State.STEPPING or np.array_equal(self.input_buffer[slots], sent):
                return push()
            sent[:] = self.input_buffer[slots]
            self._enter_event_mode()
            push()
            self._handle_event(self._time)
            return None

        return push_inputs

    # ---- FMI calls ---------------------------------------------------------------------------

    def _call(self, function: str, *args):
        """fmpy's method `function` (event-mode calls), its failure as the component's `CosimError`."""
        try:
            return getattr(self._slave, function)(*args)
        except Exception as error:
            self._fail(
                int(getattr(error, "status", 3)),
                f"fmi{self.fmi_version}{function[0].upper()}{function[1:]}",
                self._time,
            )

    def _checked(self, status: int, function: str, t: float) -> None:
        if status > 1:
            self._fail(status, f"fmi{self.fmi_version}{function}", t)

    def _set_model(self, t: float, x: np.ndarray) -> None:
        self._checked(self._set_time(self._handle, t), "SetTime", t)
        if self.nx:
            self._checked(self._set_states(self._handle, x.ctypes.data, self.nx), "SetContinuousStates", t)

    def _derivatives(self, t: float, x: np.ndarray, dx: np.ndarray) -> None:
        self._set_model(t, x)
        self._checked(self._get_derivatives(self._handle, dx.ctypes.data, self.nx), "GetDerivatives", t)

    def _indicators(self, t: float, x: np.ndarray, z: np.ndarray) -> None:
        self._set_model(t, x)
        self._checked(self._get_indicators(self._handle, z.ctypes.data, self.nz), "GetEventIndicators", t)

    def _completed(self, t: float, x: np.ndarray) -> bool:
        """Tell the FMU a solver step is accepted (when it needs to know); True: a step event."""
        if not self._needs_completed_step:
            return False
        self._set_model(t, x)
        enter, terminate = self._completed_flags
        if self.fmi_version == 1:
            status = self._completed_step(self._handle, ctypes.byref(enter))
        else:
            status = self._completed_step(self._handle, True, ctypes.byref(enter), ctypes.byref(terminate))
        self._checked(status, "CompletedIntegratorStep", t)
        if terminate.value:
            self._asked_to_terminate(t)
        return bool(enter.value)

    def _states(self) -> np.ndarray:
        x = np.zeros(self.nx)
        if self.nx:
            self._checked(
                self._get_states(self._handle, x.ctypes.data, self.nx), "GetContinuousStates", self._time
            )
        return x

    def _nominals(self) -> np.ndarray:
        nominals = np.ones(self.nx)
        if self.nx:
            status = self._get_nominals(self._handle, nominals.ctypes.data, self.nx)
            self._checked(status, "GetNominalsOfContinuousStates", self._time)
        return nominals

    def _event_iteration(self, t: float) -> None:
        """Update the discrete states until the FMU needs no more; keep its next event time."""
        update = ("eventUpdate", "newDiscreteStates", "updateDiscreteStates")[self.fmi_version - 1]
        for _ in range(_MAX_EVENT_ITERATIONS):
            if self.fmi_version == 1:  # (iterationConverged, ..., terminateSimulation, upcomingTimeEvent, t)
                converged, _, _, terminate, time_defined, next_time = self._call(update)
                needed = not converged
            else:
                needed, terminate, _, _, time_defined, next_time = self._call(update)
            if terminate:
                self._asked_to_terminate(t)
            if not needed:
                self._next_event = float(next_time) if time_defined else None
                return
        raise CosimError(
            f"FMU '{self.name}' (model {self.model_description.modelName}): the event iteration at "
            f"t = {t:.9g} s did not end after {_MAX_EVENT_ITERATIONS} discrete-state updates"
        )

    def _handle_event(self, t: float) -> None:
        """In event mode: iterate, back to continuous time, restart the solver from the FMU's states."""
        self.events += 1
        self._event_iteration(t)
        self._leave_event_mode()
        self._solver.reset(t, self._states())

    def _enter_event_mode(self) -> None:
        if self.fmi_version > 1:  # FMI 1.0 has no modes: fmiEventUpdate is called directly
            self._call("enterEventMode")

    def _leave_event_mode(self) -> None:
        if self.fmi_version > 1:
            self._call("enterContinuousTimeMode")

    # ---- lifecycle ---------------------------------------------------------------------------

    def initialize(self) -> None:
        if self.fmi_version == 1:
            self._initialize_fmi1()
        else:
            super().initialize()
            self._time = self.t0
            self._event_iteration(self.t0)  # exitInitializationMode leaves a ME FMU in event mode
            self._leave_event_mode()
        max_step = self.max_step if self.max_step is not None else math.inf
        callbacks = (self._derivatives, self._indicators, self._completed)
        self._solver = make_solver(
            self.solver_name, self.nx, self.nz, callbacks, self.tolerance, max_step, self._nominals()
        )
        self._solver.reset(self.t0, self._states())
        self._integrated_inputs[:] = self.input_buffer

    def _initialize_fmi1(self) -> None:
        """FMI 1.0: the start time, then fmiInitialize, which does the initial event iteration."""
        self._require("initialize", State.SET_UP)
        self._time = self.t0
        self._checked(self._set_time(self._handle, self.t0), "SetTime", self.t0)
        converged, _, _, terminate, time_defined, next_time = self._call("initialize")
        if terminate:
            self._asked_to_terminate(self.t0)
        self._next_event = float(next_time) if time_defined else None
        if not converged:
            self._event_iteration(self.t0)
        self.state = State.STEPPING
        self._install_fast_path()

    def do_step(self, t: float, h: float) -> None:
        self._require("do_step", State.STEPPING)
        self._integrate(t, h)

    def _integrate(self, t: float, h: float) -> None:
        """Advance the states from t to t + h [s], handling every event on the way."""
        self._step_time[0] = t
        solver = self._solver
        if not np.array_equal(self.input_buffer, self._integrated_inputs):
            self._integrated_inputs[:] = self.input_buffer
            solver.reset(self._time, self._states())
        t_end = t + h
        close = 1e-12 * max(1.0, abs(t_end))
        reached = self._time
        while reached < t_end - close:
            next_event = self._next_event
            timed = next_event is not None and next_event <= t_end + close
            target = t_end if not timed or next_event >= t_end - close else max(next_event, reached)
            reached, event = solver.advance(target)
            if timed and reached >= target - close and target >= next_event - close:
                event = True
            self._time = reached
            self._set_model(reached, solver.x[: self.nx])
            if event:
                self._enter_event_mode()
                self._handle_event(reached)
        self._time = t_end

    def native_step(self) -> NativeStep | None:
        """None: the integration loop runs in Python (module docstring)."""
        return None

    def free(self) -> None:
        if self._solver is not None and hasattr(self._solver, "free"):
            self._solver.free()
        self._solver = None
        super().free()

    def describe(self) -> dict[str, str]:
        facts = super().describe()
        facts.update(interface="model exchange", solver=self.solver_name)
        if self.solver_name == "cvode":
            facts["tolerance"] = f"{self.tolerance:g}"
        if self.max_step is not None:
            facts["max_step"] = f"{self.max_step:g}"
        return facts
