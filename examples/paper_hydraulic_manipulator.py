"""The paper's experiment 1 (Sec. 4.1, Fig. 5): the hydraulically actuated manipulator.

Runs, over the paper's 3 s with the spool steps at t = 0:
- single-rate: mechanics and hydraulics both AB3 at 2e-4 s, Jacobi (the paper's comparison run),
- dual-rate as in the paper: hydraulics Euler at 2e-4 s, mechanics AB3 at 1e-3 s (ratio 5),
  both integrated concurrently (Jacobi), the hydraulics extrapolating the strokes with order
  0 to 3 (the scene: order 2),
- the same dual rate with Gauss-Seidel coupling (hydraulics first, order 2),
and the monolithic Model Exchange reference (Radau, rtol 1e-10).  Plots the vertical position,
velocity and acceleration of body 6 (Fig. 5) and prints the measured errors against the
reference and the differences from the single-rate run.

Run: .venv/bin/python examples/paper_hydraulic_manipulator.py [--out docs/evidence]
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
from fractions import Fraction
from pathlib import Path

import numpy as np

from master.api import load_scenario, run
from master.backends.component import SimulationError
from master.evidence.errors import as_trajectory, compare
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


def configure(
    sc: Scenario, macro: Fraction, hyd_solver: int, ratio: int, coupling: str, order: int = 2
) -> Scenario:
    """The scene with its macro step (s), the hydraulics' solver, step ratio and extrapolation
    order of the strokes, AB3 mechanics holding the forces."""
    comps = []
    for c in sc.components:
        hyd = c.name == "hydraulics"
        params = {**c.parameters, "solver": hyd_solver if hyd else AB3, "internal_step": 0.0}
        comps.append(dataclasses.replace(c, parameters=params, step_ratio=ratio if hyd else 1,
                                         extrapolation_order=order if hyd else 0))  # fmt: skip
    conns = tuple(dataclasses.replace(c, extrapolation_order=None) for c in sc.connections)
    first = ("hydraulics", "mechanics") if coupling == "gauss-seidel" else ()
    return dataclasses.replace(sc, components=tuple(comps), connections=conns, macro_step=macro,
                               record_interval=Fraction(1, 1000), coupling=coupling, order=first)  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "evidence"), help="folder for the figure and table")
    ap.add_argument("--stop-time", default="3", help="s (the paper: 3)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    sc = dataclasses.replace(load_scenario(SCENE), stop_time=Fraction(a.stop_time))
    runs = {"single-rate AB3 2e-4 s": configure(sc, Fraction(2, 10000), AB3, 1, "jacobi")}
    for k in range(4):
        label = f"dual-rate Jacobi, order {k}" + (" (the scene)" if k == 2 else "")
        runs[label] = configure(sc, Fraction(1, 1000), EULER, 5, "jacobi", k)
    runs["dual-rate Gauss-Seidel, order 2"] = configure(sc, Fraction(1, 1000), EULER, 5, "gauss-seidel")
    ref_scene = dataclasses.replace(sc, macro_step=Fraction(1, 1000), record_interval=Fraction(1, 1000))
    ref = reference(ref_scene)
    results, rows = {}, []
    names = [s for s, _ in SIGNALS]
    for label, scene in runs.items():
        try:
            res = run(scene)
            status = "finished"
        except SimulationError as e:
            res, status = e.result, str(e).split(" (hint")[0]
        traj = as_trajectory(res.data)
        results[label] = traj
        err = compare(traj, ref, names).max_error
        diff = compare(traj, results["single-rate AB3 2e-4 s"], names).max_error
        rows.append([label, f"{res.summary.wall_time:.3f}", status]
                    + [f"{err[s]:.3e}" for s in names] + [f"{diff[s]:.3e}" for s in names])  # fmt: skip

    out.mkdir(parents=True, exist_ok=True)
    with open(out / "fig5_hydraulic_manipulator.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["run", "wall_time_s", "status"] + [f"error_{s}" for s in names]
                   + [f"vs_single_rate_{s}" for s in names])  # fmt: skip
        w.writerows(rows)
    shown = [
        "single-rate AB3 2e-4 s",
        "dual-rate Jacobi, order 2 (the scene)",
        "dual-rate Gauss-Seidel, order 2",
    ]
    plot({k: results[k] for k in shown}, ref, out / "fig5_hydraulic_manipulator.png")

    short = [s.split(".")[1] for s in names]
    print(f"{'':40} {'':>9}  {'error against the reference':^35}  {'difference from single-rate':^35}")
    print(f"{'run':40} {'wall [s]':>9}  " + "  ".join(f"{n:>11}" for n in short + short))
    for r in rows:
        print(f"{r[0]:40} {r[1]:>9}  " + "  ".join(f"{v:>11}" for v in r[3:])
              + ("" if r[2] == "finished" else f"  {r[2]}"))  # fmt: skip
    print(
        "errors: max |difference| over the run / range of the reference (single-rate run for the right half)"
    )
    scene, single = results["dual-rate Jacobi, order 2 (the scene)"], results["single-rate AB3 2e-4 s"]
    print(recording_lag(scene, ref, "mechanics.body6_az"))
    dv = np.abs(scene.values["mechanics.body6_vz"] - single.values["mechanics.body6_vz"])
    worst = scene.time[dv.argmax()]
    print(f"the scene's largest v_z difference from single-rate: {dv.max():.2e} m/s at t = {worst:g} s")
    return 0


def recording_lag(traj, ref, sig: str) -> str:
    """The scene's error in `sig` after the start against the reference at the same time and one
    macro step (1 ms) earlier: an output read with inputs held from the previous step lags."""
    assert np.allclose(traj.time, ref.time), "run and reference must share the 1 ms grid"
    y, r = traj.values[sig][1:], ref.values[sig]
    span = np.ptp(r)
    parts = []
    for after in (0.01, 0.05):
        m = traj.time[1:] >= after
        now, before = np.abs(y - r[1:])[m].max() / span, np.abs(y - r[:-1])[m].max() / span
        parts.append(f"after {after:g} s {now:.3f} (same time) / {before:.3f} (1 ms earlier)")
    return f"the scene's {sig.split('.')[1]} error against the reference, " + "; ".join(parts)


def plot(results: dict, ref, path: Path) -> None:
    """Fig. 5: body 6 vertical position, velocity, acceleration over the run (left) and over
    the first 0.3 s, where the valve steps ring (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 2, figsize=(12, 8), sharex="col", gridspec_kw={"width_ratios": [3, 2]})
    for row, (sig, unit) in zip(axes, SIGNALS, strict=True):
        for ax in row:
            ax.plot(ref.time, ref.values[sig], "k-", lw=2.5, alpha=0.35, label="reference (ME, Radau)")
            for (label, traj), style in zip(results.items(), ["-", "--", ":"], strict=True):
                ax.plot(traj.time, traj.values[sig], style, lw=1, label=label)
            lo, hi = ref.values[sig].min(), ref.values[sig].max()
            ax.set_ylim(lo - 0.5 * (hi - lo), hi + 0.5 * (hi - lo))  # a growing run leaves the frame
            ax.grid(True, alpha=0.3)
        row[0].set_ylabel(unit)
        row[1].set_xlim(0.0, 0.3)
    axes[0, 0].set_title("Hydraulic manipulator, body 6 (paper Fig. 5)")
    axes[0, 1].set_title("first 0.3 s")
    axes[0, 0].legend(fontsize="x-small")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
