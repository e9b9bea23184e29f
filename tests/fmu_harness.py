"""Test helper: run a project FMU through fmpy with its log messages captured."""

from __future__ import annotations

import shutil
from functools import cache
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

from cosim.fmi.builtin import builtin_fmu


@cache
def unpacked(name: str) -> tuple[str, object]:
    """(unzip directory, model description) of a project FMU, shared by the whole test session."""
    path = builtin_fmu(name)
    return extract(str(path)), read_model_description(str(path))


class Instance:
    """One FMU instance; `messages` collects (status, category, text) of every log call."""

    def __init__(self, name: str, instance_name: str = "instance", unzip_dir: str | None = None):
        directory, description = unpacked(name)
        self.description = description
        self.vr = {v.name: v.valueReference for v in description.modelVariables}
        self.messages: list[tuple[int, str, str]] = []

        def log(environment, instance, status, category, message):
            self.messages.append((status, category.decode(), message.decode()))

        self._logger = fmi2CallbackLoggerTYPE(log)  # kept alive as long as the instance
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = self._logger
        self.slave = FMU2Slave(
            guid=description.guid,
            unzipDirectory=unzip_dir or directory,
            modelIdentifier=description.coSimulation.modelIdentifier,
            instanceName=instance_name,
        )
        self.slave.instantiate(callbacks=self._callbacks)

    def set(self, **values: float | int) -> None:
        """Set variables by name; Integer variables take ints."""
        for name, value in values.items():
            if isinstance(value, int) and not isinstance(value, bool):
                self.slave.setInteger([self.vr[name]], [value])
            else:
                self.slave.setReal([self.vr[name]], [float(value)])

    def initialize(self, **parameters: float | int) -> None:
        self.slave.setupExperiment(startTime=0.0)
        self.set(**parameters)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()

    def get(self, *names: str) -> list[float]:
        return self.slave.getReal([self.vr[n] for n in names])

    def errors(self) -> str:
        return " | ".join(text for status, _, text in self.messages if status >= 3)

    def free(self) -> None:
        self.slave.freeInstance()


def copy_sources(source_root: Path, destination: Path) -> Path:
    """A copy of the FMU sources (build script, glue, models) to edit and build in a test."""
    shutil.copytree(source_root, destination, ignore=shutil.ignore_patterns("__pycache__"))
    return destination
