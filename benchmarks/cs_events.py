"""The cost of FMI 3 Co-Simulation event mode: the bouncing ball (fmus/bouncing_ball, e = 1: no Zeno
point; from h0 = 1 mm a bounce every 28.6 ms) at 10 ms communication steps, RK4, its FMI 3 build in
event mode (doStep returns early at each bounce; the master's event iteration, then the rest of the
step) against the same build with eventMode off (its bounces handled inside doStep: the same bits)
and against a flight without bounces.

    .venv/bin/python benchmarks/cs_events.py [--repeat 3] [--stop 100] [--h0 0.001]

Printed: microseconds per communication step inside the FMU (FMI calls and the kernel between them),
the best of `repeat` in-process runs, and the cost of one bounce (the difference to the flight
without bounces, per bounce).
"""

from __future__ import annotations

import argparse
import math
from fractions import Fraction
from pathlib import Path

import master.api as api
from master.fmubuild import build_fmu
from master.scenario.model import Component, Scenario

STEP = Fraction(1, 100)


def scene(stop: int, event_mode: bool, h0: float) -> Scenario:
    p = {"e": 1.0, "h0": h0, "solver": 4}
    ball = Component("ball", build_fmu("bouncing_ball", fmi=3), parameters=p, event_mode=event_mode)
    return Scenario(Path("ball.ssd"), "ball", (ball,), (), Fraction(0), Fraction(stop), STEP)


def measure(sc: Scenario, repeat: int) -> float:
    """us per communication step inside the FMU, the best of `repeat` runs."""
    best = math.inf
    for _ in range(repeat):
        s = api.run(sc, backend="in-process").summary
        best = min(best, 1e6 * s.fmu_time["ball"] / s.steps["ball"])
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--stop", type=int, default=100)
    parser.add_argument("--h0", type=float, default=0.001, help="initial height, m")
    args = parser.parse_args()
    steps = args.stop / float(STEP)
    t1 = math.sqrt(2 * args.h0 / 9.81)
    bounces = math.floor((args.stop / t1 + 1) / 2)  # at t1 (2k + 1)
    print(
        f"bouncing ball (FMI 3), e = 1, h0 = {args.h0} m, {args.stop} s at {STEP} s (RK4), {bounces} bounces:"
    )
    for event_mode in (True, False):
        kind = "event mode          " if event_mode else "events inside doStep"
        bouncing = measure(scene(args.stop, event_mode, args.h0), args.repeat)
        flying = measure(scene(args.stop, event_mode, 1e9), args.repeat)
        per_bounce = (bouncing - flying) * steps / bounces
        print(
            f"  {kind} us per step: with bounces {bouncing:6.2f}, without {flying:6.2f}; "
            f"{per_bounce:6.1f} us per bounce"
        )


if __name__ == "__main__":
    main()
