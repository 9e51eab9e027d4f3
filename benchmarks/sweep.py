"""Sweep engine: 200 oscillator cases on local Dask clusters of 1, 2 and all usable workers,
measured side by side in one run (not a test: numbers vary by machine).

    .venv/bin/python benchmarks/sweep.py [--cases 200] [--stop-time 10]

Prints the wall time of the cases (cluster start-up apart) for each cluster size and the speed-up
over one worker (the issue's targets: >= 1.8x with two workers, >= 12x with 16 on a 16-core
machine), and the engine's overhead per case: the one-worker sweep's time per case minus that of
the same runs called one after another in this process (`master.run`, serial backend).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import master
import master.api as api
from master.sweeps.cases import parse_vary, points

SCENE = Path(__file__).resolve().parent.parent / "tests" / "scenarios" / "oscillator" / "oscillator.ssd"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=200)
    ap.add_argument("--stop-time", default="10", help="s simulated per case (10: 1000 macro steps)")
    a = ap.parse_args()
    cpus = len(os.sched_getaffinity(0))
    vary = [f"mass1.c=0.5:2:{a.cases // 10}", "mass2.m=0.5:2:10"]
    print(f"{cpus} usable CPUs, load average {os.getloadavg()[0]:.2f}; {a.cases} cases, {a.stop_time} s each")

    cases = points([parse_vary(v, "grid") for v in vary], "grid", None, None)
    t0 = time.perf_counter()
    for values in cases:
        api.run(SCENE, stop_time=a.stop_time, set_values={k: repr(v) for k, v in values.items()})
    loop = time.perf_counter() - t0
    print(f"  in-process loop of master.run: {loop:.2f} s = {1e3 * loop / len(cases):.1f} ms per case")

    sizes = sorted({1, 2, cpus})
    times = {}
    for n in sizes:
        with tempfile.TemporaryDirectory() as out:
            r = master.sweep(SCENE, vary, out=out, workers=n, stop_time=a.stop_time)
            assert r.ran == len(cases) and r.failed == 0
            times[n] = r.cases_time
            line = f"  {n:2d} workers: start-up {r.startup_time:.2f} s, cases {r.cases_time:.2f} s"
            print(line + f", speed-up {times[1] / r.cases_time:.2f}x over 1 worker")
    overhead = (times[1] - loop) / len(cases)
    print(f"  engine overhead per case (1 worker vs the loop): {1e3 * overhead:.1f} ms")


if __name__ == "__main__":
    main()
