"""FMI 3 clocks of a Scheduled Execution FMU, and when the master activates its model partitions.

A Scheduled Execution component (interface SCHEDULED_EXECUTION) takes no doStep: at the points of its
communication grid t_j = start + j h the kernel activates the partitions of the input clocks that
tick there (fmi3ActivateModelPartition(clock, t_j)), its inputs set before and its outputs read
after (sample-and-hold at activations), interleaved by time with the other components' steps.

Input clocks by intervalVariability:
- constant, fixed, tunable with an interval in the description (intervalDecimal, or
  intervalCounter / resolution; shiftDecimal or shiftCounter / resolution): periodic, ticking at
  start + shift + i interval, exact integer points of the grid (interval and shift must be
  multiples of h). A tunable clock keeps the interval it starts with.
- countdown: the FMU announces its next tick with fmi3GetIntervalDecimal (qualifier changed) after an
  activation; it ticks that interval later, on the grid.
- triggered: ticks where the scenario says: a step stimulus on the clock, a tick at each of its
  times with a nonzero value (times on the grid); or a Clock connection from an output clock
  (linked): at each point where the source's count of ticks, which the connection carries as a held
  integer, has grown since the clock last ticked. The source is a Scheduled Execution component or
  an FMI 3 Co-Simulation one in event mode, whose output clocks the kernel reads after each event
  iteration; a Co-Simulation consumer in event mode has its linked clocks set active (fmi3SetClock)
  in an input event instead (`link_problem`).
- changing (and fixed or tunable without an interval in the description): not supported.

Clocks that tick at the same point are activated in priority order (a smaller priority first), each
at most once per point. Output clocks are read with fmi3GetClock after each point's activations and
their ticks counted; that count is the output clock's value in a Clock connection. Clock variables
are not recorded as numbers.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

PERIODIC = ("constant", "fixed", "tunable")
MAX_CLOCKS = 64  # input clocks of one component (kernel.h: MK_MAX_CLOCKS)
SUPPORTED = (*PERIODIC, "countdown", "triggered")
# what the kernel does with an input clock (kernel.h: mk_scheduled.kinds)
TICK_PERIODIC, TICK_COUNTDOWN, TICK_TRIGGERED, TICK_LINKED = 0, 1, 2, 3


@dataclass(frozen=True)
class ClockVariable:
    """One Clock variable as its modelDescription.xml declares it (times in s, exact)."""

    name: str
    vr: int
    causality: str
    interval_variability: str
    interval: Fraction | None = None  # periodic clocks with an interval in the description
    shift: Fraction = Fraction(0)
    priority: int = 0


def _exact(decimal: str | None, counter: str | None, resolution: str | None) -> Fraction | None:
    """A time given as intervalDecimal (exact as written) or as counter / resolution."""
    if decimal is not None:
        return Fraction(decimal.strip())
    if counter is not None:
        return Fraction(int(counter), int(resolution or 1))
    return None


def read_clocks(path: Path) -> tuple[ClockVariable, ...]:
    """The Clock variables of the FMI 3 FMU at `path` (fmpy does not read their intervals)."""
    from lxml import etree

    with zipfile.ZipFile(path) as zf:
        root = etree.fromstring(zf.read("modelDescription.xml"))
    out = []
    for v in root.iterfind("ModelVariables/Clock"):
        resolution = v.get("resolution")
        out.append(
            ClockVariable(
                name=v.get("name"),
                vr=int(v.get("valueReference")),
                causality=v.get("causality", "local"),
                interval_variability=v.get("intervalVariability", ""),
                interval=_exact(v.get("intervalDecimal"), v.get("intervalCounter"), resolution),
                shift=_exact(v.get("shiftDecimal"), v.get("shiftCounter"), resolution) or Fraction(0),
                priority=int(v.get("priority", "0")),
            )
        )
    return tuple(out)


@dataclass(frozen=True)
class InputClock:
    """How the kernel activates one input clock: TICK_* `tick`; a periodic one at points
    phase + i every; a triggered one at `points`."""

    name: str
    vr: int
    tick: int
    every: int = 0
    phase: int = 0
    points: tuple[int, ...] = ()


@dataclass(frozen=True)
class Scheduled:
    """A Scheduled Execution component's activations on its grid of step h (exact integers)."""

    inputs: tuple[InputClock, ...]  # in activation order: priority, then value reference
    outputs: tuple[ClockVariable, ...]  # read after each point's activations

    def describe(self, step: Fraction) -> str:
        parts = []
        for c in self.inputs:
            if c.tick == TICK_PERIODIC and not c.every:
                parts.append(f"{c.name} every interval the FMU gives at the start, from {c.phase * step} s")
            elif c.tick == TICK_PERIODIC:
                parts.append(f"{c.name} every {c.every * step} s from {c.phase * step} s")
            elif c.tick == TICK_COUNTDOWN:
                parts.append(f"{c.name} when the FMU counts it down")
            elif c.tick == TICK_LINKED:
                parts.append(f"{c.name} at the ticks of the output clock connected to it")
            else:
                parts.append(f"{c.name} at {len(c.points)} stimulus times")
        return ", ".join(parts)


