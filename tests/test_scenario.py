"""Scenario files: good ones load to the expected Scenario, bad ones give clear problems.

Real files (tests/scenarios/), real FMUs (the project's msd and dcmotor, built from C).
"""

from __future__ import annotations

import re
import subprocess
import sys
import zipfile
from fractions import Fraction
from pathlib import Path

import pytest

from master.fmubuild import fmu_path
from master.scenario import Problem, ScenarioError, load, validate
from master.scenario.model import Connection, Stimulus

HERE = Path(__file__).parent / "scenarios"
OSCILLATOR = HERE / "oscillator" / "oscillator.ssd"
BAD = sorted((HERE / "bad").glob("*.ssd"))
EXPECT = re.compile(
    r"<!-- expect: (?:(?P<file>[\w.]+):)?(?P<line>\d+) \| (?P<element>[^|]+) \| (?P<text>.*) -->"
)


def expectations(path: Path) -> list[dict]:
    """The problems a malformed fixture announces in its trailing comments."""
    found = [m.groupdict() for m in EXPECT.finditer(path.read_text())]
    assert found, f"{path.name} announces no expected problem"
    return found


def test_there_are_enough_malformed_fixtures():
    assert len(BAD) >= 12


@pytest.mark.parametrize("path", BAD, ids=[p.stem for p in BAD])
def test_malformed_scenario_gives_its_expected_problems(path: Path):
    problems = validate(path)
    expected = expectations(path)
    shown = "\n".join(map(str, problems))
    assert len(problems) == len(expected), shown
    for e in expected:
        file = path.parent / e["file"] if e["file"] else path
        hits = [
            p
            for p in problems
            if p.file == str(file)
            and p.line == int(e["line"])
            and p.element == e["element"].strip()
            and e["text"] in p.message
        ]
        assert hits, f"expected {e} among:\n{shown}"
    assert "Traceback" not in shown
    with pytest.raises(ScenarioError) as info:
        load(path)
    assert info.value.problems == problems


def test_validate_reports_all_problems_of_a_file_at_once():
    problems = validate(HERE / "bad" / "several_problems.ssd")
    kinds = {
        "schema violation",
        "unknown variable",
        "is an input, not an output",
        "whole number of macro steps",
        "unknown component",
        "does not divide the macro step",
    }
    assert len(problems) == 6
    assert all(any(k in p.message for p in problems) for k in kinds)


def test_good_scenario_loads_to_the_expected_scenario():
    sc = load(OSCILLATOR)
    assert validate(OSCILLATOR) == []
    assert sc.name == "two-mass oscillator"
    assert sc.path == OSCILLATOR.resolve()
    assert (sc.start_time, sc.stop_time, sc.macro_step) == (Fraction(0), Fraction(10), Fraction(1, 100))
    assert sc.coupling == "gauss-seidel" and sc.order == ("mass2", "mass1")
    m1, m2 = sc.components
    assert m1.fmu_path == m2.fmu_path == fmu_path("msd")  # "msd" and "project:msd" alike
    assert (m1.name, m1.step_ratio, m1.extrapolation_order, m1.interpolate_inputs, m1.group) == (
        "mass1",
        1,
        2,
        False,
        "mechanics",
    )
    # communicationStep 0.0025 in a macro step of 0.01: ratio 4; order: the Settings default 1
    assert (m2.name, m2.step_ratio, m2.extrapolation_order, m2.interpolate_inputs, m2.group) == (
        "mass2",
        4,
        1,
        True,
        None,
    )
    assert sc.connections == (
        Connection("mass1", "x", "mass2", "x_in", None),
        Connection("mass1", "v", "mass2", "v_in", None),
        Connection("mass2", "F_c", "mass1", "F", 3),
    )
    assert sc.record == (("mass1", "x"), ("mass1", "v")) and sc.record_interval == Fraction(1, 10)
    assert sc.stimuli == ()


def test_parameter_precedence_file_then_inline_then_system_then_overrides():
    sc = load(OSCILLATOR)
    m1, m2 = sc.components
    # mass1.ssv: m c d = 1, x0 = 0.5, internal_step; the inline set (written first) still wins: x0 = 1
    assert m1.parameters == {"m": 1.0, "c": 1.0, "d": 1.0, "x0": 1.0, "internal_step": 0.0025, "solver": 3}
    # coupling.ssv: dc = 0.5; the system-level binding (prefix "mass2.") wins: dc = 1
    # and its communication step 0.0025 s with interpolated inputs becomes its internal step
    assert m2.parameters == {"m": 1.0, "c": 1.0, "d": 1.0, "cc": 1.0, "dc": 1.0, "internal_step": 0.0025}
    over = load(
        OSCILLATOR, {"mass2.dc": "0.25", "mass1.solver": "rk4", "mass1.F": "2", "mass2.internal_step": "1e-3"}
    )
    m1, m2 = over.components
    assert m2.parameters["dc"] == 0.25 and m2.parameters["internal_step"] == 0.001
    assert m1.parameters["solver"] == 4 and m1.parameters["F"] == 2.0
    assert isinstance(m1.parameters["F"], float) and isinstance(m1.parameters["solver"], int)


