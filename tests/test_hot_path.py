"""The stepping loop's shortcuts give the step-by-step arithmetic bit for bit.

LinkBlock (all steps of a macro step at once) against History.combine step by step; stimulus
spans against point values; outputs read only where used, with unchanged results.
"""

import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from test_oscillator import oscillator

import master.api as api
import master.backends.component as component
from master.backends.component import _InLink, samples_read
from master.coupling import History, stimulus_span, stimulus_value, weights
from master.scenario.model import Stimulus
from master.schedule import Link


def step_by_step(lk: Link, hist: History, n: int, relaxed: bool, blocks, cols) -> np.ndarray:
    """The polynomial values of every step of macro step n, one step at a time (as before LinkBlock).

    Derivatives are per unit source step (the runner divides by h_s**d afterwards).
    """
    out = np.zeros((len(blocks), lk.k_consumer, len(cols)))
    for m in range(lk.k_consumer):
        j = n * lk.k_consumer + m
        j_end, p = lk.window(n, j, relaxed)
        for b, (shift, d) in enumerate(blocks):
            if d <= p:
                w = weights(p, (j + shift) * lk.k_source - j_end * lk.k_consumer, lk.k_consumer, d)
                hist.combine(j_end, w, cols, out[b, m])
    return out


@pytest.mark.parametrize("order", [0, 1, 2, 3])
@pytest.mark.parametrize("ks,kc", [(1, 1), (1, 5), (5, 1), (3, 2), (2, 3)])
@pytest.mark.parametrize("first", [False, True])
def test_link_block_equals_step_by_step_combine(order, ks, kc, first):
    rng = np.random.default_rng(100 * order + 10 * ks + kc)
    lk = Link("s", "c", ("a", "b"), ("u", "v"), order, first, ks, kc)
    blocks = [(0, 0), (1, 0)] + [(0, d) for d in range(1, 4)]
    cols = np.array([2, 0])
    il = _InLink(lk, cols, slice(0, 2), blocks, 0.37)
    hist = History(3, ks + order + 3)
    for n in range(8):
        for j in range(n * ks + 1 if n else 0, (n + 1) * ks + 1):  # the source runs ahead by one macro step
            hist.push(j, rng.normal(size=3) * 10.0 ** rng.integers(-3, 4, size=3))
        for relaxed in (False, True):
            out = np.empty((len(blocks), kc, 2))
            il.block(n, relaxed).evaluate(hist, n * ks, out)
            ref = step_by_step(lk, hist, n, relaxed, blocks, cols)
            assert out.tobytes() == ref.tobytes(), (n, relaxed)
    assert il.steady[False] <= order + 1


@pytest.mark.parametrize(
    "stim",
    [
        Stimulus("c", "u", "step", (0.1, 0.5, 0.5, 0.9), (1.0, -2.0, 3.0, 4.0)),
        Stimulus("c", "u", "table", (0.2, 0.4, 0.6, 0.6, 0.8), (1.0, 1.0, 3.0, -1.0, 0.5)),
    ],
    ids=["step", "table"],
)
def test_stimulus_span_holds_the_value_over_its_span(stim):
    for t in np.linspace(-0.1, 1.1, 241):
        v, lo, hi = stimulus_span(stim, float(t), 7.0)
        assert v == stimulus_value(stim, float(t), 7.0)
        assert lo <= t and (hi > t or lo == hi == t)
        inside = np.linspace(lo, hi, 9)[:-1] if np.isfinite(lo) and np.isfinite(hi) else [t]
        for s in inside:
            assert stimulus_value(stim, float(s), 7.0) == v


def test_outputs_are_read_where_a_consumer_or_the_recorder_uses_them():
    # mass1 steps 5 times per macro step; mass2 (one step) extrapolates from samples n k - i
    for order, reads in ((0, [False] * 4 + [True]), (2, [False, False, True, True, True])):
        plan = api.plan(oscillator(Fraction(1, 20), order, ratios=(5, 1), interpolate=(False, False)))
        assert samples_read(plan, "mass1") == reads
        assert samples_read(plan, "mass2") == [True]
    # mass2 steps 3 times per macro step; mass1 (one step, order 1) uses samples 3n and 3n - 1
    plan = api.plan(oscillator(Fraction(1, 20), 1, "gauss-seidel", ratios=(1, 3), interpolate=(False, False)))
    assert samples_read(plan, "mass2") == [False, True, True]


def test_reading_fewer_outputs_changes_no_result(monkeypatch):
    sc = oscillator(Fraction(1, 20), 0, ratios=(5, 1), interpolate=(False, False), stop=Fraction(2))
    fewer = api.run(sc)
    monkeypatch.setattr(component, "samples_read", lambda plan, name: [True] * plan.component(name).ratio)
    every = api.run(sc)
    assert fewer.summary.steps == every.summary.steps
    for name in fewer.data.dtype.names:
        assert fewer.data[name].tobytes() == every.data[name].tobytes(), name


def test_fmi3_fmu_through_the_raw_calls(tmp_path):
    """Lag3 (FMI 3.0, pythonfmu3) driven by body.x: Euler steps of the lag from the recorded inputs."""
    fmi3 = Path(__file__).parent / "scenarios" / "fmi3"
    subprocess.run(
        [sys.executable, "-m", "pythonfmu3", "build", "-f", str(fmi3 / "Lag3.py"), "-d", str(tmp_path)],
        check=True,
        capture_output=True,
        timeout=120,
    )
    shutil.copy(fmi3 / "lag_and_body.ssd", tmp_path)
    tau = 0.5
    res = api.run(tmp_path / "lag_and_body.ssd", set_values={"lag.tau": tau, "body.x0": 1.0})
    d = res.data
    assert res.summary.steps == {"lag": 200, "body": 100}
    assert list(d["lag.steps"]) == list(range(0, 201, 2))
    y = [0.0]
    for x in d["body.x"][:-1]:  # order 0: the lag holds body.x of the macro step start
        for _ in range(2):
            y.append(y[-1] + 0.005 * (x - y[-1]) / tau)
    np.testing.assert_allclose(d["lag.y"], y[::2], rtol=1e-14, atol=1e-300)
    assert np.abs(d["lag.y"]).max() > 0.1
