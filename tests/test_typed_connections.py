"""Connections of every FMI 3.0 numeric type, each carried through the FMI calls of its own type.

Real FMUs throughout: the project's FMI 3.0 test FMU alltypes (fmus/alltypes/model.c), whose
numeric outputs are y_<type> = u_<type> + p_<type> (Float32 added in float arithmetic, integers
saturated at their type's range), y_enumeration = u_enumeration mod 6 + 1 and y_boolean = not
u_boolean; the FMI 2.0 FMUs gain (y = K u) and discrete for connections across FMI versions.
The expected values are computed here from those rules and from the documented coupling (held
samples for integers and Booleans, Lagrange polynomials for Float32 and Float64), with numpy's
fixed-width types and exact fractions, not with the master's own code.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from helpers import BACKENDS, run_everywhere, ssd

import master.api as api
from master.fmubuild import fmu_path
from master.recorder import read_csv
from master.scenario import ScenarioError, validate
from master.scenario.fmuinfo import connection_problem
from master.scenario.model import Component, Connection, Scenario, Stimulus

H = Fraction(1, 10)
STOP = Fraction(2)
N = int(STOP / H)
INTS = {"int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32,
        "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64}  # fmt: skip
TYPES = ("float32", "float64", *INTS, "enumeration", "boolean")
CONTINUOUS = ("float32", "float64")
EXACT = 2**53

# a's inputs: step stimuli (times between communication points), a table on Float32
TIMES = (0.25, 0.85, 1.35)
STEPS = {
    "float64": (0.5, -1.25, 3.0),
    "int8": (-100, 120, -128),
    "uint8": (10, 100, 0),
    "int16": (-30000, 32000, 5),
    "uint16": (65000, 3, 600),
    "int32": (-(2**31), 2**31 - 5, 7),
    "uint32": (2**32 - 1, 5, 2**31),
    "int64": (-EXACT + 5, EXACT - 3, 12345),  # a.y = u - 4: -(2^53 - 1), 2^53 - 7 (odd, exact)
    "uint64": (EXACT - 3, 0, 2**40 + 1),  # a.y = u + 2: 2^53 - 1
    "enumeration": (3, 6, 1),
}
TABLE = ((0.0, 0.7, 2.0), (0.6, 1.9, 1.1))  # a.u_float32, piecewise linear
START = {"enumeration": 1, "boolean": False}  # start values of the inputs (the others 0)
P_A = {"p_float32": 0.25, "p_float64": 1.5, "p_int8": 100, "p_uint8": 200, "p_int16": 1000, "p_uint16": 600,
       "p_int32": 10, "p_uint32": 7, "p_int64": -4, "p_uint64": 2}  # fmt: skip
P_B = {"p_float32": 0.1, "p_float64": -0.25, "p_int8": -120, "p_uint8": 50, "p_int16": -5000, "p_uint16": 0,
       "p_int32": -20, "p_uint32": 2**32 - 10, "p_int64": -1, "p_uint64": 1}  # fmt: skip


def rule(t: str, u, p):
    """alltypes' output y_<t> for input u and parameter p (fmus/alltypes/model.c)."""
    if t == "float32":
        return float(np.float32(u) + np.float32(p))  # float arithmetic, the inputs rounded to float
    if t == "float64":
        return u + p
    if t in INTS:
        info = np.iinfo(INTS[t])
        return min(max(int(u) + int(p), int(info.min)), int(info.max))
    if t == "enumeration":
        return int(u) % 6 + 1
    return not u


def stimulus(t: str, time: float):
    """The value a's stimulus gives u_<t> at `time` (s), as the FMU stores it."""
    if t == "float32":
        return float(np.float32(np.interp(time, *TABLE)))  # fmi3SetFloat32 rounds
    if t == "boolean":
        return False
    value = START.get(t, 0)
    for at, v in zip(TIMES, STEPS[t], strict=True):
        if time >= at:
            value = v
    return value


