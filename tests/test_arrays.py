"""FMI 3.0 arrays: recorded a column per element, connected element by element, set and read by one
FMI call per kind that passes each array's value reference once with all its elements.

Real FMUs throughout: the project's FMI 3.0 test FMU alltypes (fmus/alltypes/model.c), whose arrays
are y_vec = 2 u_vec (Float64[3]), y_ivec = u_ivec + p_int32 (Int32[2]), y_mat = p_mat transposed
(Float64[2,2], row major), and wave = (sin t, cos 3t, t^3) (Float64[3]) and ticks = (k, -2 k),
k = round(10 t) (Int32[2]), which depend on time only. The FMU refuses a get or set whose number
of values is not its arrays' element count, so a run that passes says the calls are right.
The expected values are computed here from those rules and from the documented coupling (Lagrange
polynomials through the producer's samples for Float64 elements, held samples for Int32 ones), with
exact fractions, not with the master's own code.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import zipfile
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from helpers import run_everywhere

import master.api as api
from master.description import element_names, lookup, split_element, variables_of
from master.fmu import read_description
from master.fmubuild import fmu_path
from master.recorder import read_csv
from master.scenario import ScenarioError, load, read, validate
from master.scenario.model import Component, Connection, Scenario, Stimulus

SCENES = Path(__file__).parent / "scenarios"
ARRAYS = SCENES / "fmi3" / "arrays.ssd"  # c.wave, c.ticks -> a.u_vec, a.u_ivec; a.y_vec, a.y_ivec -> b
H = Fraction(1, 10)
N = 20  # macro steps of arrays.ssd (stop time 2 s)
P_INT32 = {"a": 1, "b": 10}  # a keeps the FMU's start value, arrays.ssd binds b's
Y_MAT = [1.0, -3.5, 2.0, 1.0]  # b's p_mat = [[1, 2], [-3.5, 1]] (two elements bound), transposed


def columns(d: np.ndarray, name: str, n: int) -> list[list[float]]:
    """Rows of the n element columns name[1] .. name[n] of a vector."""
    return [list(row) for row in zip(*(d[f"{name}[{i}]"] for i in range(1, n + 1)), strict=True)]


def test_elements_are_named_as_fmi_writes_them_row_major_from_1():
    assert element_names("m", (2, 3)) == ["m[1,1]", "m[1,2]", "m[1,3]", "m[2,1]", "m[2,2]", "m[2,3]"]
    assert element_names("v", (3,)) == ["v[1]", "v[2]", "v[3]"] and element_names("x", ()) == ["x"]
    assert split_element("m[2,13]") == ("m", (2, 13))
    assert split_element("m[02]") is None and split_element("m[1, 2]") is None and split_element("m") is None
    variables = variables_of(read_description(fmu_path("alltypes", fmi=3)))
    y_mat, _ = lookup(variables, "y_mat")
    assert y_mat.shape == (2, 2) and y_mat.size == 4
    assert [lookup(variables, e)[1] for e in element_names("y_mat", (2, 2))] == [0, 1, 2, 3]  # row major
    assert lookup(variables, "y_mat[3,1]") is None and lookup(variables, "y_vec[0]") is None
    assert lookup(variables, "y_vec[1,1]") is None and lookup(variables, "x[1]") is None  # x is a scalar
    assert lookup({"x[1]": y_mat}, "x[1]") == (y_mat, None)  # a variable of that very name wins


def scene(coupling: str, ka: int, kb: int) -> Scenario:
    """arrays.ssd with a stepping `ka` and b `kb` times per macro step (b extrapolates with order 2)."""
    sc = load(ARRAYS)
    ratios = {"c": 1, "a": ka, "b": kb}
    comps = tuple(dataclasses.replace(c, step_ratio=ratios[c.name]) for c in sc.components)
    order = ("c", "a", "b") if coupling == "gauss-seidel" else ()
    return dataclasses.replace(sc, components=comps, coupling=coupling, order=order)


@pytest.mark.parametrize(
    "coupling, ka, kb", [("jacobi", 1, 3), ("gauss-seidel", 1, 3), ("jacobi", 3, 1), ("gauss-seidel", 3, 1)]
)
def test_an_array_output_drives_an_array_input_element_by_element(coupling, ka, kb):
    sc = scene(coupling, ka, kb)
    plan = api.plan(sc)
    kinds = {(lk.source, lk.consumer, lk.kind): (lk.outputs, lk.inputs, lk.order) for lk in plan.links}
    assert kinds[("a", "b", "Real")] == (
        ("y_vec[1]", "y_vec[2]", "y_vec[3]"),
        ("u_vec[1]", "u_vec[2]", "u_vec[3]"),
        2,
    )
    assert kinds[("a", "b", "Integer")] == (("y_ivec[1]", "y_ivec[2]"), ("u_ivec[1]", "u_ivec[2]"), 0)
    d = run_everywhere(sc)
    assert len(d) == N + 1
    startup = plan.startup_steps  # start-up sweeps where a's samples do not yet suffice for order 2
    assert plan.startup_sweeps == (2 if startup else 0)

    # c: its arrays as the FMU computes them from time
    times = [n * H for n in range(N + 1)]
    wave, ticks = columns(d, "c.wave", 3), columns(d, "c.ticks", 2)
    for t, w, k in zip(times, wave, ticks, strict=True):
        x = float(t)
        assert w == pytest.approx([math.sin(x), math.cos(3 * x), x**3], abs=1e-12)
        assert k == [round(10 * x), -2 * round(10 * x)]

    def ahead(n: int) -> bool:
        """Whether macro step n reads its sources' samples at its end: the source goes first, or a
        relaxed start-up sweep."""
        return coupling == "gauss-seidel" or n < startup

    def src(n: int) -> int:
        """c's sample that a holds through macro step n (c -> a has order 0)."""
        return n + 1 if ahead(n) else n

    def a_vec(j: int) -> list[Fraction]:
        """a's sample j of y_vec: 2 u_vec; at a macro step's end (and the start) a's input-dependent
        outputs are read again after its inputs were set to c's samples there (resampling)."""
        n, m = divmod(j, ka)
        return [2 * Fraction(w) for w in wave[n if m == 0 else src(n)]]

    def a_ivec(j: int) -> list[int]:
        """a's sample j of y_ivec = u_ivec + p_int32, read again as y_vec is (held outputs too)."""
        n, m = divmod(j, ka)
        return [int(k) + P_INT32["a"] for k in ticks[n if m == 0 else src(n)]]

    # the chain doubles: a's recorded samples (at macro steps' ends)
    assert columns(d, "a.y_vec", 3) == [[float(v) for v in a_vec(r * ka)] for r in range(N + 1)]
    assert columns(d, "a.y_ivec", 2) == [a_ivec(r * ka) for r in range(N + 1)]
    # b's recorded inputs: a's samples at the row's time, set again element by element before b's
    # outputs are read again (resampling), the Int32 elements as the Float64 ones
    for row in range(N + 1):
        u, ui = a_vec(row * ka), a_ivec(row * ka)
        assert [d[f"b.u_vec[{i}]"][row] for i in (1, 2, 3)] == [float(v) for v in u], row
        assert [d["b.u_ivec[1]"][row], d["b.u_ivec[2]"][row]] == ui, row
        assert [d["b.y_ivec[1]"][row], d["b.y_ivec[2]"][row]] == [k + P_INT32["b"] for k in ui], row
    # b's y_vec depends on u_vec: read again at each macro step's end with a's final samples
    for i in (1, 2, 3):
        assert np.array_equal(d[f"b.y_vec[{i}]"], 2 * d[f"a.y_vec[{i}]"])
    # p_mat [[1, 2], [-3.5, 1]] transposed, in row-major columns y_mat[1,1], y_mat[1,2], ...
    assert [list(d[e]) for e in ("b.y_mat[1,1]", "b.y_mat[1,2]", "b.y_mat[2,1]", "b.y_mat[2,2]")] == [
        [v] * (N + 1) for v in Y_MAT
    ]


