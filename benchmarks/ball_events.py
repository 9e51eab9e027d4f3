"""The cost of events, by how they are handled: the bouncing ball (fmus/bouncing_ball, e = 1: no Zeno
point; from h0 = 1 mm a bounce every 28.6 ms) at 10 ms communication steps, RK4, bounces located to
1e-10 s (Illinois on the solver's step), against a flight without bounces (h0 so high that the ball
never lands). The ways:

- Model Exchange: the master integrates it and locates the bounces (event indicators at each trial);
- Co-Simulation (FMI 2): its doStep locates them with the same code, the same bits;
- FMI 3 Co-Simulation in event mode: doStep returns early at each bounce, the master's event
  iteration, then the rest of the step (the same bits as FMI 2);
- FMI 3 Co-Simulation with eventMode off: its bounces handled inside doStep.

    .venv/bin/python benchmarks/ball_events.py [--repeat 3] [--stop 100] [--h0 0.001]

Printed: microseconds per communication step inside the FMU (FMI calls, and the kernel's solver and
event location or event iteration between them), the best of `repeat` in-process runs, and the
cost of one bounce (the difference to the flight without bounces, per bounce).
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
WAYS = {  # name: (FMI version, Model Exchange, event mode)
    "model exchange      ": (2, True, False),
    "co-simulation FMI 2 ": (2, False, False),
    "FMI 3 event mode    ": (3, False, True),
    "FMI 3 inside doStep ": (3, False, False),
}


def scene(stop: int, way: tuple[int, bool, bool], h0: float) -> Scenario:
    fmi, model_exchange, event_mode = way
    p = {"e": 1.0, "h0": h0} if model_exchange else {"e": 1.0, "h0": h0, "solver": 4}
    me = ModelExchange("rk4") if model_exchange else None
    ball = Component(
        "ball", fmu_path("bouncing_ball", fmi), parameters=p, model_exchange=me, event_mode=event_mode
    )
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
    for kind, way in WAYS.items():
        bouncing = measure(scene(args.stop, way, args.h0), args.repeat)
        flying = measure(scene(args.stop, way, 1e9), args.repeat)
        per_bounce = (bouncing - flying) * steps / bounces
        print(
            f"  {kind} us per step: with bounces {bouncing:6.2f}, without {flying:6.2f}; "
            f"{per_bounce:6.1f} us per bounce"
        )


if __name__ == "__main__":
    main()
