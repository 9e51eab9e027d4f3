"""FMI 3 Co-Simulation in event mode: the project's FMUs with events declare hasEventMode, the master
instantiates them with eventModeUsed and early return allowed; doStep returns at an event (early
inside the step), the kernel does the event iteration there and completes the step, so the
component's communication points stay the schedule's; a discrete input that changes is an input
event (kernel.h: mk_component.cs_events).

Closed forms: bouncing_ball (state events), stair (time events); fmpy's single-FMU event-mode
simulation of the same FMU; a network of stair and two latches passing an Int32 at events.
"""

from __future__ import annotations

import dataclasses
import math
import re
import shutil
from fractions import Fraction
from pathlib import Path

import fmpy
import numpy as np
import pytest
from helpers import BACKENDS, run_everywhere, ssd

import master.api as api
from master.backends.component import SimulationError
from master.fmubuild import build_fmu, fmu_path
from master.scenario import ScenarioError
from master.scenario.model import Component, Connection, Iteration, Scenario, Scheme
from master.solvers import NUMBERS

EVENT_TOLERANCE = 1e-10  # s, fmus/solvers/solvers.h
G, E, H0 = 9.81, 0.7, 1.0  # bouncing_ball's defaults


def fmu3(name: str) -> Path:
    return build_fmu(name, fmi=3)


def single(name: str, path: Path, stop: Fraction, step: Fraction, **parameters) -> Scenario:
    comp = Component(name, path, parameters=parameters)
    return Scenario(Path(f"{name}.ssd"), name, (comp,), (), Fraction(0), stop, step)


def bounces(until: float) -> list[float]:
    """The closed-form bounce times before `until`: t1 = sqrt(2 h0 / g), then flights of 2 e^k v1 / g."""
    v1 = math.sqrt(2 * G * H0)
    times = [v1 / G]
    while times[-1] + 2 * E ** len(times) * v1 / G < until:
        times.append(times[-1] + 2 * E ** len(times) * v1 / G)
    return times


def at_points(result: np.ndarray, step: float) -> np.ndarray:
    """fmpy's rows at the communication points (after an event there: its last row of that time)."""
    t = result["time"]
    last = np.r_[t[1:] != t[:-1], True]
    return result[last & np.isclose(t / step, np.round(t / step), rtol=0, atol=1e-9)]


def test_the_fmi3_builds_of_models_with_events_declare_event_mode():
    for name in ("bouncing_ball", "stair", "latch", "ratchet"):
        assert fmpy.read_model_description(str(fmu3(name))).coSimulation.hasEventMode, name
    assert not fmpy.read_model_description(str(fmu3("dahlquist"))).coSimulation.hasEventMode


def test_bouncing_ball_returns_early_at_its_bounces_and_agrees_with_its_closed_form_and_fmpy():
    """fmpy's event-mode loop records a row where doStep returned early and one after the event
    iteration: those times are the bounces, located to the tolerance (bounce k up to 2 k tolerances
    late, as inside the step). The master's run (every backend) meets them the same way, its
    samples on the flights' closed form, and equals fmpy's at the communication points."""
    step, stop = 0.01, 2.0
    params = {"solver": NUMBERS["rk4"], "internal_step": 0.0025}
    path = fmu3("bouncing_ball")
    ref = fmpy.simulate_fmu(
        str(path), stop_time=stop, output_interval=step, output=["h", "v"], start_values=params,
        use_event_mode=True, early_return_allowed=True,
    )  # fmt: skip
    t = ref["time"]
    events = t[1:][t[1:] == t[:-1]]  # recorded before and after the event iteration
    closed = bounces(stop)
    assert len(events) == len(closed) == 4
    for k, (found, tk) in enumerate(zip(events, closed, strict=True), start=1):
        assert 0 <= found - tk <= 2 * k * EVENT_TOLERANCE, (k, found - tk)
        assert not np.isclose(found / step, round(found / step), rtol=0, atol=1e-6)  # inside a step
    d = run_everywhere(single("bouncing_ball", path, Fraction(2), Fraction(1, 100), **params))
    fm = at_points(ref, step)
    assert len(fm) == len(d)
    for c in ("h", "v"):
        np.testing.assert_allclose(d[f"bouncing_ball.{c}"], fm[c], rtol=0, atol=1e-12)
    # each flight is the parabola of the bounce before it: apex e^(2k) h0
    for k, tk in enumerate(closed, start=1):
        end = closed[k] if k < len(closed) else stop
        flight = (d["time"] > tk + 1e-6) & (d["time"] < end - 1e-6)
        h, v = d["bouncing_ball.h"][flight], d["bouncing_ball.v"][flight]
        np.testing.assert_allclose(h + v**2 / (2 * G), E ** (2 * k) * H0, rtol=0, atol=1e-9)


