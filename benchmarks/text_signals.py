"""What a String or Binary connection, recorded at every row, costs against an Int32 one.

    .venv/bin/python benchmarks/text_signals.py [--repeats N]

Two alltypes FMUs (FMI 3.0), a -> b, macro step 1 ms, 10 s (10 000 macro steps, a row each):
a.y_int32 -> b.u_int32 recording b.y_int32; a.y_string -> b.u_string recording b.y_string (held,
the same text throughout); a.stamp -> b.u_binary recording b.y_binary (a Binary that changes
every 100 ms). Medians over the repeats, cases timed in turn: wall time of the run, time inside
the FMUs, and the master's own time per macro step (kernel, text rings, recorder).
"""

from __future__ import annotations

import argparse
import os
import statistics
from fractions import Fraction
from pathlib import Path

import master.api as api
from master.fmubuild import fmu_path
from master.scenario.model import Component, Connection, Scenario

CASES = {  # output of a, input of b, recorded output of b
    "Int32": ("y_int32", "u_int32", "y_int32"),
    "String": ("y_string", "u_string", "y_string"),
    "Binary": ("stamp", "u_binary", "y_binary"),
}


def scene(output: str, input_: str, recorded: str) -> Scenario:
    fmu = fmu_path("alltypes", fmi=3)
    comps = (Component("a", fmu), Component("b", fmu))
    return Scenario(Path("text_signals.ssd"), "text signals", comps, (Connection("a", output, "b", input_),),
                    Fraction(0), Fraction(10), Fraction(1, 1000), record=(("b", recorded),))  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    print(f"{os.cpu_count()} processors, load average {os.getloadavg()[0]:.2f}")
    for backend in ("in-process", "serial"):
        scenes = {name: scene(*ends) for name, ends in CASES.items()}
        times: dict[str, list[tuple[float, float, float]]] = {name: [] for name in CASES}
        for _ in range(args.repeats):
            for name, sc in scenes.items():
                s = api.run(sc, backend=backend).summary
                times[name].append((s.wall_time, sum(s.fmu_time.values()), s.overhead_per_macro_step))
        for name, rows in times.items():
            wall, fmu, master = (statistics.median(r[i] for r in rows) for i in range(3))
            print(f"{backend:10s} {name:6s}  wall {wall * 1e3:6.1f} ms  inside the FMUs {fmu * 1e3:6.1f} ms  "
                  f"master {master * 1e6:5.2f} us per macro step")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
