"""Test helper: the project FMUs in either FMI version, driven by variable name through fmpy's own
FMU2Slave / FMU3Slave (not the orchestrator's component), with their log messages kept.

FMI 3.0 arrays are set and read whole: `set(ranges=[...720 values])` is one fmi3SetFloat64 call.
Not a test module.
"""

from __future__ import annotations

import atexit
import math
import shutil
from collections.abc import Sequence
from functools import cache
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.fmi3 import FMU3Slave

from cosim.fmi import builtin as fmus

NAMES = fmus.known_names()


@cache
def fmu_path(name: str, fmi_version: int) -> Path:
    """The built project FMU `name` of `fmi_version` (`cosim.builtin_fmu`)."""
    return fmus.builtin_fmu(name, fmi_version)


@cache
def _unpacked(name: str, fmi_version: int) -> tuple[str, object]:
    path = fmu_path(name, fmi_version)
    directory = extract(str(path))
    atexit.register(shutil.rmtree, directory, ignore_errors=True)
    return directory, read_model_description(str(path))


class Slave:
    """One instance of project FMU `name` in FMI `fmi_version` (2 or 3), addressed by variable name.
    FMI 2.0 array elements are `ranges[1]`.., FMI 3.0 arrays are `ranges` (a sequence of values)."""

    def __init__(self, name: str, fmi_version: int, instance_name: str = "test") -> None:
        directory, description = _unpacked(name, fmi_version)
        self.fmi_version = fmi_version
        self.description = description
        self.variables = {v.name: v for v in description.modelVariables}
        self.messages: list[str] = []
        self.time = 0.0
        if fmi_version == 2:
            self._logger = fmi2CallbackLoggerTYPE(self._log2)
            callbacks = fmi2CallbackFunctions()
            callbacks.logger = self._logger
            self._callbacks = callbacks
            self.fmu = FMU2Slave(
                guid=description.guid,
                unzipDirectory=directory,
                modelIdentifier=description.coSimulation.modelIdentifier,
                instanceName=instance_name,
            )
            self.fmu.instantiate(callbacks=callbacks)
        else:
            self.fmu = FMU3Slave(
                guid=description.instantiationToken,
                unzipDirectory=directory,
                modelIdentifier=description.coSimulation.modelIdentifier,
                instanceName=instance_name,
            )
            self.fmu.instantiate(logMessage=self._log3)

    def _log2(self, environment, instance, status, category, message) -> None:
        self.messages.append(message.decode("utf-8", "replace"))

    def _log3(self, environment, status, category, message) -> None:
        self.messages.append(message.decode("utf-8", "replace"))

    def size(self, name: str) -> int:
        dimensions = getattr(self.variables[name], "dimensions", None) or []
        return math.prod(int(d.start) for d in dimensions) if dimensions else 1

    def initialize(self, **values) -> None:
        if self.fmi_version == 2:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=0.0)
        self.set(**values)
        self.fmu.exitInitializationMode()

    def set(self, **values) -> None:
        """Set variables by name; an FMI 3.0 array takes a sequence of all its values."""
        for name, value in values.items():
            variable = self.variables[name]
            vr = [variable.valueReference]
            numbers = list(np.ravel(value)) if isinstance(value, Sequence | np.ndarray) else [value]
            kind = variable.type
            if kind in ("Real", "Float64"):
                (self.fmu.setReal if self.fmi_version == 2 else self.fmu.setFloat64)(
                    vr, [float(v) for v in numbers]
                )
            elif kind in ("Integer", "Int32"):
                (self.fmu.setInteger if self.fmi_version == 2 else self.fmu.setInt32)(
                    vr, [int(v) for v in numbers]
                )
            else:
                self.fmu.setBoolean(vr, [bool(v) for v in numbers])

    def set_array(self, name: str, values) -> None:
        """Set every element of array `name` (1-D or 2-D, row-major) in one call: in FMI 3.0 the
        array variable, in FMI 2.0 its scalars `name[i]` / `name[i,j]`."""
        array = np.asarray(values, dtype=float)
        if self.fmi_version == 3:
            self.fmu.setFloat64([self.variables[name].valueReference], list(array.ravel()))
            return
        indices = np.ndindex(array.shape)
        names = [f"{name}[{','.join(str(i + 1) for i in index)}]" for index in indices]
        self.fmu.setReal([self.variables[n].valueReference for n in names], list(array.ravel()))

    def get(self, name: str) -> list:
        """All values of variable `name` (one for a scalar, every element of an FMI 3.0 array)."""
        variable = self.variables[name]
        vr, n = [variable.valueReference], self.size(name)
        kind = variable.type
        if self.fmi_version == 2:
            getter = {
                "Real": self.fmu.getReal,
                "Integer": self.fmu.getInteger,
                "Boolean": self.fmu.getBoolean,
            }
            return list(getter[kind](vr))
        getter = {"Float64": self.fmu.getFloat64, "Int32": self.fmu.getInt32, "Boolean": self.fmu.getBoolean}
        return list(getter[kind](vr, n))

    def outputs(self) -> dict[str, list]:
        return {name: self.get(name) for name, v in self.variables.items() if v.causality == "output"}

    def step(self, step_size: float = 0.05) -> None:
        self.fmu.doStep(self.time, step_size)
        self.time += step_size

    def free(self) -> None:
        self.fmu.freeInstance()