@pytest.mark.parametrize("solver", ["rk4", "ab3"])
def test_event_mode_gives_the_bits_of_the_events_handled_inside_dostep(solver):
    """The FMI 2 build handles its bounces inside doStep; the FMI 3 build in event mode returns at
    them and completes its step on the same grid of internal steps after the master's event
    iteration (the multistep history restarted alike): the same numbers, bit for bit."""
    params = {"solver": NUMBERS[solver], "internal_step": 0.0025}
    a = api.run(single("bouncing_ball", fmu_path("bouncing_ball"), Fraction(2), Fraction(1, 100), **params))
    b = api.run(single("bouncing_ball", fmu3("bouncing_ball"), Fraction(2), Fraction(1, 100), **params))
    assert np.min(a.data["bouncing_ball.v"]) < -4 and np.max(a.data["bouncing_ball.v"]) > 2  # it bounced
    for name in a.data.dtype.names:
        assert np.array_equal(a.data[name], b.data[name]), name


@pytest.mark.parametrize("step", [Fraction(1, 10), Fraction(3, 10)], ids=["events-at-points", "inside-steps"])
def test_stair_in_event_mode_counts_its_time_events_exactly(step):
    """counter(t) = 1 + floor(t); an event inside a step: the FMU returns early there, the rest of the
    step follows; the master's points stay those of the schedule. fmpy's event mode agrees."""
    path = fmu3("stair")
    d = run_everywhere(single("stair", path, Fraction(3), step))
    times = [Fraction(j) * step for j in range(len(d))]
    assert times[-1] == 3 and d["time"].tolist() == [float(t) for t in times]
    assert d["stair.counter"].tolist() == [1 + math.floor(t) for t in times]
    ref = at_points(
        fmpy.simulate_fmu(str(path), stop_time=3.0, output_interval=float(step), output=["counter"],
                          use_event_mode=True, early_return_allowed=True),
        float(step),
    )  # fmt: skip
    assert ref["counter"].tolist() == d["stair.counter"].tolist()


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_run_summary_counts_the_events_handled(backend):
    """stair's time events at 1, 2 and 3 s, each handled once, whether at a point or inside a step."""
    for step, steps in ((Fraction(1, 10), 30), (Fraction(3, 10), 10)):
        summary = api.run(single("stair", fmu3("stair"), Fraction(3), step), backend=backend).summary
        assert summary.steps == {"stair": steps} and summary.events == {"stair": 3}
        assert f"  stair: {steps} steps, 3 events, " in str(summary)


def network(scheme: Scheme, fmi: int = 3, period: float = 1.0, stop: int = 3) -> Scenario:
    """stair (its counter, an Int32 stepped by time events) -> latch a -> latch b, macro step 0.1."""
    path = fmu3 if fmi == 3 else fmu_path
    comps = (
        Component("clock", path("stair"), parameters={"period": period}),
        Component("a", path("latch")),
        Component("b", path("latch")),
    )
    conns = (Connection("clock", "counter", "a", "u"), Connection("a", "latched", "b", "u"))
    order = ("clock", "a", "b") if scheme == Scheme.GAUSS_SEIDEL else ()
    return Scenario(
        Path("net.ssd"), "net", comps, conns, Fraction(0), Fraction(stop), Fraction(1, 10), scheme, order
    )


