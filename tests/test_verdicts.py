"""One set of rules: every scenario file of the project gets the same verdict from `validate` and
from `master.api.plan`. A file validate accepts is scheduled without a word (the checks of a
Scenario object find nothing validate missed); a file it refuses does not load (the reader raises
the same problems)."""

from fractions import Fraction
from pathlib import Path

import pytest

import master.api as api
from master.fmubuild import fmu_path
from master.scenario import ScenarioError
from master.scenario.model import Component, Connection, Scenario, Stimulus

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted(p for d in ("tests", "models", "docs") for p in (ROOT / d).rglob("*.ss[dp]"))


def test_the_project_has_scenarios_of_every_kind():
    assert len([p for p in SCENES if "/bad/" in str(p)]) >= 12 and len(SCENES) >= 20


@pytest.mark.parametrize("path", SCENES, ids=[str(p.relative_to(ROOT)) for p in SCENES])
def test_validate_and_the_planner_give_the_same_verdict(path):
    problems = api.validate(path)
    if problems:
        with pytest.raises(ScenarioError) as refused:
            api.load_scenario(path)
        assert [str(p) for p in refused.value.problems] == [str(p) for p in problems]
    else:
        plan = api.plan(api.load_scenario(path))  # raises ScenarioError where the rules differ
        assert plan.n_macro > 0


OSCILLATOR = ROOT / "tests" / "scenarios" / "oscillator" / "oscillator.ssd"  # H = 0.01 s, stop 10 s


def refused(call) -> str:
    """The one line of the only problem `call` raises ScenarioError with."""
    with pytest.raises(ScenarioError) as e:
        call()
    (problem,) = e.value.problems
    assert problem.line is None and str(problem) == str(e.value)
    return str(problem)


@pytest.mark.parametrize(
    "overrides, message",
    [
        (
            dict(stop_time="0.015"),
            "stop time: stop time - start time = 0.015 s is not a whole number of macro",
        ),
        (
            dict(record=["mass1.nope"]),
            "record mass1.nope: unknown variable: the FMU of mass1 (msd.fmu) has no",
        ),
        (
            dict(output_interval="0.015"),
            "record interval: interval 0.015 s is not a positive multiple of the",
        ),
        (dict(stop_time="1e9"), "stop time: 1e+11 macro steps from startTime to stopTime: at most 1e+10"),
    ],
)
def test_an_overridden_scenario_that_breaks_a_rule_is_refused_by_the_scenario_layer(overrides, message):
    assert f"oscillator.ssd: {message}" in refused(lambda: api.run(OSCILLATOR, **overrides))


def test_a_scenario_built_in_python_that_breaks_a_rule_gets_the_scenario_layers_message():
    fmu = fmu_path("alltypes", fmi=3)
    H = Fraction(1, 10)

    def scene(**kw) -> Scenario:
        comps = (Component("a", fmu), Component("b", fmu))
        times = dict(start_time=Fraction(0), stop_time=Fraction(1), macro_step=H)
        return Scenario(Path("built.ssd"), "built", comps, **({"connections": ()} | times | kw))

    assert api.plan(scene(connections=(Connection("a", "y_int32", "b", "u_int32"),))).n_macro == 10
    connection = (Connection("a", "y_int32", "b", "u_float64"),)
    assert refused(lambda: api.plan(scene(connections=connection))) == (
        "built.ssd: connection a.y_int32 -> b.u_float64: type mismatch: a.y_int32 is Int32, b.u_float64 is "
        "Float64"
    )
    stimulus = (Stimulus("a", "u_nope", "step", (0.5,), (1.0,)),)
    assert refused(lambda: api.run(scene(stimuli=stimulus))) == (
        'built.ssd: stimulus a.u_nope: unknown variable: the FMU of a (alltypes.fmu) has no variable "u_nope"'
    )
    stimulus = (Stimulus("a", "u_int8", "step", (0.5,), (300.0,)),)
    assert "value 300 is outside [-128, 127] (a.u_int8 is Int8)" in refused(
        lambda: api.run(scene(stimuli=stimulus))
    )
    assert "record a.y_vec[4]: " in refused(lambda: api.run(scene(), record=["a.y_vec[4]"]))
    assert api.plan(scene(record=(("a", "y_string"), ("a", "y_binary")))).column_types == {
        "a.y_string": "String", "a.y_binary": "Binary"
    }  # fmt: skip
    # every problem at once, as for a file
    with pytest.raises(ScenarioError) as e:
        api.plan(scene(connections=connection, stop_time=Fraction(21, 20)))
    assert [p.element for p in e.value.problems] == ["stop time", "connection a.y_int32 -> b.u_float64"]
