"""Serial and parallel backends give bit-identical results (same ComponentRunner code)."""

from fractions import Fraction

import numpy as np
import pytest
from test_oscillator import oscillator

import master.api as api

CASES = {
    "jacobi order 2, start-up sweeps, polynomials to the FMUs": oscillator(
        Fraction(1, 20), 2, stop=Fraction(2)
    ),
    "gauss-seidel multirate 1:3": oscillator(
        Fraction(1, 20), 1, "gauss-seidel", ratios=(1, 3), interpolate=(True, False), stop=Fraction(2)
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_serial_and_parallel_are_bit_identical(case):
    sc = CASES[case]
    a = api.run(sc, backend="serial")
    b = api.run(sc, backend="parallel")
    assert a.data.dtype == b.data.dtype and len(a.data) == len(b.data) == 41
    for name in a.data.dtype.names:
        assert np.array_equal(a.data[name], b.data[name]), name
    assert a.summary.steps == b.summary.steps
