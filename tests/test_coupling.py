"""Coupling polynomials against exact polynomials; stimuli."""

from fractions import Fraction

import numpy as np
import pytest

from master.coupling import lagrange_weights, stimulus_value
from master.scenario.model import Stimulus


def test_known_extrapolation_weights():
    assert lagrange_weights(0, Fraction(1)) == (1.0,)
    assert lagrange_weights(1, Fraction(1)) == (2.0, -1.0)
    assert lagrange_weights(2, Fraction(1)) == (3.0, -3.0, 1.0)
    assert lagrange_weights(3, Fraction(1)) == (4.0, -6.0, 4.0, -1.0)


@pytest.mark.parametrize("order", [0, 1, 2, 3])
@pytest.mark.parametrize("s", [Fraction(1), Fraction(1, 3), Fraction(0), Fraction(-1, 2), Fraction(5, 2)])
def test_weights_reproduce_polynomials_of_their_degree_and_derivatives(order, s):
    rng = np.random.default_rng(order)
    c = rng.normal(size=order + 1)
    poly = np.polynomial.Polynomial(c)
    samples = poly(-np.arange(order + 1.0))  # y(0), y(-1), ...
    for d in range(order + 1):
        w = np.array(lagrange_weights(order, s, d))
        assert w @ samples == pytest.approx(poly.deriv(d)(float(s)), abs=1e-12)
    # one degree more is not reproduced (for s off the nodes)
    if s not in [Fraction(-i) for i in range(order + 1)]:
        big = np.polynomial.Polynomial(np.r_[c, 1.0])
        w = np.array(lagrange_weights(order, s))
        assert abs(w @ big(-np.arange(order + 1.0)) - big(float(s))) > 1e-6


def test_stimuli():
    step = Stimulus("c", "u", "step", (1.0, 2.0), (5.0, -1.0))
    assert stimulus_value(step, 0.5, 7.0) == 7.0
    assert stimulus_value(step, 1.0, 7.0) == 5.0
    assert stimulus_value(step, 2.5, 7.0) == -1.0
    table = Stimulus("c", "u", "table", (0.0, 2.0), (0.0, 4.0))
    assert stimulus_value(table, 0.5, 0.0) == 1.0
    assert stimulus_value(table, 3.0, 0.0) == 4.0
