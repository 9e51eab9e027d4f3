"""Issue 12's work-precision target, measured side by side: on each paper scene, the single-rate
AB3 baseline of the bench (its error against the Model Exchange reference, measured as `master
tune` measures it: over the scene's stop time on the tune's check grid, and its wall time), then
`master tune` at that error as the tolerance, and the ratio of the baseline's wall time to the
cheapest multirate configuration's and to the tune's choice (target: multirate in at most a third
of the baseline's time). Wall times: serial backend over the scene's stop time, the baseline and
the winners timed in turn, --repeats rounds, medians; one process.

    python benchmarks/tune_vs_baseline.py [--repeats 5] [scene ...]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
from pathlib import Path

from master.api import load_scenario, run
from master.evidence import bench
from master.tune import pilot_for, report, tune

REPO = Path(__file__).resolve().parents[1]
SCENES = ("hydraulic-manipulator", "dc-motor-arm")


def interleaved(scenes: dict[str, object], repeats: int) -> dict[str, float]:
    """Median wall time (s) of each scene, timed in turn `repeats` rounds (serial backend): load on
    the machine then falls on all of them alike. Prints each one's median time inside each FMU."""
    times: dict[str, list[float]] = {k: [] for k in scenes}
    inside: dict[str, dict[str, list[float]]] = {k: {} for k in scenes}
    for _ in range(repeats):
        for k, sc in scenes.items():
            s = run(sc, backend="serial").summary
            times[k].append(s.wall_time)
            for fmu, t in s.fmu_time.items():
                inside[k].setdefault(fmu, []).append(t)
    for k, per in inside.items():
        calls = ", ".join(f"{fmu} {statistics.median(t) * 1e3:.3g} ms" for fmu, t in per.items())
        print(f"  {k}: inside the FMUs: {calls}")
    return {k: statistics.median(v) for k, v in times.items()}


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
        pilot, _ = pilot_for(sc, math.inf)
        base = pilot(p.baseline)
        result = tune(sc, base.error, repeats=a.repeats)
        if a.report:
            print(report(result))
        print(f"\n{name}: baseline {p.baseline.label}: error {base.error:.3g} over {result.horizon:g} s "
              f"every {result.grid:g} s")  # fmt: skip
        if result.best is None:
            print("  tune found nothing within the baseline's error")
            continue
        multi = next((ch for ch in result.choices if ch.trial.config.ratio > 1), None)  # the cheapest
        chosen = {"baseline": p.baseline, "tuned": result.best.trial.config}
        if multi is not None and multi is not result.best:
            chosen["multirate"] = multi.trial.config
        t = interleaved({k: pilot.scene(c) for k, c in chosen.items()}, a.repeats)
        print(f"  baseline: {t['baseline'] * 1e3:.3g} ms")
        for key, ch in (("tuned", result.best), ("multirate", multi)):
            if ch is None:
                print("  no multirate configuration (step ratio > 1) within the baseline's error")
                continue
            if key not in t:
                print("  multirate: the tuned one")
                continue
            c = ch.trial.config
            speed = t["baseline"] / t[key]
            print(f"  {key}: {ch.family}, H={float(c.macro_step):g} s: error {ch.trial.error:.3g}, "
                  f"{t[key] * 1e3:.3g} ms: {speed:.2f}x the baseline's speed (target 3x)")  # fmt: skip
        print(f"  load average now {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