def test_the_default_record_has_a_column_per_element_of_every_array_output(tmp_path: Path):
    sc = dataclasses.replace(load(ARRAYS), record=())
    plan = api.plan(sc)
    for comp in "cab":
        for name, shape in (
            ("y_vec", (3,)),
            ("y_ivec", (2,)),
            ("y_mat", (2, 2)),
            ("wave", (3,)),
            ("ticks", (2,)),
        ):
            assert all((comp, e) in plan.record for e in element_names(name, shape)), (comp, name)
    assert ("a", "y_mat[2,1]") in plan.record and ("a", "y_mat") not in plan.record
    d = api.run(sc, backend="in-process", output=tmp_path / "out.csv").data
    assert [d[f"b.y_mat[{e}]"][-1] for e in ("1,1", "1,2", "2,1", "2,2")] == Y_MAT
    # the CSV file: a matrix element's name holds a comma inside its quotes ("b.y_mat[1,2]")
    assert '"b.y_mat[1,2]"' in (tmp_path / "out.csv").read_text().splitlines()[0]
    back = read_csv(tmp_path / "out.csv")
    assert back.dtype.names == d.dtype.names
    for n in d.dtype.names:  # a Binary (bytes) is written as hex digits
        if isinstance(d[n][0], bytes):
            assert [bytes.fromhex(v) for v in back[n]] == list(d[n]), n
        else:
            assert np.array_equal(back[n], d[n]), n
    assert [d[f"c.ticks[{i}]"][-1] for i in (1, 2)] == [20, -40]  # at t = 2 s
    assert d["b.y_vec[3]"][-1] == 4 * d["c.wave[3]"][-1]  # doubled twice, read again at the row


