"""The master's own settings: one ssc:Annotation of type "org.multirate-master.settings"
holding one mm:Settings element (schema: master/schemas/multirate-settings.xsd).

The schema has already checked every value's form; here the settings are checked against
the scene: known components and connections, steps that divide the macro step, stimuli only
on undriven inputs, a complete Gauss-Seidel order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

from lxml import etree

from master.clocks import scheduled_problems, stimulus_problems
from master.description import FLOATS, SCHEDULED_EXECUTION, Description, typed
from master.schedule import Clock
from master.solvers import NUMBERS

from .context import Context
from .fmuinfo import iteration_problem, point_problem, record_problem, stimulus_problem
from .model import Iteration, LoopSolver, ModelExchange, Scheme, Stimulus
from .numbers import parse_time
from .problems import NS_MM, NS_SSC, NS_SSD
from .xmlio import tag

ANNOTATION_TYPE = "org.multirate-master.settings"


@dataclass
class Settings:
    macro_step: Fraction
    coupling: Scheme = Scheme.JACOBI
    order: tuple[str, ...] = ()
    step_ratio: dict[str, int] = field(default_factory=dict)
    extrapolation_order: dict[str, int] = field(default_factory=dict)
    interpolate_inputs: dict[str, bool] = field(default_factory=dict)
    group: dict[str, str] = field(default_factory=dict)
    connection_order: dict[tuple[str, str], int] = field(default_factory=dict)  # (comp, input) -> order
    internal_step: dict[str, Fraction] = field(default_factory=dict)  # interpolating FMUs' substeps (s)
    record: tuple[tuple[str, str], ...] = ()
    record_interval: Fraction | None = None
    record_coupling_errors: bool = False
    stimuli: tuple[Stimulus, ...] = ()
    loops: LoopSolver = LoopSolver()
    iteration: Iteration | None = None
    origins: dict[str, str] = field(default_factory=dict)  # setting -> where its value came from
    model_exchange: dict[str, ModelExchange] = field(default_factory=dict)  # components run as ME
    scheduled: set[str] = field(default_factory=set)  # components run as Scheduled Execution


def model_exchange_problems(me: ModelExchange, step: Fraction, info: Description | None) -> list[str]:
    """What is wrong with running a component as Model Exchange, `me`, with communication step
    `step` (s) and FMU `info` (None: unreadable, reported elsewhere): the one rule of files and of
    scenarios built in Python."""
    found = []
    if me.solver not in NUMBERS:
        found.append(f'solver "{me.solver}" is not one of {", ".join(NUMBERS)}')
    if me.internal_step is not None and (Fraction(me.internal_step) <= 0 or me.substeps(step) is None):
        found.append(
            f"internalStep {seconds(Fraction(me.internal_step))} does not divide the communication step "
            f"{seconds(step)} into whole steps"
        )
    if info is not None and not info.integrable:
        found.append(f"modelExchange: {info.path.name} has no Model Exchange 2.0 or 3.0 interface")
    return found


INTERNAL_STEP = "internal_step"  # the project's FMUs: solver step inside a communication step (s)
MAX_STEP_RATIO = 100_000  # communication steps of one component per macro step
MAX_MACRO_STEPS = 10**10  # macro steps of one run
MAX_ITERATIONS = 10_000  # of a loop solve at one point, or sweeps of one macro step
MAX_ORDER = 3  # highest extrapolation order (the schema's TExtrapolationOrder)


def _time(ctx: Context, elem: etree._Element, attr: str) -> Fraction | None:
    """A time attribute as an exact rational; None if absent, or if it is not a usable time (the
    problem reported: `parse_time` bounds its length, exponent and size)."""
    text = elem.get(attr)
    if text is None:
        return None
    try:
        return parse_time(text)
    except ValueError as e:
        ctx.at(elem, f"{attr}: {e}")
        return None


def _int(text: str | None) -> int | None:
    """A schema-checked integer attribute (None if absent or malformed: the schema check reports
    malformed ones); one of more than 18 digits is 10**18, which every limit refuses."""
    if text is None:
        return None
    t = text.strip().lstrip("+")
    if len(t) > 18 and t.isdigit():
        return 10**18
    try:
        return int(t)
    except ValueError:
        return None


def _bool(text: str | None) -> bool | None:
    return None if text is None else text.strip() in ("true", "1")


def find(ctx: Context, root: etree._Element, system: etree._Element) -> etree._Element | None:
    """The one settings annotation (None if the file has none: defaults.choose then picks the
    settings); problems for several, or one in the wrong place."""
    found = []
    allowed = (system, root.find(tag(NS_SSD, "DefaultExperiment")))
    for ann in root.iter(tag(NS_SSC, "Annotation")):
        if ann.get("type") != ANNOTATION_TYPE:
            continue
        holder = ann.getparent().getparent()
        if holder not in allowed:
            ctx.at(ann, "the settings annotation belongs on ssd:System or ssd:DefaultExperiment")
        elif found:
            ctx.at(ann, f"a second settings annotation (the first is on line {found[0].sourceline})")
        else:
            found.append(ann)
    return found[0] if found else None


def read(
    ctx: Context,
    annotation: etree._Element,
    root: etree._Element,
    system: etree._Element,
    times: tuple[Fraction, Fraction] | None,
    macro_step: Fraction | None = None,
) -> Settings | None:
    """The checked settings of the annotation `find` returned, or None if the macro step is
    unusable (problems added).  macro_step: the command line's (--macro-step), which wins."""
    elem = annotation.find(tag(NS_MM, "Settings"))
    if elem is None:
        ctx.at(annotation, f"must hold one mm:Settings element in namespace {NS_MM}")
        return None
    macro = macro_step if macro_step is not None else _time(ctx, elem, "macroStep")
    if macro is None:
        return None  # reported (absent: by the schema check)
    if macro <= 0:
        ctx.at(elem, "macroStep must be positive")
        return None
    s = Settings(macro_step=macro, coupling=Scheme(elem.get("coupling", Scheme.JACOBI)))
    given = macro_step is not None
    s.origins["macro step"] = "command line (--macro-step)" if given else "mm:Settings macroStep"
    if times is not None:
        whole = steps_problem(times[1] - times[0], macro)
        if whole:
            exp = root.find(tag(NS_SSD, "DefaultExperiment"))
            ctx.at(exp if exp is not None else elem, f"stopTime - startTime = {whole}")
    _components(ctx, elem, s)
    if times is not None:
        _limits(ctx, elem, s, times)
    _order(ctx, elem, s)
    # driven inputs (oriented: those of connections written input -> output too) and every end as
    # written (also of connections with problems of their own, resolved through system connectors)
    _connections(ctx, elem, s, set(ctx.driven) | ctx.ends)
    _record(ctx, elem, s)
    _stimuli(ctx, elem, s, times[0] if times is not None else Fraction(0))
    _coupling_iterations(ctx, elem, s)
    _saved_states(ctx, elem, s)
    return s


