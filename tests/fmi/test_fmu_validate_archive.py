"""`cosim fmu validate` refuses what `cosim run` refuses in the archive itself: a zip bomb and a
zip slip are problems, not "valid"."""

from __future__ import annotations

import shutil
import zipfile

import pytest

from cosim.errors import CosimError
from cosim.fmi.builtin import builtin_fmu
from cosim.fmi.component import FmuComponent
from cosim.fmi.inspect import validate


def _with_member(tmp_path, name: str, data: bytes):
    fmu = tmp_path / "Vehicle.fmu"
    shutil.copy(builtin_fmu("DifferentialDrive"), fmu)
    with zipfile.ZipFile(fmu, "a", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr(name, data)
    return fmu


def test_a_valid_fmu_stays_valid():
    assert validate(builtin_fmu("DifferentialDrive")) == []


@pytest.mark.slow
def test_a_zip_bomb_is_a_problem_and_run_refuses_it_too(tmp_path):
    fmu = _with_member(tmp_path, "resources/zeros.bin", bytes(1100 * 2**20))  # deflates to ~1 MB
    problems = validate(fmu)
    assert len(problems) == 1 and "more than the default limit of 1,024 MiB" in problems[0]
    with pytest.raises(CosimError, match="would unpack to"):
        FmuComponent(fmu, "vehicle")


@pytest.mark.parametrize("name", ["../escaped.txt", "resources/../../escaped.txt", "/etc/escaped.txt"])
def test_a_member_outside_the_fmu_folder_is_a_problem(tmp_path, name):
    problems = validate(_with_member(tmp_path, name, b"x"))
    assert problems and "would be extracted outside the FMU's folder" in problems[0]
