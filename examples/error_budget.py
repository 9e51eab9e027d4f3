"""Error budget of a paper scene's dual-rate runs, per source, against the Model Exchange reference.

    .venv/bin/python examples/error_budget.py [--out docs/evidence]

For the hydraulic manipulator (mechanics AB3 at H = 1 ms, hydraulics Euler at H/5, strokes
extrapolated with order 2, Jacobi; 1 s) and the DC-motor arm (mechanics AB3 at 20 ms, motors
Euler at H/4, order 0; 3.6 s), and for the configurations `master tune` found at the single-rate
baselines' errors (README "Tuning"), it runs the scene as it is, then with one source taken away at a
time, and reports the bench's error (worst scaled max error over the paper's variables) and each
variable's:
- mechanics solver: the mechanics integrates with 20 internal steps per communication step;
- control solver: the control side likewise;
- both solvers: what is left is the coupling (extrapolation over the macro step), start-up
  included; the same with the macro step halved shows how the coupling part scales;
- start-up: the error of the as-is run after the first 50 macro steps only;
- output sampling: nothing to take away (resampling reads every input-dependent output with the
  inputs of its time; docs/evidence/README.md).
Writes OUT/error_budget.txt.
"""

from __future__ import annotations

import argparse
import dataclasses
from fractions import Fraction
from pathlib import Path

import numpy as np

from master.api import load_scenario, run
from master.evidence.bench import AB2, Config, apply, base_scene, profile_for
from master.evidence.errors import as_trajectory, variable_range
from master.evidence.reference import reference

ROOT = Path(__file__).resolve().parents[1]
SCENES = [  # the paper's dual-rate runs, then what `master tune` found at the baselines' errors
    ("hydraulic-manipulator", Config("dual-rate", Fraction(1, 1000), ratio=5, order=2)),
    ("dc-motor-arm", Config("dual-rate", Fraction(2, 100), ratio=4, order=0)),
    ("hydraulic-manipulator", Config("dual-rate", Fraction(1, 800), ratio=4, order=3, ctrl_solver=AB2,
                                     control_first=True, mech_order=2, mech_substeps=2)),
    ("dc-motor-arm", Config("dual-rate", Fraction(1, 200), ratio=2, order=3, control_first=True, mech_order=3,
                            mech_substeps=2)),
]  # fmt: skip
SUBSTEPS = 20


def refined(sc, names: tuple[str, ...], steps: int = SUBSTEPS):
    """The scene with `names` integrating `steps` solver steps per communication step."""
    comps = []
    for c in sc.components:
        if c.name in names:
            h = sc.macro_step / c.step_ratio
            c = dataclasses.replace(c, parameters={**c.parameters, "internal_step": float(h / steps)})
        comps.append(c)
    return dataclasses.replace(sc, components=tuple(comps))


def errors(data: np.ndarray, ref, variables: list[str], after: float = -1.0) -> dict[str, float]:
    """Scaled max error per variable on the shared grid (times > after only)."""
    res = as_trajectory(data)
    common, i_res, i_ref = np.intersect1d(np.round(res.time, 12), np.round(ref.time, 12), return_indices=True)
    keep = common > after
    out = {}
    for v in variables:
        y, y_ref = res.values[v][i_res][keep], ref.values[v][i_ref][keep]
        out[v] = float(np.max(np.abs(y - y_ref)) / variable_range(ref.values[v]))
    return out


def budget(name: str, config: Config) -> list[str]:
    path = ROOT / "models" / name / "SystemStructure.ssd"
    sc = load_scenario(path)
    p = profile_for(sc)
    ref = reference(base_scene(sc, p))
    variables = list(p.variables)
    scene = apply(sc, p, config)
    mech, ctrl = p.mechanics, p.control
    halved = dataclasses.replace(config, macro_step=config.macro_step / 2)
    runs = [
        ("as it is", scene, -1.0),
        ("mechanics solver x20", refined(scene, mech), -1.0),
        ("control solver x20", refined(scene, ctrl), -1.0),
        ("both solvers x20 (coupling left)", refined(scene, mech + ctrl), -1.0),
        ("both x20, macro step halved", refined(apply(sc, p, halved), mech + ctrl), -1.0),
        ("as it is, after 50 macro steps", scene, 50 * float(config.macro_step)),
    ]
    short = [v.split(".")[1] for v in variables]
    lines = [f"{name}: {config.label}", f"{'run':<36} {'worst':>10} " + " ".join(f"{s:>10}" for s in short)]
    for label, s, after in runs:
        e = errors(run(s, backend="in-process").data, ref, variables, after)
        lines.append(f"{label:<36} {max(e.values()):10.3e} " + " ".join(f"{e[v]:10.3e}" for v in variables))
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "evidence"))
    out = Path(ap.parse_args().out)
    text = []
    for name, config in SCENES:
        text += budget(name, config) + [""]
    text.append("errors: max |y - y_ref| / range(y_ref) over the paper's variables; x20: 20 solver steps per")
    text.append("communication step (internal_step); the reference is the scene's Model Exchange solution")
    (out / "error_budget.txt").write_text("\n".join(text) + "\n")
    print("\n".join(text))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
