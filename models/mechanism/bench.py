"""Cost of one derivative evaluation of the manipulator FMU (microseconds).

One fmi2DoStep of 1 s with AB3 at internal_step 1e-4 s makes 10000 derivative
evaluations inside C (AB3 evaluates once per step), so the wall time of the call over
10000 is the cost of one evaluation (Newton loop closure, eqs. 6-10, Cholesky) plus the
solver's small share.  Best of 5 calls.  Run: python bench.py
"""

from __future__ import annotations

import time

import parameters
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from master import fmubuild

N_STEPS = 10_000


def cost_per_evaluation(params: dict[str, float]) -> float:
    """Best wall time per derivative evaluation (s) over 5 one-second AB3 runs."""
    path = str(fmubuild.fmu_path("manipulator"))
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s = FMU2Slave(
        guid=md.guid, unzipDirectory=extract(path), modelIdentifier="manipulator", instanceName="bench"
    )
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setInteger([vr["solver"]], [3])
    s.setReal([vr["internal_step"]], [1.0 / N_STEPS])
    for name, value in {**params, "qd1_0": 0.5}.items():
        integer = name == "actuation" or name.endswith(("_body_a", "_body_b"))
        (s.setInteger if integer else s.setReal)([vr[name]], [value])
    s.exitInitializationMode()
    best = float("inf")
    for k in range(5):
        t0 = time.perf_counter()
        s.doStep(float(k), 1.0)
        best = min(best, time.perf_counter() - t0)
    s.terminate()
    s.freeInstance()
    return best / N_STEPS


def main() -> None:
    for name in ("table2", "table3"):
        cost = cost_per_evaluation(getattr(parameters, name)())
        print(f"{name}: {cost * 1e6:.2f} us per derivative evaluation")


if __name__ == "__main__":
    main()
