"""Drive a project FMU by variable name in tests: instantiate, set parameters, initialise, step.

A thin layer over `fmpy.fmi2.FMU2Slave` that resolves names once, keeps the FMU's log messages
(to check that an error names its parameter) and offers preallocated raw ctypes calls for
timing. Not a test module.
"""

from __future__ import annotations

import atexit
import ctypes
import math
import shutil
import tempfile
import time
from collections.abc import Iterable, Mapping
from functools import cache
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    calloc,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    free,
)
from fmpy.logging import addLoggerProxy

from cosim.fmi.builtin import builtin_fmu

Value = float | int | bool


@cache
def _unpacked(name: str) -> tuple[Path, object]:
    """(unzip directory, model description) of a built project FMU, once per test session."""
    fmu = builtin_fmu(name)
    directory = Path(tempfile.mkdtemp(prefix=f"navcosim-test-{name}-"))
    atexit.register(shutil.rmtree, directory, ignore_errors=True)
    extract(str(fmu), str(directory))
    return directory, read_model_description(str(fmu))


class FmuInstance:
    """One instance of a project FMU, addressed by variable name.

    `parameters` are set before initialisation (with the inputs in `inputs`); `initialize=False`
    leaves the instance in initialisation mode so a test can watch exitInitializationMode fail.
    """

    def __init__(
        self,
        name: str,
        parameters: Mapping[str, Value] | None = None,
        inputs: Mapping[str, Value] | None = None,
        initialize: bool = True,
        instance_name: str = "test",
    ) -> None:
        directory, description = _unpacked(name)
        self.description = description
        self.variables = {v.name: v for v in description.modelVariables}
        self.messages: list[str] = []
        self.time = 0.0
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(ctypes.byref(self._callbacks))
        self.fmu = FMU2Slave(
            guid=description.guid,
            unzipDirectory=str(directory),
            modelIdentifier=description.coSimulation.modelIdentifier,
            instanceName=instance_name,
        )
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set({**(parameters or {}), **(inputs or {})})
        if initialize:
            self.fmu.exitInitializationMode()

    def _log(self, environment, instance_name, status, category, message) -> None:
        self.messages.append(message.decode("utf-8", "replace"))

    def exit_initialization(self) -> None:
        self.fmu.exitInitializationMode()

    def value_reference(self, name: str) -> int:
        if name not in self.variables:
            raise KeyError(f"{self.description.modelName} has no variable {name!r}")
        return self.variables[name].valueReference

    def set(self, values: Mapping[str, Value]) -> None:
        """Set variables by name, grouped by type into one call each."""
        groups: dict[str, tuple[list[int], list[Value]]] = {
            t: ([], []) for t in ("Real", "Integer", "Boolean")
        }
        for name, value in values.items():
            variable = self.variables.get(name)
            if variable is None:
                raise KeyError(f"{self.description.modelName} has no variable {name!r}")
            references, numbers = groups[variable.type]
            references.append(variable.valueReference)
            numbers.append(value)
        if groups["Real"][0]:
            self.fmu.setReal(groups["Real"][0], [float(v) for v in groups["Real"][1]])
        if groups["Integer"][0]:
            self.fmu.setInteger(groups["Integer"][0], [int(v) for v in groups["Integer"][1]])
        if groups["Boolean"][0]:
            self.fmu.setBoolean(groups["Boolean"][0], [bool(v) for v in groups["Boolean"][1]])

    def get(self, name: str) -> Value:
        variable = self.variables[name]
        getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger, "Boolean": self.fmu.getBoolean}
        return getter[variable.type]([variable.valueReference])[0]

    def outputs(self) -> dict[str, Value]:
        """Every output by name."""
        return {name: self.get(name) for name, v in self.variables.items() if v.causality == "output"}

    def step(self, step_size: float = 0.05) -> None:
        self.fmu.doStep(currentCommunicationPoint=self.time, communicationStepSize=step_size)
        self.time += step_size

    def close(self) -> None:
        try:
            self.fmu.terminate()
        except FMICallException:
            pass  # an instance whose initialisation failed cannot terminate; it can still be freed
        self.fmu.freeInstance()

    def __enter__(self) -> FmuInstance:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def time_raw_step(self, inputs: Mapping[str, Value], outputs: Iterable[str], repeats: int) -> float:
        """Seconds per (setReal of `inputs`, doStep, getReal of `outputs`) through the raw C functions
        with preallocated ctypes arrays, as an orchestrator would call them."""
        functions = self.fmu._functions
        set_real, do_step, get_real = (
            functions["fmi2SetReal"],
            functions["fmi2DoStep"],
            functions["fmi2GetReal"],
        )
        input_refs = (ctypes.c_uint * len(inputs))(*(self.value_reference(n) for n in inputs))
        input_values = (ctypes.c_double * len(inputs))(*(float(v) for v in inputs.values()))
        output_names = list(outputs)
        output_refs = (ctypes.c_uint * len(output_names))(*(self.value_reference(n) for n in output_names))
        output_values = (ctypes.c_double * len(output_names))()
        component = self.fmu.component
        start = time.perf_counter()
        for _ in range(repeats):
            set_real(component, input_refs, len(inputs), input_values)
            do_step(component, self.time, 0.05, 1)
            get_real(component, output_refs, len(output_names), output_values)
        return (time.perf_counter() - start) / repeats


def array_inputs(name: str, values: Iterable[float] | np.ndarray, capacity: int) -> dict[str, float]:
    """`name[1]`..`name[capacity]` (or `name[k,j]` for a 2-D array), NaN-padded."""
    array = np.asarray(values, dtype=float)
    result: dict[str, float] = {}
    if array.ndim <= 1:
        padded = np.full(capacity, math.nan)
        padded[: array.size] = array
        result.update({f"{name}[{k + 1}]": float(v) for k, v in enumerate(padded)})
    else:
        padded = np.full((capacity, array.shape[1]), math.nan)
        padded[: array.shape[0]] = array
        for k in range(capacity):
            for j in range(array.shape[1]):
                result[f"{name}[{k + 1},{j + 1}]"] = float(padded[k, j])
    return result
