"""Two-mass oscillator benchmark (parameter set A) split into two msd FMUs: error table.

Run: .venv/bin/python examples/oscillator.py
Global error = max over the macro points of |x1 - x1_exact| on [0, 10] s, exact solution from
the matrix exponential. The FMUs integrate with RK4 at a fine internal step, so the error is
the coupling error.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

import master.api as api
from master.evidence.oscillator import SET_A, SET_A_Z0, scene
from master.scenario.model import Scenario

SUBSTEPS = 20  # RK4 steps inside each communication step of the FMUs


def oscillator(
    H: Fraction,
    order: int,
    coupling: str = "jacobi",
    ratios: tuple[int, int] = (1, 1),
    interpolate: bool = True,
    interpolate_mass1: bool | None = None,
    stop: Fraction = Fraction(10),
) -> Scenario:
    """The benchmark scene: mass1 (input F) and mass2 with the coupling (output F_c)."""
    first = interpolate if interpolate_mass1 is None else interpolate_mass1
    return scene(
        split="force",
        macro_step=H,
        stop_time=stop,
        order=order,
        step_ratios=ratios,
        coupling=coupling,
        interpolate=(first, interpolate),
        substeps=SUBSTEPS,
    )


def global_error(sc: Scenario) -> float:
    """Max |x1 - exact| over the recorded points (m); inf if the run diverged."""
    try:
        d = api.run(sc).data
    except api.SimulationError:
        return float("inf")
    exact = SET_A.exact(d["time"], SET_A_Z0)
    return float(np.max(np.abs(d["mass1.x"] - exact[:, 0])))


def slope(hs: list[float], errs: list[float]) -> float:
    """Least-squares slope of log(error) over log(H) (nan if a run diverged)."""
    if not np.all(np.isfinite(errs)):
        return float("nan")
    return float(np.polyfit(np.log(hs), np.log(errs), 1)[0])


def fl(steps: list[Fraction]) -> list[float]:
    return [float(h) for h in steps]


def main() -> None:
    steps = [Fraction(1, 10), Fraction(1, 20), Fraction(1, 40)]
    print("Jacobi, inputs handed to the FMUs as polynomials (canInterpolateInputs)")
    print(f"{'order':>5} " + " ".join(f"{'H=' + str(float(h)):>10}" for h in steps) + "  slope")
    for order in (0, 1, 2, 3):
        errs = [global_error(oscillator(h, order)) for h in steps]
        print(f"{order:>5} " + " ".join(f"{e:10.3e}" for e in errs) + f"  {slope(fl(steps), errs):5.2f}")
    print("\nGauss-Seidel (mass1 first) beside Jacobi, order 0, held inputs")
    for coupling in ("jacobi", "gauss-seidel"):
        errs = [global_error(oscillator(h, 0, coupling, interpolate=False)) for h in steps]
        print(f"{coupling:>12} " + " ".join(f"{e:10.3e}" for e in errs) + f"  {slope(fl(steps), errs):5.2f}")
    print("\nMultirate: mass2 steps k times per macro step (held inputs), mass1 gets polynomials, order 1")
    for k in (1, 2, 5, 10):
        errs = [
            global_error(oscillator(h, 1, ratios=(1, k), interpolate=False, interpolate_mass1=True))
            for h in steps
        ]
        print(
            f"{'k = ' + str(k):>12} "
            + " ".join(f"{e:10.3e}" for e in errs)
            + f"  {slope(fl(steps), errs):5.2f}"
        )


if __name__ == "__main__":
    main()
