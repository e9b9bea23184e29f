"""Per-step cost of each project FMU: through fmpy's methods and through preallocated ctypes buffers;
then VFH's 720-beam scan exchanged as FMI 3.0 arrays against FMI 2.0 scalars.

One step = set the per-step inputs, fmi2DoStep, get every Real output (as the orchestrator does).
PurePursuit's waypoints are set once (a plan), not every step; VFH gets a 720-beam scan every step.
The FMI 3.0 comparison sets the same 1441 values (ranges, angles, target_dir) with one
fmi3SetFloat64 of 3 value references instead of one fmi2SetReal of 1441, same model, same steps.

    python3 benchmarks/bench_fmus.py [--steps N]
"""

from __future__ import annotations

import argparse
import ctypes
import math
import time

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from cosim.fmi.builtin import builtin_fmu, known_names

BEAMS = 720
REPEATS = 5  # best of several runs; CPU time of this process, so other load does not count
SCALAR_INPUTS = {"v": 1.0, "v_in": 1.0, "omega": 0.2, "omega_in": 0.2, "x": 9.9, "target_dir": 0.3}


def _inputs(description) -> tuple[dict[int, float], dict[int, float]]:
    """(values set once, values set every step) by value reference: a plausible robot situation."""
    once, every_step = {}, {}
    angles = np.linspace(-math.pi, math.pi, BEAMS, endpoint=False)
    ranges = 1.2 + 0.6 * np.sin(3 * angles)  # an uneven room, partly inside the distance limits
    for variable in description.modelVariables:
        if variable.causality != "input" or variable.type != "Real":
            continue
        name, vr = variable.name, variable.valueReference
        if name.startswith("waypoints["):
            row, column = (int(i) for i in name[len("waypoints[") : -1].split(","))
            if row <= 200:  # a 200-point arc, the rest stays NaN padding
                once[vr] = 10 * math.cos(row / 100) if column == 1 else 10 * math.sin(row / 100)
        elif name.startswith("ranges["):
            every_step[vr] = float(ranges[int(name[7:-1]) - 1])
        elif name.startswith("angles["):
            every_step[vr] = float(angles[int(name[7:-1]) - 1])
        else:
            every_step[vr] = {
                "v": 1.0,
                "v_in": 1.0,
                "omega": 0.2,
                "omega_in": 0.2,
                "x": 9.9,
                "target_dir": 0.3,
            }.get(name, 0.1)
    return once, every_step


def _slave(name: str):
    path = builtin_fmu(name)
    description = read_model_description(str(path))
    slave = FMU2Slave(
        guid=description.guid,
        unzipDirectory=extract(str(path)),
        modelIdentifier=description.coSimulation.modelIdentifier,
        instanceName=name,
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    once, every_step = _inputs(description)
    if once:
        slave.setReal(list(once), list(once.values()))
    slave.exitInitializationMode()
    outputs = [
        v.valueReference for v in description.modelVariables if v.causality == "output" and v.type == "Real"
    ]
    return slave, every_step, outputs


def bench_methods(name: str, steps: int) -> float:
    """µs per step through fmpy's setReal/doStep/getReal (new ctypes arrays every call)."""
    slave, inputs, outputs = _slave(name)
    input_vrs, input_values = list(inputs), list(inputs.values())
    h, best, k = 0.01, math.inf, 0
    for _ in range(REPEATS):
        start = time.process_time()
        for _ in range(steps):
            slave.setReal(input_vrs, input_values)
            slave.doStep(k * h, h)
            slave.getReal(outputs)
            k += 1
        best = min(best, time.process_time() - start)
    slave.terminate()
    slave.freeInstance()
    return best / steps * 1e6


def bench_raw(name: str, steps: int) -> tuple[float, float]:
    """(µs per step, µs per doStep alone) through the raw functions and preallocated buffers."""
    slave, inputs, outputs = _slave(name)
    set_real, get_real, do_step = slave.dll.fmi2SetReal, slave.dll.fmi2GetReal, slave.dll.fmi2DoStep
    for function in (set_real, get_real):
        function.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p]
    do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    input_vrs = (ctypes.c_uint * len(inputs))(*inputs)
    input_values = (ctypes.c_double * len(inputs))(*inputs.values())
    output_vrs = (ctypes.c_uint * len(outputs))(*outputs)
    output_values = (ctypes.c_double * len(outputs))()
    component, h = slave.component, 0.01
    n_in, n_out = len(inputs), len(outputs)
    total = step_only = math.inf
    k = 0
    for _ in range(REPEATS):
        start = time.process_time()
        for _ in range(steps):
            set_real(component, input_vrs, n_in, input_values)
            do_step(component, k * h, h, 1)
            get_real(component, output_vrs, n_out, output_values)
            k += 1
        total = min(total, time.process_time() - start)
        start = time.process_time()
        for _ in range(steps):
            do_step(component, k * h, h, 1)
            k += 1
        step_only = min(step_only, time.process_time() - start)
    slave.terminate()
    slave.freeInstance()
    return total / steps * 1e6, step_only / steps * 1e6


