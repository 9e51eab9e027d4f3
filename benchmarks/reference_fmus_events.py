"""The Reference-FMUs BouncingBall and Stair (FMI 3, event mode) run by the master against their
reference results and fmpy's event-mode simulation: a check, not part of the tests (the project
holds no third-party code and no built FMU).

    git clone https://github.com/modelica/Reference-FMUs
    .venv/bin/python benchmarks/reference_fmus_events.py Reference-FMUs

Each model is compiled from the checkout (cc, its src/fmi3Functions.c and src/cosimulation.c) into
an FMU in a temporary folder with its FMI3.xml, run at its reference's output interval (BouncingBall
10 ms to 3 s, Stair 0.2 s to 10 s) in every backend, and compared at every communication point with
<Model>/<Model>_out.csv (an event's time listed twice there: its last row) and with
fmpy.simulate_fmu(use_event_mode=True, early_return_allowed=True) on the points both have.
Printed: the largest difference per variable.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import tempfile
import zipfile
from fractions import Fraction
from pathlib import Path

import fmpy
import numpy as np

import master.api as api
from master.scenario.model import Component, Scenario

MODELS = {"BouncingBall": ("0.01", "3", ["h", "v"]), "Stair": ("0.2", "10", ["counter"])}


def build(checkout: Path, model: str, into: Path) -> Path:
    """<model>.fmu in `into`, compiled from the checkout."""
    so = into / f"{model}.so"
    sources = [
        checkout / "src" / "fmi3Functions.c",
        checkout / "src" / "cosimulation.c",
        checkout / model / "model.c",
    ]
    cc = shutil.which("cc") or "gcc"
    flags = ["-shared", "-fPIC", "-O2", "-DFMI_VERSION=3", "-DDISABLE_PREFIX", "-Wl,--no-undefined"]
    includes = [f"-I{checkout / 'include'}", f"-I{checkout / model}"]
    subprocess.run([cc, *flags, *includes, *map(str, sources), "-o", str(so), "-lm"], check=True)
    fmu = into / f"{model}.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.write(checkout / model / "FMI3.xml", "modelDescription.xml")
        z.write(so, f"binaries/x86_64-linux/{model}.so")
    return fmu


def at_points(rows: np.ndarray, step: float) -> np.ndarray:
    """The rows at the communication points (after an event there: the last row of that time)."""
    t = rows["time"]
    last = np.r_[t[1:] != t[:-1], True]
    return rows[last & np.isclose(t / step, np.round(t / step), rtol=0, atol=1e-9)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkout", type=Path, help="a checkout of github.com/modelica/Reference-FMUs")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for model, (step, stop, columns) in MODELS.items():
            fmu = build(args.checkout, model, Path(tmp))
            h, end = Fraction(step), Fraction(stop)
            sc = Scenario(Path(f"{model}.ssd"), model, (Component(model, fmu),), (), Fraction(0), end, h)
            csv = np.genfromtxt(args.checkout / model / f"{model}_out.csv", delimiter=",", names=True)
            ref = at_points(csv, float(h))
            ours = fmpy.simulate_fmu(
                str(fmu), stop_time=float(end), output_interval=float(h), output=columns,
                use_event_mode=True, early_return_allowed=True,
            )  # fmt: skip
            single = at_points(ours, float(h))
            for backend in ("serial", "parallel", "in-process"):
                d = api.run(sc, backend=backend).data
                n = min(len(d), len(single))
                assert len(d) == len(ref) and np.allclose(d["time"], ref["time"], rtol=0, atol=1e-12)
                for c in columns:
                    to_ref = np.max(np.abs(d[f"{model}.{c}"] - ref[c]))
                    to_fmpy = np.max(np.abs(d[f"{model}.{c}"][:n] - single[c][:n]))
                    print(f"{model} {backend:10s} {c:8s} |master - reference| <= {to_ref:.3g}, "
                          f"|master - fmpy event mode| <= {to_fmpy:.3g} ({len(d)} points)")  # fmt: skip


if __name__ == "__main__":
    main()
