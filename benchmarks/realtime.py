"""Hard real time: the hydraulic scene paced at 1 ms frames, lateness per frame.

    .venv/bin/python benchmarks/realtime.py [--seconds 60] [--backend serial|parallel] [--cpus 2,3]

Runs the hydraulic-manipulator scene at the paper's steps (macro step 1 ms) for `--seconds` of
simulated time at real-time factor 1 and prints the frame lateness quantiles, the worst lateness
and the overruns from the run summary (the issue's target: no overrun, worst under 100 us, on an
idle multi-core machine), and the real-time factor achieved (how close to the wall clock a paced
run ends: the tests only check that it is not faster), with the machine's processor count and
load. The scene's constant valve openings would drive a cylinder into its end after 57 s; here
each valve reverses every 1.5 s (same opening), so the arm goes back and forth for as long as the
run lasts.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
from pathlib import Path

import master.api as api
from master.cli import _cpu_list
from master.scenario.model import Scenario

SCENE = Path(__file__).resolve().parent.parent / "models" / "hydraulic-manipulator" / "SystemStructure.ssd"


def back_and_forth(sc: Scenario, seconds: float, period: float = 1.5) -> Scenario:
    """`sc` with every step stimulus reversing its value every `period` s."""
    n = int(seconds / period) + 1
    stimuli = tuple(
        dataclasses.replace(
            s,
            times=tuple(i * period for i in range(n)),
            values=tuple(s.values[-1] * (-1) ** i for i in range(n)),
        )
        for s in sc.stimuli
    )
    return dataclasses.replace(sc, stimuli=stimuli)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--backend", default="serial", choices=("serial", "parallel"))
    ap.add_argument("--cpus", type=_cpu_list, default=None)
    args = ap.parse_args()
    load = os.getloadavg()[0]
    sc = back_and_forth(api.load_scenario(SCENE), args.seconds)
    s = api.run(sc, backend=args.backend, real_time=1.0, stop_time=args.seconds, cpus=args.cpus).summary
    late = ", ".join(f"{q} {v * 1e6:.0f} us" for q, v in (s.lateness or {}).items())
    print(
        f"{os.cpu_count()} CPUs, load average {load:.2f} before; {args.backend}, cpus {args.cpus or 'any'}: "
        f"{s.macro_steps} frames of 1 ms, {s.overruns} overruns, worst lateness "
        f"{(s.worst_lateness or 0) * 1e6:.0f} us; {late}; real-time factor {s.real_time_factor:.4f} "
        f"(wall {s.wall_time:.3f} s for {s.simulated_time:g} s simulated; 1 is exact pacing)"
    )
    for note in s.notes:
        print(f"note: {note}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
