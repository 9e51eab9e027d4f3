"""The coupling error estimate as recorded columns (`record_coupling_errors`, `--record-coupling-errors`,
`<mm:Record couplingErrors="true">`): per extrapolated connection the latest |prediction - sample|
of the consumer's polynomial, the row at time t showing the prediction of the source's sample at
t - H. Real FMUs: the two-mass oscillator of two msd FMUs, the FMI 3 alltypes chain.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from fmpy.util import read_csv

import master.api as api
from master.coupling import weights
from master.evidence.oscillator import scene
from master.recorder import result_figure
from master.scenario import validate

OSCILLATOR = Path(__file__).parent / "scenarios" / "oscillator" / "oscillator.ssd"
BACKENDS = ("serial", "parallel", "in-process")
X = "coupling_error(mass1.x -> mass2.x_in)"
V = "coupling_error(mass1.v -> mass2.v_in)"
F = "coupling_error(mass2.F_c -> mass1.F)"
RECORD = ["mass1.x", "mass1.v", "mass2.F_c"]  # the sources of the three connections


def latest_errors(y: np.ndarray, order: int) -> np.ndarray:
    """What the column of a connection whose source's macro-step samples are y (one row per macro
    step, row r at t_r) holds: row r (after macro step n = r - 1) the error found at the start of
    macro step n, |p(t_n) - y(t_n)| with p the order-`order` polynomial through y(t_n-1-q), q <=
    order, made in macro step n - 1; 0 until the first full-order prediction (n > order)."""
    w = weights(order, 1, 1)
    out = np.zeros(len(y))
    for r in range(order + 2, len(y)):
        n = r - 1
        predicted = sum(w[q] * y[n - 1 - q] for q in range(order + 1))
        out[r] = abs(predicted - y[n])
    return out


@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_the_column_is_the_latest_prediction_error_and_its_max_the_summarys(order):
    sc = scene(split="force", macro_step=Fraction(1, 20), stop_time=Fraction(3), order=order)
    r = api.run(sc, record=RECORD, record_coupling_errors=True)
    d = r.data
    assert list(d.dtype.names) == ["time", *RECORD, X, V, F]
    assert len(d) == 61  # a row every macro step
    n_macro = len(d) - 1
    for column, source in ((X, "mass1.x"), (V, "mass1.v"), (F, "mass2.F_c")):
        y = d[source]
        expected = latest_errors(y, order)
        assert np.array_equal(d[column], expected), (column, np.abs(d[column] - expected).max())
        assert (d[column][: order + 2] == 0).all() and (d[column][order + 2 :] > 0).all()
        # the summary: max and RMS over the same errors, relative to the range of the samples seen
        # (macro steps order .. n_macro - 1)
        span = y[order:n_macro].max() - y[order:n_macro].min()
        est = r.summary.coupling_errors[column[len("coupling_error(") : -1]]
        assert est["max"] == d[column].max() / span
        errors = d[column][order + 2 :]
        assert est["rms"] == pytest.approx(np.sqrt(np.mean(errors**2)) / span, rel=1e-12)


@pytest.mark.parametrize(
    "step_ratios, coupling", [((1, 1), "jacobi"), ((2, 3), "jacobi"), ((3, 2), "gauss-seidel")]
)
def test_serial_parallel_and_in_process_record_the_same_bits(step_ratios, coupling):
    sc = scene(split="force", macro_step=Fraction(1, 20), stop_time=Fraction(2), order=2,
               step_ratios=step_ratios, coupling=coupling)  # fmt: skip
    runs = {b: api.run(sc, backend=b, record_coupling_errors=True) for b in BACKENDS}
    names = runs["serial"].data.dtype.names
    # Gauss-Seidel, mass1 first: its outputs drive mass2 interpolated, no estimate
    assert names[5:] == ((X, V, F) if coupling == "jacobi" else (F,))
    for b, res in runs.items():
        assert res.data.dtype.names == names
        for n in names:
            assert res.data[n].tobytes() == runs["serial"].data[n].tobytes(), (b, n)
        assert res.summary.coupling_errors == runs["serial"].summary.coupling_errors
    assert runs["serial"].data[F].max() > 0


def test_rows_recorded_less_often_show_the_same_latest_errors():
    sc = scene(split="force", macro_step=Fraction(1, 20), stop_time=Fraction(2), order=1, step_ratios=(2, 1))
    every = api.run(sc, record_coupling_errors=True).data
    fifth = api.run(sc, record_coupling_errors=True, output_interval="0.25").data
    assert len(fifth) == 9
    picked = every[np.isin(every["time"], fifth["time"])]
    for n in (X, V, F):
        assert np.array_equal(fifth[n], picked[n]), n


def test_held_discrete_connections_get_no_column():
    from test_typed_connections import chain

    sc = dataclasses.replace(chain("jacobi", 1, 3), record_coupling_errors=True)
    plan = api.plan(sc)
    assert set(plan.record_errors) == {
        ("a", "y_float64", "b", "u_float64"),
        ("a", "y_float32", "b", "u_float32"),
    }
    runs = {b: api.run(sc, backend=b).data for b in BACKENDS}
    added = plan.columns[1 + len(plan.record) :]
    f32 = "coupling_error(a.y_float32 -> b.u_float32)"
    assert sorted(added) == [f32, "coupling_error(a.y_float64 -> b.u_float64)"]
    for b, d in runs.items():
        for n in added:
            assert d[n].tobytes() == runs["serial"][n].tobytes(), (b, n)
    assert runs["serial"][f32].max() > 0  # a.y_float32 follows a table: a kink is mispredicted


def test_without_the_option_nothing_changes():
    sc = scene(split="force", macro_step=Fraction(1, 20), stop_time=Fraction(2), order=2)
    plain = api.run(sc).data
    assert list(plain.dtype.names) == ["time", "mass1.x", "mass1.v", "mass2.x", "mass2.v"]
    assert api.plan(sc).record_errors == ()
    with_errors = api.run(sc, record_coupling_errors=True).data
    for n in plain.dtype.names:
        assert np.array_equal(plain[n], with_errors[n]), n


@pytest.fixture
def oscillator(tmp_path) -> Path:
    """A copy of tests/scenarios/oscillator (Gauss-Seidel, mass2 first: mass2.F_c -> mass1.F is
    interpolated, mass1's outputs to mass2 extrapolated; a row every 10 macro steps)."""
    folder = tmp_path / "oscillator"
    shutil.copytree(OSCILLATOR.parent, folder)
    return folder / OSCILLATOR.name


def with_attribute(path: Path, value: str) -> Path:
    text = path.read_text()
    path.write_text(
        text.replace('<mm:Record interval="0.1">', f'<mm:Record interval="0.1" couplingErrors="{value}">')
    )
    assert path.read_text() != text
    return path


def test_a_scene_file_with_coupling_errors_true_validates_and_records_them(oscillator):
    with_attribute(oscillator, "true")
    assert validate(oscillator) == []
    sc = api.load_scenario(oscillator)
    assert sc.record_coupling_errors
    r = api.run(sc, stop_time=2)
    assert r.data.dtype.names == ("time", "mass1.x", "mass1.v", X, V)
    assert len(r.data) == 21 and (r.data[X][3:] > 0).all()
    assert set(r.summary.coupling_errors) == {X[15:-1], V[15:-1]}
    assert not api.load_scenario(OSCILLATOR).record_coupling_errors  # the default: false
    assert api.run(OSCILLATOR, stop_time=2).data.dtype.names == ("time", "mass1.x", "mass1.v")


def test_a_coupling_errors_value_that_is_no_boolean_is_a_schema_problem(oscillator):
    problems = validate(with_attribute(oscillator, "sometimes"))
    assert len(problems) == 1 and "couplingErrors" in problems[0].message, problems


def master(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "master", *args], capture_output=True, text=True, timeout=120
    )


