"""The rules for a `Scenario` that did not come straight from a file: one built in Python, or a
file's scenario after `master.api.apply_overrides` (--stop-time, --record, --output-interval).

The reader applies these rules to files, with file:line, through the same rule functions
(`fmuinfo`, `settings`); here a problem names the scenario's path and the part of the scenario,
without a line (the object has none). `master.api.plan` runs `check` before the planner, which
assumes a valid scenario and keeps no rule of its own.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from fractions import Fraction

from master.clocks import EVENTS, SCHEDULED, link_problem, read_clocks, scheduled_problems, stimulus_problems
from master.description import Description, Variable, lookup, typed

from . import fmuinfo, transforms
from .fmuinfo import (
    SourceError,
    connection_problem,
    direction_problems,
    no_element,
    point_problem,
    record_problem,
    stimulus_problem,
)
from .model import LOOP_METHODS, Scenario, Scheme
from .problems import Problem, Problems
from .settings import (
    MAX_ITERATIONS,
    MAX_ORDER,
    interval_problem,
    limit_problems,
    model_exchange_problems,
    ratio_problem,
    steps_problem,
)

COUPLINGS = tuple(Scheme)
STIMULUS_KINDS = ("step", "table")

At = Callable[[str, str], None]  # at(element, message): report one problem
Infos = Mapping[str, Description | None]  # component -> its FMU (None: unreadable, reported once)


def check(sc: Scenario, fmus: Mapping[str, Description] | None = None) -> list[Problem]:
    """Every problem of `sc` at once (empty: the planner can schedule it). fmus: component name ->
    its FMU as the checks see it; None reads each component's `fmu_path` (an unreadable FMU is a
    problem of its component)."""
    problems = Problems()

    def at(element: str, message: str) -> None:
        problems.add(str(sc.path), None, element, message)

    infos: Infos = dict(fmus) if fmus is not None else _read(sc, at)
    _times(sc, at)
    _components(sc, at)
    driven = _connections(sc, infos, at)
    _stimuli(sc, infos, driven, at)
    _record(sc, infos, at)
    _model_exchange(sc, infos, at)
    _scheduled(sc, infos, at)
    _clock_links(sc, infos, at)
    _iteration(sc, infos, at)
    return problems.items


def _model_exchange(sc: Scenario, infos: Infos, at: At) -> None:
    for c in sc.components:
        if c.model_exchange is not None and _ratio_ok(c.step_ratio):
            step = Fraction(sc.macro_step) / c.step_ratio
            for problem in model_exchange_problems(c.model_exchange, step, infos.get(c.name)):
                at(f"component {c.name}", problem)


def _scheduled(sc: Scenario, infos: Infos, at: At) -> None:
    """Scheduled Execution components: an interface to instantiate, input clocks the master can
    activate on the component's grid (master.clocks)."""
    for c in sc.components:
        info = infos.get(c.name)
        if not c.scheduled or info is None or not _ratio_ok(c.step_ratio):
            continue
        se = info.scheduled_execution
        if se is None:
            at(f"component {c.name}", f"{info.path.name} has no Scheduled Execution interface")
            continue
        step = Fraction(sc.macro_step) / c.step_ratio
        for problem in scheduled_problems(se.clocks, step):
            at(f"component {c.name}", problem)


def _clock_links(sc: Scenario, infos: Infos, at: At) -> None:
    modes = {c.name: clock_mode(infos.get(c.name), c.scheduled, c.event_mode) for c in sc.components}
    for cn in sc.connections:
        ends = (cn.start_component, cn.start_connector), (cn.end_component, cn.end_connector)
        problem = clock_link_problem(ends, infos, modes, sc.iteration is not None)
        if problem:
            at(f"connection {ends[0][0]}.{ends[0][1]} -> {ends[1][0]}.{ends[1][1]}", problem)


def clock_mode(info: Description | None, scheduled: bool, event_mode: bool) -> str:
    """How a component's clocks tick (master.clocks.link_problem): SCHEDULED, EVENTS or ""."""
    cs = info.co_simulation if info is not None else None
    return SCHEDULED if scheduled else EVENTS if event_mode and cs is not None and cs.event_mode else ""


def clock_link_problem(ends, infos: Infos, modes: Mapping[str, str], iterated: bool) -> str | None:
    """Why a Clock connection ((component, output clock), (component, input clock)) cannot carry
    ticks (modes: component -> `clock_mode`; master.clocks.link_problem; iterated: mm:Iteration).
    None if it can, or if it is not a connection of two clocks (a Clock to a non-clock is a type
    mismatch: `connection_problem`)."""
    if any(infos.get(comp) is None or comp not in modes for comp, _ in ends):
        return None
    variables = [infos[comp].variables.get(name) for comp, name in ends]
    if not all(v is not None and v.fmi_type == "Clock" for v in variables):
        return None

    def clock(comp: str, name: str):
        return next((k for k in read_clocks(infos[comp].path) if k.name == name), None)

    problem = link_problem(clock(*ends[0]), clock(*ends[1]), tuple(modes[comp] for comp, _ in ends))
    if problem is None and iterated:  # the kernel's counts of ticks are not part of the saved states
        return "a Clock connection does not run with iterated macro steps (mm:Iteration)"
    return problem


