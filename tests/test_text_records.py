"""Strings and FMI 3 Binaries recorded and Binaries connected (kernel.h: text rings, MK_STRING_SLOT).

Real FMUs: the FMI 3.0 FMU alltypes, whose output `stamp` is k % 3 + 1 bytes of value k % 256 and a
zero byte, k = round(10 t) (a Binary whose length changes and that ends in a zero), and whose
y_binary is the bytes of u_binary reversed; the text FMU (FMI 2.0 and 3.0) for Strings. Expected
values are computed here from those rules and the documented holding of discrete signals.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from fractions import Fraction
from math import floor
from pathlib import Path

import numpy as np
import pytest
from helpers import BACKENDS, run_everywhere, ssd

import master.api as api
from master.fmubuild import fmu_path
from master.recorder import read_csv
from master.scenario.model import Component, Connection, Scenario, Stimulus

H = Fraction(1, 10)
STOP = Fraction(2)
N = int(STOP / H)


def alltypes() -> Path:
    return fmu_path("alltypes", fmi=3)


def stamp(t: Fraction) -> bytes:
    k = floor(10 * t + Fraction(1, 2))
    return bytes([k % 256]) * (k % 3 + 1) + b"\0"


def binary_scene(coupling: str, ka: int, kb: int, record) -> Scenario:
    comps = (Component("a", alltypes(), {}, ka), Component("b", alltypes(), {}, kb))
    order = ("a", "b") if coupling == "gauss-seidel" else ()
    link = Connection("a", "stamp", "b", "u_binary")
    return Scenario(Path("binary.ssd"), "binary", comps, (link,), Fraction(0), STOP, H, coupling=coupling,
                    order=order, record=tuple(record))  # fmt: skip


@pytest.mark.parametrize("coupling, ka, kb", [("jacobi", 1, 3), ("jacobi", 3, 1), ("gauss-seidel", 3, 2)])
def test_a_binary_is_held_along_a_connection_and_recorded_with_every_byte(coupling, ka, kb):
    """a.stamp -> b.u_binary, multirate: b's step m of macro step n sets the held sample (the
    first at or after the step's end that a has produced); after each macro step b's Binary input
    is set again to a's sample at its end before b.y_binary is read again (resampling), so b.y_binary
    at t is a.stamp at t reversed, whatever else is recorded. Every backend gives the same bytes."""
    for extra in ([], [("b", "y_float64")]):
        sc = binary_scene(coupling, ka, kb, [("a", "stamp"), ("b", "y_binary"), *extra])
        plan = api.plan(sc)
        assert [(lk.kind, lk.order) for lk in plan.links] == [("Binary", 0)]
        d = run_everywhere(sc)
        assert list(d["a.stamp"]) == [stamp(n * H) for n in range(N + 1)]
        assert list(d["b.y_binary"]) == [stamp(n * H)[::-1] for n in range(N + 1)]
        assert {len(u) for u in d["b.y_binary"]} == {2, 3, 4} and all(u[0] == 0 for u in d["b.y_binary"])
        assert plan.column_types["a.stamp"] == plan.column_types["b.y_binary"] == "Binary"


def test_binary_and_string_columns_in_the_csv_file_and_back(tmp_path: Path):
    """A Binary column is quoted hex digits, a String quoted text (quotes doubled, UTF-8);
    `read_csv` gives the texts back, a Binary's as its hex digits."""
    text = fmu_path("text", fmi=2)
    comps = (Component("a", alltypes()), Component("t", text, {"suffix": 'é"', "u_string": "x,y"}))
    sc = Scenario(Path("csv.ssd"), "csv", comps, (), Fraction(0), Fraction(1, 2), H,
                  record=(("a", "stamp"), ("t", "y_string"), ("t", "y_length")))  # fmt: skip
    out = tmp_path / "out.csv"
    d = api.run(sc, backend="serial", output=out).data
    assert d.dtype["a.stamp"].kind == "O" and d.dtype["t.y_length"] == np.float64
    assert list(d["t.y_string"]) == ['x,yé"'] * len(d)  # repeat = 1 copy of the suffix
    lines = out.read_text(encoding="utf-8").splitlines()
    assert lines[0] == 'time,"a.stamp","t.y_string","t.y_length"'
    assert lines[2] == '0.10000000000000001,"010100","x,yé""",3'
    back = read_csv(out)
    assert [bytes.fromhex(v) for v in back["a.stamp"]] == list(d["a.stamp"])
    assert list(back["t.y_string"]) == list(d["t.y_string"])
    assert np.array_equal(back["t.y_length"], d["t.y_length"]) and np.array_equal(back["time"], d["time"])


