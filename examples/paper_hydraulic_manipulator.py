"""The paper's experiment 1 (Sec. 4.1, Fig. 5): the hydraulically actuated manipulator.

Runs, over the paper's 3 s with the spool steps at t = 0:
- single-rate: mechanics and hydraulics both AB3 at 2e-4 s, Jacobi (the paper's comparison run),
- dual-rate as in the paper: hydraulics Euler at 2e-4 s, mechanics AB3 at 1e-3 s (ratio 5),
  both integrated concurrently (Jacobi), as the paper's algorithm does,
- the same dual rate with the scene's Gauss-Seidel coupling (hydraulics first),
and the monolithic Model Exchange reference (Radau, rtol 1e-10).  Plots the vertical position,
velocity and acceleration of body 6 (Fig. 5) and prints the measured differences.

Run: /work/venv/bin/python examples/paper_hydraulic_manipulator.py [--out docs/evidence]
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
from fractions import Fraction
from pathlib import Path

from master.api import load_scenario, run
from master.backends.component import SimulationError
from master.evidence.bench import as_trajectory
from master.evidence.errors import compare
from master.evidence.reference import reference
from master.scenario.model import Scenario

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "models" / "hydraulic-manipulator" / "SystemStructure.ssd"
EULER, AB3 = 1, 3
SIGNALS = [
    ("mechanics.body6_z", "z [m]"),
    ("mechanics.body6_vz", "v_z [m/s]"),
    ("mechanics.body6_az", "a_z [m/s²]"),
]


def configure(sc: Scenario, macro: Fraction, hyd_solver: int, ratio: int, coupling: str) -> Scenario:
    """The scene with its macro step (s), the hydraulics' solver and step ratio, AB3 mechanics."""
    comps = []
    for c in sc.components:
        hyd = c.name == "hydraulics"
        params = {**c.parameters, "solver": hyd_solver if hyd else AB3, "internal_step": 0.0}
        comps.append(dataclasses.replace(c, parameters=params, step_ratio=ratio if hyd else 1))
    return dataclasses.replace(
        sc, components=tuple(comps), macro_step=macro, record_interval=Fraction(1, 1000), coupling=coupling
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "evidence"), help="folder for the figure and table")
    ap.add_argument("--stop-time", default="3", help="s (the paper: 3)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    sc = dataclasses.replace(load_scenario(SCENE), stop_time=Fraction(a.stop_time))
    runs = {
        "single-rate AB3 2e-4 s": configure(sc, Fraction(2, 10000), AB3, 1, "jacobi"),
        "dual-rate Euler 2e-4 s + AB3 1e-3 s, Jacobi (paper)": configure(
            sc, Fraction(1, 1000), EULER, 5, "jacobi"
        ),
        "dual-rate, Gauss-Seidel (hydraulics first)": configure(
            sc, Fraction(1, 1000), EULER, 5, "gauss-seidel"
        ),
    }
    ref_scene = dataclasses.replace(sc, macro_step=Fraction(1, 1000), record_interval=Fraction(1, 1000))
    ref = reference(ref_scene, overrides={"stop_time": a.stop_time, "grid": "1e-3"})
    results, rows = {}, []
    for label, scene in runs.items():
        try:
            res = run(scene)
            status = "finished"
        except SimulationError as e:
            res, status = e.result, str(e).split(" (hint")[0]
        traj = as_trajectory(res.data)
        results[label] = traj
        rep = compare(traj, ref, [s for s, _ in SIGNALS])
        rows.append([label, f"{res.summary.wall_time:.3f}", status]
                    + [f"{rep.max_error[s]:.3e}" for s, _ in SIGNALS])  # fmt: skip
    single, paper, gs = list(results.values())
    diff = compare(gs, single, [s for s, _ in SIGNALS])  # dual-rate (scene) against single-rate

    out.mkdir(parents=True, exist_ok=True)
    with open(out / "fig5_hydraulic_manipulator.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["run", "wall_time_s", "status"] + [f"error_{s}" for s, _ in SIGNALS])
        w.writerows(rows)
        w.writerow(
            ["dual-rate (paper) vs single-rate", "", ""] + [f"{diff.max_error[s]:.3e}" for s, _ in SIGNALS]
        )
    plot(results, ref, out / "fig5_hydraulic_manipulator.png")

    print(f"{'run':48} {'wall [s]':>9}  " + "  ".join(f"{s.split('.')[1]:>11}" for s, _ in SIGNALS))
    for r in rows:
        print(
            f"{r[0]:48} {r[1]:>9}  "
            + "  ".join(f"{v:>11}" for v in r[3:])
            + ("" if r[2] == "finished" else f"  {r[2]}")
        )
    print(f"{'dual-rate Gauss-Seidel vs single-rate':48} {'':>9}  "
          + "  ".join(f"{diff.max_error[s]:11.3e}" for s, _ in SIGNALS))  # fmt: skip
    print("errors: max |difference| over the run / range of the reference (single-rate for the last row)")
    return 0


def plot(results: dict, ref, path: Path) -> None:
    """Fig. 5: body 6 vertical position, velocity, acceleration over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for ax, (sig, unit) in zip(axes, SIGNALS, strict=True):
        ax.plot(ref.time, ref.values[sig], "k-", lw=2.5, alpha=0.35, label="reference (ME, Radau)")
        for (label, traj), style in zip(results.items(), ["-", "--", ":"], strict=True):
            ax.plot(traj.time, traj.values[sig], style, lw=1, label=label)
        lo, hi = ref.values[sig].min(), ref.values[sig].max()
        ax.set_ylim(lo - 0.5 * (hi - lo), hi + 0.5 * (hi - lo))  # a growing run leaves the frame
        ax.set_ylabel(unit)
        ax.grid(True, alpha=0.3)
    axes[0].set_title("Hydraulic manipulator, body 6 (paper Fig. 5)")
    axes[0].legend(fontsize="x-small")
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