def test_bad_overrides_are_named_one_by_one():
    problems = validate(
        OSCILLATOR,
        {
            "mass3.m": "1",
            "mass1.mass": "1",
            "mass1.m": "heavy",
            "mass1.x": "0",
            "mass2.m": "-2",
            "mass1.solver": "rk5",
            "mass1.d": "nan",
        },
    )
    got = {p.element: p.message for p in problems}
    assert all(p.file == "--set" and p.line is None for p in problems)
    assert "component.variable with a component of the scenario" in got["mass3.m"]
    assert 'has no "mass"' in got["mass1.mass"]
    assert '"heavy" is not a number' in got["mass1.m"]
    assert "causality output" in got["mass1.x"]
    assert "outside the range [0, inf]" in got["mass2.m"]
    assert '"rk5" is not an item of solver' in got["mass1.solver"]
    assert "not a finite number" in got["mass1.d"]
    assert len(problems) == 7


def test_times_are_exact_rationals_from_the_decimal_strings():
    sc = load(HERE / "step_force.ssd")
    assert sc.macro_step == Fraction(1, 5000) != Fraction(0.0002)
    assert (sc.start_time, sc.stop_time) == (Fraction(1, 10), Fraction(2, 5))
    assert (sc.stop_time - sc.start_time) / sc.macro_step == 1500
    body, tethered = sc.components
    assert body.step_ratio == 4  # 0.0002 / 0.00005 exactly
    assert body.interpolate_inputs and tethered.interpolate_inputs  # global default, msd can
    assert tethered.parameters == {"cc": 100.0, "solver": 5}
    assert sc.coupling == "jacobi" and sc.order == ()
    assert sc.stimuli == (
        Stimulus("body", "F", "step", (0.2, 0.3), (1.0, 0.0)),
        Stimulus("tethered", "x_in", "table", (0.1, 0.2, 0.4), (0.0, 0.01, 0.01)),
    )
    assert sc.record == () and sc.record_interval is None  # empty Record: all outputs


def test_problem_text_names_file_line_and_element():
    assert (
        str(Problem("a.ssd", 7, "ssd:Connection a.x -> b.u", "bad"))
        == "a.ssd:7: ssd:Connection a.x -> b.u: bad"
    )
    assert str(Problem("--set", None, "a.m", "bad")) == "--set: a.m: bad"


@pytest.mark.parametrize(
    "content", [None, b"", b"\x00\x01binary", b"<a/>"], ids=["missing", "empty", "binary", "other"]
)
def test_validate_never_raises(tmp_path: Path, content: bytes | None):
    path = tmp_path / "scene.ssd"
    if content is not None:
        path.write_bytes(content)
    problems = validate(path)
    assert len(problems) == 1 and problems[0].file == str(path)
    with pytest.raises(ScenarioError):
        load(path)


def test_cli_validate_prints_each_problem_without_traceback():
    bad = HERE / "bad" / "several_problems.ssd"
    proc = subprocess.run(
        [sys.executable, "-m", "master", "validate", str(bad)], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 1
    assert proc.stdout.splitlines() == [str(p) for p in validate(bad)]
    assert "Traceback" not in proc.stderr


def test_fmu_with_invalid_model_description_is_a_problem_of_its_component(tmp_path: Path):
    # The real msd FMU with the start value of its input F removed (FMI requires one).
    broken = tmp_path / "nostart.fmu"
    with zipfile.ZipFile(fmu_path("msd")) as src, zipfile.ZipFile(broken, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                at = text.index('name="F"')
                end = text.index("</ScalarVariable>", at)
                data = (text[:at] + re.sub(r' start="[^"]*"', "", text[at:end]) + text[end:]).encode()
            dst.writestr(item, data)
    scene = tmp_path / "scene.ssd"
    scene.write_text(
        (HERE / "step_force.ssd")
        .read_text()
        .replace('name="body" source="msd"', 'name="body" source="nostart.fmu"')
    )
    problems = validate(scene)
    assert problems[0].element == 'ssd:Component "body"'
    assert "cannot read the modelDescription.xml of nostart.fmu" in problems[0].message
    assert 'Variable "F"' in problems[0].message and "has no start value" in problems[0].message
    # the stimulus on body.F can no longer be checked; nothing else is reported
    assert len(problems) == 1