def on_grid(t: Fraction, step: Fraction) -> int | None:
    """t / step where it is a whole number, else None."""
    q = t / step
    return int(q) if q.denominator == 1 else None


def clock_problems(clock: ClockVariable, step: Fraction) -> list[str]:
    """Why the master cannot activate input clock `clock` on a grid of step `step` (s)."""
    name = f"clock {clock.name}"
    v = clock.interval_variability
    if v not in SUPPORTED:
        return [
            f'{name}: intervalVariability "{v}" is not supported (the master activates '
            f"{', '.join(SUPPORTED)} input clocks)"
        ]
    if v in PERIODIC:
        if clock.interval is None and v == "constant":
            return [f'{name}: intervalVariability "constant" without an interval in the description']
        if clock.interval is None:  # fixed, tunable: fmi3GetIntervalDecimal at the start (runtime)
            return []
        if clock.interval <= 0 or on_grid(clock.interval, step) is None:
            return [
                f"{name}: interval {float(clock.interval):g} s is not a multiple of the component's "
                f"communication step {float(step):g} s"
            ]
        if clock.shift < 0 or on_grid(clock.shift, step) is None:
            return [
                f"{name}: shift {float(clock.shift):g} s is not a multiple of the component's "
                f"communication step {float(step):g} s"
            ]
    return []


def scheduled_problems(clocks: tuple[ClockVariable, ...], step: Fraction) -> list[str]:
    """Why the master cannot activate the input clocks `clocks` of a Scheduled Execution component
    on its grid of step `step` (s)."""
    inputs = [c for c in clocks if c.causality == "input"]
    found = (
        [f"{len(inputs)} input clocks: the master activates at most {MAX_CLOCKS}"]
        if len(inputs) > MAX_CLOCKS
        else []
    )
    for clock in inputs:
        found += clock_problems(clock, step)
    return found


def stimulus_problems(
    clock: ClockVariable,
    scheduled: bool,
    kind: str,
    times: tuple[float, ...],
    start: Fraction,
    step: Fraction,
) -> list[str]:
    """Why a stimulus of kind `kind` at `times` cannot give input clock `clock` its ticks (a step
    stimulus, a tick at each time with a nonzero value) on a grid of step `step` from `start`;
    scheduled: its component runs as Scheduled Execution."""
    if not scheduled:
        return [f"clock {clock.name}: only a Scheduled Execution component's clocks tick"]
    if kind != "step":
        return [f"clock {clock.name}: its ticks are a step stimulus (a tick per nonzero value), not a {kind}"]
    if clock.interval_variability != "triggered":
        return [
            f"clock {clock.name}: a stimulus gives ticks to triggered clocks only, "
            f'not "{clock.interval_variability}" ones'
        ]
    why = tick_points(times, tuple(1.0 for _ in times), start, step)[1]
    return [f"clock {clock.name}: {why}"] if why else []


