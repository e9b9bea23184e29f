"""Integrators of a Model Exchange FMU's continuous states between events: CVode, RK4, Euler.

A solver integrates dx/dt = f(t, x) from its current time to `t_end` and stops early at the first
state event: an event indicator z_i that crosses zero (from > 0 to <= 0 or from < 0 to >= 0; an
indicator that starts at exactly 0 does not trigger until it has left 0, as in CVode). It talks to
the model through three callbacks on NumPy arrays:

    derivatives(t, x, dx)   fill dx with f(t, x)
    indicators(t, x, z)     fill z with the event indicators at (t, x)
    completed(t, x) -> bool called after each accepted step; True: the model asks for an event
                            (a step event: fmi*CompletedIntegratorStep's enterEventMode)

`advance(t_end) -> (t, event)` leaves the state at `solver.x` and returns the time reached and
whether it stopped for an event (state or step event); `reset(t, x)` restarts it after the model
changed (an event, a new input value).

`FixedStep` (`euler`: x + h f, order 1; `rk4`: the classic fourth-order Runge-Kutta) takes equal
substeps of at most `max_step` over each call and locates a state event by bisection on the
substep's length, to `EVENT_RESOLUTION` (relative to t): the step stops just after the crossing.
`CVodeSolver` runs SUNDIALS CVode (BDF, dense Newton) from fmpy's own build (fmpy.sundials), with
relative tolerance `tolerance`, absolute tolerance `tolerance` x the states' nominal values, its
own root finding for the indicators, and a stop time at `t_end` (it never integrates past it).
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable

import numpy as np

from cosim.errors import CosimError

SOLVERS = ("cvode", "rk4", "euler")
EVENT_RESOLUTION = 1e-12  # [s per s of t] width of the bracket a fixed-step solver locates events to
_MAX_BISECTIONS = 100


def crossed(before: np.ndarray, after: np.ndarray) -> bool:
    """Whether any indicator went from > 0 to <= 0 or from < 0 to >= 0."""
    return bool(np.any(((before > 0) & (after <= 0)) | ((before < 0) & (after >= 0))))


class FixedStep:
    """Euler or RK4 with substeps of at most `max_step` [s] (see the module docstring)."""

    def __init__(self, method: str, nx: int, nz: int, derivatives, indicators, completed, max_step: float):
        self.method, self.max_step = method, float(max_step)
        self.derivatives, self.indicators, self.completed = derivatives, indicators, completed
        self.x = np.zeros(nx)
        self.z, self.z_new = np.zeros(nz), np.zeros(nz)
        self._k = [np.zeros(nx) for _ in range(4)]
        self._trial = np.zeros(nx)
        self.t = 0.0

    def reset(self, t: float, x: np.ndarray) -> None:
        self.t = float(t)
        self.x[:] = x
        if len(self.z):
            self.indicators(self.t, self.x, self.z)

    def _step(self, t: float, x: np.ndarray, h: float, out: np.ndarray) -> None:
        k1, k2, k3, k4 = self._k
        self.derivatives(t, x, k1)
        if self.method == "euler":
            np.add(x, h * k1, out=out)
            return
        self.derivatives(t + h / 2, x + h / 2 * k1, k2)
        self.derivatives(t + h / 2, x + h / 2 * k2, k3)
        self.derivatives(t + h, x + h * k3, k4)
        np.add(x, h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), out=out)

    def advance(self, t_end: float) -> tuple[float, bool]:
        span = t_end - self.t
        if span <= 0:
            return self.t, False
        substeps = max(1, math.ceil(span / self.max_step * (1 - 1e-12)))
        start = self.t
        for k in range(1, substeps + 1):
            t0 = self.t
            t1 = t_end if k == substeps else start + span * k / substeps
            self._step(t0, self.x, t1 - t0, self._trial)
            event = False
            if len(self.z):
                self.indicators(t1, self._trial, self.z_new)
                if crossed(self.z, self.z_new):
                    t1 = self._locate(t0, t1)
                    event = True
            self.t = t1
            self.x[:] = self._trial
            if len(self.z):
                self.indicators(self.t, self.x, self.z)
            if self.completed(self.t, self.x) or event:
                return self.t, True
        return self.t, False

    def _locate(self, t0: float, t1: float) -> float:
        """The end of the shortest step from (t0, x) after which an indicator has crossed; the
        step's state is left in `_trial`."""
        x0 = self.x.copy()
        low, high = 0.0, t1 - t0  # no crossing after `low`; a crossing after `high`
        resolution = EVENT_RESOLUTION * max(1.0, abs(t1))
        for _ in range(_MAX_BISECTIONS):
            if high - low <= resolution:
                break
            middle = (low + high) / 2
            self._step(t0, x0, middle, self._trial)
            self.indicators(t0 + middle, self._trial, self.z_new)
            if crossed(self.z, self.z_new):
                high = middle
            else:
                low = middle
        self._step(t0, x0, high, self._trial)
        return t0 + high


