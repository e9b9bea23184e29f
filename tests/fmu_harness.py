"""Test harness: a project FMU in either FMI version, driven by variable name through fmpy's own
FMU2Slave / FMU3Slave (not the orchestrator's component), with its log messages kept (to check that
an error names its variable). Not a test module.

`FmuInstance(name, fmi_version)` is instantiated only; `initialize(values)` sets up the experiment,
sets `values` in initialisation mode and leaves it (`exit=False`: stays, to watch the exit fail).
FMI 2.0 array elements are variables `ranges[1]`.. (`array_inputs` fills them), FMI 3.0 arrays are
set and read whole (`set(ranges=[...720 values])` is one fmi3SetFloat64 call).
"""

from __future__ import annotations

import atexit
import math
import shutil
import tempfile
from collections.abc import Iterable, Mapping, Sequence
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
from fmpy.fmi3 import FMU3Slave

from cosim.fmi import builtin as fmus

NAMES = fmus.known_names()
ERROR = 3  # fmi2Error / fmi3Error: a logged message of this status or worse is an error
_REALS, _INTEGERS = ("Real", "Float64"), ("Integer", "Int32")


@cache
def fmu_path(name: str, fmi_version: int = 2) -> Path:
    """The built project FMU `name` of `fmi_version` (`cosim.builtin_fmu`)."""
    return fmus.builtin_fmu(name, fmi_version)


@cache
def unpacked(name: str, fmi_version: int = 2) -> tuple[str, object]:
    """(unzip directory, model description) of a project FMU, once per test session."""
    path = fmu_path(name, fmi_version)
    directory = tempfile.mkdtemp(prefix=f"navcosim-test-{name}-")
    atexit.register(shutil.rmtree, directory, ignore_errors=True)
    extract(str(path), directory)
    return directory, read_model_description(str(path))


