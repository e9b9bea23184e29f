"""An SSP's experiment: start and stop time, master, and the macro step with where it comes from.

SSP has no step size. The macro step is the first given of (`--set simulation.macro_step` comes
before all, in `cosim.ssp.run`): navcosim's annotation on the DefaultExperiment,
`<ssc:Annotation type="org.navcosim.simulation"><nc:Simulation macroStep="0.01" master="jacobi"/>`
(which also names the master); the Open Simulation Platform's there, `<ssc:Annotation
type="com.opensimulationplatform"><osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="0.01"/>`
(libcosim's); the OpenModelica one on the root system, `<ssc:Annotation type="org.openmodelica">
<oms:Annotations><oms:SimulationInformation><oms:FixedStepMaster stepSize="0.01"/>` (OMSimulator's;
matched by local names, as its namespace has changed between versions); else the smallest
`stepSize` of the FMUs' own DefaultExperiment.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from cosim.errors import CosimError
from cosim.ssp.schema import annotations_of, local_name, number, tag

SIMULATION_ANNOTATION = "org.navcosim.simulation"
OSP_ANNOTATION = "com.opensimulationplatform"
OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
OMS_ANNOTATION = "org.openmodelica"
NAVCOSIM_STEP = "navcosim annotation nc:Simulation macroStep"


def read_experiment(root: ET.Element, components, where: str):
    """(start [s], stop [s] or None, macro step [s] or None, master or None, where the step comes
    from or "") of the SSD `root`; `components` have `default_step` and `member` (`SspComponent`)."""
    experiment = root.find(tag("ssd:DefaultExperiment"))
    start, stop, step, master = _experiment(experiment, where)
    if step is not None:
        return start, stop, step, master, NAVCOSIM_STEP
    step, source = _foreign_step(experiment, root.find(tag("ssd:System")), components, where)
    return start, stop, step, master, source


def _experiment(element: ET.Element | None, where: str):
    if element is None:
        return 0.0, None, None, None
    start = float(element.get("startTime", 0.0))
    stop = float(element.get("stopTime")) if element.get("stopTime") is not None else None
    simulation = annotations_of(element).get(SIMULATION_ANNOTATION)
    macro_step = master = None
    if simulation is not None:
        if simulation.tag != tag("nc:Simulation"):
            raise CosimError(f"{where}: annotation {SIMULATION_ANNOTATION} must hold one nc:Simulation")
        macro_step = number(simulation, "macroStep", where) if simulation.get("macroStep") else None
        master = simulation.get("master")
    return start, stop, macro_step, master


def _foreign_step(experiment: ET.Element | None, system: ET.Element, components, where: str):
    """(macro step, where it comes from) from the OSP or OMS annotation, else the FMUs' own
    DefaultExperiment stepSize (the smallest); (None, "") when none gives one."""
    algorithm = annotations_of(experiment).get(OSP_ANNOTATION)
    if algorithm is not None:
        fixed = algorithm.find(f"{{{OSP_NS}}}FixedStepAlgorithm")
        if fixed is not None and fixed.get("baseStepSize") is not None:
            step = _positive(fixed, "baseStepSize", f"{where}: annotation {OSP_ANNOTATION}")
            return step, "OSP annotation osp:FixedStepAlgorithm baseStepSize"
    oms = annotations_of(system).get(OMS_ANNOTATION)  # oms:Annotations
    informations = (
        _children(oms, "SimulationInformation")
        if oms is not None and local_name(oms.tag) == "Annotations"
        else []
    )
    for information in informations:
        for master in _children(information, "FixedStepMaster"):
            if master.get("stepSize") is not None:
                step = _positive(master, "stepSize", f"{where}: annotation {OMS_ANNOTATION}")
                return step, "OMS annotation oms:FixedStepMaster stepSize"
    steps = [(c.default_step, c.member) for c in components if c.default_step is not None]
    if steps:
        step, member = min(steps)
        return step, f"smallest FMU DefaultExperiment stepSize, of {member}"
    return None, ""


def _children(element: ET.Element | None, local: str) -> list[ET.Element]:
    """The children of `element` with this local name, whatever their namespace."""
    return [child for child in (element if element is not None else ()) if local_name(child.tag) == local]


def _positive(element: ET.Element, attribute: str, where: str) -> float:
    value = number(element, attribute, where)
    if not (math.isfinite(value) and value > 0):
        raise CosimError(
            f"{where}: {local_name(element.tag)}.{attribute} must be a number > 0, got {value!r}"
        )
    return value


def fmu_default_step(model_description) -> float | None:
    """[s] the FMU's DefaultExperiment stepSize, None when it gives none (or not a positive number)."""
    experiment = getattr(model_description, "defaultExperiment", None)
    try:
        step = float(getattr(experiment, "stepSize", None))
    except (TypeError, ValueError):
        return None
    return step if math.isfinite(step) and step > 0 else None
