"""Clock connections (master/clocks.py, kernel.h: MK_CLOCK, MK_TICK_LINKED): an output clock of a
Scheduled Execution component drives a triggered input clock of another; the connection carries the
source's count of ticks, and the consumer's clock ticks at each point where that count has grown.

Two instances of the project's `clocks` model (fmus/clocks/, the Reference FMUs' Clocks): in `a`,
inClock1 ticks every second, inClock2 at 1 s (a stimulus) and inClock3 once at 4 s, so its
totalInClockTicks becomes 5 at 3 s and 10 at 7 s, where its outClock ticks; a.outClock drives
b.inClock2.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from helpers import run_everywhere, ssd

import master.api as api
from master.scenario import ScenarioError
from master.scenario.model import Scheme

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
