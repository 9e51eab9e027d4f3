"""Two-mass oscillator (numerics-facts.md, parameter set A) split into two msd FMUs.

The FMUs integrate with RK4 at 20 internal steps per communication step, so the error
measured against the exact solution (matrix exponential) is the coupling error.
"""

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import master.api as api
from master.evidence.oscillator import SET_A, SET_A_X1_10, SET_A_Z0, scene

STEPS = [Fraction(1, 10), Fraction(1, 20), Fraction(1, 40)]


def oscillator(H, order, coupling="jacobi", ratios=(1, 1), interpolate=(True, True), stop=Fraction(10)):
    """The benchmark, force split, RK4 with 20 internal steps per communication step."""
    return scene(
        split="force",
        macro_step=H,
        stop_time=stop,
        order=order,
        step_ratios=ratios,
        coupling=coupling,
        interpolate=interpolate,
        substeps=20,
        path=Path("oscillator.ssd"),
    )


def error(sc) -> float:
    d = api.run(sc).data
    exact = SET_A.exact(d["time"], SET_A_Z0)
    return float(np.max(np.abs(d["mass1.x"] - exact[:, 0])))


def slope(errs, steps=STEPS) -> float:
    return float(np.polyfit(np.log([float(h) for h in steps]), np.log(errs), 1)[0])


def test_reference_value_at_10s():
    d = api.run(oscillator(Fraction(1, 100), 2)).data
    assert d["time"][-1] == 10.0
    assert d["mass1.x"][-1] == pytest.approx(SET_A_X1_10, abs=1e-7)


@pytest.mark.parametrize("order", [0, 1, 2])
def test_jacobi_error_falls_with_order_plus_one(order):
    errs = [error(oscillator(h, order)) for h in STEPS]
    print(f"Jacobi order {order}: errors {errs}, slope {slope(errs):.2f}")
    assert slope(errs) == pytest.approx(order + 1, abs=0.3)


@pytest.mark.parametrize("k", [1, 2, 5, 10])
def test_multirate_converges(k):
    """mass2 steps k times per macro step with held inputs; mass1 gets the polynomials through
    its force samples, the macro-step ends' read again with the actual inputs, the inner ones
    with extrapolated ones: first order, reached from H = 1/20 s on (k = 2: 0.48 from 1/10 s)."""
    steps = [h / 2 for h in STEPS]
    errs = [error(oscillator(h, 1, ratios=(1, k), interpolate=(True, False))) for h in steps]
    print(f"multirate k = {k}: errors {errs}, slope {slope(errs, steps):.2f}")
    assert errs[0] > errs[1] > errs[2]
    assert slope(errs, steps) > 0.8
    assert errs[-1] < 5e-3


def test_gauss_seidel_beside_jacobi():
    """Equal steps, held inputs, order 0: both converge at first order; the errors are measured."""
    jac = [error(oscillator(h, 0, interpolate=(False, False))) for h in STEPS]
    gs = [error(oscillator(h, 0, "gauss-seidel", interpolate=(False, False))) for h in STEPS]
    print(f"Jacobi {jac}\nGauss-Seidel {gs}")
    assert slope(jac) == pytest.approx(1, abs=0.3) and slope(gs) == pytest.approx(1, abs=0.3)
    assert all(g != j for g, j in zip(gs, jac, strict=True))  # a different scheme indeed


def test_order_three_at_a_large_step_is_reported_unstable():
    # linear analysis: order 3 is stable up to H = 0.183 s; rho = 1.24 at 0.25 s
    with pytest.raises(api.SimulationError, match=r"unstable: mass\d\.\w+ at t=.*smaller macro step"):
        api.run(oscillator(Fraction(1, 4), 3, stop=Fraction(40)))
