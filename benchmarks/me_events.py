"""The cost of events in a Model Exchange component: the bouncing ball (fmus/bouncing_ball, e = 1: no
Zeno point; from h0 = 1 mm a bounce every 28.6 ms) integrated by the master with RK4 at 10 ms steps,
its bounces located to 1e-10 s (Illinois on the solver's step; each trial a step and the event
indicators), against the same FMU as Co-Simulation (its doStep locates them with the same code:
the same bits) and against a flight without bounces (h0 so high that the ball never lands).

    .venv/bin/python benchmarks/me_events.py [--repeat 3] [--stop 100] [--h0 0.001]

Printed: microseconds per communication step inside the FMU (for Model Exchange with the kernel's
solver and event location between the calls), the best of `repeat` in-process runs, the bounces,
and the cost of one bounce (the difference to the flight without bounces, per bounce).
"""

from __future__ import annotations

import argparse
import math
from fractions import Fraction
from pathlib import Path

import master.api as api
from master.fmubuild import fmu_path
from master.scenario.model import Component, ModelExchange, Scenario

STEP = Fraction(1, 100)


def scene(stop: int, model_exchange: bool, h0: float) -> Scenario:
    p = {"e": 1.0, "h0": h0} if model_exchange else {"e": 1.0, "h0": h0, "solver": 4}
    me = ModelExchange("rk4") if model_exchange else None
    ball = Component("ball", fmu_path("bouncing_ball"), parameters=p, model_exchange=me)
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
    print(f"bouncing ball, e = 1, h0 = {args.h0} m, {args.stop} s at {STEP} s (RK4), {bounces} bounces:")
    for model_exchange in (True, False):
        kind = "model exchange" if model_exchange else "co-simulation "
        bouncing = measure(scene(args.stop, model_exchange, args.h0), args.repeat)
        flying = measure(scene(args.stop, model_exchange, 1e9), args.repeat)
        per_bounce = (bouncing - flying) * steps / bounces
        print(
            f"  {kind} us per step: with bounces {bouncing:6.2f}, without {flying:6.2f}; "
            f"{per_bounce:6.1f} us per bounce"
        )


if __name__ == "__main__":
    main()