def test_texts_with_newlines_and_quotes_a_plot_of_numbers_only_and_a_non_utf8_locale(tmp_path: Path):
    """A String with a newline, quotes and non-ASCII bytes survives the CSV file (written as UTF-8
    whatever the locale) and `read_csv` (blank lines skipped); `master plot` draws the numeric
    columns and refuses a text column in one line."""
    text = fmu_path("text", fmi=2)
    comp = Component("t", text, {"suffix": "", "u_string": 'a\n"é"\r\nb'})
    sc = Scenario(Path("nl.ssd"), "nl", (comp,), (), Fraction(0), Fraction(1, 2), H,
                  record=(("t", "y_string"), ("t", "y_length")))  # fmt: skip
    out, scene = tmp_path / "out.csv", tmp_path / "scene.pkl"
    scene.write_bytes(pickle.dumps(sc))
    script = (f"import pickle, master.api as api; sc = pickle.loads(open({str(scene)!r}, 'rb').read())\n"
              f"api.run(sc, backend='serial', output={str(out)!r})")  # fmt: skip
    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=env)
    assert run.returncode == 0, run.stderr
    with out.open("a", encoding="utf-8") as f:
        f.write("\n")  # a blank line at the end: skipped
    back = read_csv(out)
    assert list(back["t.y_string"]) == ['a\n"é"\r\nb'] * 6 and list(back["t.y_length"]) == [9.0] * 6
    plot = [sys.executable, "-m", "master", "plot", str(out)]
    assert subprocess.run(plot, capture_output=True, text=True, timeout=120).returncode == 0
    refused = subprocess.run([*plot, "--record", "t.y_string"], capture_output=True, text=True, timeout=120)
    assert refused.returncode == 1 and refused.stderr.strip().splitlines() == [
        f"error: {out}: column 't.y_string' holds text, not numbers to plot"
    ]


def test_a_recorded_string_beyond_1023_bytes_stops_the_run_and_keeps_the_rows_before(tmp_path: Path):
    """t.y_string = u_string + 6 copies of a 200-byte suffix from t = 0.6 on (the stimulus steps at
    0.55; y_string depends on repeat, so the step-end input is set after each step): 1200 bytes,
    which the row at 0.6 cannot hold; the run stops with one line, the rows before are written."""
    text = fmu_path("text", fmi=3)
    sc = Scenario(Path("long.ssd"), "long", (Component("t", text, {"suffix": "s" * 200}),), (), Fraction(0),
                  Fraction(1), H, stimuli=(Stimulus("t", "repeat", "step", (0.55,), (6.0,)),),
                  record=(("t", "y_string"),))  # fmt: skip
    message = "t.y_string is 1200 bytes long at t=0.6: a recorded String holds at most 1023 bytes"
    for backend in BACKENDS:
        with pytest.raises(api.SimulationError) as failed:
            api.run(sc, backend=backend, output=tmp_path / f"{backend}.csv")
        assert message in str(failed.value)
        rows = failed.value.result.data  # type: ignore[attr-defined]
        assert list(rows["t.y_string"]) == ["s" * 200] * 6  # t = 0 ... 0.5
        assert len(read_csv(tmp_path / f"{backend}.csv")) == 6


def test_validate_and_run_accept_binary_connections_in_a_scenario_file(tmp_path: Path):
    comps = {"a": "project:alltypes", "b": "project:alltypes"}
    path = ssd(tmp_path / "b.ssd", comps, [("a", "stamp", "b", "u_binary")],
               '<mm:Record><mm:Variable component="b" name="y_binary"/></mm:Record>', stop="0.5")  # fmt: skip
    assert api.validate(path) == []
    out = tmp_path / "out.csv"
    run = subprocess.run([sys.executable, "-m", "master", "run", str(path), "-o", str(out), "-q"],
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert out.read_text().splitlines()[-1] == '0.5,"00050505"'  # a's stamp at 0.5 reversed


def test_every_scalar_type_is_recordable_and_arrays_of_numbers_and_booleans():
    from master.scenario.fmuinfo import recordable, recorded_as

    fmi3 = ("Float64", "Float32", "Int8", "UInt64", "Boolean", "Enumeration", "String", "Binary")
    assert all(recordable(t, "3.0") for t in fmi3) and not recordable("Clock", "3.0")
    assert recordable("Int8", "3.0", (2,)) and recordable("Boolean", "3.0", (2, 2))
    assert not recordable("String", "3.0", (2,)) and not recordable("Binary", "3.0", (3,))
    assert [recorded_as(t) for t in ("Float32", "Int64", "UInt64", "String", "Binary", "Enumeration")] == [
        "float64", "int64", "uint64", "String", "Binary", "float64"
    ]  # fmt: skip