def test_one_element_can_be_recorded_and_an_array_element_bound(tmp_path: Path):
    text = ARRAYS.read_text()
    one = text[: text.index("<mm:Record>")] + (
        '<mm:Record><mm:Variable component="b" name="y_mat[2,1]"/>'
        '<mm:Variable component="a" name="y_vec[3]"/></mm:Record>'
    ) + text[text.index("</mm:Record>") + len("</mm:Record>") :]  # fmt: skip
    path = tmp_path / "one.ssd"
    path.write_text(one)
    assert validate(path) == []
    sc = load(path, {"b.p_mat[1,2]": "5", "b.u_vec[2]": "7"})  # --set, last: beats the file's binding
    assert sc.components[2].parameters == {
        "p_mat[1,2]": 5.0,
        "p_mat[2,1]": -3.5,
        "p_int32": 10,
        "u_vec[2]": 7.0,
    }
    d = api.run(sc, backend="serial").data
    assert d.dtype.names == ("time", "b.y_mat[2,1]", "a.y_vec[3]")
    assert set(d["b.y_mat[2,1]"]) == {5.0}  # p_mat[1,2] transposed
    assert list(d["a.y_vec[3]"]) == pytest.approx([2 * (n / 10) ** 3 for n in range(N + 1)], abs=1e-12)
    for bad, message in (
        ("b.p_mat", "it is an array (Float64[2,2]); array parameters are not supported as a whole"),
        ("b.p_mat[2]", "unknown variable: b.p_mat is Float64[2,2]: it has no element p_mat[2]"),
        ("b.y_vec[1]", "cannot set b.y_vec[1]: it has causality output"),
    ):
        (problem,) = read(path, {bad: "1"})[1]
        assert problem.file == "--set" and message in problem.message, problem


def test_a_shape_mismatch_is_one_problem_naming_both_ends_and_both_shapes():
    problems = validate(SCENES / "bad" / "array_problems.ssd")
    messages = [p.message for p in problems if p.element.startswith("ssd:Connection")]
    assert messages == [
        "shape mismatch: a.y_vec is Float64[3], b.u_float64 is a scalar Float64; an array drives an array "
        "of the same shape",
        "shape mismatch: a.y_mat is Float64[2,2], b.u_vec is Float64[3]; an array drives an array of the "
        "same shape",
    ]
    # the same verdict for scenarios built in Python (master.scenario.check)
    fmu = fmu_path("alltypes", fmi=3)
    for (out, inp), message in zip((("y_vec", "u_float64"), ("y_mat", "u_vec")), messages, strict=True):
        sc = Scenario(Path("shapes.ssd"), "shapes", (Component("a", fmu), Component("b", fmu)),
                      (Connection("a", out, "b", inp),), Fraction(0), Fraction(1), H)  # fmt: skip
        with pytest.raises(ScenarioError, match=message.replace("[", r"\[").replace("]", r"\]")):
            api.plan(sc)
    sc = Scenario(Path("s.ssd"), "s", (Component("a", fmu),), (), Fraction(0), Fraction(1), H,
                  stimuli=(Stimulus("a", "u_vec", "step", (0.0,), (1.0,)),))  # fmt: skip
    with pytest.raises(
        ScenarioError, match=r"a\.u_vec is Float64\[3\]: stimuli drive scalar inputs, not arrays"
    ):
        api.plan(sc)
    sc = dataclasses.replace(sc, stimuli=(), record=(("a", "y_vec"), ("a", "y_vec[1]")))
    with pytest.raises(ScenarioError, match=r"record a\.y_vec\[1\]: recorded twice"):
        api.plan(sc)