def _clock_stimulus(sc: Scenario, s, clock, where: str, at: At) -> None:
    """A step stimulus on a triggered input clock of a Scheduled Execution component: its ticks."""
    comp = sc.component(s.component)
    if _ratio_ok(comp.step_ratio):
        step = Fraction(sc.macro_step) / comp.step_ratio
        for problem in stimulus_problems(
            clock, comp.scheduled, s.kind, s.times, Fraction(sc.start_time), step
        ):
            at(where, problem)


def times(sc: Scenario) -> list[Problem]:
    """The problems of `sc`'s times alone (the reader's, for a stop time from the command line)."""
    problems = Problems()
    _times(sc, lambda element, message: problems.add(str(sc.path), None, element, message))
    return problems.items


def _read(sc: Scenario, at: At) -> dict[str, Description | None]:
    infos: dict[str, Description | None] = {}
    for c in sc.components:
        try:
            info = fmuinfo.read(c.fmu_path)
        except (SourceError, OSError) as err:
            at(f"component {c.name}", f"{c.fmu_path}: {err}")
            info = None
        if info is not None and info.unsupported:
            at(f"component {c.name}", f"{info.path.name}: {info.unsupported}")
            info = None
        infos[c.name] = info
    return infos


def _times(sc: Scenario, at: At) -> None:
    start, stop, H = Fraction(sc.start_time), Fraction(sc.stop_time), Fraction(sc.macro_step)
    if H <= 0:
        at("macro step", f"the macro step must be positive, got {H} s")
        return
    if stop <= start:
        at("stop time", f"stop time {float(stop):g} s is not after start time {float(start):g} s")
        return
    whole = steps_problem(stop - start, H)
    if whole:
        at("stop time", f"stop time - start time = {whole}")
    ratios = {c.name: c.step_ratio for c in sc.components if _ratio_ok(c.step_ratio)}
    for problem in limit_problems(start, stop, H, ratios):
        at("stop time", problem)
    if sc.record_interval is not None:
        problem = interval_problem(Fraction(sc.record_interval), H)
        if problem:
            at("record interval", problem)


def _whole(x: object) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _ratio_ok(k: object) -> bool:
    return _whole(k) and k >= 1 and ratio_problem(k) is None


def _components(sc: Scenario, at: At) -> None:
    names = [c.name for c in sc.components]
    for name in sorted({n for n in names if names.count(n) > 1}):
        at(f"component {name}", f'a second component named "{name}"')
    for c in sc.components:
        where = f"component {c.name}"
        if not _whole(c.step_ratio) or c.step_ratio < 1:
            at(
                where,
                f"step ratio {c.step_ratio!r}: a positive whole number of communication steps is needed",
            )
        elif ratio_problem(c.step_ratio):
            at(where, ratio_problem(c.step_ratio))
        if not _order_ok(c.extrapolation_order):
            at(where, f"extrapolation order {c.extrapolation_order!r} not in 0..{MAX_ORDER}")
    if sc.coupling not in COUPLINGS:
        at("coupling", f'"{sc.coupling}" is not a coupling: {" or ".join(COUPLINGS)}')
    # Unlike a file's (settings: a likely mistake there), a Scenario's order under Jacobi is left
    # alone: code that switches a scene's coupling keeps it, and Jacobi steps everyone at once
    if sc.coupling == Scheme.GAUSS_SEIDEL and sc.order and sorted(sc.order) != sorted(names):
        at("order", f"{list(sc.order)} must list every component once: {names}")
    if sc.loops.method not in LOOP_METHODS:
        at("loops", f'method "{sc.loops.method}" is not one of {", ".join(LOOP_METHODS)}')
    for what, it in (("loops", sc.loops), ("iteration", sc.iteration)):
        if it is None:
            continue
        if not 0 < it.tolerance < 1:
            at(what, f"tolerance {it.tolerance!r}: between 0 and 1 (relative to 1 + |value|)")
        if not _whole(it.max_iterations) or not 1 <= it.max_iterations <= MAX_ITERATIONS:
            at(what, f"max_iterations {it.max_iterations!r}: a whole number in 1..{MAX_ITERATIONS}")


def _iteration(sc: Scenario, infos: Infos, at: At) -> None:
    """Iterated macro steps repeat each macro step from saved FMU states: every FMU must save its state."""
    if sc.iteration is None:
        return
    for c in sc.components:
        info = infos.get(c.name)
        problem = fmuinfo.iteration_problem(info) if info is not None else None
        if problem:
            at(f"component {c.name}", problem)


def _order_ok(order: object) -> bool:
    return _whole(order) and 0 <= order <= MAX_ORDER


