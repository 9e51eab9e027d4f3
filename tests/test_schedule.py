"""The schedule: exact times, window selection (extrapolate vs interpolate), start-up; the rules a
Scenario built in Python must keep before the planner sees it (`master.scenario.check`)."""

from fractions import Fraction
from pathlib import Path

import pytest

from master.description import CO_SIMULATION, Capability, Description, Variable
from master.scenario import check
from master.scenario.model import Component, Connection, Scenario, Stimulus
from master.schedule import Clock, Link, build_plan


def var(name, causality, type_="Real"):
    return Variable(name, 0, type_, causality, "continuous", None, None, None, None)


VARS = {
    "a": {"y": var("y", "output"), "u": var("u", "input"), "n": var("n", "output", "Integer")},
    "b": {"y": var("y", "output"), "u": var("u", "input"), "w": var("w", "input")},
}


# the same FMUs as the scenario checks see them
FMUS = {
    c: Description(Path(f"{c}.fmu"), "2.0", vs, {}, {CO_SIMULATION: Capability()}) for c, vs in VARS.items()
}


def scene(**kw):
    base = dict(
        path=Path("scene.ssd"),
        name="s",
        components=(
            Component("a", Path("a.fmu"), step_ratio=2),
            Component("b", Path("b.fmu"), extrapolation_order=2),
        ),
        connections=(Connection("a", "y", "b", "u"), Connection("b", "y", "a", "u")),
        start_time=Fraction(0),
        stop_time=Fraction(1),
        macro_step=Fraction(1, 10),
    )
    base.update(kw)
    return Scenario(**base)


def test_a_million_steps_end_exactly_at_the_stop_time():
    start, H, k = Fraction(1, 10), Fraction(1, 3), 8
    stop = start + 125_000 * H
    plan = build_plan(scene(start_time=start, stop_time=stop, macro_step=H), VARS)
    clock = Clock.make(start, H, k)
    n_steps = plan.n_macro * k
    assert n_steps == 10**6
    assert clock.time(n_steps) == float(stop)
    # every point is the float nearest to the exact rational
    for j in (1, 3, 999_999, 123_457):
        assert clock.time(j) == float(start + j * H / k)
        assert clock.exact(j) == start + j * H / k


def test_window_jacobi_uses_only_samples_up_to_the_macro_point():
    lk = Link("a", "b", ("y",), ("u",), 2, False, k_source=3, k_consumer=2)
    for n in range(5):
        for j in range(2 * n, 2 * n + 2):
            j_end, p = lk.window(n, j)
            assert j_end == 3 * n
            assert p == min(2, 3 * n)


def test_window_gauss_seidel_interpolates_over_the_consumer_step():
    # source 4 steps per macro step, consumer 2: consumer step j covers source samples 2j .. 2j+2
    lk = Link("a", "b", ("y",), ("u",), 1, True, k_source=4, k_consumer=2)
    n = 3
    for j in (6, 7):
        j_end, p = lk.window(n, j)
        assert j_end == 2 * (j + 1)  # first source sample at/after the consumer step's end
        assert j_end <= 4 * (n + 1)
        assert p == 1
    # slower source: only samples up to the macro end exist
    lk = Link("a", "b", ("y",), ("u",), 0, True, k_source=1, k_consumer=3)
    assert [lk.window(2, j)[0] for j in (6, 7, 8)] == [3, 3, 3]


def test_startup_lowers_the_order_until_history_exists():
    lk = Link("a", "b", ("y",), ("u",), 3, False, k_source=1, k_consumer=1)
    assert lk.startup() == [(0, 0), (1, 1), (2, 2)]
    lk = Link("a", "b", ("y",), ("u",), 3, False, k_source=2, k_consumer=1)
    assert lk.startup() == [(0, 0), (1, 2)]
    plan = build_plan(scene(), VARS)
    assert any("start-up" in n and "full order 2" in n for n in plan.notes)


