"""Coupling signals: output history ring buffers and the polynomials through them.

A source's outputs are sampled at its communication points j = 0, 1, 2, ... (uniform spacing
h_s). The input of a consumer at time t is the Lagrange polynomial through samples
j_end - p .. j_end evaluated at s = (t - t_{j_end}) / h_s: s > 0 extrapolates, s <= 0
interpolates. Weights are computed exactly with rationals and cached, so the same step
always gets bit-identical inputs whatever backend runs it.

`LinkBlock` evaluates one link's polynomials for all steps of a macro step at once (one gather
from the history, one multiply, one add per further sample), in the same floating-point
operations as `History.combine` step by step.
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


class History:
    """The last `capacity` output samples of one component: row j % capacity holds sample j."""

    def __init__(self, n_values: int, capacity: int, buf: np.ndarray | None = None):
        """`buf` (capacity x n_values float64), e.g. in shared memory; None: a private array."""
        self.capacity = capacity
        self.buf = np.zeros((capacity, n_values)) if buf is None else buf

    def copy(self) -> History:
        """An independent copy (a start-up sweep reads the previous sweep's samples from it)."""
        return History(self.buf.shape[1], self.capacity, self.buf.copy())

    def push(self, j: int, values: np.ndarray) -> None:
        """Store sample j (must be the next one)."""
        self.buf[j % self.capacity] = values

    def combine(self, j_end: int, w: np.ndarray, columns: np.ndarray, out: np.ndarray) -> None:
        """out = sum_i w[i] * sample(j_end - i)[columns]: the polynomial's value (or derivative)."""
        cap = self.capacity
        buf = self.buf
        out[:] = w[0] * buf[j_end % cap, columns]
        for i in range(1, len(w)):
            out += w[i] * buf[(j_end - i) % cap, columns]


class LinkBlock:
    """Polynomial values of one link for a block of consumer steps: out[b, m, c] for b < B, m < k.

    Value b at step m is sum_i weights[b, i, m] * sample(base + offsets[i, m])[columns[c]], summed
    in the order i = 0, 1, ... (as `History.combine`), where base is a multiple of the source's
    step ratio given per call. Gather indices are cached per ring position of `base`.
    """

    def __init__(
        self, columns: np.ndarray, offsets: np.ndarray, weights: np.ndarray, zero: np.ndarray | None = None
    ):
        """columns: history columns (nc); offsets: int (terms, k); weights: (B, terms, k);
        zero: bool (B, k), values that are exactly 0.0 whatever the samples (e.g. a derivative
        beyond the polynomial's degree; a zero-weighted sum could give -0.0)."""
        self.columns = np.asarray(columns, dtype=np.intp)
        self.offsets = np.asarray(offsets, dtype=np.intp)
        self.weights = np.ascontiguousarray(weights, dtype=np.float64)[..., np.newaxis]
        terms, k = self.offsets.shape
        self.gathered = np.empty((terms, k, len(self.columns)))
        self.products = np.empty((self.weights.shape[0], terms, k, len(self.columns)))
        # one term of weight 1 (order 0): the samples themselves, no arithmetic
        self.copy = terms == 1 and bool((self.weights == 1.0).all())
        self.zero = zero if zero is not None and zero.any() else None
        self._shape: tuple[int, ...] = ()  # history shape the cached indices are for
        self._index: dict[int, np.ndarray] = {}

    def evaluate(self, history: History, base: int, out: np.ndarray) -> None:
        """out (B, k, nc), e.g. a view into a larger array: the polynomial values from `base` on."""
        buf = history.buf
        if buf.shape != self._shape:
            self._shape, self._index = buf.shape, {}
        cap = buf.shape[0]
        idx = self._index.get(base % cap)
        if idx is None:
            rows = (base + self.offsets) % cap
            idx = self._index[base % cap] = rows[:, :, np.newaxis] * buf.shape[1] + self.columns
        g = self.gathered
        buf.take(idx, None, g, "clip")
        if self.copy:
            out[...] = g
        elif len(g) == 1:
            np.multiply(self.weights[:, 0], g[0], out)
        else:  # terms in order: (w0 y0 + w1 y1) + w2 y2 ...
            np.multiply(self.weights, g, self.products)
            np.add.reduce(self.products, 1, None, out)
        if self.zero is not None:
            out[self.zero] = 0.0


def stimulus_span(stim: Stimulus, t: float, start_value: float) -> tuple[float, float, float]:
    """(value at t, lo, hi): the stimulus equals that value at every time in [lo, hi) (s).

    lo == hi (== t) where the value changes around t (a sloped table segment).
    """
    times, values = stim.times, stim.values
    if t < times[0]:
        return (start_value if stim.kind == "step" else float(values[0])), -np.inf, float(times[0])
    if stim.kind == "step":
        i = int(np.searchsorted(times, t, side="right")) - 1
        hi = float(times[i + 1]) if i + 1 < len(times) else np.inf
        return float(values[i]), float(times[i]), hi
    if t >= times[-1]:
        return float(values[-1]), float(times[-1]), np.inf
    return float(np.interp(t, times, values)), t, t


def stimulus_value(stim: Stimulus, t: float, start_value: float) -> float:
    """Value of a step or table stimulus at time t (s)."""
    times, values = stim.times, stim.values
    if stim.kind == "step":
        if t < times[0]:
            return start_value
        i = int(np.searchsorted(times, t, side="right")) - 1
        return float(values[i])
    return float(np.interp(t, times, values))