def _variable(infos: Infos, comp: str, name: str, at: At, where: str) -> Variable | None:
    """The FMU variable `comp`.`name`, or None after reporting an unknown component or variable
    (silent where the component's FMU could not be read: that is reported once)."""
    if comp not in infos:
        at(where, f'unknown component "{comp}"')
        return None
    info = infos[comp]
    if info is None:
        return None
    var = info.variables.get(name)
    if var is None:
        at(where, f'unknown variable: the FMU of {comp} ({info.path.name}) has no variable "{name}"')
    return var


def _connections(sc: Scenario, infos: Infos, at: At) -> dict[tuple[str, str], str]:
    """Checks the connections; returns the inputs they drive: (component, input) -> connection."""
    driven: dict[tuple[str, str], str] = {}
    for cn in sc.connections:
        se, sc_, ee, ec = cn.start_component, cn.start_connector, cn.end_component, cn.end_connector
        where = f"connection {se}.{sc_} -> {ee}.{ec}"
        if cn.extrapolation_order is not None and not _order_ok(cn.extrapolation_order):
            at(where, f"extrapolation order {cn.extrapolation_order!r} not in 0..{MAX_ORDER}")
        out = _variable(infos, se, sc_, at, where)
        inp = _variable(infos, ee, ec, at, where)
        if out is None or inp is None:
            continue
        wrong_way = direction_problems(f"{se}.{sc_}", out.causality, f"{ee}.{ec}", inp.causality)
        for problem in wrong_way:
            at(where, problem)
        if wrong_way:
            continue
        problem = connection_problem(
            f"{se}.{sc_}", out.fmi_type, infos[se].fmi_version,
            f"{ee}.{ec}", inp.fmi_type, infos[ee].fmi_version, out.shape, inp.shape,
        )  # fmt: skip
        ends = (f"{se}.{sc_}", f"{ee}.{ec}")
        t = cn.transformation
        problem = (
            problem
            or (t is not None and transforms.problem(t, ends, out, inp, infos[ee].fmi_version))
            or transforms.unit_problem(ends, out, inp, t)
        )
        if problem:
            at(where, problem)
        if (ee, ec) in driven:
            at(where, f"{ee}.{ec} is already driven by {driven[(ee, ec)]}")
            continue
        driven[(ee, ec)] = where
    return driven


def _stimuli(sc: Scenario, infos: Infos, driven: dict[tuple[str, str], str], at: At) -> None:
    driven = dict(driven)
    for s in sc.stimuli:
        key, name = (s.component, s.variable), f"{s.component}.{s.variable}"
        where = f"stimulus {name}"
        if s.kind not in STIMULUS_KINDS:
            at(where, f'kind "{s.kind}": a stimulus is a {" or a ".join(STIMULUS_KINDS)}')
        if len(s.times) != len(s.values) or not s.times:
            at(
                where,
                f"{len(s.times)} times and {len(s.values)} values: a stimulus needs as many of each, "
                "one or more",
            )
        if not all(math.isfinite(x) for x in (*s.times, *s.values)):
            at(where, "times and values must be finite numbers")
        elif any(b < a for a, b in zip(s.times, s.times[1:], strict=False)):
            at(where, "its times must not decrease")  # a repeated time: a jump in a table
        var = _variable(infos, *key, at, where)
        if var is None:
            continue
        if var.causality != "input":
            at(where, f"{name} is {var.causality}, not an input: stimuli drive inputs")
        elif key in driven:
            at(where, f"{name} is driven by {driven[key]}: stimuli are for undriven inputs")
        driven[key] = where
        if var.fmi_type == "Clock":
            clocks = infos[s.component].scheduled_execution
            clock = next(c for c in clocks.clocks if c.name == s.variable) if clocks else None
            if clock is None:
                at(where, f"{name} is a Clock: only a Scheduled Execution component's clocks tick")
            else:
                _clock_stimulus(sc, s, clock, where, at)
            continue
        version = infos[s.component].fmi_version
        problem = stimulus_problem(var.fmi_type, version, s.kind, var.shape)
        if problem:
            at(where, f"{name} is {typed(var.fmi_type, var.shape)}: {problem}")
            continue
        for t, v in zip(s.times, s.values, strict=False):
            problem = point_problem(name, var, version, t, v) if math.isfinite(v) else None
            if problem:
                at(where, problem)


def _record(sc: Scenario, infos: Infos, at: At) -> None:
    columns: set[tuple[str, str]] = set()  # (component, variable or array element) recorded so far
    for comp, name in sc.record:
        where = f"record {comp}.{name}"
        if comp not in infos:
            at(where, f'unknown component "{comp}"')
            continue
        info = infos[comp]
        if info is None:
            continue
        found = lookup(info.variables, name)  # a variable, an array (every element) or one element
        if found is None:
            why = no_element(info.variables, name)
            unknown = (
                f"{comp}.{why}" if why else f'the FMU of {comp} ({info.path.name}) has no variable "{name}"'
            )
            at(where, f"unknown variable: {unknown}")
            continue
        problem = record_problem(comp, name, *found, info.fmi_version, columns)
        if problem:
            at(where, problem)