def test_plan_links_orders_and_recording():
    sc = scene(
        coupling="gauss-seidel",
        order=("b", "a"),
        connections=(Connection("a", "y", "b", "u", extrapolation_order=3), Connection("b", "y", "a", "u")),
        stimuli=(Stimulus("b", "w", "step", (0.5,), (1.0,)),),
        record_interval=Fraction(3, 10),
    )
    plan = build_plan(sc, VARS)
    assert [c.name for c in plan.components] == ["b", "a"]
    by = {(lk.source, lk.consumer): lk for lk in plan.links}
    assert by[("a", "b")].order == 3 and not by[("a", "b")].source_first
    assert by[("b", "a")].order == 0 and by[("b", "a")].source_first
    assert plan.record == (("a", "y"), ("a", "n"), ("b", "y"))  # all outputs by default
    assert plan.record_every == 3
    # rows after every third of the 10 macro steps, and after the last (at the stop time)
    assert [n for n in range(plan.n_macro) if plan.record_due(n)] == [2, 5, 8, 9]
    assert plan.component("a").step == Fraction(1, 20)


def test_interpolate_inputs_steps_once_per_macro_step_only_if_the_fmu_can():
    comps = (
        Component("a", Path("a.fmu"), step_ratio=4, interpolate_inputs=True),
        Component("b", Path("b.fmu")),
    )
    plan = build_plan(scene(components=comps), VARS, {"a": Capability(True)})
    assert plan.component("a").step_ratio == 1 and plan.component("a").interpolate_inputs
    plan = build_plan(scene(components=comps), VARS, {"a": Capability(False)})
    assert plan.component("a").step_ratio == 4
    assert any("cannot interpolate inputs" in n for n in plan.notes)


def test_the_scenes_these_tests_schedule_keep_every_rule():
    assert check(scene(), FMUS) == []


@pytest.mark.parametrize(
    "kw, message",
    [
        (
            dict(stop_time=Fraction(21, 20)),
            "stop time - start time = 1.05 s is not a whole number of macro steps",
        ),
        (
            dict(connections=(Connection("a", "y", "b", "nope"),)),
            'the FMU of b (b.fmu) has no variable "nope"',
        ),
        (dict(connections=(Connection("a", "u", "b", "u"),)), "start a.u is an input, not an output"),
        (
            dict(connections=(Connection("a", "y", "b", "u"), Connection("b", "y", "b", "u"))),
            "already driven",
        ),
        (dict(connections=(Connection("a", "n", "b", "u"),)), "type mismatch: a.n is Integer, b.u is Real"),
        (dict(connections=(Connection("x", "y", "b", "u"),)), 'unknown component "x"'),
        (dict(record_interval=Fraction(1, 20)), "not a positive multiple of the macro step"),
        (dict(record=(("a", "zz"),)), 'has no variable "zz"'),
        (dict(stimuli=(Stimulus("a", "u", "step", (0.5,), (1.0,)),)), "stimuli are for undriven inputs"),
        (dict(stimuli=(Stimulus("b", "w", "step", (0.5, 0.2), (1.0, 2.0)),)), "times must not decrease"),
        (
            dict(components=(Component("a", Path("a.fmu"), step_ratio=0), Component("b", Path("b.fmu")))),
            "step ratio 0",
        ),
        (dict(coupling="gauss-seidel", order=("a",)), "must list every component once"),
        (dict(connections=(Connection("a", "y", "b", "u", extrapolation_order=4),)), "order 4 not in 0..3"),
        (
            dict(
                components=(
                    Component("a", Path("a.fmu")),
                    Component("a", Path("a.fmu")),
                    Component("b", Path("b.fmu")),
                )
            ),
            'a second component named "a"',
        ),
        (dict(macro_step=Fraction(0)), "the macro step must be positive"),
        (dict(stop_time=Fraction(0)), "is not after start time"),
    ],
)
def test_bad_scenarios_get_clear_problems(kw, message):
    (problem,) = check(scene(**kw), FMUS)
    assert problem.file == "scene.ssd" and problem.line is None
    assert message in str(problem)
