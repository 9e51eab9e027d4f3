"""Iterated against explicit coupling: work and precision on the two-mass oscillator, set B.

Parameter set B (m1 = 100 kg, cc = 100 N/m, the rest 1), force split, Jacobi, order 2, inputs
handed to the msd FMUs as polynomials, RK4 at a tenth of the macro step inside each doStep;
x1(0) = 1 m. At each macro step H: explicit coupling (each macro step stepped once) and iterated
coupling (repeated from saved FMU states until the coupled signals change by at most tol (1 +
|value|)), each with

- the linear model's verdict (master.evidence.linear: spectral radius of the macro-step map; the
  iterated scheme as the sweep's converged fixed point, rho(M) the sweep's contraction),
- the error: the largest deviation of x1 and x2 from the exact solution (matrix exponential) over
  the run, relative to the exact x1's range,
- the work: doStep calls of both FMUs (each RK4 x 10 inside), sweeps per macro step, and the
  stepping wall time (median of --repeats runs, serial backend, workers started before the clock).

    python benchmarks/iterated.py [--stop-time 30] [--repeats 3] [--tolerance 1e-8]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from master.api import run  # noqa: E402
from master.backends.component import SimulationError  # noqa: E402
from master.evidence import linear  # noqa: E402
from master.evidence.oscillator import SET_A, SET_A_Z0, scene, split_scheme  # noqa: E402
from master.scenario.model import Iteration  # noqa: E402

SET_B = dataclasses.replace(SET_A, m1=100.0, cc=100.0)
SUBSTEPS = 10
STEPS = ("0.01", "0.02", "0.05", "0.1", "0.2", "0.5", "0.6", "0.75", "1", "2")  # each divides --stop-time


def model(iterated: bool) -> linear.LinearScheme:
    lin = split_scheme(SET_B, order=2, inputs="polynomial", split="force", substeps=(SUBSTEPS, SUBSTEPS))
    return dataclasses.replace(lin, iterate="converged" if iterated else 0)


def measure(h: Fraction, stop: Fraction, iteration: Iteration | None, repeats: int) -> dict:
    sc = scene(SET_B, split="force", macro_step=h, stop_time=stop, order=2, interpolate=(True, True),
               substeps=SUBSTEPS)  # fmt: skip
    sc = dataclasses.replace(sc, iteration=iteration)
    walls, result = [], None
    for _ in range(repeats):
        try:
            result = run(sc, backend="serial")
        except SimulationError as e:
            return {"failed": str(e).split(" (hint")[0]}
        walls.append(result.summary.stepping_time)
    d = result.data
    exact = SET_B.exact(d["time"], SET_A_Z0)
    span = float(np.ptp(exact[:, 0]))
    error = max(np.max(np.abs(d["mass1.x"] - exact[:, 0])), np.max(np.abs(d["mass2.x"] - exact[:, 2]))) / span
    it = result.summary.iterations
    return {
        "error": float(error),
        "steps": sum(result.summary.steps.values()),
        "sweeps": it["sweeps"] / it["macro_steps"] if it else 0.0,
        "wall": statistics.median(walls),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stop-time", default="30", help="s (default 30)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tolerance", type=float, default=1e-8, help="of the iterated steps (default 1e-8)")
    args = ap.parse_args()
    stop = Fraction(args.stop_time)
    iteration = Iteration(tolerance=args.tolerance, max_iterations=50)
    explicit_limit = linear.largest_stable_step(model(False), 0.05, 5.0)
    iterated_limit = linear.largest_stable_step(model(True), 0.05, 5.0)
    print(f"set B, force split, Jacobi, order 2, polynomial inputs, RK4 x {SUBSTEPS} per doStep, {stop} s")
    print(f"linear model: largest stable macro step explicit {explicit_limit:.4f} s, iterated "
          f"{iterated_limit:.4f} s (tolerance {args.tolerance:g})")  # fmt: skip
    print(f"{'H [s]':>6} {'coupling':>9} {'rho(G)':>8} {'rho(M)':>7} {'error':>9} {'doSteps':>8} "
          f"{'sweeps':>6} {'wall [ms]':>9}")  # fmt: skip
    for text in STEPS:
        h = Fraction(text)
        if (stop / h).denominator != 1:
            continue
        for iterated in (False, True):
            rho = linear.spectral_radius(model(iterated), float(h))
            m = f"{linear.sweep_radius(model(True), float(h)):7.3f}" if iterated else f"{'':>7}"
            r = measure(h, stop, iteration if iterated else None, args.repeats)
            name = "iterated" if iterated else "explicit"
            if "failed" in r:
                print(f"{text:>6} {name:>9} {rho:8.4f} {m}  {r['failed']}")
                continue
            print(f"{text:>6} {name:>9} {rho:8.4f} {m} {r['error']:9.2e} {r['steps']:8d} {r['sweeps']:6.2f} "
                  f"{r['wall'] * 1e3:9.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
