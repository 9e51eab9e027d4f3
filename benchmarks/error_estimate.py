"""The coupling error estimate against the true error, on the two-mass oscillator.

    .venv/bin/python benchmarks/error_estimate.py

For macro steps H = 0.1 ... 0.01 s and extrapolation orders 0-3 (force split, polynomial inputs
handed to both FMUs): the largest error of mass1.x against the exact solution and the run
summary's estimate for mass1.x -> mass2.x_in, both relative to the signal's range, and their ratio.
"""

from fractions import Fraction

import numpy as np

import master.api as api
from master.evidence.oscillator import SET_A, SET_A_Z0, scene


def main() -> int:
    for H in (Fraction(1, 10), Fraction(1, 20), Fraction(1, 50), Fraction(1, 100)):
        row = []
        for p in range(4):
            try:
                r = api.run(
                    scene(
                        split="force", macro_step=H, stop_time=Fraction(10), order=p, interpolate=(True, True)
                    ),
                    backend="in-process",
                )
            except api.SimulationError:
                row.append(f"p{p}: unstable")
                continue
            d = r.data
            ex = SET_A.exact(d["time"], SET_A_Z0)
            span = np.ptp(ex[:, 0])
            true = np.max(np.abs(d["mass1.x"] - ex[:, 0])) / span
            est = r.summary.coupling_errors["mass1.x -> mass2.x_in"]["max"]
            row.append(f"p{p}: true {true:.1e} est {est:.1e} ({est / true:.2f})")
        print(f"H={float(H)}", " | ".join(row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