def _coupling_iterations(ctx: Context, elem: etree._Element, s: Settings) -> None:
    """mm:Loops and mm:Iteration (their values' forms checked by the schema; defaults: the model's)."""
    loops = elem.find(tag(NS_MM, "Loops"))
    if loops is not None:
        default = LoopSolver()
        s.loops = LoopSolver(
            method=loops.get("method", default.method),
            tolerance=_tolerance(loops, default.tolerance),
            max_iterations=_iterations(ctx, loops, default.max_iterations),
            directional_derivatives=_bool(loops.get("directionalDerivatives", "true")) is not False,
        )
    iteration = elem.find(tag(NS_MM, "Iteration"))
    if iteration is not None:
        default = Iteration()
        s.iteration = Iteration(
            tolerance=_tolerance(iteration, default.tolerance),
            max_iterations=_iterations(ctx, iteration, default.max_iterations),
        )


def _saved_states(ctx: Context, elem: etree._Element, s: Settings) -> None:
    """Iterated macro steps: every FMU saves its state (the problem at mm:Iteration, per component)."""
    if s.iteration is None:
        return
    where = elem.find(tag(NS_MM, "Iteration"))
    for name, comp in ctx.comps.items():
        problem = iteration_problem(comp.info) if comp.info is not None else None
        if problem:
            ctx.at(where, f"component {name}: {problem}")


