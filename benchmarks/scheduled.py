"""The cost of a Scheduled Execution component's communication step: the project's clocks model
(fmus/clocks, the Reference FMUs' Clocks) on a grid of 0.1 s, inClock1 activated every tenth point
(1 s), no other clock ticking; each point sets nothing (no inputs connected), asks fmi3GetClock of
outClock and reads the recorded outputs.

    .venv/bin/python benchmarks/scheduled.py [--repeat 5] [--stop 1000]

Printed, the best of `repeat` in-process runs: microseconds per communication step inside FMI calls
(activations, fmi3GetClock, output reads), and the master's overhead per macro step (the summary's).
"""

from __future__ import annotations

import argparse
import math
from fractions import Fraction
from pathlib import Path

import master.api as api
from master.fmubuild import build_fmu
from master.scenario.model import Component, Scenario


def scene(stop: int) -> Scenario:
    clocks = Component("clocks", build_fmu("clocks", fmi=3), scheduled=True)
    return Scenario(Path("clocks.ssd"), "clocks", (clocks,), (), Fraction(0), Fraction(stop), Fraction(1, 10))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--stop", type=int, default=1000)
    args = parser.parse_args()
    sc = scene(args.stop)
    inside, overhead = math.inf, math.inf
    for _ in range(args.repeat):
        s = api.run(sc, backend="in-process").summary
        inside = min(inside, 1e6 * s.fmu_time["clocks"] / s.steps["clocks"])
        overhead = min(overhead, 1e6 * s.overhead_per_macro_step)
        ticks = s.clock_ticks
    print(f"{s.steps['clocks']} communication steps, activations and ticks {ticks}")
    print(
        f"inside FMI calls: {inside:.2f} us per communication step; "
        f"master overhead {overhead:.2f} us per macro step"
    )


if __name__ == "__main__":
    main()