def _vfh_slaves():
    """The FMI 2.0 and FMI 3.0 builds of VectorFieldHistogram, initialised, with their per-step
    value references: (slave, input references, output references) each."""
    scan_angles = np.linspace(-math.pi, math.pi, BEAMS, endpoint=False)
    slaves = {}
    for version in (2, 3):
        path = builtin_fmu("VectorFieldHistogram", version)
        description = read_model_description(str(path))
        vr = {v.name: v.valueReference for v in description.modelVariables}
        kind = FMU2Slave if version == 2 else FMU3Slave
        slave = kind(
            guid=description.guid,
            unzipDirectory=extract(str(path)),
            modelIdentifier="VectorFieldHistogram",
            instanceName=f"vfh{version}",
        )
        slave.instantiate()
        if version == 2:
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
            inputs = [vr[f"ranges[{k}]"] for k in range(1, BEAMS + 1)]
            inputs += [vr[f"angles[{k}]"] for k in range(1, BEAMS + 1)] + [vr["target_dir"]]
        else:
            slave.enterInitializationMode(startTime=0.0)
            inputs = [vr["ranges"], vr["angles"], vr["target_dir"]]
        slave.exitInitializationMode()
        slaves[version] = (slave, inputs, [vr["steering_dir"]])
    values = np.concatenate([1.2 + 0.6 * np.sin(3 * scan_angles), scan_angles, [0.3]])
    return slaves, values


def bench_vfh_fmi3_against_fmi2(steps: int) -> dict[str, tuple[float, float, float]]:
    """µs per step for FMI 2.0 and 3.0: (set inputs alone, doStep alone, set + doStep + get), raw
    C calls with pointer arguments passed as addresses."""
    slaves, values = _vfh_slaves()
    results = {}
    for version, (slave, inputs, outputs) in slaves.items():
        prefix = f"fmi{version}"
        real = "Real" if version == 2 else "Float64"
        set_values = getattr(slave.dll, f"{prefix}Set{real}")
        get_values = getattr(slave.dll, f"{prefix}Get{real}")
        do_step = getattr(slave.dll, f"{prefix}DoStep")
        extra = [] if version == 2 else [ctypes.c_size_t]
        for function in (set_values, get_values):
            function.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, *extra]
        input_vrs = (ctypes.c_uint32 * len(inputs))(*inputs)
        input_values = (ctypes.c_double * len(values))(*values)
        output_vrs = (ctypes.c_uint32 * len(outputs))(*outputs)
        output_values = (ctypes.c_double * len(outputs))()
        counts = [] if version == 2 else [len(values)]
        out_counts = [] if version == 2 else [len(outputs)]
        if version == 2:
            do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
            step_args = [1]
        else:
            do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_bool]
            do_step.argtypes += [ctypes.c_void_p] * 4  # eventHandlingNeeded, terminate, earlyReturn, time
            flags, last = (ctypes.c_bool * 3)(), ctypes.c_double()
            first = ctypes.addressof(flags)
            step_args = [True, first, first + 1, first + 2, ctypes.addressof(last)]
        component, h, k = slave.component, 0.05, 0
        set_only = step_only = total = math.inf
        for _ in range(REPEATS):
            start = time.process_time()
            for _ in range(steps):
                set_values(component, input_vrs, len(inputs), input_values, *counts)
            set_only = min(set_only, time.process_time() - start)
            start = time.process_time()
            for _ in range(steps):
                do_step(component, k * h, h, *step_args)
                k += 1
            step_only = min(step_only, time.process_time() - start)
            start = time.process_time()
            for _ in range(steps):
                set_values(component, input_vrs, len(inputs), input_values, *counts)
                do_step(component, k * h, h, *step_args)
                get_values(component, output_vrs, len(outputs), output_values, *out_counts)
                k += 1
            total = min(total, time.process_time() - start)
        results[prefix] = (set_only / steps * 1e6, step_only / steps * 1e6, total / steps * 1e6)
        slave.terminate()
        slave.freeInstance()
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="steps per measurement (default 2000)")
    args = parser.parse_args()
    header = f"{'FMU':<22}{'inputs/step':>12}{'fmpy methods':>16}{'raw ctypes':>14}{'doStep only':>14}"
    print(header + f"   [CPU µs per step, best of {REPEATS}]")
    for name in known_names():
        _, inputs, _ = _slave(name)
        methods = bench_methods(name, args.steps)
        raw, step_only = bench_raw(name, args.steps)
        print(f"{name:<22}{len(inputs):>12}{methods:>16.2f}{raw:>14.2f}{step_only:>14.2f}")
    results = bench_vfh_fmi3_against_fmi2(args.steps)
    print(
        f"\nVectorFieldHistogram, {2 * BEAMS + 1} input values a step   [CPU µs per step, best of {REPEATS}]"
    )
    print(f"{'interface':<34}{'set inputs':>12}{'doStep only':>13}{'set+step+get':>14}")
    rows = [
        ("FMI 2.0: 1441 scalar references", results["fmi2"]),
        ("FMI 3.0: 3 array references", results["fmi3"]),
    ]
    ratios = tuple(a / b for a, b in zip(results["fmi3"], results["fmi2"], strict=True))
    rows.append(("ratio FMI 3.0 / FMI 2.0", ratios))
    for label, (set_inputs, step, whole) in rows:
        print(f"{label:<34}{set_inputs:>12.2f}{step:>13.2f}{whole:>14.2f}")


if __name__ == "__main__":
    main()