def _tolerance(elem: etree._Element, default: float) -> float:
    try:
        return float(elem.get("tolerance", default))
    except ValueError:  # reported by the schema check
        return default


def _iterations(ctx: Context, elem: etree._Element, default: int) -> int:
    n = _int(elem.get("maxIterations")) or default
    if n > MAX_ITERATIONS:
        ctx.at(elem, f"maxIterations {n}: at most {MAX_ITERATIONS}")
        return default
    return n


def _limits(ctx: Context, elem: etree._Element, s: Settings, times: tuple[Fraction, Fraction]) -> None:
    for problem in limit_problems(*times, s.macro_step, s.step_ratio):
        ctx.at(elem, problem)


def steps_problem(span: Fraction, macro_step: Fraction) -> str | None:
    """Why a run of `span` seconds is not a whole number of macro steps ("0.015 s is not a whole
    number of macro steps (0.01 s)"); None if it is."""
    if (span / macro_step).denominator == 1:
        return None
    return f"{seconds(span)} is not a whole number of macro steps ({seconds(macro_step)})"


def limit_problems(
    start: Fraction, stop: Fraction, macro_step: Fraction, ratios: dict[str, int]
) -> list[str]:
    """A run no machine can finish, or whose clocks leave exact float arithmetic, is refused before
    it starts with the figure that exceeds the limit, not discovered while running.
    ratios: component -> step ratio."""
    n_macro = (stop - start) / macro_step
    if n_macro > MAX_MACRO_STEPS:
        return [f"{float(n_macro):.3g} macro steps from startTime to stopTime: at most {MAX_MACRO_STEPS:.0e}"]
    return [
        f"{name}: times {seconds(start)} + j {seconds(macro_step / k)} need integers beyond 2^53 over "
        f"{int(n_macro)} macro steps; choose times with fewer decimals"
        for name, k in {"the macro clock": 1, **ratios}.items()
        if not Clock.make(start, macro_step, k).exact_up_to(math.ceil(n_macro) * k)
    ]


def interval_problem(interval: Fraction, macro_step: Fraction) -> str | None:
    """Why rows cannot be recorded every `interval` seconds; None if they can."""
    if interval > 0 and (interval / macro_step).denominator == 1:
        return None
    return f"interval {seconds(interval)} is not a positive multiple of the macro step {seconds(macro_step)}"


def ratio_problem(k: int) -> str | None:
    """Why a component cannot take `k` (>= 1) communication steps per macro step; None if it can."""
    if k > MAX_STEP_RATIO:
        return f"{k} communication steps per macro step: at most {MAX_STEP_RATIO} are allowed"
    return None


def seconds(t: Fraction) -> str:
    """A time for messages: a decimal where it has a finite one, else the exact fraction."""
    d = t.denominator
    for p in (2, 5):
        while d % p == 0:
            d //= p
    return f"{float(t):.15g} s" if d == 1 else f"{t} s"