def test_master_validate_reports_a_stimulus_outside_its_variables_range(tmp_path: Path):
    """The FMU would refuse the value in the run (fmi3SetInt64 ... outside [1, 6]): validate says so
    first, at the stimulus point, with the variable's range (an Enumeration's: its items')."""
    path = SCENES / "bad" / "stimulus_outside_range.ssd"
    run = subprocess.run([sys.executable, "-m", "master", "validate", str(path)], capture_output=True,
                         text=True, timeout=120)  # fmt: skip
    assert run.returncode == 1
    assert run.stdout.splitlines() == [
        f"{path}:20: mm:Point: value 7 at time 0.55 s is outside [1, 6], "
        "the range of a.u_enumeration (its items)"
    ]
    inside = tmp_path / "inside.ssd"
    inside.write_text(path.read_text().replace('value="7"', 'value="1"'))
    assert validate(inside) == []
    assert list(api.run(inside, backend="in-process").data["a.y_enumeration"][[0, 3, 6]]) == [2, 1, 2]


def edited(tmp_path: Path, name: str, edit: Callable[[str], str]) -> Path:
    """A copy of alltypes.fmu whose modelDescription.xml `edit` changed."""
    dest = tmp_path / f"{name}.fmu"
    with zipfile.ZipFile(fmu_path("alltypes", fmi=3)) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                data = edit(text).encode()
                assert data != text.encode()
            zout.writestr(item, data)
    return dest


def test_array_sizes_come_from_the_model_description(tmp_path: Path):
    """A dimension given by a structural parameter takes that parameter's start value; a size that
    cannot be known before the run, or a binding that would change one, is a problem."""
    size = '<Dimension start="3"/>\n    </Float64>\n    <Float64 name="y_vec"'
    n = '<UInt64 name="n" valueReference="90" causality="structuralParameter" variability="fixed" start="3"/>'

    def sized_by(reference: str, declare: str) -> Callable[[str], str]:
        def edit(text: str) -> str:
            text = text.replace(size, size.replace('start="3"', f'valueReference="{reference}"'))
            return text.replace('<Float64 name="stop_at"', f'{declare}\n    <Float64 name="stop_at"')

        return edit

    cases = {
        "by_n": sized_by("90", n),
        "undeclared": sized_by("777", ""),
        "no_start": sized_by("90", n.replace(' start="3"', ' initial="exact"')),
    }
    for name, edit in cases.items():
        fmu = edited(tmp_path, name, edit)
        path = tmp_path / f"{name}.ssd"
        path.write_text(ARRAYS.read_text().replace('source="project:alltypes"', f'source="{fmu.name}"'))
        problems = [p.message for p in validate(path)]
        if name == "by_n":  # sized by n's start: as before
            assert problems == []
            sc = load(path)
            assert lookup(variables_of(read_description(fmu)), "u_vec")[0].shape == (3,)
            (problem,) = read(path, {"a.n": "4"})[1]
            assert problem.message == (
                "cannot set a.n: it is the size of u_vec; array sizes are the model description's "
                "(structural parameters that size arrays are not set)"
            )
            assert len(api.run(sc, backend="in-process").data) == N + 1
        else:
            why = {
                "undeclared": "the size of array u_vec is variable 777, which the model description does "
                "not declare",
                "no_start": "the size of array u_vec is n, which has no start value: its size cannot be "
                "known before the run",
            }[name]
            assert problems == [f"cannot read the modelDescription.xml of {fmu.name}: {why}"] * 3
