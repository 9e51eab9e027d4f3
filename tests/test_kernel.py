"""The compiled stepping kernel (master/runtime/kernel.c): clean C, numpy's arithmetic, paced frames.

Serial (the kernel) against the parallel backend's Python stepping, bit for bit, is in
tests/test_parallel.py; here the kernel's own pieces are checked against their definitions.
"""

import dataclasses
import shutil
import subprocess
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from test_run import build_pythonfmu

import master.api as api
from master.runtime import native
from master.scenario.model import Component, Scenario, Stimulus

ECHO = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Echo(Fmi2Slave):
    """y after a step is the input u set before it: the master's input values made visible."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = 0.0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.y = self.u
        return True
'''


@pytest.fixture(scope="module")
def echo(tmp_path_factory) -> Path:
    return build_pythonfmu("Echo", ECHO, tmp_path_factory.mktemp("echo"))


def test_kernel_compiles_warnings_clean(tmp_path):
    cc = shutil.which("cc") or shutil.which("gcc")
    flags = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-fPIC", "-shared"]
    includes = [f"-I{d}" for d in native.INCLUDES]  # with the shared solvers it links (Model Exchange)
    sources = [str(p) for p in (native.SOURCE, *native.SOLVER_SOURCES)]
    out = str(tmp_path / "k.so")
    run = subprocess.run([cc, *flags, *includes, *sources, "-o", out, "-lm"], capture_output=True)
    assert run.returncode == 0, run.stderr.decode()


def test_structures_agree_with_the_c_header():
    lib = native.library()  # raises if a ctypes mirror and its C structure differ in size
    sizes = (native._i64 * len(native.STRUCTS))()
    lib.mk_layout(sizes)
    assert [native.C.sizeof(s) for s in native.STRUCTS] == list(sizes)
    values = (native._i64 * len(native.CONSTANTS))()  # the constants both sides use, the String slot too
    lib.mk_constants(values)
    assert list(native.CONSTANTS.values()) == list(values)


def test_stimuli_are_numpys_interpolation_and_steps(echo):
    """Table stimuli with a jump (a repeated time), points exactly on breakpoints and beyond both
    ends, and a step stimulus: each communication point's input is np.interp / the step value."""
    times, values = (0.1, 0.25, 0.25, 0.5, 0.7), (1.0, 3.0, -2.0, 0.3, 1.0 / 3.0)
    sc = Scenario(
        path=Path("echo.ssd"),
        name="echo",
        components=(Component("table", echo, step_ratio=2), Component("step", echo)),
        connections=(),
        start_time=Fraction(0),
        stop_time=Fraction(1),
        macro_step=Fraction(1, 20),
        stimuli=(
            Stimulus("table", "u", "table", times, values),
            Stimulus("step", "u", "step", (0.25, 0.6), (4.0, 5.0)),
        ),
        record=(("table", "y"), ("step", "y")),
    )
    d = api.run(sc).data
    t_before = d["time"][1:] - 1 / 40  # the table component's last step of each macro step began here
    expected = [np.interp(float(Fraction(2 * n + 1, 40)), times, values) for n in range(20)]
    assert np.array_equal(d["table.y"][1:], expected)
    assert np.allclose(t_before, [float(Fraction(2 * n + 1, 40)) for n in range(20)])
    step_start = d["time"][:-1]  # the step component's input was set at the macro step's start
    np.testing.assert_array_equal(
        d["step.y"][1:], np.where(step_start < 0.25, 0.0, np.where(step_start < 0.6, 4.0, 5.0))
    )


def test_paced_run_reports_a_lateness_histogram(echo):
    sc = Scenario(
        path=Path("echo.ssd"),
        name="echo",
        components=(Component("e", echo),),
        connections=(),
        start_time=Fraction(0),
        stop_time=Fraction(1, 10),
        macro_step=Fraction(1, 500),
        stimuli=(Stimulus("e", "u", "step", (0.0,), (1.0,)),),
    )
    s = api.run(sc, real_time=1.0).summary
    assert s.wall_time > 0.095  # 50 frames of 2 ms, not faster (how close: benchmarks/realtime.py)
    late = s.lateness
    assert late is not None and 0 <= late["p50"] <= late["p99"] <= late["p99.9"] <= s.worst_lateness
    assert s.idle_time > 0 and "frame lateness: p50" in str(s)


@pytest.mark.parametrize("macro_step", [Fraction(1, 10), Fraction(1, 20), Fraction(1, 50)])
def test_coupling_error_estimate_tracks_the_true_coupling_error(macro_step):
    """On the two-mass oscillator, orders 0-3: the estimate of mass1.x -> mass2.x_in is within a
    factor of 3 of the connection's true coupling error (the value mass2 was given against the
    exact x1), and falls with the order as that error does."""
    from master.evidence.oscillator import estimate_against_truth

    found = [estimate_against_truth(macro_step, p) for p in range(4)]
    for est, link, _ in found:
        assert link / 3 <= est <= 3 * link
    assert all(a[0] > b[0] and a[1] > b[1] for a, b in zip(found, found[1:], strict=False))


@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_coupling_error_estimate_is_its_definition(order):
    """mass1.x -> mass2.x_in (Jacobi, order p): at each macro step end the sample the polynomial
    through y(n - i), i <= p, predicted against the sample then produced; max and RMS over the
    macro steps with full order, relative to the range of the samples seen (the last macro step
    is not estimated). Recomputed here from the recorded mass1.x."""
    from master.coupling import weights
    from master.evidence.oscillator import scene

    sc = scene(split="force", macro_step=Fraction(1, 20), stop_time=Fraction(3), order=order)
    r = api.run(sc)
    y = r.data["mass1.x"]
    w = weights(order, 1, 1)
    predicted = [sum(w[q] * y[n - 1 - q] for q in range(order + 1)) for n in range(order + 1, len(y) - 1)]
    diff = np.abs(np.array(predicted) - y[order + 1 : len(y) - 1])
    span = y[order : len(y) - 1].max() - y[order : len(y) - 1].min()
    est = r.summary.coupling_errors["mass1.x -> mass2.x_in"]
    assert est["max"] == pytest.approx(diff.max() / span, rel=1e-9)
    assert est["rms"] == pytest.approx(np.sqrt(np.mean(diff**2)) / span, rel=1e-9)
    if order:  # a higher order predicts better on this smooth signal
        lower = api.run(dataclasses.replace(sc, components=tuple(
            dataclasses.replace(c, extrapolation_order=order - 1) for c in sc.components
        ))).summary.coupling_errors["mass1.x -> mass2.x_in"]  # fmt: skip
        assert est["max"] < lower["max"]