def alltypes() -> Path:
    return fmu_path("alltypes", fmi=3)


def chain(coupling: str, ka: int, kb: int) -> Scenario:
    """a -> b, every type of a's outputs driving the same type of b's inputs; b extrapolates its
    continuous inputs with order 2 and records its inputs and outputs (Float64 ones aside)."""
    fmu = alltypes()
    comps = (Component("a", fmu, dict(P_A), ka, 0), Component("b", fmu, dict(P_B), kb, 2))
    conns = tuple(Connection("a", f"y_{t}", "b", f"u_{t}") for t in TYPES)
    stimuli = (Stimulus("a", "u_float32", "table", *TABLE),) + tuple(
        Stimulus("a", f"u_{t}", "step", TIMES, tuple(float(v) for v in values)) for t, values in STEPS.items()
    )
    record = tuple(("a", f"y_{t}") for t in TYPES) + tuple(("b", f"u_{t}") for t in TYPES)
    record += tuple(("b", f"y_{t}") for t in TYPES if t != "float64")
    order = ("a", "b") if coupling == "gauss-seidel" else ()
    return Scenario(Path("chain.ssd"), "typed chain", comps, conns, Fraction(0), STOP, H, coupling=coupling,
                    order=order, stimuli=stimuli, record=record)  # fmt: skip


