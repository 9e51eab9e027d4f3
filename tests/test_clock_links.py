"""Clock connections (master/clocks.py, kernel.h: MK_CLOCK, MK_TICK_LINKED): an output clock of a
Scheduled Execution component drives a triggered input clock of another; the connection carries the
source's count of ticks, and the consumer's clock ticks at each point where that count has grown.

Two instances of the project's `clocks` model (fmus/clocks/, the Reference FMUs' Clocks): in `a`,
inClock1 ticks every second, inClock2 at 1 s (a stimulus) and inClock3 once at 4 s, so its
totalInClockTicks becomes 5 at 3 s and 10 at 7 s, where its outClock ticks; a.outClock drives
b.inClock2.

The project's `ticker` (fmus/ticker/, FMI 3 Co-Simulation in event mode) ticks its output clock at
its time events, k period; with period 0.75 s and communication step 0.5 s most of them fall inside
a step (it returns early there), and its count is read after each event iteration.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from helpers import run_everywhere, ssd

import master.api as api
from master.scenario import ScenarioError
from master.scenario.model import Iteration, Scheme

TICKS_OF_A = [0, 0, 0, 1, 1, 1, 1, 2, 2, 2]  # a.outClock's count at 0 .. 9 s
A_TICKS_AT_1 = (
    '<mm:Stimuli><mm:Step component="a" variable="inClock2">'
    '<mm:Point time="1" value="1"/></mm:Step></mm:Stimuli>'
)


def _linked(tmp_path: Path, coupling: Scheme, end: str = "inClock2") -> Path:
    return ssd(
        tmp_path / "linked.ssd",
        {"a": "project:clocks", "b": "project:clocks"},
        [("a", "outClock", "b", end)],
        settings=A_TICKS_AT_1,
        macro_step="1",
        stop="9",
    )


def _run(tmp_path: Path, coupling: Scheme):
    sc = api.load_scenario(_linked(tmp_path, coupling))
    if coupling == Scheme.GAUSS_SEIDEL:
        sc = dataclasses.replace(sc, coupling=coupling, order=("a", "b"))
    else:
        sc = dataclasses.replace(sc, coupling=coupling)
    record = [("a", "totalInClockTicks"), ("b", "inClock2Ticks"), ("b", "totalInClockTicks")]
    return run_everywhere(dataclasses.replace(sc, record=tuple(record)))


def test_an_output_clock_ticks_a_linked_input_clock_in_every_backend(tmp_path):
    # Gauss-Seidel, a first: b's inClock2 ticks at the points where a's outClock ticked, 3 and 7 s
    data = _run(tmp_path, Scheme.GAUSS_SEIDEL)
    assert list(data["a.totalInClockTicks"]) == [1, 3, 4, 5, 7, 8, 9, 10, 11, 12]
    assert list(data["b.inClock2Ticks"]) == TICKS_OF_A
    # Jacobi: b sees a's count of the macro step's start, one step later
    data = _run(tmp_path, Scheme.JACOBI)
    assert list(data["b.inClock2Ticks"]) == [0] + TICKS_OF_A[:-1]


def test_validate_accepts_a_clock_connection_and_info_names_it(tmp_path):
    path = _linked(tmp_path, Scheme.JACOBI)
    assert api.validate(path) == []
    shown = api.plan(api.load_scenario(path)).describe()
    assert "inClock2 at the ticks of the output clock connected to it" in shown
    assert "a.outClock -> b.inClock2: order 0, held (Clock)" in shown


def test_a_bad_clock_connection_is_one_clear_line(tmp_path):
    (problem,) = map(str, api.validate(_linked(tmp_path, Scheme.JACOBI, end="inClock1")))
    assert "ssd:Connection a.outClock -> b.inClock1" in problem
    assert 'clock inClock1 is "constant": a Clock connection drives a triggered input clock' in problem
    (problem,) = map(str, api.validate(_linked(tmp_path, Scheme.JACOBI, end="input2")))
    assert "type mismatch: a.outClock is Clock, b.input2 is Int32" in problem


def test_a_scenario_built_in_python_keeps_the_same_rule(tmp_path):
    sc = api.load_scenario(_linked(tmp_path, Scheme.JACOBI))
    (cn,) = sc.connections
    bad = dataclasses.replace(sc, connections=(dataclasses.replace(cn, end_connector="inClock3"),))
    with pytest.raises(
        ScenarioError, match='clock inClock3 is "countdown": a Clock connection drives a triggered'
    ):
        api.plan(bad)
    # iterated macro steps repeat steps from saved FMU states, which do not hold the counts of ticks
    with pytest.raises(ScenarioError, match="a Clock connection does not run with iterated macro steps"):
        api.plan(dataclasses.replace(sc, iteration=Iteration()))


TICKER = [0, 0, 1, 2, 2, 3, 4, 4, 5]  # ticks of period 0.75 s by 0, 0.5 .. 4 s


def _ticker_file(tmp_path: Path, settings: str = "") -> Path:
    return ssd(
        tmp_path / "ticker.ssd",
        {"t": "project:ticker", "b": "project:clocks"},
        [("t", "tick", "b", "inClock2")],
        settings=settings,
        macro_step="0.5",
        stop="4",
    )


def _from_ticker(tmp_path: Path, coupling: Scheme):
    sc = api.load_scenario(_ticker_file(tmp_path))
    comps = tuple(
        dataclasses.replace(c, parameters={"period": 0.75}) if c.name == "t" else c for c in sc.components
    )
    record = (("t", "ticks"), ("b", "inClock2Ticks"))
    return dataclasses.replace(sc, components=comps, coupling=coupling, order=("t", "b"), record=record)


def test_a_co_simulation_output_clock_ticks_at_its_events_in_every_backend(tmp_path):
    # Gauss-Seidel, ticker first: b's inClock2 ticks at each point by which the ticker ticked since
    # the previous one (at most once a point), in the same instant
    sc = _from_ticker(tmp_path, Scheme.GAUSS_SEIDEL)
    data = run_everywhere(sc)
    assert list(data["t.ticks"]) == TICKER
    assert list(data["b.inClock2Ticks"]) == [0, 0, 1, 2, 2, 3, 4, 4, 5]
    summary = api.run(sc).summary
    assert summary.events == {"t": 5} and summary.clock_ticks["b.inClock2"] == 5
    # Jacobi: one point later
    data = run_everywhere(_from_ticker(tmp_path, Scheme.JACOBI))
    assert list(data["b.inClock2Ticks"]) == [0, 0, 0, 1, 2, 2, 3, 4, 4]


def test_a_co_simulation_output_clock_needs_event_mode(tmp_path):
    off = '<mm:Component name="t" eventMode="false"/>'
    (problem,) = map(str, api.validate(_ticker_file(tmp_path, off)))
    assert "ssd:Connection t.tick -> b.inClock2: a Clock connection starts at an output clock of a" in problem
    assert "or of an FMI 3 Co-Simulation component in event mode" in problem


def test_a_co_simulation_input_clock_ticks_in_an_input_event_in_every_backend(tmp_path):
    """ticker -> counter, both FMI 3 Co-Simulation in event mode: counter's inClock is set active
    (fmi3SetClock) in an input event where the ticker's count grew, and counter counts it."""
    path = ssd(
        tmp_path / "counter.ssd",
        {"t": "project:ticker", "c": "project:counter"},
        [("t", "tick", "c", "inClock")],
        macro_step="0.5",
        stop="4",
    )
    assert api.validate(path) == []
    sc = api.load_scenario(path)
    comps = tuple(
        dataclasses.replace(c, parameters={"period": 0.75}) if c.name == "t" else c for c in sc.components
    )
    sc = dataclasses.replace(sc, components=comps, record=(("t", "ticks"), ("c", "count")))
    data = run_everywhere(dataclasses.replace(sc, coupling=Scheme.GAUSS_SEIDEL, order=("t", "c")))
    assert list(data["t.ticks"]) == TICKER
    assert list(data["c.count"]) == [0, 0, 1, 2, 2, 3, 4, 4, 5]  # a tick a point where the count grew
    data = run_everywhere(dataclasses.replace(sc, coupling=Scheme.JACOBI))
    assert list(data["c.count"]) == [0, 0, 0, 1, 2, 2, 3, 4, 4]