def latch_times(d: np.ndarray, name: str) -> list[float]:
    """The times at which latch `name` latched a change after the start, from its rows (t_latched
    where changes grew)."""
    changes, when = d[f"{name}.changes"], d[f"{name}.t_latched"]
    return [float(when[i]) for i in range(1, len(d)) if changes[i] > changes[i - 1]]


@pytest.mark.parametrize("ratio", [1, 2])
def test_a_discrete_signal_passes_along_a_chain_at_its_event_in_gauss_seidel_order(ratio):
    """In the stepping order clock, a, b the counter's time event at t = k (a communication point)
    is handled by the clock at the end of its step; a takes the new value as an input event at k,
    after its step to k (with two steps per macro step: after the second, the sample being of k),
    and b, fed by a, at k too: the event sequence of one instant, every backend."""
    sc = network(Scheme.GAUSS_SEIDEL)
    comps = tuple(dataclasses.replace(c, step_ratio=ratio) if c.name == "a" else c for c in sc.components)
    d = run_everywhere(dataclasses.replace(sc, components=comps))
    assert latch_times(d, "a") == latch_times(d, "b") == [1.0, 2.0, 3.0]
    expected = (1 + np.floor(d["time"] + 1e-9)).tolist()
    for column in ("clock.counter", "a.latched", "b.latched"):
        assert d[column].tolist() == expected, column
    # at the start: the initial event iterations, then b's input event with a's value after a's
    assert d["a.changes"][0] == d["b.changes"][0] == 1 and d["a.t_latched"][0] == d["b.t_latched"][0] == 0


def test_in_jacobi_each_link_passes_the_discrete_signal_at_the_next_macro_step():
    """Jacobi takes every source's sample of the macro step's start: a sees the counter of time k
    at k (an input event there, before its step), b sees a's sample of k + 0.1 at k + 0.1. The FMI
    2 builds, without event mode, latch at their first step event after the change: one step later
    each."""
    d = run_everywhere(network(Scheme.JACOBI))
    assert latch_times(d, "a") == [1.0, 2.0]
    assert np.allclose(latch_times(d, "b"), [1.1, 2.1], rtol=0, atol=1e-12)
    old = api.run(network(Scheme.JACOBI, fmi=2)).data
    assert np.allclose(latch_times(old, "a"), [1.1, 2.1], rtol=0, atol=1e-12)
    # (b's first: a's start value, at b's first step event; in event mode an input event at the start)
    assert np.allclose(latch_times(old, "b"), [0.1, 1.2, 2.2], rtol=0, atol=1e-12)


def test_iterated_jacobi_passes_the_discrete_signal_along_the_chain_in_one_instant():
    """Iterated macro steps (mm:Iteration) take the sources' samples of the macro step's end in their
    relaxed sweeps: a and b latch the counter's change at k, as in Gauss-Seidel order, in every
    backend."""
    d = run_everywhere(dataclasses.replace(network(Scheme.JACOBI), iteration=Iteration()))
    assert latch_times(d, "a") == latch_times(d, "b") == [1.0, 2.0, 3.0]


def test_time_events_between_communication_points_reach_the_consumers_at_their_next_point():
    """period 0.35 s: the clock returns early at k 0.35 inside its step and completes it; a and b
    latch the new count at the first point after it, ceil(k 3.5) / 10 (every backend)."""
    d = run_everywhere(network(Scheme.GAUSS_SEIDEL, period=0.35, stop=2))
    events = [Fraction(35, 100) * k for k in range(1, 6)]
    seen = [float(Fraction(math.ceil(e * 10), 10)) for e in events]
    assert np.allclose(latch_times(d, "a"), seen, rtol=0, atol=1e-12)
    assert np.allclose(latch_times(d, "b"), seen, rtol=0, atol=1e-12)
    expected = [1 + math.floor(Fraction(j, 10) / Fraction(35, 100)) for j in range(len(d))]
    assert d["clock.counter"].tolist() == expected