SCHEDULED, EVENTS = "Scheduled Execution", "event mode"  # how a component's clocks tick (`link_problem`)


def link_problem(
    source: ClockVariable | None, target: ClockVariable | None, modes: tuple[str, str]
) -> str | None:
    """Why a Clock connection cannot carry the ticks of output clock `source` to input clock `target`
    (None: no such clock); modes: how the source and the consumer run (SCHEDULED, EVENTS: FMI 3
    Co-Simulation in event mode, "" otherwise). None if it can."""
    if source is None or modes[0] not in (SCHEDULED, EVENTS):
        return (
            "a Clock connection starts at an output clock of a Scheduled Execution component or of an "
            "FMI 3 Co-Simulation component in event mode"
        )
    if target is None or modes[1] not in (SCHEDULED, EVENTS):
        return (
            "a Clock connection ends at a triggered input clock of a Scheduled Execution component or of "
            "an FMI 3 Co-Simulation component in event mode"
        )
    if target.interval_variability != "triggered":
        return (
            f'clock {target.name} is "{target.interval_variability}": a Clock connection drives a triggered '
            "input clock"
        )
    return None


def every_from_fmu(clock: InputClock, interval: float, step: Fraction) -> tuple[int | None, str]:
    """A periodic clock's interval as the FMU gives it (fmi3GetIntervalDecimal, s) in points of the
    grid of step `step`: (points, "") or (None, why not)."""
    q = Fraction(interval) / step
    whole = round(q)
    if interval > 0 and abs(q - whole) <= Fraction(1, 10**9) * max(1, whole):
        return whole, ""
    return None, (
        f"clock {clock.name}: interval {interval:g} s (fmi3GetIntervalDecimal) is not a multiple of the "
        f"component's communication step {float(step):g} s"
    )


def tick_points(
    times: tuple[float, ...], values: tuple[float, ...], start: Fraction, step: Fraction
) -> tuple[tuple[int, ...], str | None]:
    """The grid points of a step stimulus's ticks (its times with a nonzero value), and why not
    where a time is off the grid of step `step` from `start`."""
    points = []
    for t, v in zip(times, values, strict=False):
        j = on_grid(Fraction(t) - start, step)
        if j is None:  # a float time: its nearest point within rounding
            q = (Fraction(t) - start) / step
            j = round(q)
            if abs(q - j) > Fraction(1, 10**9):
                grid = f"the component's grid (step {float(step):g} s)"
                return (), f"tick time {t:g} s is not a point of {grid}"
        if j < 0:
            return (), f"tick time {t:g} s is before the start time"
        if v != 0:
            points.append(j)
    return tuple(sorted(set(points))), None


def schedule(
    clocks: tuple[ClockVariable, ...],
    start: Fraction,
    step: Fraction,
    ticks: dict[str, tuple[tuple[float, ...], tuple[float, ...]]],
    linked: frozenset[str] = frozenset(),
) -> Scheduled:
    """The activation tables of a valid component (`clock_problems` finds nothing); ticks: clock
    name -> the (times, values) of its step stimulus; linked: the inputs a connection drives."""
    inputs = []
    for c in sorted((c for c in clocks if c.causality == "input"), key=lambda c: (c.priority, c.vr)):
        v = c.interval_variability
        if v in PERIODIC:  # every 0: the FMU's interval, read at the start (`every_from_fmu`)
            every = on_grid(c.interval, step) if c.interval is not None else 0
            inputs.append(InputClock(c.name, c.vr, TICK_PERIODIC, every, on_grid(c.shift, step)))
        elif v == "countdown":
            inputs.append(InputClock(c.name, c.vr, TICK_COUNTDOWN))
        elif c.name in linked:
            inputs.append(InputClock(c.name, c.vr, TICK_LINKED))
        else:
            points = tick_points(*ticks[c.name], start, step)[0] if c.name in ticks else ()
            inputs.append(InputClock(c.name, c.vr, TICK_TRIGGERED, points=points))
    outputs = tuple(c for c in clocks if c.causality == "output")
    return Scheduled(tuple(inputs), outputs)
