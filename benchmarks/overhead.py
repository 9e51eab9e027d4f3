"""Master overhead per macro step and real-time factor, serial backend.

    .venv/bin/python benchmarks/overhead.py            # hydraulic scene (both forms), oscillator
    .venv/bin/python benchmarks/overhead.py --memory   # peak memory, 10^3 vs 10^6 recorded steps

Overhead = (wall time - time inside FMI calls) / macro steps: what the master itself costs.
The hydraulic-manipulator scene runs at the paper's steps (mechanics 1e-3 s, hydraulics 2e-4 s,
3 s) in two forms: five hydraulic doSteps per macro step with the master evaluating the
extrapolation polynomials, and one doStep per macro step with the polynomial handed to the FMU
(interpolateInputs, internal_step 2e-4 s).  Each case is the fastest of a few runs: the machine
is shared, so the load average is printed too.

Measured with the command above on the 2-core development machine (load average 1.1), the
scene with seal friction, Jacobi, order 2, the macro-step loop in the compiled kernel (one worker
process):

    hydraulic, 5 doSteps per macro step        wall 0.041 s, overhead 0.8 us, RTF 72.5
    hydraulic, 1 doStep + polynomials to FMU   wall 0.036 s, overhead 0.5 us, RTF 84.0
    the same with the runtime in Python (numpy polynomials, ctypes calls per step):
    hydraulic, 5 doSteps per macro step        wall 0.077 s, overhead 10.3 us, RTF 39
    hydraulic, 1 doStep + polynomials to FMU   wall 0.067 s, overhead 10.7 us, RTF 45

When other jobs share the processors every figure can be 1.5 times worse.

Connection transformations (SSP ssc:LinearTransformation, unit conversion, mappings) cost links
without one nothing: three interleaved runs each of the command above before and after they came
(load average 1.8 to 2.9), the untransformed cases' overheads the same to the 0.1 us shown
(hydraulic 1.0 / 0.8-1.0 us, oscillator 0.4 us each; one run of each disturbed by load); the
case "the same, every connection transformed" (an identity transformation on each of the
oscillator's connections, order 2) 0.4-0.6 us against 0.4 us without.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import tempfile
from fractions import Fraction
from pathlib import Path

import numpy as np

import master.api as api
from master.evidence.oscillator import scene
from master.recorder import RunSummary
from master.scenario.model import Scenario, Transformation

HYDRAULIC_SCENE = (
    Path(__file__).resolve().parent.parent / "models" / "hydraulic-manipulator" / "SystemStructure.ssd"
)
HYDRAULIC_STEP = 2e-4  # s: the paper's hydraulic integration step
IDENTITY = Transformation("linear", 1.0, 0.0)  # same results, through the transformation path


def oscillator(H: Fraction, stop: Fraction, order: int, interpolate: bool) -> Scenario:
    """The two-mass oscillator (parameter set A), one RK4 step per communication step."""
    return scene(
        split="force", macro_step=H, stop_time=stop, order=order, interpolate=(interpolate, interpolate)
    )


def hydraulic(polynomials_to_fmu: bool) -> Scenario:
    """The hydraulic-manipulator scene at the paper's steps, in one of its two forms.

    False: hydraulics steps k = H / 2e-4 times per macro step (one Euler step per doStep).
    True: one doStep per macro step, the input polynomials handed to the FMU, Euler substeps of
    2e-4 s inside it.
    """
    sc = api.load_scenario(HYDRAULIC_SCENE)
    H = float(sc.macro_step)
    comps = []
    for c in sc.components:
        if c.name == "hydraulics":
            k = round(H / HYDRAULIC_STEP)
            internal = HYDRAULIC_STEP if polynomials_to_fmu else 0.0
            params = {**c.parameters, "internal_step": internal}
            c = dataclasses.replace(c, step_ratio=k, interpolate_inputs=polynomials_to_fmu, parameters=params)
        comps.append(c)
    return dataclasses.replace(sc, components=tuple(comps))


def overhead(repeats: int = 7) -> None:
    """Run every case `repeats` times, interleaved (load on a shared machine comes in phases), and
    print the fastest run of each."""
    cases = {
        "hydraulic, 5 doSteps per macro step": hydraulic(False),
        "hydraulic, 1 doStep + polynomials to FMU": hydraulic(True),
    }
    for order, interp in ((0, False), (2, False), (2, True)):
        name = f"oscillator H=1ms order {order}{' polynomials to FMU' if interp else ''}"
        cases[name] = oscillator(Fraction(1, 1000), Fraction(10), order, interp)
    # the cost of a transformation: every connection of the order-2 case through an identity one
    sc = cases["oscillator H=1ms order 2"]
    every = tuple(dataclasses.replace(c, transformation=IDENTITY) for c in sc.connections)
    cases["the same, every connection transformed"] = dataclasses.replace(sc, connections=every)
    best: dict[str, RunSummary] = {}
    data: dict[str, np.ndarray] = {}
    for _ in range(repeats):
        for name, sc in cases.items():
            r = api.run(sc, backend="serial")
            if name not in best or r.summary.wall_time < best[name].wall_time:
                best[name], data[name] = r.summary, r.data
    load = os.getloadavg()[0]
    print(f"serial backend, fastest of {repeats} runs each; load average {load:.2f} on {os.cpu_count()} CPUs")
    head = (
        f"{'case':<45} {'macro steps':>11} {'doSteps':>8} {'wall s':>7} {'in FMUs s':>9} {'overhead us':>11}"
    )
    print(f"{head} {'RTF':>6}")
    for name, s in best.items():
        print(
            f"{name:<45} {s.macro_steps:>11} {sum(s.steps.values()):>8} {s.wall_time:>7.3f} "
            f"{sum(s.fmu_time.values()):>9.3f} {s.overhead_per_macro_step * 1e6:>11.1f} "
            f"{s.real_time_factor:>6.1f}"
        )
    a, b = (data[n] for n in list(cases)[:2])
    diff = max(float(np.max(np.abs(a[n] - b[n])) / max(np.max(np.abs(a[n])), 1e-300)) for n in a.dtype.names)
    print(f"the two hydraulic forms agree to {diff:.1e} (largest difference / largest value, per column)")


CHILD = (
    "import resource, sys; from fractions import Fraction; sys.path.insert(0, sys.argv[3]); "
    "import overhead, master.api as api; "
    "api.run(overhead.oscillator(Fraction(1, int(sys.argv[1])), Fraction(1), 0, False), output=sys.argv[2]); "
    "print(max(resource.getrusage(w).ru_maxrss for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)))"
)


def memory() -> None:
    scene()  # builds the msd FMU before the timed subprocesses
    here = str(Path(__file__).parent)
    with tempfile.TemporaryDirectory() as d:
        peaks = {}
        for n in (10**3, 10**6):
            out = Path(d) / f"{n}.csv"
            r = subprocess.run(
                [sys.executable, "-c", CHILD, str(n), str(out), here], capture_output=True, text=True
            )
            if r.returncode:
                sys.exit(r.stderr)
            peaks[n] = int(r.stdout.split()[-1]) / 1024
            rows = sum(1 for _ in open(out)) - 1
            print(f"{n:>8} macro steps: {rows} rows written, peak RSS {peaks[n]:.1f} MB (master or worker)")
        print(f"difference: {peaks[10**6] - peaks[10**3]:.1f} MB (limit 50 MB)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--memory", action="store_true", help="peak memory of a 10^6-step run vs 10^3")
    args = p.parse_args()
    memory() if args.memory else overhead()


if __name__ == "__main__":
    main()