class CVodeSolver:
    """SUNDIALS CVode from fmpy's build (see the module docstring). `nominals`: the states' nominal
    values (absolute tolerance = tolerance x nominal); `max_step` [s], inf for no limit."""

    def __init__(
        self,
        nx: int,
        nz: int,
        derivatives: Callable,
        indicators: Callable,
        completed: Callable,
        tolerance: float,
        max_step: float,
        nominals: np.ndarray,
    ):
        from fmpy import sundials as sd

        self._sd = sd
        self.derivatives, self.indicators, self.completed = derivatives, indicators, completed
        # CVode needs a state: a model without one integrates a dummy (its events still happen).
        self.nx, self.nz, self._dummy = max(nx, 1), nz, nx == 0
        self.tolerance = float(tolerance)
        self._context = sd.SUNContext()
        self._check(sd.SUNContext_Create(sd.SUN_COMM_NULL, ctypes.byref(self._context)), "SUNContext_Create")
        self._vector = sd.N_VNew_Serial(self.nx, self._context)
        self._abstol = sd.N_VNew_Serial(self.nx, self._context)
        self.x = np.ctypeslib.as_array(sd.NV_DATA_S(self._vector), (self.nx,))
        self._abstol_values = np.ctypeslib.as_array(sd.NV_DATA_S(self._abstol), (self.nx,))
        self._abstol_values[:] = self.tolerance * (np.abs(nominals) if nx else 1.0)
        self._memory = sd.CVodeCreate(sd.CV_BDF, self._context)
        self._message = ""
        # Kept as attributes: CVode holds the C pointers of these Python callbacks.
        self._rhs = sd.CVRhsFn(self._rhs_callback)
        self._roots = sd.CVRootFn(self._root_callback)
        self._errors = sd.SUNErrHandlerFn(self._error_callback)
        self._check(
            sd.SUNContext_PushErrHandler(self._context, self._errors, None), "SUNContext_PushErrHandler"
        )
        self._check(sd.CVodeInit(self._memory, self._rhs, 0.0, self._vector), "CVodeInit")
        self._check(sd.CVodeSVtolerances(self._memory, self.tolerance, self._abstol), "CVodeSVtolerances")
        if nz:
            self._check(sd.CVodeRootInit(self._memory, nz, self._roots), "CVodeRootInit")
            self._check(sd.CVodeSetNoInactiveRootWarn(self._memory), "CVodeSetNoInactiveRootWarn")
        self._matrix = sd.SUNDenseMatrix(self.nx, self.nx, self._context)
        self._linear = sd.SUNLinSol_Dense(self._vector, self._matrix, self._context)
        self._check(sd.CVodeSetLinearSolver(self._memory, self._linear, self._matrix), "CVodeSetLinearSolver")
        if math.isfinite(max_step):
            self._check(sd.CVodeSetMaxStep(self._memory, float(max_step)), "CVodeSetMaxStep")
        self._check(sd.CVodeSetMaxNumSteps(self._memory, 100_000), "CVodeSetMaxNumSteps")
        library = sd.libraries.sundials_cvode
        self._set_stop_time = library.CVodeSetStopTime
        self._set_stop_time.argtypes = [ctypes.c_void_p, ctypes.c_double]
        self._t_returned = ctypes.c_double()
        self._root_info = np.zeros(max(nz, 1), dtype=np.int32)
        self.t = 0.0

    def _check(self, flag: int, function: str) -> None:
        if flag < 0:
            detail = f": {self._message}" if self._message else ""
            raise CosimError(f"CVode: {function} failed (flag {flag}){detail}")

    def _error_callback(self, line, function, file, message, code, user_data, context) -> None:
        self._message = " ".join((message or b"").decode(errors="replace").split())

    def _rhs_callback(self, t, y, ydot, user_data) -> int:
        sd = self._sd
        dx = np.ctypeslib.as_array(sd.NV_DATA_S(ydot), (self.nx,))
        if self._dummy:
            dx[:] = 0.0
            return 0
        try:
            self.derivatives(t, np.ctypeslib.as_array(sd.NV_DATA_S(y), (self.nx,)), dx)
        except CosimError as error:
            self._failure = error
            return -1  # an unrecoverable error: CVode returns it
        return 0

    def _root_callback(self, t, y, gout, user_data) -> int:
        z = np.ctypeslib.as_array(gout, (self.nz,))
        try:
            self.indicators(t, np.ctypeslib.as_array(self._sd.NV_DATA_S(y), (self.nx,)), z)
        except CosimError as error:
            self._failure = error
            return -1
        return 0

    def reset(self, t: float, x: np.ndarray) -> None:
        self.t = float(t)
        if not self._dummy:
            self.x[:] = x
        self._check(self._sd.CVodeReInit(self._memory, self.t, self._vector), "CVodeReInit")

    def advance(self, t_end: float) -> tuple[float, bool]:
        if t_end <= self.t:
            return self.t, False
        sd = self._sd
        self._failure = None
        self._check(self._set_stop_time(self._memory, t_end), "CVodeSetStopTime")
        flag = sd.CVode(self._memory, t_end, self._vector, ctypes.byref(self._t_returned), sd.CV_NORMAL)
        if self._failure is not None:
            raise self._failure
        self._check(flag, "CVode")
        self.t = self._t_returned.value if flag == sd.CV_ROOT_RETURN else t_end
        state = self.x if not self._dummy else np.zeros(0)
        step_event = self.completed(self.t, state)
        return self.t, flag == sd.CV_ROOT_RETURN or step_event

    def free(self) -> None:
        sd = self._sd
        if self._memory is not None:
            sd.CVodeFree(ctypes.byref(ctypes.c_void_p(self._memory)))
            self._memory = None
            for name, handle in (("SUNLinSolFree", self._linear), ("SUNMatDestroy", self._matrix)):
                function = getattr(sd.libraries.sundials_core, name)
                function.argtypes = [ctypes.c_void_p]
                function(handle)
            destroy = sd.libraries.sundials_nvecserial.N_VDestroy_Serial
            destroy.argtypes = [ctypes.c_void_p]
            destroy(self._vector)
            destroy(self._abstol)


def make_solver(name: str, nx: int, nz: int, callbacks: tuple, tolerance: float, max_step: float, nominals):
    """The solver `name` ("cvode", "rk4", "euler") over `callbacks` (derivatives, indicators,
    completed); `max_step` [s] bounds each step (a fixed-step solver's substep)."""
    if name == "cvode":
        return CVodeSolver(nx, nz, *callbacks, tolerance=tolerance, max_step=max_step, nominals=nominals)
    if name in ("rk4", "euler"):
        return FixedStep(name, nx, nz, *callbacks, max_step=max_step)
    raise CosimError(f"unknown solver '{name}'; solvers: {', '.join(SOLVERS)}")
