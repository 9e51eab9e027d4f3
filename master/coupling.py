"""Coupling signals: the polynomials through a source's samples, and stimuli.

A source's outputs are sampled at its communication points j = 0, 1, 2, ... (uniform spacing
h_s). The input of a consumer at time t is the Lagrange polynomial through samples
j_end - p .. j_end evaluated at s = (t - t_{j_end}) / h_s: s > 0 extrapolates, s <= 0
interpolates: sum_i w_i y(j_end - i), summed in the order i = 0, 1, ... (the kernel does exactly
this). Weights are computed exactly with rationals and cached, so the same step always gets
bit-identical inputs whatever backend runs it.
"""

from __future__ import annotations

from fractions import Fraction
from functools import lru_cache

import numpy as np

from master.scenario.model import Stimulus


@lru_cache(maxsize=4096)
def lagrange_weights(order: int, s: Fraction, derivative: int = 0) -> tuple[float, ...]:
    """Weights w_i, i = 0..order, of samples y(-i) for the `derivative`-th derivative at s.

    p(s) = sum_i w_i y(-i) is the polynomial of degree `order` through the nodes 0, -1, ..., -order
    (unit spacing); divide a derivative weight by h_s**derivative to get units per second.
    """
    nodes = [Fraction(-i) for i in range(order + 1)]
    out = []
    for i, xi in enumerate(nodes):
        # coefficients (lowest power first) of the basis polynomial l_i(x)
        coef = [Fraction(1)]
        denom = Fraction(1)
        for m, xm in enumerate(nodes):
            if m == i:
                continue
            coef = [Fraction(0)] + coef  # multiply by x
            for q in range(len(coef) - 1):
                coef[q] -= xm * coef[q + 1]
            denom *= xi - xm
        for _ in range(derivative):  # differentiate
            coef = [q * c for q, c in enumerate(coef)][1:] or [Fraction(0)]
        val = sum((c * s**q for q, c in enumerate(coef)), Fraction(0))
        out.append(float(val / denom))
    return tuple(out)


def weights(order: int, num: int, den: int, derivative: int = 0) -> np.ndarray:
    """`lagrange_weights` at s = num / den as a cached read-only float array."""
    return _weights_array(order, num, den, derivative)


@lru_cache(maxsize=4096)
def _weights_array(order: int, num: int, den: int, derivative: int) -> np.ndarray:
    w = np.array(lagrange_weights(order, Fraction(num, den), derivative))
    w.flags.writeable = False
    return w


def stimulus_value(stim: Stimulus, t: float, start_value: float) -> float:
    """Value of a step or table stimulus at time t (s)."""
    times, values = stim.times, stim.values
    if stim.kind == "step":
        if t < times[0]:
            return start_value
        i = int(np.searchsorted(times, t, side="right")) - 1
        return float(values[i])
    return float(np.interp(t, times, values))
