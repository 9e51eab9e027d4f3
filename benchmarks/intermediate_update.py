"""The cost of FMI 3 intermediate update: the kernel's callback answering an FMU that asks for its
inputs at every stage time (the input polynomials evaluated, one fmi3SetFloat64), against the same
FMU with its inputs held, and in a scene against FMI 2 input derivatives.

    .venv/bin/python benchmarks/intermediate_update.py [--repeat 5]

Per call: msd built as FMI 3 (three intermediate-update inputs), RK4 with `--internal` internal steps
per doStep (2 internal + 1 distinct stage times, so as many calls), stepped from Python through the
raw fmi3DoStep, once instantiated with the kernel's callback and an environment filled as the
kernel's tables fill it (order-2 polynomials), once without (held inputs, no call): the difference
in wall time over the calls the environment counted. Best of `repeat` runs of `--steps` doSteps.

Per communication step: the hydraulic manipulator (models/), the hydraulics taking its strokes and
stroke rates as polynomials in one doStep per macro step (interpolateInputs), 3 s, in-process:
microseconds inside the hydraulics' FMI calls per communication step with its FMI 2 build (input
derivatives) and with its FMI 3 build (intermediate update); both give the same results bit for
bit (tests/test_intermediate_update.py).
"""

from __future__ import annotations

import argparse
import ctypes as C
import dataclasses
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

import master.api as api
from master.fmu import Fmu
from master.fmubuild import fmu_path
from master.runtime import native

ROOT = Path(__file__).resolve().parent.parent
H = 0.01  # doStep, s


def stepping(fmu: Fmu, first: int, steps: int) -> float:
    """Wall time of `steps` raw doSteps of H from communication point `first`, s."""
    do, handle, h, prior = fmu.raw_do_step, fmu.handle, C.c_double(H), C.c_int(1)
    t0 = time.perf_counter()
    for j in range(first, first + steps):
        if do(handle, C.c_double(j * H), h, prior) > 1:
            raise RuntimeError(fmu.describe("fmi3DoStep failed"))
    return time.perf_counter() - t0


def opened(internal: int, asks: bool) -> tuple[Fmu, list]:
    """msd as FMI 3 in Step Mode; asking: with the kernel's callback and its environment filled."""
    fmu = Fmu(fmu_path("msd", fmi=3), "msd", intermediate_update=asks)
    fmu.set_values({"internal_step": H / internal, "x0": 1.0, "solver": 4})
    fmu.enter_initialization(0.0, 1e9)
    fmu.exit_initialization()
    keep: list = []
    if asks:  # as master.runtime.tables fills it for a component of three Real inputs, order 2
        names = ["F", "x_in", "v_in"]
        u = np.array([[0.1, 0.2, 0.3], [1.0, -1.0, 0.5], [2.0, 3.0, -4.0]])  # values, d1, d2
        vrs = np.array([fmu.variables[n].vr for n in names], dtype=np.uint32)
        slots, values = np.arange(3, dtype=np.int32), np.zeros(3)
        c = native.Component(
            instance=fmu.slave.component, set_real=C.cast(fmu.slave.dll.fmi3SetFloat64, C.c_void_p)
        )
        c.n_in = c.n_in_real = 3
        c.n_values, c.n_blocks = 1, 3
        iu = fmu.intermediate
        iu.component, iu.n = C.addressof(c), 3
        iu.u = u.ctypes.data_as(C.POINTER(C.c_double))
        iu.slots = slots.ctypes.data_as(C.POINTER(C.c_int32))
        iu.vrs = vrs.ctypes.data_as(C.POINTER(C.c_uint32))
        iu.values = values.ctypes.data_as(C.POINTER(C.c_double))
        keep = [c, u, vrs, slots, values]
    return fmu, keep


def per_call(internal: int, steps: int, repeat: int) -> tuple[float, float, float]:
    """(ns per callback, us per doStep held, calls per doStep), best of `repeat`."""
    held, held_keep = opened(internal, False)
    asking, keep = opened(internal, True)
    try:
        best_held = best_asked = float("inf")
        calls = 0
        for r in range(repeat):
            best_held = min(best_held, stepping(held, r * steps, steps))
            before = asking.intermediate.calls
            best_asked = min(best_asked, stepping(asking, r * steps, steps))
            calls = asking.intermediate.calls - before
    finally:
        held.close()
        asking.close()
    return 1e9 * (best_asked - best_held) / calls, 1e6 * best_held / steps, calls / steps


def scene_step_cost(repeat: int) -> dict[str, float]:
    """us per communication step inside the hydraulics' FMI calls: FMI 2 derivatives, FMI 3 asking."""
    with tempfile.TemporaryDirectory() as tmp:
        shutil.copytree(ROOT / "models" / "hydraulic-manipulator", Path(tmp) / "scene")
        ssd = Path(tmp) / "scene" / "SystemStructure.ssd"
        old = '<mm:Component name="hydraulics" stepRatio="5" extrapolationOrder="2"'
        ssd.write_text(ssd.read_text().replace(old, old + ' interpolateInputs="true"'))
        sc = api.load_scenario(ssd)
        three = tuple(
            dataclasses.replace(c, fmu_path=fmu_path("hydraulics", fmi=3)) if c.name == "hydraulics" else c
            for c in sc.components
        )
        out = {}
        for label, s in (
            ("FMI 2 input derivatives", sc),
            ("FMI 3 intermediate update", dataclasses.replace(sc, components=three)),
        ):
            best = float("inf")
            for _ in range(repeat):
                summary = api.run(s, backend="in-process").summary
                best = min(best, 1e6 * summary.fmu_time["hydraulics"] / summary.steps["hydraulics"])
            out[label] = best
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--internal", type=int, default=100, help="RK4 internal steps per doStep")
    args = parser.parse_args()
    ns, held_us, calls = per_call(args.internal, args.steps, args.repeat)
    print(
        f"msd FMI 3, RK4, {args.internal} internal steps per doStep: {calls:.0f} callbacks per doStep, "
        f"{ns:.0f} ns per callback (polynomials of 3 inputs + fmi3SetFloat64); "
        f"doStep with held inputs {held_us:.1f} us"
    )
    for label, us in scene_step_cost(args.repeat).items():
        print(f"hydraulic manipulator, hydraulics {label}: {us:.2f} us per communication step")


if __name__ == "__main__":
    main()