def _components(ctx: Context, elem: etree._Element, s: Settings) -> None:
    default_order = _int(elem.get("extrapolationOrder", "0")) or 0
    default_interp = _bool(elem.get("interpolateInputs", "false")) or False
    seen: dict[str, etree._Element] = {}
    for ce in elem.findall(tag(NS_MM, "Component")):
        name = ce.get("name")
        if name not in ctx.comps:
            ctx.at(ce, f'unknown component "{name}"')
            continue
        if name in seen:
            ctx.at(ce, f"{name} already has settings on line {seen[name].sourceline}")
            continue
        seen[name] = ce
    for name, comp in ctx.comps.items():
        ce = seen.get(name)
        attrs = dict(ce.attrib) if ce is not None else {}
        s.step_ratio[name] = _ratio(ctx, ce, s.macro_step) if ce is not None else 1
        s.origins[f"{name} communication step"] = "mm:Component" if ce is not None else "the macro step"
        order = _int(attrs.get("extrapolationOrder"))
        s.extrapolation_order[name] = default_order if order is None else order
        if model_exchange(ctx, ce if ce is not None else elem, attrs, s, name, comp.info):
            s.interpolate_inputs[name] = False  # its inputs are polynomials at every stage time anyway
            if "group" in attrs:
                s.group[name] = attrs["group"]
            continue
        can = comp.info is not None and comp.info.can_interpolate_inputs
        asked = _bool(attrs.get("interpolateInputs"))
        if asked and comp.info is not None and not can:
            ctx.at(
                ce,
                f"interpolateInputs: {comp.info.path.name} cannot interpolate inputs "
                "(canInterpolateInputs; FMI 3: providesIntermediateUpdate, inputs intermediateUpdate)",
            )
        # The global default only applies where the FMU can; an explicit request must be honoured.
        s.interpolate_inputs[name] = bool(asked) if asked is not None else default_interp and can
        k = s.step_ratio[name]
        if s.interpolate_inputs[name] and can and k > 1:
            _substeps(ctx, ce, s, name, comp.info.variables.get(INTERNAL_STEP), k)
        if "group" in attrs:
            s.group[name] = attrs["group"]


# SSP's implementation attribute of a component: the interface it asks for (absent or "any": either)
IMPLEMENTATIONS = {"ModelExchange": True, "CoSimulation": False}
DEFAULT_MODEL_EXCHANGE = (
    f"{ModelExchange.solver}, one step per communication step (the default for Model Exchange)"
)


def model_exchange(
    ctx: Context, ce: etree._Element, attrs: dict, s: Settings, name: str, info: Description | None
) -> bool:
    """Whether component `name` runs as Model Exchange (modelExchange="true" on its mm:Component
    `ce`, else implementation="ModelExchange" on its ssd:Component, else an FMU without a
    Co-Simulation interface), its solver and internalStep then in s.model_exchange."""
    if scheduled_execution(ctx, s, name, info):
        return False
    asked, where, said = _bool(attrs.get("modelExchange")), ce, 'modelExchange="false"'
    comp = ctx.comps[name].elem
    if asked is None and comp.get("implementation") in IMPLEMENTATIONS:
        asked, where = IMPLEMENTATIONS[comp.get("implementation")], comp
        said = 'implementation="CoSimulation"'
    only = info is not None and not info.co_simulation
    if asked is False and only:
        ctx.at(where, f"{said}: {info.path.name} has no Co-Simulation interface")
    if not (asked or (asked is None and only)):
        if "solver" in attrs or "internalStep" in attrs:
            ctx.at(ce, 'solver and internalStep are for Model Exchange components (modelExchange="true")')
        return False
    step = _time(ctx, ce, "internalStep") if "internalStep" in attrs else None
    me = ModelExchange(attrs.get("solver", ModelExchange.solver), step)
    for problem in model_exchange_problems(me, s.macro_step / s.step_ratio[name], info):
        ctx.at(ce, problem)
    s.model_exchange[name] = me
    if "solver" not in attrs and "internalStep" not in attrs:
        s.origins[f"{name} integration"] = DEFAULT_MODEL_EXCHANGE
    return True


def scheduled_execution(ctx: Context, s: Settings, name: str, info: Description | None) -> bool:
    """Whether component `name` runs as Scheduled Execution (implementation="ScheduledExecution" on
    its ssd:Component, or an FMU whose only interface that is): then in s.scheduled."""
    comp = ctx.comps[name].elem
    asked = comp.get("implementation") == SCHEDULED_EXECUTION
    has = info is not None and info.scheduled_execution is not None
    if asked and info is not None and not has:
        why = f"{info.path.name} has no Scheduled Execution interface"
        ctx.at(comp, f'implementation="{SCHEDULED_EXECUTION}": {why}')
    only = has and info.co_simulation is None and info.model_exchange is None
    if not (asked or only):
        return False
    s.scheduled.add(name)
    step = s.macro_step / s.step_ratio[name]
    for problem in scheduled_problems(info.scheduled_execution.clocks, step) if has else ():
        ctx.at(comp, problem)
    return True