class FmuInstance:
    """One instance of project FMU `name` in FMI `fmi_version` (2 or 3), addressed by variable name.
    `messages` are the texts it logged, `statuses` their FMI statuses; `fmu` is fmpy's instance."""

    def __init__(self, name: str, fmi_version: int = 2, instance_name: str = "test") -> None:
        directory, description = unpacked(name, fmi_version)
        self.fmi_version = fmi_version
        self.description = description
        self.variables = {v.name: v for v in description.modelVariables}
        self.messages: list[str] = []
        self.statuses: list[int] = []
        self.time = 0.0
        identifier = description.coSimulation.modelIdentifier
        if fmi_version == 2:
            self._callbacks = fmi2CallbackFunctions()  # kept alive as long as the instance
            self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log2)
            self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            self.fmu = FMU2Slave(
                guid=description.guid,
                unzipDirectory=directory,
                modelIdentifier=identifier,
                instanceName=instance_name,
            )
            self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        else:
            self.fmu = FMU3Slave(
                guid=description.instantiationToken,
                unzipDirectory=directory,
                modelIdentifier=identifier,
                instanceName=instance_name,
            )
            self.fmu.instantiate(loggingOn=True, logMessage=self._log3)

    def _log2(self, environment, instance_name, status, category, message) -> None:
        self.statuses.append(status)
        self.messages.append(message.decode("utf-8", "replace"))

    def _log3(self, environment, status, category, message) -> None:
        self.statuses.append(status)
        self.messages.append(message.decode("utf-8", "replace"))

    def errors(self) -> str:
        """The messages logged as errors (or worse), joined."""
        return " | ".join(
            text for status, text in zip(self.statuses, self.messages, strict=True) if status >= ERROR
        )

    def value_reference(self, name: str) -> int:
        if name not in self.variables:
            raise KeyError(f"{self.description.modelName} has no variable {name!r}")
        return self.variables[name].valueReference

    def size(self, name: str) -> int:
        """Values of variable `name`: an FMI 3.0 array's element count, else 1."""
        dimensions = getattr(self.variables[name], "dimensions", None) or []
        return math.prod(int(d.start) for d in dimensions) if dimensions else 1

    def initialize(self, values: Mapping | None = None, /, *, exit: bool = True, **named) -> FmuInstance:
        """Set up the experiment at t = 0, enter initialisation mode, set `values` (and `named`),
        leave it unless `exit` is False. Returns the instance."""
        if self.fmi_version == 2:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=0.0)
        self.set(values, **named)
        if exit:
            self.exit_initialization()
        return self

    def exit_initialization(self) -> None:
        self.fmu.exitInitializationMode()

    def set(self, values: Mapping | None = None, /, **named) -> None:
        """Set variables by name, one call per type; an FMI 3.0 array takes a sequence of all its values."""
        groups: dict[str, tuple[list[int], list]] = {
            "real": ([], []),
            "integer": ([], []),
            "boolean": ([], []),
        }
        for name, value in {**(values or {}), **named}.items():
            reference, kind = self.value_reference(name), self.variables[name].type
            group = "real" if kind in _REALS else "integer" if kind in _INTEGERS else "boolean"
            references, given = groups[group]
            references.append(reference)
            given.extend(np.ravel(value) if isinstance(value, Sequence | np.ndarray) else [value])
        setters = (
            {"real": self.fmu.setReal, "integer": self.fmu.setInteger, "boolean": self.fmu.setBoolean}
            if self.fmi_version == 2
            else {"real": self.fmu.setFloat64, "integer": self.fmu.setInt32, "boolean": self.fmu.setBoolean}
        )
        convert = {"real": float, "integer": int, "boolean": bool}
        for group, (references, given) in groups.items():
            if references:
                setters[group](references, [convert[group](v) for v in given])

    def set_array(self, name: str, values) -> None:
        """Set every element of array `name` (1-D or 2-D, row-major) in one call: in FMI 3.0 the
        array variable, in FMI 2.0 its scalars `name[i]` / `name[i,j]`."""
        array = np.asarray(values, dtype=float)
        if self.fmi_version == 3:
            self.fmu.setFloat64([self.value_reference(name)], list(array.ravel()))
            return
        names = [f"{name}[{','.join(str(i + 1) for i in index)}]" for index in np.ndindex(array.shape)]
        self.fmu.setReal([self.value_reference(n) for n in names], list(array.ravel()))

    def values(self, *names: str) -> list:
        """Every value of each variable of `names`, in order (all elements of an FMI 3.0 array)."""
        found = []
        for name in names:
            variable, count = self.variables[name], self.size(name)
            kind, references = variable.type, [self.value_reference(name)]
            if self.fmi_version == 2:
                getter = (
                    self.fmu.getReal if kind in _REALS else self.fmu.getInteger if kind in _INTEGERS else None
                )
                found += list((getter or self.fmu.getBoolean)(references))
            else:
                getter = (
                    self.fmu.getFloat64
                    if kind in _REALS
                    else self.fmu.getInt32
                    if kind in _INTEGERS
                    else None
                )
                found += list((getter or self.fmu.getBoolean)(references, count))
        return found

    def get(self, name: str):
        """The value of scalar variable `name`; the list of values of an FMI 3.0 array."""
        found = self.values(name)
        return found if self.size(name) > 1 else found[0]

    def outputs(self) -> dict:
        """Every output by name (`get`)."""
        return {name: self.get(name) for name, v in self.variables.items() if v.causality == "output"}

    def step(self, step_size: float = 0.05) -> None:
        self.fmu.doStep(self.time, step_size)
        self.time += step_size

    def free(self) -> None:
        self.fmu.freeInstance()

    def close(self) -> None:
        """Terminate (where the state allows it) and free."""
        try:
            self.fmu.terminate()
        except FMICallException:
            pass  # an instance whose initialisation failed cannot terminate; it can still be freed
        self.free()

    def __enter__(self) -> FmuInstance:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def array_inputs(name: str, values: Iterable[float] | np.ndarray, capacity: int) -> dict[str, float]:
    """FMI 2.0 array inputs `name[1]`..`name[capacity]` (or `name[k,j]` for a 2-D array), NaN-padded."""
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


def copy_sources(source_root: Path, destination: Path) -> Path:
    """A copy of the FMU sources (build script, glue, models) to edit and build in a test."""
    shutil.copytree(source_root, destination, ignore=shutil.ignore_patterns("__pycache__"))
    return destination
