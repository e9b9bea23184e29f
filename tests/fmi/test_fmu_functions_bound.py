"""fmpy's instances bind every FMI function of their library (argument names and types, result type)
from the signatures of its Python wrappers; `functions_bound_once` reads them once per class and
model identifier. Truth: fmpy's own class on the same library, for FMI 2.0 and 3.0, co-simulation
and Model Exchange (a bouncing ball), and a second, third instance as the first."""

from __future__ import annotations

import pytest
from fixtures.conftest_helpers import fixture_fmu
from fmpy import extract
from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.fmi3 import FMU3Model, FMU3Slave

from cosim.fmi.builtin import builtin_fmu
from cosim.fmi.component import functions_bound_once
from cosim.fmi.description import checked_description, file_key


def _bindings(instance) -> dict:
    return {
        name: (f.__name__, list(f.argnames), tuple(f.argtypes or ()), f.restype)
        for name, f in instance._functions.items()
    }


@pytest.mark.parametrize(
    ("version", "fmpy_class"), [(2, FMU2Slave), (2, FMU2Model), (3, FMU3Slave), (3, FMU3Model)]
)
def test_every_instance_binds_the_functions_as_fmpy_does(tmp_path, version, fmpy_class):
    slave = "Slave" in fmpy_class.__name__
    path = (
        builtin_fmu("DifferentialDrive", version) if slave else fixture_fmu(f"bouncing_ball_me_fmi{version}")
    )
    description = checked_description(path, None, file_key(path, None)).model_description
    interface = description.coSimulation if slave else description.modelExchange
    folder = extract(str(path), unzipdir=str(tmp_path / "unpacked"))
    guid = description.guid if version < 3 else description.instantiationToken
    arguments = {"guid": guid, "unzipDirectory": folder, "modelIdentifier": interface.modelIdentifier}
    truth = _bindings(fmpy_class(**arguments))
    bound = functions_bound_once(fmpy_class)
    assert bound.__name__ == fmpy_class.__name__ and issubclass(bound, fmpy_class)
    made = [bound(instanceName=f"i{n}", **arguments) for n in range(3)]
    assert len(truth) > 20
    for instance in made:
        assert _bindings(instance) == truth
