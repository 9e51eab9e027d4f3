"""The kernel's tables give the step-by-step arithmetic bit for bit.

A link's tables (master.runtime.tables.link_tables, read as kernel.c reads them) against the
polynomial of each step evaluated on its own; outputs read only where used, with unchanged results.
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
import master.runtime.tables as tables
from master.backends.component import samples_read
from master.coupling import weights
from master.runtime.tables import link_tables
from master.schedule import Link


def step_by_step(lk: Link, ring: np.ndarray, n: int, relaxed: bool, blocks, cols) -> np.ndarray:
    """The polynomial values of every step of macro step n, one step at a time: sum_i w_i y(j_end - i)
    in the order i = 0, 1, ... (derivatives per unit source step)."""
    cap = len(ring)
    out = np.zeros((len(blocks), lk.k_consumer, len(cols)))
    for m in range(lk.k_consumer):
        j = n * lk.k_consumer + m
        j_end, p = lk.window(n, j, relaxed)
        for b, (shift, d) in enumerate(blocks):
            if d <= p:
                w = weights(p, (j + shift) * lk.k_source - j_end * lk.k_consumer, lk.k_consumer, d)
                acc = w[0] * ring[j_end % cap, cols]
                for i in range(1, len(w)):
                    acc = acc + w[i] * ring[(j_end - i) % cap, cols]
                out[b, m] = acc
    return out


def from_tables(tabs, lk: Link, ring: np.ndarray, n: int, relaxed: bool, n_blocks: int, cols) -> np.ndarray:
    """The same values as kernel.c's fill_inputs computes them from the link's tables."""
    n_plain, n_relaxed, offsets, w, zero = tabs
    t = n_plain + 1 + min(n, n_relaxed) if relaxed else min(n, n_plain)
    cap, base = len(ring), n * lk.k_source
    out = np.zeros((n_blocks, lk.k_consumer, len(cols)))
    for m in range(lk.k_consumer):
        for b in range(n_blocks):
            if zero[t, b, m]:
                continue
            acc = w[t, b, 0, m] * ring[(base + offsets[t, 0, m]) % cap, cols]
            for q in range(1, lk.order + 1):
                acc = acc + w[t, b, q, m] * ring[(base + offsets[t, q, m]) % cap, cols]
            out[b, m] = acc
    return out


@pytest.mark.parametrize("order", [0, 1, 2, 3])
@pytest.mark.parametrize("ks,kc", [(1, 1), (1, 5), (5, 1), (3, 2), (2, 3)])
@pytest.mark.parametrize("first", [False, True])
def test_link_tables_equal_step_by_step_polynomials(order, ks, kc, first):
    rng = np.random.default_rng(100 * order + 10 * ks + kc)
    lk = Link("s", "c", ("a", "b"), ("u", "v"), order, first, ks, kc)
    blocks = [(0, 0), (1, 0)] + [(0, d) for d in range(1, 4)]
    cols = np.array([2, 0])
    tabs = link_tables(lk, blocks)
    ring = np.zeros((ks + order + 3, 3))
    for n in range(8):
        for j in range(n * ks + 1 if n else 0, (n + 1) * ks + 1):  # the source runs ahead by one macro step
            ring[j % len(ring)] = rng.normal(size=3) * 10.0 ** rng.integers(-3, 4, size=3)
        for relaxed in (False, True):
            got = from_tables(tabs, lk, ring, n, relaxed, len(blocks), cols)
            ref = step_by_step(lk, ring, n, relaxed, blocks, cols)
            assert got.tobytes() == ref.tobytes(), (n, relaxed)
    assert tabs[0] <= order + 1 and tabs[1] <= order + 1


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
    monkeypatch.setattr(tables, "samples_read", lambda plan, name: [True] * plan.component(name).step_ratio)
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
