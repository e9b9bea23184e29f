"""The error base lives in `native.errors` and keeps the names users import it by: `planner`,
`planner.errors` and `cosim.errors` hand out the same class, the base of both packages' errors."""

from __future__ import annotations

import cosim.errors
import planner
import planner.errors
from native.errors import NavcosimError


def test_one_base_under_every_public_name():
    assert (
        planner.NavcosimError is planner.errors.NavcosimError is cosim.errors.NavcosimError is NavcosimError
    )
    for error in (planner.PlannerError, cosim.errors.CosimError, cosim.errors.SimulationEnded):
        assert issubclass(error, NavcosimError)
    assert planner.PlannerError is planner.errors.PlannerError