def test_the_command_line_flag_adds_the_columns_to_the_csv_and_plot_reads_them(tmp_path):
    out = tmp_path / "out.csv"
    r = master(
        "run", str(OSCILLATOR), "--stop-time", "2", "-o", str(out), "--serial", "--record-coupling-errors"
    )
    assert r.returncode == 0, r.stderr
    header = out.read_text().splitlines()[0]
    assert header == f'time,"mass1.x","mass1.v","{X}","{V}"'
    data = read_csv(str(out))  # fmpy's reader keeps the names whole
    assert data.dtype.names == ("time", "mass1.x", "mass1.v", X, V)
    expected = api.run(OSCILLATOR, stop_time=2, record_coupling_errors=True).data
    for n in expected.dtype.names:
        assert np.array_equal(data[n], expected[n]), n  # %.17g: every bit
    units = json.loads(out.with_suffix(".json").read_text())["units"]
    assert units[X] == "m" and units[V] == "m/s"
    png = tmp_path / "errors.png"
    r = master("plot", str(out), "--record", X, "--record", "mass1.x", "-o", str(png))
    assert r.returncode == 0 and png.stat().st_size > 0, r.stderr
    r = master("plot", str(out))
    assert r.returncode == 0 and out.with_suffix(".png").is_file(), r.stderr
    labels = [ax.get_ylabel() for ax in result_figure(data, units=units).axes]  # a panel per unit
    assert labels == ["[m]", "[m/s]", "coupling error [m]", "coupling error [m/s]"]
    plain = tmp_path / "plain.csv"
    assert master("run", str(OSCILLATOR), "--stop-time", "2", "-o", str(plain), "--serial").returncode == 0
    assert not re.search("coupling_error", plain.read_text().splitlines()[0])
