"""Linearisation of FMU scenes and measured stability limits, on the two-mass oscillator."""

from fractions import Fraction

import numpy as np
import pytest

from master.api import run
from master.evidence.linear import largest_stable_step, spectral_radius
from master.evidence.oscillator import SET_A, scene, split_scheme
from master.evidence.stability import linearize, measured_limit
from master.solvers import AB3, EULER

CFG = dict(split="force", solvers=(AB3, EULER), step_ratios=(1, 10))


@pytest.mark.parametrize("split", ["force", "displacement"])
def test_linearised_fmus_give_the_analytic_scheme(split):
    cfg = {**CFG, "split": split}
    lin = linearize(scene(order=2, **cfg), t=0.5)
    exact = split_scheme(SET_A, order=2, **cfg)
    for a, b in zip(lin.components, exact.components, strict=True):
        for m in "abcd":
            assert np.allclose(getattr(a, m), getattr(b, m), atol=1e-8), (a.name, m)
    for h in (0.05, 0.2):
        assert spectral_radius(lin, h) == pytest.approx(spectral_radius(exact, h), abs=1e-8)


def test_measured_limit_of_the_runtime_matches_the_prediction():
    predicted = largest_stable_step(split_scheme(SET_A, order=1, **CFG), 1e-2, 2.0, rel_tol=1e-3)

    def make_run(h):
        return lambda: run(scene(order=1, macro_step=h, stop_time=300 * h, **CFG))

    lo = Fraction(0.7 * predicted).limit_denominator(1000)
    hi = Fraction(1.4 * predicted).limit_denominator(1000)
    measured = float(measured_limit(make_run, lo, hi, rel_tol=0.02))
    assert measured == pytest.approx(predicted, rel=0.04)
