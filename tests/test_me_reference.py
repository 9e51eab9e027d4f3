"""Model Exchange components integrated by the master against tight references.

vanderpol (no closed form) against scipy's Radau at rtol 1e-11 (checked against LSODA: the two
agree far below the smallest error measured): each of the six methods shows its order p, the error
falling by 2^p when the internal step halves, and the error is the method's asymptotic error
C h^p, which the solutions themselves estimate without the reference (Richardson:
y_h/2 - y_h/4 = (2^p - 1) C (h/4)^p). bouncing_ball, with its located events, against the closed
form: the methods exact on a flight miss by the event location alone, Euler's and the semi-implicit
Euler's error is exactly g h t / 2 over the fall and halves with h, the semi-implicit midpoint's
stays within its restarts' g h^2 per bounce.
"""

from __future__ import annotations

import itertools
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from test_me_events import EVENT_TOLERANCE, H0, E, G, bounces

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


def ball(solver: str, h: Fraction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = api.run(one("bouncing_ball", solver, h, BALL_STOP), backend="in-process").data
    return d["time"], d["bouncing_ball.h"], d["bouncing_ball.v"]


BALL_STOP = 2  # s: four bounces
BALL_STEPS = (Fraction(1, 400), Fraction(1, 800), Fraction(1, 1600))


def closed_form(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Height, velocity and the number of bounces so far of the ball at times t."""
    times = np.array(bounces(BALL_STOP))
    k = np.searchsorted(times, t, side="right")
    since = np.where(k > 0, t - times[np.maximum(k - 1, 0)], t)
    v_up = np.where(k > 0, E**k * math.sqrt(2 * G * H0), 0.0)
    start = np.where(k > 0, 0.0, H0)
    return start + v_up * since - G * since**2 / 2, v_up - G * since, k


@pytest.mark.parametrize("solver", ["ab2", "ab3", "rk4"])
def test_bouncing_ball_methods_exact_on_a_flight_miss_only_by_the_event_location(solver):
    """Flights are quadratics in t, which AB2, AB3 and RK4 integrate exactly (their history
    restarted by RK4 steps after each bounce): whatever the internal step, the height and velocity
    miss the closed form only by the bounces' lateness, at most 2 k location tolerances after
    bounce k (test_me_events), times the velocity jump at most (1 + e) v1, or (1 + e) g."""
    v1 = math.sqrt(2 * G * H0)
    for h in BALL_STEPS:
        t, height, v = ball(solver, h)
        exact_h, exact_v, k = closed_form(t)
        late = 2 * k * EVENT_TOLERANCE
        assert k[-1] == 4
        assert np.all(np.abs(height - exact_h) <= (1 + E) * v1 * late + 1e-12), h
        assert np.all(np.abs(v - exact_v) <= (1 + E) * G * late + 1e-12), h


@pytest.mark.parametrize("solver, sign", [("euler", 1), ("semi_implicit_euler", -1)])
def test_bouncing_ball_first_order_methods(solver, sign):
    """Euler's height over a fall is h0 - g h^2 n (n - 1) / 2 after n steps, the semi-implicit
    Euler's h0 - g h^2 n (n + 1) / 2: each misses the closed form by exactly g h t / 2 (above,
    below) until the first bounce; over the four bounces the error halves with the step."""
    worst = []
    for h in BALL_STEPS:
        t, height, _ = ball(solver, h)
        exact_h, _, k = closed_form(t)
        falling = k == 0
        np.testing.assert_allclose(height[falling] - exact_h[falling], sign * G * float(h) * t[falling] / 2,
                                   rtol=0, atol=1e-12)  # fmt: skip
        worst.append(float(np.max(np.abs(height - exact_h))))
    for coarse, fine in itertools.pairwise(worst):
        assert 1.8 < coarse / fine < 2.2, worst


def test_bouncing_ball_semi_implicit_midpoint():
    """The semi-implicit midpoint rule integrates a flight exactly once started, but it is a
    two-step method started by a semi-implicit Euler step (height error g h^2 / 2, velocity exact):
    restarted on each side of every located bounce, each bounce adds at most about g h^2 to the
    height error (it moves the later bounces by that over the impact speed, each of which passes on
    at most (1 + e) times the error). Exact until the first bounce; after bounce k within 2 k g h^2
    (second order: Euler's first-order error is 60 times that bound at h = 2.5 ms)."""
    for h in BALL_STEPS:
        t, height, _ = ball("semi_implicit_midpoint", h)
        exact_h, _, k = closed_form(t)
        error = np.abs(height - exact_h)
        assert np.all(error[k == 0] < 1e-12)
        bound = 2 * k * G * float(h) ** 2 + 1e-12
        assert np.all(error <= bound), (h, float(np.max(error / bound)))