def test_event_mode_off_for_a_component_handles_its_events_inside_dostep(tmp_path):
    """eventMode="false" on a component's mm:Component: instantiated without, the clock handles its
    events inside doStep and a latches its input at its step events (FMI 2's behaviour, one step
    late); the other latch keeps event mode. An FMU without Event Mode cannot be asked
    for it: one line naming the file and the component's settings."""
    for name in ("stair", "latch"):
        shutil.copy(fmu3(name), tmp_path / f"{name}.fmu")
    comps = {"clock": "stair.fmu", "a": "latch.fmu", "b": "latch.fmu"}
    links = [("clock", "counter", "a", "u"), ("a", "latched", "b", "u")]
    settings = '<mm:Component name="clock" eventMode="false"/><mm:Component name="a" eventMode="false"/>'
    path = ssd(tmp_path / "net.ssd", comps, links, settings, stop="3")
    sc = api.load_scenario(path)
    assert [c.event_mode for c in sc.components] == [False, False, True]
    d = run_everywhere(sc)
    # a latches at its step events, at the ends of the steps into which the counter changed; b, in
    # event mode, at once where it takes a's sample of that time
    assert np.allclose(latch_times(d, "a"), [1.1, 2.1], rtol=0, atol=1e-12)
    assert np.allclose(latch_times(d, "b"), [1.1, 2.1], rtol=0, atol=1e-12)
    on = api.run(api.load_scenario(ssd(tmp_path / "on.ssd", comps, links, stop="3"))).data
    assert latch_times(on, "a") == [1.0, 2.0]  # in event mode: an input event at the counter's sample of k
    shutil.copy(fmu_path("latch"), tmp_path / "latch2.fmu")  # FMI 2.0: no Event Mode
    bad = ssd(
        tmp_path / "bad.ssd",
        {"clock": "stair.fmu", "a": "latch2.fmu"},
        links[:1],
        '<mm:Component name="a" eventMode="true"/>',
    )
    with pytest.raises(ScenarioError) as e:
        api.load_scenario(bad)
    line = 'bad.ssd:16: mm:Component "a": eventMode: latch2.fmu has no FMI 3 Co-Simulation Event Mode'
    assert str(e.value).endswith(line + " (hasEventMode)")
    assert "\n" not in str(e.value)


def cycle(limit: int, iteration: Iteration | None) -> Scenario:
    """Two latches in a discrete cycle: a takes b's next = min(b.latched + 1, limit), b takes a's latched."""
    comps = (
        Component("a", fmu3("latch")),
        Component("b", fmu3("latch"), parameters={"increment": 1, "limit": limit}),
    )
    conns = (Connection("b", "next", "a", "u"), Connection("a", "latched", "b", "u"))
    return Scenario(
        Path("cycle.ssd"),
        "cycle",
        comps,
        conns,
        Fraction(0),
        Fraction(1),
        Fraction(1, 10),
        iteration=iteration,
    )


def test_a_discrete_cycle_is_iterated_to_its_fixed_point_in_one_macro_step():
    """Explicit coupling passes the count once around the cycle per two macro steps (Jacobi: one
    step per connection; the start time's sweeps after initialisation went around it once).
    Iterated macro steps repeat the first one, each sweep an event iteration of both with the
    other's new value, until nothing changes: a and b hold the limit from the first macro step's
    end on, in every backend; a cycle that never settles (a limit beyond the sweeps) stops the run
    with one line."""
    explicit = run_everywhere(cycle(5, None))
    assert explicit["a.latched"].tolist() == [2, 3, 3, 4, 4, 5, 5, 5, 5, 5, 5]
    assert explicit["b.latched"].tolist() == [2, 2, 3, 3, 4, 4, 5, 5, 5, 5, 5]
    d = run_everywhere(cycle(5, Iteration()))
    assert d["a.latched"][1:].tolist() == d["b.latched"][1:].tolist() == d["b.next"][1:].tolist() == [5] * 10
    with pytest.raises(SimulationError) as e:
        api.run(cycle(100, Iteration()))
    assert re.fullmatch(
        r"iterated coupling did not converge in the macro step from t=0.0 to t=0.1: after 20 sweeps "
        r"(a\.latched|b\.next) still changed by 1 \(tolerance 1e-08 \(1 \+ \|value\|\)\); "
        r"raise maxIterations of mm:Iteration or shorten the macro step",
        str(e.value),
    ), str(e.value)