def _substeps(ctx: Context, ce: etree._Element, s: Settings, name: str, var, k: int) -> None:
    """An FMU that interpolates its inputs takes one doStep per macro step, so its communication
    step H/k becomes its internal step (the parameter `internal_step` of the project's FMUs);
    an FMU without one cannot keep it, which is a problem, not a silent ratio of 1."""
    settable = (
        var is not None
        and var.kind in FLOATS
        and var.causality == "parameter"
        and var.variability != "constant"
    )
    if settable:
        s.internal_step[name] = s.macro_step / k
        return
    ctx.at(
        ce,
        f"interpolateInputs: {name} takes one doStep per macro step, so its {k} communication steps "
        f"per macro step would be lost ({name} has no {INTERNAL_STEP} parameter to take them); "
        "drop the step ratio or interpolateInputs",
    )


def _ratio(ctx: Context, ce: etree._Element, macro: Fraction) -> int:
    """The step ratio k (communication step = macro step / k) of one mm:Component."""
    ratio, step = _int(ce.get("stepRatio")), _time(ctx, ce, "communicationStep")
    if ratio is not None and ce.get("communicationStep") is not None:
        ctx.at(ce, "give stepRatio or communicationStep, not both")
        return ratio
    if step is None:
        return _ratio_limit(ctx, ce, ratio or 1)
    if step <= 0:
        ctx.at(ce, "communicationStep must be positive")
        return 1
    k = macro / step
    if k.denominator != 1:
        ctx.at(
            ce,
            f"communicationStep {seconds(step)} does not divide the macro step {seconds(macro)} (ratio {k})",
        )
        return 1
    return _ratio_limit(ctx, ce, int(k))


def _ratio_limit(ctx: Context, ce: etree._Element, k: int) -> int:
    problem = ratio_problem(k)
    if problem:
        ctx.at(ce, problem)
        return 1
    return k


def _order(ctx: Context, elem: etree._Element, s: Settings) -> None:
    text = elem.get("order")
    if text is None:
        # Gauss-Seidel without an order: document order of the components
        s.order = tuple(ctx.comps) if s.coupling == Scheme.GAUSS_SEIDEL else ()
        return
    if s.coupling != Scheme.GAUSS_SEIDEL:
        ctx.at(elem, 'order is only meaningful with coupling="gauss-seidel"')
        return
    names = text.split()
    for name in names:
        if name not in ctx.comps:
            ctx.at(elem, f'order: unknown component "{name}"')
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        ctx.at(elem, f"order: {', '.join(repeated)} listed more than once")
    missing = [n for n in ctx.comps if n not in names]
    if missing:
        ctx.at(elem, f"order: must list every component once; missing {', '.join(missing)}")
    s.order = tuple(names)


def _connections(ctx: Context, elem: etree._Element, s: Settings, ends: set[tuple[str, str]]) -> None:
    """Per-connection extrapolation orders, keyed by the input each connection drives."""
    for ce in elem.findall(tag(NS_MM, "Connection")):
        key = (ce.get("endElement", ""), ce.get("endConnector", ""))
        order = _int(ce.get("extrapolationOrder"))
        if key not in ends:
            ctx.at(ce, f"no connection drives {key[0]}.{key[1]}")
        elif key in s.connection_order:
            ctx.at(ce, f"{key[0]}.{key[1]} has settings twice")
        elif order is not None:
            s.connection_order[key] = order