@pytest.mark.parametrize(
    "coupling, ka, kb", [("jacobi", 1, 3), ("jacobi", 3, 1), ("gauss-seidel", 1, 3), ("gauss-seidel", 3, 1)]
)
def test_every_numeric_type_drives_its_own_type(coupling, ka, kb):
    sc = chain(coupling, ka, kb)
    plan = api.plan(sc)
    held = ("Integer", "Boolean", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64", "UInt64")
    assert {lk.kind: lk.order for lk in plan.links} == {"Real": 2, "Float32": 2} | dict.fromkeys(held, 0)
    d = run_everywhere(sc)
    assert len(d) == N + 1

    # a's samples at its communication points j: rule(stimulus at t_j) (a sets its step-end inputs)
    times = [Fraction(j, ka) * H for j in range(N * ka + 1)]
    a = {t: [rule(t, stimulus(t, float(tj)), P_A.get(f"p_{t}")) for tj in times] for t in TYPES}
    for t in TYPES:
        assert [float(v) for v in a[t][::ka]] == list(d[f"a.y_{t}"]), t

    # b's inputs at each row: a's sample at the row's time, set again through each type's own call
    # before b's outputs are read (resampling: recorded inputs and outputs that depend on them)
    for t in TYPES:
        assert list(d[f"b.u_{t}"]) == list(d[f"a.y_{t}"]), t
        if t != "float64":
            assert list(d[f"b.y_{t}"]) == [rule(t, u, P_B.get(f"p_{t}")) for u in d[f"a.y_{t}"]], t
    # 64-bit integers near 2^53 travel exactly (odd values: a float32 or a rounding would lose them)
    assert EXACT - 1 in d["b.u_uint64"] and EXACT in d["b.y_uint64"]
    assert -EXACT + 1 in d["b.u_int64"] and EXACT - 7 in d["b.u_int64"] and -EXACT in d["b.y_int64"]
    # saturation at both ends of a range, Enumeration items cycling
    assert {127, -28} <= set(d["a.y_int8"]) and {-128, 7} <= set(d["b.y_int8"])
    assert 2**32 - 1 in d["b.y_uint32"] and {4, 1, 2} <= set(d["b.u_enumeration"])


def test_outputs_of_every_kind_are_read_again_after_their_inputs_are_set_again():
    """Resampling (kernel.h): b's coupled outputs depend on inputs, so after each macro step b's
    linked inputs are set to a's samples at its end (the typed ones with fmi3SetFloat32 /
    fmi3SetInt16 ...) and its outputs of every kind read again (fmi3GetFloat32, fmi3GetInt16 ...):
    no lag, for a held Int16 as for an extrapolated Float32. c records its inputs: b's samples at
    the row's time."""
    fmu = alltypes()
    kinds = ("float32", "float64", "int16", "uint64")
    comps = (Component("a", fmu, dict(P_A)), Component("b", fmu, dict(P_B), 2), Component("c", fmu))
    conns = tuple(Connection(s, f"y_{t}", e, f"u_{t}") for s, e in (("a", "b"), ("b", "c")) for t in kinds)
    stimuli = (Stimulus("a", "u_float32", "table", *TABLE),) + tuple(
        Stimulus("a", f"u_{t}", "step", TIMES, tuple(float(v) for v in STEPS[t])) for t in kinds[1:]
    )
    record = tuple((c, f"{k}_{t}") for c in "ab" for k in "uy" for t in kinds) + tuple(
        ("c", f"u_{t}") for t in kinds
    )
    sc = Scenario(Path("chain3.ssd"), "three", comps, conns, Fraction(0), STOP, H, stimuli=stimuli,
                  record=record)  # fmt: skip
    d = run_everywhere(sc)
    for t in kinds:
        assert np.array_equal(d[f"b.u_{t}"], d[f"a.y_{t}"]), t  # a's final samples
        assert list(d[f"b.y_{t}"]) == [rule(t, u, P_B[f"p_{t}"]) for u in d[f"a.y_{t}"]], t
        assert np.array_equal(d[f"c.u_{t}"], d[f"b.y_{t}"]), t
    assert len(np.unique(d["b.y_float32"])) > N // 2 and len(np.unique(d["b.y_int16"])) == 4


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A folder holding alltypes.fmu (FMI 3.0) for scenario files to name."""
    shutil.copy(alltypes(), tmp_path / "alltypes.fmu")
    fmu_path("gain"), fmu_path("discrete")  # FMI 2.0 project FMUs, built before the checks
    return tmp_path


def test_a_scenario_file_connects_and_stimulates_every_numeric_type():
    path = Path(__file__).parent / "scenarios" / "fmi3" / "every_type.ssd"  # source="project:alltypes"
    assert validate(path) == []
    plan = api.plan(api.load_scenario(path))
    links = {(lk.kind, lk.order) for lk in plan.links}
    assert links >= {("Float32", 2), ("Real", 2), ("Int8", 0), ("Int64", 0), ("UInt64", 0)}
    d = api.run(path, backend="serial").data  # every output; p = 1 where the file sets none
    assert d["a.y_uint64"][-1] == EXACT - 1 and d["b.y_uint64"][-1] == EXACT
    assert d["a.y_int64"][-1] == -EXACT + 3 and d["b.y_int64"][-1] == -EXACT + 4
    assert list(d["a.y_int8"][[2, 3, 9]]) == [1, -6, 121] and list(d["b.y_int8"][[3, 9]]) == [-126, 1]
    assert d["a.y_enumeration"][-1] == 5 and d["b.y_enumeration"][-1] == 6
    assert d["a.y_uint32"][-1] == 2**32 - 1 and d["b.y_uint32"][-1] == 2**32 - 1  # saturated
    assert d["b.y_float32"][-1] == float(np.float32(2.25) + np.float32(0.1))  # (2 + 0.25) + 0.1 in float


def test_mismatched_and_unconnectable_types_are_one_problem_each_naming_both_ends(folder: Path):
    conns = [("a", "y_float32", "b", "u_float64"), ("a", "y_int8", "b", "u_int16"),
             ("a", "y_binary", "b", "u_string"), ("g", "y", "b", "u_float32"),
             ("a", "y_enumeration", "b", "u_int64")]  # fmt: skip
    stimuli = (
        '<mm:Stimuli><mm:Table component="b" variable="u_int8"><mm:Point time="0" value="1"/></mm:Table>'
        '<mm:Step component="b" variable="u_uint8"><mm:Point time="0" value="300"/></mm:Step>'
        '<mm:Step component="b" variable="u_boolean"><mm:Point time="0" value="2"/></mm:Step></mm:Stimuli>'
    )
    path = ssd(
        folder / "bad.ssd", {"a": "alltypes.fmu", "b": "alltypes.fmu", "g": "gain"}, conns, stimuli, stop="2"
    )
    problems = [(p.element, p.message) for p in validate(path)]
    assert problems == [
        ("ssd:Connection a.y_float32 -> b.u_float64",
         "type mismatch: a.y_float32 is Float32, b.u_float64 is Float64"),
        ("ssd:Connection a.y_int8 -> b.u_int16", "type mismatch: a.y_int8 is Int8, b.u_int16 is Int16"),
        ("ssd:Connection a.y_binary -> b.u_string",
         "type mismatch: a.y_binary is Binary, b.u_string is String"),
        ("ssd:Connection g.y -> b.u_float32", "type mismatch: g.y is Real, b.u_float32 is Float32"),
        ("ssd:Connection a.y_enumeration -> b.u_int64",
         "type mismatch: a.y_enumeration is Enumeration, b.u_int64 is Int64"),
        ("mm:Table b.u_int8", "b.u_int8 is Int8: an Int8 input takes a step stimulus, not a table"),
        ("mm:Point", "value 300 is outside [0, 255] (b.u_uint8 is UInt8)"),
        ("mm:Point", "value 2 is not 0 (false) or 1 (true) (b.u_boolean is Boolean)"),
    ]  # fmt: skip
    # an FMI 2 Enumeration is carried as an Integer, an FMI 3 one as an Int64: not connected either
    assert "connect enumerations of one FMI version" in connection_problem(
        "x.e", "Enumeration", "2.0", "y.e", "Enumeration", "3.0"
    )
    assert connection_problem("x.n", "Integer", "2.0", "y.n", "Int32", "3.0") is None


def test_fmi2_real_integer_and_boolean_drive_fmi3_float64_int32_and_boolean(folder: Path):
    """FMI 2 Real -> FMI 3 Float64 (gain -> alltypes), FMI 3 Int32 -> FMI 2 Integer and Boolean ->
    Boolean (alltypes -> discrete), as SSP compares the types."""
    conns = [("g", "y", "a", "u_float64"), ("a", "y_int32", "d", "n_in"), ("a", "y_boolean", "d", "on_in")]
    settings = (
        '<mm:Record><mm:Variable component="g" name="y"/><mm:Variable component="a" name="u_float64"/>'
        '<mm:Variable component="a" name="y_float64"/><mm:Variable component="a" name="y_int32"/>'
        '<mm:Variable component="d" name="n_in"/><mm:Variable component="d" name="on_in"/></mm:Record>'
        '<mm:Stimuli><mm:Step component="a" variable="u_int32"><mm:Point time="0.45" value="3"/></mm:Step>'
        '<mm:Table component="g" variable="u"><mm:Point time="0" value="0"/><mm:Point time="2" value="1"/>'
        "</mm:Table></mm:Stimuli>"
    )
    path = ssd(
        folder / "mixed.ssd", {"g": "gain", "a": "alltypes.fmu", "d": "discrete"}, conns, settings, stop="2"
    )
    assert validate(path) == []
    for backend in ("serial", "in-process"):
        d = api.run(path, backend=backend).data
        t = d["time"]
        assert np.array_equal(d["g.y"], 2.0 * np.interp(t, [0.0, 2.0], [0.0, 1.0]))  # K = 2
        assert np.array_equal(d["a.u_float64"], d["g.y"])  # recorded inputs: the source's sample
        assert np.array_equal(d["a.y_float64"], d["g.y"] + 1.5)  # read again at the macro step's end
        assert np.array_equal(d["a.y_int32"], np.where(t >= 0.45, 4.0, 1.0))
        assert np.array_equal(d["d.n_in"], d["a.y_int32"])
        assert set(d["d.on_in"]) == {1.0}


def beyond(folder: Path) -> Path:
    """a.y_uint64 = u + 1 becomes 2^53 + 1 at t = 0.4 (the stimulus steps at 0.35 s to 2^53)."""
    stim = f'<mm:Stimuli><mm:Step component="a" variable="u_uint64"><mm:Point time="0.35" value="{2**53}"/>'
    stim += "</mm:Step></mm:Stimuli>"
    return ssd(folder / "beyond.ssd", {"a": "alltypes.fmu", "b": "alltypes.fmu"},
               [("a", "y_uint64", "b", "u_uint64")], stim, stop="1")  # fmt: skip


def test_a_64_bit_output_beyond_2_to_the_53_on_a_connection_stops_the_run(folder: Path):
    path = beyond(folder)
    assert validate(path) == []
    message = "a.y_uint64 = 9007199254740993 (UInt64) at t=0.4: beyond 2^53 in magnitude"
    for backend in BACKENDS:
        with pytest.raises(api.SimulationError, match=message.replace("^", r"\^").replace("(", r"\(")
                           .replace(")", r"\)")) as failed:  # fmt: skip
            api.run(path, backend=backend)
        assert (failed.value.component, failed.value.variable) == ("a", "y_uint64")
    command = [sys.executable, "-m", "master", "run", str(path), "-o", str(folder / "out.csv")]
    run = subprocess.run([*command, "-q"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 1
    assert run.stderr.strip().splitlines() == [
        f"error: {message}, which a connection cannot carry exactly (values travel as float64)"
    ]
    loud = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert loud.returncode == 1 and "Traceback" not in loud.stderr and f"error: {message}" in loud.stderr


def test_an_int64_beyond_minus_2_to_the_53_stops_the_run_too():
    fmu = alltypes()
    sc = Scenario(Path("low.ssd"), "low", (Component("a", fmu, {"p_int64": -2}), Component("b", fmu)),
                  (Connection("a", "y_int64", "b", "u_int64"),), Fraction(0), Fraction(1), H,
                  stimuli=(Stimulus("a", "u_int64", "step", (0.55,), (-(2.0**53),)),))  # fmt: skip
    with pytest.raises(api.SimulationError, match=r"a\.y_int64 = -9007199254740994 \(Int64\) at t=0\.6"):
        api.run(sc, backend="in-process")


def test_a_recorded_64_bit_integer_beyond_2_to_the_53_keeps_every_bit(folder: Path):
    """Recorded, not connected: the results hold Int64 and UInt64 as int64 / uint64 (the row's 8
    bytes carry the integer's bits), the CSV file writes them in full, in every backend."""
    fmu = alltypes()
    big, low = 2**64 - 3, -(2**62) - 1  # no float64 holds either
    sc = Scenario(Path("wide.ssd"), "wide", (Component("a", fmu, {"p_uint64": big, "p_int64": low}),), (),
                  Fraction(0), Fraction(1), H, record=(("a", "y_uint64"), ("a", "y_int64")))  # fmt: skip
    for backend in BACKENDS:
        out = folder / f"{backend}.csv"
        d = api.run(sc, backend=backend, output=out).data
        assert (d.dtype["a.y_uint64"], d.dtype["a.y_int64"]) == (np.uint64, np.int64)
        assert [int(v) for v in d["a.y_uint64"]] == [big] * len(d)  # u = 0: y = 0 + p, every row
        assert [int(v) for v in d["a.y_int64"]] == [low] * len(d)
        assert all(line.endswith(f",{big},{low}") for line in out.read_text().splitlines()[1:])


def test_read_csv_gives_back_every_column_with_its_type_and_every_bit(folder: Path):
    """A run's CSV file read back by `read_csv`: with the metadata beside it each column has the
    type the results hold (Int64 and UInt64 beyond 2^53 exact, an Int32 as float64); without it
    the text decides, a column of integers only being int64 (uint64 beyond int64's range)."""
    fmu = alltypes()
    odd, big = 2**53 + 1, 2**64 - 3  # 9007199254740993 reads 9007199254740992.0 as a float64
    params = {"p_int64": odd, "p_uint64": big, "p_int32": 7, "p_float64": 0.5}
    step = Stimulus("a", "u_int64", "step", (0.35,), (-(2.0**40),))  # y_int64 = 2^53 + 1 - 2^40 from 0.4
    record = tuple(("a", f"y_{t}") for t in ("int64", "uint64", "int32", "float64"))
    sc = Scenario(Path("wide.ssd"), "wide", (Component("a", fmu, params),), (), Fraction(0), Fraction(1), H,
                  stimuli=(step,), record=record)  # fmt: skip
    out = folder / "back.csv"
    d = api.run(sc, backend="serial", output=out).data
    assert [int(v) for v in d["a.y_int64"]] == [odd] * 4 + [odd - 2**40] * 7
    back = read_csv(out)
    assert back.dtype == d.dtype  # names and types: time, int64, uint64, float64, float64
    for name in d.dtype.names:
        assert np.array_equal(back[name], d[name]), name
    out.with_suffix(".json").unlink()  # the text alone: the integer columns are integers
    guessed = read_csv(out)
    assert [guessed.dtype[n] for n in guessed.dtype.names] == [
        np.float64,
        np.int64,
        np.uint64,
        np.int64,
        np.float64,
    ]
    assert int(guessed["a.y_int64"][0]) == odd and int(guessed["a.y_uint64"][-1]) == big
    for name in d.dtype.names:
        assert np.array_equal(guessed[name], d[name]), name


def test_a_failing_typed_call_is_named_with_its_fmi_function(monkeypatch):
    # 7 is an Int64 (the type of an FMI 3 Enumeration) but no item of Solver (1..6): the FMU refuses.
    # The scenario checks refuse it first (outside the range of a.u_enumeration); past them, as if
    # they had missed it, the run names the call that failed
    sc = Scenario(Path("item.ssd"), "item", (Component("a", alltypes()),), (), Fraction(0), Fraction(1), H,
                  stimuli=(Stimulus("a", "u_enumeration", "step", (0.55,), (7.0,)),))  # fmt: skip
    with pytest.raises(ScenarioError, match=r"value 7 at time 0.55 s is outside \[1, 6\]"):
        api.run(sc)
    monkeypatch.setattr(api, "check", lambda sc: [])
    failure = r"^a: fmi3SetInt64 failed with status 3 .*u_enumeration"
    for backend in ("serial", "in-process"):
        with pytest.raises(api.SimulationError, match=failure):
            api.run(sc, backend=backend)


def test_a_step_stimulus_drives_a_boolean_input():
    """u_boolean steps 0 -> 1 -> 0 through fmi3SetBoolean; y_boolean = not u_boolean, read at each
    row with the input at the row's time (y depends on u: the step-end input is set after each
    step), in every backend."""
    switch = Stimulus("a", "u_boolean", "step", (0.3, 0.7), (1.0, 0.0))
    sc = Scenario(Path("switch.ssd"), "switch", (Component("a", alltypes()),), (), Fraction(0), Fraction(1),
                  H, stimuli=(switch,), record=(("a", "u_boolean"), ("a", "y_boolean")))  # fmt: skip
    d = run_everywhere(sc)
    assert list(d["a.u_boolean"]) == [0, 0, 0, 1, 1, 1, 1, 0, 0, 0, 0]  # from 0.3 on, from 0.7 on
    assert np.array_equal(d["a.y_boolean"], 1 - d["a.u_boolean"])
