"""Issue 12's work-precision target, measured side by side: on each paper scene, the single-rate
AB3 baseline of the bench (its error against the Model Exchange reference and its wall time), then
`master tune` at that error as the tolerance, and the ratio of the baseline's wall time to the
fastest multirate configuration's and to the fastest of all (target: multirate in at most a third
of the baseline's time). Wall times: serial backend, median of --repeats runs, one process.

    python benchmarks/tune_vs_baseline.py [--repeats 5] [scene ...]
"""

from __future__ import annotations

import argparse
import os
import statistics
from pathlib import Path

from master.api import load_scenario
from master.evidence import bench
from master.evidence.reference import reference
from master.tune import report, tune

REPO = Path(__file__).resolve().parents[1]
SCENES = ("hydraulic-manipulator", "dc-motor-arm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--report", action="store_true", help="print each tune report whole")
    a = ap.parse_args()
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    for name in a.scenes:
        sc = load_scenario(REPO / "models" / name / "SystemStructure.ssd")
        p = bench.profile_for(sc)
        ref = reference(bench.base_scene(sc, p))
        row = bench.measure(sc, p, p.baseline, ref, a.repeats)
        result = tune(sc, row.error, repeats=a.repeats)
        if a.report:
            print(report(result))
        multi = next((ch for ch in result.choices if ch.timed and ch.trial.config.ratio > 1), None)
        base_t = statistics.median(row.wall_times)
        print(f"\n{name}: baseline {p.baseline.label}: error {row.error:.3g}, {base_t * 1e3:.3g} ms")
        if result.best is None:
            print("  tune found nothing within the baseline's error")
            continue
        b = result.best
        print(f"  fastest within it: {b.family} H={float(b.trial.config.macro_step):g} s, error "
              f"{b.trial.error:.3g}, {b.wall_time * 1e3:.3g} ms: {base_t / b.wall_time:.2f}x the baseline's "
              "speed")  # fmt: skip
        if multi is not None:
            print(f"  fastest multirate: {multi.family} H={float(multi.trial.config.macro_step):g} s, error "
                  f"{multi.trial.error:.3g}, {multi.wall_time * 1e3:.3g} ms: {base_t / multi.wall_time:.2f}x "
                  f"(target 3x)")  # fmt: skip
        else:
            print("  no multirate configuration (step ratio > 1) within the baseline's error was timed")


if __name__ == "__main__":
    main()