def _record(ctx: Context, elem: etree._Element, s: Settings) -> None:
    rec = elem.find(tag(NS_MM, "Record"))
    if rec is None:
        return
    s.record_coupling_errors = bool(_bool(rec.get("couplingErrors")))
    interval = _time(ctx, rec, "interval")
    if interval is not None:
        problem = interval_problem(interval, s.macro_step)
        if problem:
            ctx.at(rec, problem)
        else:
            s.record_interval = interval
    chosen = []
    columns: set[tuple[str, str]] = set()  # (component, variable or array element) recorded so far
    for ve in rec.findall(tag(NS_MM, "Variable")):
        key = (ve.get("component", ""), ve.get("name", ""))
        found = ctx.element(*key, ve)  # a variable, an array (every element) or one element
        if found is not None:
            problem = record_problem(*key, *found, ctx.comps[key[0]].info.fmi_version, columns)
            if problem:
                ctx.at(ve, problem)
            else:
                chosen.append(key)
    s.record = tuple(chosen)


def _clock_ticks(
    ctx: Context, se: etree._Element, s: Settings, key, kind: str, times, start: Fraction
) -> bool:
    """A stimulus on a Clock: the ticks of a triggered input clock (master.clocks); False if not."""
    info = ctx.comps[key[0]].info
    found = (
        [c for c in info.scheduled_execution.clocks if c.name == key[1]] if info.scheduled_execution else []
    )
    if not found:
        ctx.at(se, f"{key[0]}.{key[1]} is a Clock: only a Scheduled Execution component's clocks tick")
        return False
    step = s.macro_step / s.step_ratio[key[0]]
    problems = stimulus_problems(found[0], key[0] in s.scheduled, kind, times, start, step)
    for problem in problems:
        ctx.at(se, problem)
    return not problems


def _stimuli(ctx: Context, elem: etree._Element, s: Settings, start: Fraction = Fraction(0)) -> None:
    holder = elem.find(tag(NS_MM, "Stimuli"))
    found: dict[tuple[str, str], etree._Element] = {}
    stimuli = []
    for se in holder if holder is not None else ():
        kind = etree.QName(se).localname.lower()
        key = (se.get("component", ""), se.get("variable", ""))
        var = ctx.variable(*key, se)
        if var is None:
            continue
        ok = True
        if var.causality != "input":
            ctx.at(se, f"{key[0]}.{key[1]} is {var.causality}, not an input: stimuli drive inputs")
            ok = False
        elif key in ctx.driven:
            line = ctx.driven[key].sourceline
            ctx.at(
                se,
                f"{key[0]}.{key[1]} is driven by the connection on line {line}:"
                " stimuli are for undriven inputs",
            )
            ok = False
        version = ctx.comps[key[0]].info.fmi_version
        clock = var.fmi_type == "Clock"  # a triggered clock's ticks (master.clocks), checked below
        problem = None if clock else stimulus_problem(var.fmi_type, version, kind, var.shape)
        if problem:
            ctx.at(se, f"{key[0]}.{key[1]} is {typed(var.fmi_type, var.shape)}: {problem}")
            ok = False
        if key in found:
            ctx.at(se, f"{key[0]}.{key[1]} already has a stimulus on line {found[key].sourceline}")
            ok = False
        found[key] = se
        times, values = [], []
        for pe in se.findall(tag(NS_MM, "Point")):
            try:
                t, v = float(pe.get("time", "")), float(pe.get("value", ""))
            except ValueError:
                ok = False  # schema error already
                continue
            if not (math.isfinite(t) and math.isfinite(v)):
                ctx.at(pe, "time and value must be finite numbers")
                ok = False
                continue
            if times and t <= times[-1]:
                ctx.at(pe, f"time {t:g} s is not after the previous point's {times[-1]:g} s")
                ok = False
            problem = None if clock else point_problem(f"{key[0]}.{key[1]}", var, version, t, v)
            if problem:
                ctx.at(pe, problem)
                ok = False
            times.append(t)
            values.append(v)
        if clock and ok and times:
            ok = _clock_ticks(ctx, se, s, key, kind, tuple(times), start)
        if ok and times:
            stimuli.append(Stimulus(key[0], key[1], kind, tuple(times), tuple(values)))
    s.stimuli = tuple(stimuli)
