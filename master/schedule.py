"""The schedule: who steps when, with which inputs, from exact rational times.

A `Plan` is built from a `Scenario` and the model descriptions (variables and capabilities)
of its FMUs; it never calls an FMU. Component i advances with communication step
h_i = H / k_i; its j-th communication point is t_start + j * h_i, computed from integers, so a
run of any length ends exactly at the stop time. Times are in seconds.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

from master.clocks import Scheduled
from master.clocks import schedule as schedule_clocks
from master.description import (
    CO_SIMULATION,
    MODEL_EXCHANGE,
    SCHEDULED_EXECUTION,
    Capability,
    Variable,
    element_names,
    lookup,
)
from master.scenario.fmuinfo import (
    CONTINUOUS,
    RECORDED,
    coupling_kind,
    recordable,
    recorded_as,
)
from master.scenario.loops import cycle_in, port_graph, strongly_connected
from master.scenario.model import Iteration, ModelExchange, Scenario, Scheme, Stimulus, Transformation

EXACT = 2**53  # clock integers at or beyond this would not convert to float exactly


@dataclass(frozen=True)
class Clock:
    """Communication points of one component: t_j = (num0 + j * dnum) / den (exact up to float rounding)."""

    num0: int
    dnum: int
    den: int

    @staticmethod
    def make(start: Fraction, macro_step: Fraction, ratio: int) -> Clock:
        h = macro_step / ratio
        den = math.lcm(start.denominator, h.denominator)
        return Clock(start.numerator * (den // start.denominator), h.numerator * (den // h.denominator), den)

    def exact_up_to(self, points: int) -> bool:
        """Whether points 0 .. `points` convert to floats exactly as the kernel computes them
        ((num0 + j dnum) / den in double precision: every integer below 2^53)."""
        return self.den < EXACT and abs(self.num0) + points * abs(self.dnum) < EXACT

    def time(self, j: int) -> float:
        """Communication point j as the float nearest to the exact rational (s)."""
        return (self.num0 + j * self.dnum) / self.den

    def exact(self, j: int) -> Fraction:
        """Communication point j as an exact rational (s)."""
        return Fraction(self.num0 + j * self.dnum, self.den)


# what numeric connections carry (fmuinfo.coupling_kind), in the kernel's order of inputs and
# outputs; String and Binary connections (fmuinfo.TEXTS) have rings and inputs of their own (kernel.h)
KINDS = ("Real", "Integer", "Boolean", "Float32", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64",
         "UInt64", "Clock")  # fmt: skip


def value_kind(v: Variable, fmi_version: str) -> str | None:
    """The kind (`KINDS`, "String" or "Binary") of a variable's value as connections carry it."""
    return coupling_kind(v.fmi_type or v.type, fmi_version)


@dataclass(frozen=True)
class Link:
    """Outputs of `source` that drive inputs of `consumer` through polynomials of one order."""

    source: str
    consumer: str
    outputs: tuple[str, ...]  # source variables
    inputs: tuple[str, ...]  # consumer variables, same order
    order: int  # requested polynomial order 0..3
    source_first: bool  # the source completes the macro step before the consumer starts it
    k_source: int  # effective step ratios
    k_consumer: int
    kind: str = "Real"  # what it carries (`KINDS`, "String", "Binary"): Real, Float32 or a held kind
    # each input's transformation of the value its output carries (None: none); () where no
    # input has one, which the kernel's hot path sees as a NULL table
    transformations: tuple[Transformation | None, ...] = ()

    def window(self, n: int, j: int, relaxed: bool = False) -> tuple[int, int]:
        """Source samples for the consumer's step j (inside macro step n).

        Returns (j_end, order_used): the polynomial goes through source samples
        j_end - order_used .. j_end. j_end is the first source sample at or after the end of the
        consumer's step, but no later than what exists (Jacobi: t_n; source first: t_n+1).
        order_used < order only at start-up, while there is not enough history.
        relaxed: a start-up sweep that repeats macro step n with the source's samples of the
        previous sweep, so samples up to t_n+1 exist as if the source went first.
        """
        ks, kc = self.k_source, self.k_consumer
        available = (n + 1) * ks if (self.source_first or relaxed) else n * ks
        j_end = min(available, -((-(j + 1) * ks) // kc))
        return j_end, min(self.order, j_end)

    @property
    def estimated(self) -> bool:
        """Whether the coupling error estimate covers this link: an extrapolated one (not a source
        that goes first, not a held discrete signal)."""
        return not self.source_first and self.kind in CONTINUOUS

    def startup(self) -> list[tuple[int, int]]:
        """(macro step, lowest order used in it) for the macro steps that use a lower order."""
        out = []
        n = 0
        while True:
            low = min(self.window(n, n * self.k_consumer + m)[1] for m in range(self.k_consumer))
            if low >= self.order:
                return out
            out.append((n, low))
            n += 1


# what an algebraic loop's Jacobian entry d(unknown i)/d(unknown j) is known to be (kernel.h: MK_EDGE_*)
EDGE_NONE, EDGE_DECLARED, EDGE_ASSUMED = range(3)


@dataclass(frozen=True)
class Loop:
    """An algebraic loop: components whose outputs depend directly on inputs around a cycle, solved
    at every communication point they share (the macro step's end) by iterating its unknowns, the
    members' outputs that drive members' inputs (kernel.h: mk_loop)."""

    members: tuple[str, ...]  # in stepping order; one process steps them all
    unknowns: tuple[tuple[str, str], ...]  # (member, output)
    # (member, input, index of the unknown driving it, the connection's linear factor)
    inputs: tuple[tuple[str, str, int, float], ...]
    structure: tuple[tuple[int, ...], ...]  # [i][j]: EDGE_* of d unknown i / d unknown j
    cycle: str  # one cycle through it, "a.y -> b.u -> b.y -> a.u -> a.y", for messages
    derivatives: bool  # the Jacobian from directional derivatives (else finite differences)

    @property
    def assumed(self) -> bool:
        """Whether an entry rests on an FMU that declares no dependencies (the run tests it)."""
        return any(EDGE_ASSUMED in row for row in self.structure)


@dataclass(frozen=True)
class PlanComponent:
    name: str
    step_ratio: int  # effective k: steps per macro step (the scene's stepRatio, 1 if it interpolates)
    step: Fraction  # its communication step (s)
    clock: Clock
    interpolate_inputs: bool  # one step per macro step, inputs handed over as polynomials
    derivative_order: int  # highest input derivative handed to the FMU (0: none)
    # a Model Exchange component (the kernel integrates it, its inputs the polynomials at every
    # stage time: derivative_order as for an interpolating FMU); None: Co-Simulation
    model_exchange: ModelExchange | None = None
    # a Scheduled Execution component: its clocks' activations on its grid (master.clocks); None: none
    scheduled: Scheduled | None = None

    @property
    def interface(self) -> str:
        """CO_SIMULATION, MODEL_EXCHANGE or SCHEDULED_EXECUTION: how the kernel runs it."""
        if self.scheduled is not None:
            return SCHEDULED_EXECUTION
        return MODEL_EXCHANGE if self.model_exchange is not None else CO_SIMULATION


@dataclass(frozen=True)
class Plan:
    scenario: Scenario
    components: tuple[PlanComponent, ...]  # in stepping order
    links: tuple[Link, ...]
    stimuli: tuple[Stimulus, ...]
    n_macro: int
    record: tuple[tuple[str, str], ...]
    record_every: int  # macro steps between recorded rows
    macro_clock: Clock
    notes: tuple[str, ...] = field(default=())  # start-up and capability notes for the run log
    # per FMU file, what holds whatever the run (a pythonfmu FMU needs Python): said once per process
    fmu_notes: tuple[tuple[str, str], ...] = field(default=())  # (FMU file, note)
    # Start-up (the paper's step 3): macro steps 0 .. startup_steps-1 are each repeated
    # `startup_sweeps` times from saved FMU states with relaxed windows (Link.window).
    startup_steps: int = 0
    startup_sweeps: int = 0
    # components whose FMU may be instantiated only once per process, by FMU file: each set
    # needs as many processes as it has members
    exclusive: tuple[tuple[str, ...], ...] = ()
    # Scenario.record_coupling_errors: a column per extrapolated connection (source, output,
    # consumer, input) after the `record` columns, its latest coupling error (kernel.h: mk_link)
    record_errors: tuple[tuple[str, str, str, str], ...] = ()
    # how the results hold each `record` column (fmuinfo.recorded_as); empty: every one a float64
    record_types: tuple[str, ...] = ()
    loops: tuple[Loop, ...] = ()  # algebraic loops, solved at communication points (Scenario.loops)
    # iterated macro steps (strong coupling, Scenario.iteration): every macro step repeated from saved
    # FMU states, relaxed windows as in start-up, until its coupled samples settle; None: explicit
    iteration: Iteration | None = None

    @property
    def column_types(self) -> dict[str, str]:
        """The columns the results do not hold as float64: name -> "int64", "uint64", "String" or
        "Binary" (fmuinfo.recorded_as)."""
        types = zip(self.record, self.record_types, strict=False)  # (none: every one a float64)
        return {f"{c}.{v}": t for (c, v), t in types if t != "float64"}

    @property
    def columns(self) -> list[str]:
        """The names of the recorded columns: "time", "component.variable" of each `record`, then
        "coupling_error(source.output -> consumer.input)" of each `record_errors`."""
        return (
            ["time"]
            + [f"{c}.{v}" for c, v in self.record]
            + [coupling_error_column(*e) for e in self.record_errors]
        )

    def component(self, name: str) -> PlanComponent:
        for c in self.components:
            if c.name == name:
                return c
        raise KeyError(name)

    def links_into(self, name: str) -> list[Link]:
        return [lk for lk in self.links if lk.consumer == name]

    def record_due(self, n: int) -> bool:
        """Whether a row is recorded after macro step n: every `record_every` steps, and the last."""
        return (n + 1) % self.record_every == 0 or n + 1 == self.n_macro

    def describe(self) -> str:
        """Human-readable schedule (for `master info`)."""
        sc = self.scenario
        lines = [
            f"schedule: {sc.coupling}, macro step H = {sc.macro_step} s = {float(sc.macro_step):g} s, "
            f"{self.n_macro} macro steps from t = {float(sc.start_time):g} to {float(sc.stop_time):g} s",
        ]
        for c in self.components:
            extra = (
                f", inputs as polynomials (derivatives up to {c.derivative_order})"
                if c.interpolate_inputs
                else ""
            )
            if c.model_exchange:
                me = c.model_exchange
                substep = f"steps of {float(me.internal_step):g} s" if me.internal_step else "one step"
                extra = (
                    f", Model Exchange integrated by the master with {me.solver} ({substep} per "
                    "communication step), inputs as polynomials at every stage time"
                )
            if c.scheduled:
                activated = c.scheduled.describe(c.step)
                extra = f", Scheduled Execution: partitions activated by the master ({activated})"
            lines.append(f"  {c.name}: k = {c.step_ratio}, h = {c.step} s = {float(c.step):g} s{extra}")
        for lk in self.links:
            how = "interpolated" if lk.source_first else "extrapolated"
            how = how if lk.kind in CONTINUOUS else f"held ({lk.kind})"
            for n, (o, i) in enumerate(zip(lk.outputs, lk.inputs, strict=True)):
                t = lk.transformations[n] if lk.transformations else None
                lines.append(f"  {lk.source}.{o} -> {lk.consumer}.{i}: order {lk.order}, {how}{described(t)}")
        for s in self.stimuli:
            lines.append(f"  stimulus {s.kind} -> {s.component}.{s.variable}")
        for lp in self.loops:
            lines.append(f"  algebraic loop {lp.cycle}: {', '.join(lp.members)}")
        if self.iteration is not None:
            it = self.iteration
            lines.append(
                f"  iterated: every macro step repeated from saved FMU states until no coupled sample "
                f"changes by more than {it.tolerance:g} (1 + |value|), at most {it.max_iterations} sweeps"
            )
        lines.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(lines)


def described(t: Transformation | None) -> str:
    """A transformation as `master info` shows it after its connection ("" for none)."""
    if t is None:
        return ""
    if t.kind == "map":
        return ", mapped " + ", ".join(f"{a:g} -> {b:g}" for a, b in t.mapping)
    units = f" ({t.units[0]} -> {t.units[1]})" if t.units else ""
    return f", then {t.factor!r} * value + {t.offset!r}{units}"


def connection_name(source: str, output: str, consumer: str, input_: str) -> str:
    """The name of a connection in the run summary: "source.output -> consumer.input"."""
    return f"{source}.{output} -> {consumer}.{input_}"


def coupling_error_column(source: str, output: str, consumer: str, input_: str) -> str:
    """The recorded column of a connection's coupling error: "coupling_error(source.output ->
    consumer.input)" (no comma: the CSV header and fmpy.util.read_csv keep it whole)."""
    return f"coupling_error({connection_name(source, output, consumer, input_)})"


def build_plan(
    sc: Scenario,
    variables: dict[str, dict[str, Variable]],
    capabilities: dict[str, Capability] | None = None,
) -> Plan:
    """Schedule `sc`, a valid scenario (`master.scenario.check` finds no problem: the planner keeps
    no rule of its own). `variables[component]` are the variables of its FMU (FMI 3 arrays with
    their shapes: links and the record name each element, `description.element_names`)."""
    caps = {c.name: (capabilities or {}).get(c.name, Capability()) for c in sc.components}
    H = Fraction(sc.macro_step)
    steps = (Fraction(sc.stop_time) - Fraction(sc.start_time)) / H
    assert steps.denominator == 1 and steps > 0, "an unchecked scenario (master.scenario.check)"
    notes: list[str] = []
    comps = _components(sc, caps, notes)
    links = _links(sc, variables, caps, comps)
    startup_steps, startup_sweeps = _startup(sc, caps, links, notes)
    for name, pc in comps.items():  # what an interpolating FMU is handed: its links' highest order
        if pc.interpolate_inputs or pc.model_exchange:
            orders = [lk.order for lk in links if lk.consumer == name]
            comps[name] = dataclasses.replace(pc, derivative_order=max(orders, default=0))
    loops, fmu_notes = _loops(sc, variables, caps, links, notes)
    record, types = _recording(sc, variables, caps, notes)
    exclusive, tool_notes = _processes(sc, caps, notes)
    return Plan(
        scenario=sc,
        components=tuple(comps[n] for n in stepping_order(sc)),
        links=tuple(links),
        stimuli=tuple(s for s in sc.stimuli if not _ticks(s, comps)),
        n_macro=int(steps),
        record=record,
        record_types=types,
        record_every=1 if sc.record_interval is None else int(Fraction(sc.record_interval) / H),
        macro_clock=Clock.make(Fraction(sc.start_time), H, 1),
        notes=tuple(notes),
        fmu_notes=fmu_notes + tool_notes,
        startup_steps=startup_steps if startup_sweeps else 0,
        startup_sweeps=startup_sweeps,
        exclusive=exclusive,
        iteration=sc.iteration,
        record_errors=tuple(
            (lk.source, o, lk.consumer, i)
            for lk in links
            if lk.estimated
            for o, i in zip(lk.outputs, lk.inputs, strict=True)
        )
        if sc.record_coupling_errors
        else (),
        loops=loops,
    )


def _ticks(s: Stimulus, comps: dict[str, PlanComponent]) -> bool:
    """Whether stimulus `s` gives a Scheduled Execution component's clock its ticks."""
    se = comps[s.component].scheduled
    return se is not None and any(c.name == s.variable for c in se.inputs)


def stepping_order(sc: Scenario) -> list[str]:
    """The components in the order they step: Gauss-Seidel's order, else the scene's."""
    names = [c.name for c in sc.components]
    return list(sc.order) if sc.coupling == Scheme.GAUSS_SEIDEL and sc.order else names


def _components(sc: Scenario, caps: dict[str, Capability], notes: list[str]) -> dict[str, PlanComponent]:
    """Each component's step ratio and clock, and whether it takes its inputs as polynomials."""
    H, start = Fraction(sc.macro_step), Fraction(sc.start_time)
    comps: dict[str, PlanComponent] = {}
    for c in sc.components:
        cap = caps[c.name]
        me = (c.model_exchange or ModelExchange()) if c.model_exchange or cap.model_exchange else None
        interp = bool(c.interpolate_inputs and cap.can_interpolate_inputs and me is None)
        if c.interpolate_inputs and not interp:
            notes.append(
                f"{c.name}: interpolate_inputs asked but the FMU cannot interpolate inputs "
                f"(FMI {cap.fmi_version}); it steps {c.step_ratio} times per macro step instead"
            )
        k = 1 if interp else c.step_ratio
        if interp and c.step_ratio > 1:
            notes.append(
                f"{c.name}: one doStep per macro step with its inputs as polynomials; its communication step "
                f"{float(H / c.step_ratio):g} s is its internal step"
            )
        se = None
        if c.scheduled:  # its input clocks' ticks; triggered ones from step stimuli (master.clocks)
            ticks = {s.variable: (s.times, s.values) for s in sc.stimuli if s.component == c.name}
            linked = frozenset(cn.end_connector for cn in sc.connections if cn.end_component == c.name)
            se = schedule_clocks(cap.clocks, start, H / k, ticks, linked)
        comps[c.name] = PlanComponent(c.name, k, H / k, Clock.make(start, H, k), interp, 0, me, se)
    return comps


def _links(
    sc: Scenario,
    variables: dict[str, dict[str, Variable]],
    caps: dict[str, Capability],
    comps: dict[str, PlanComponent],
) -> list[Link]:
    """The connections grouped by (source, consumer, order, kind) into links."""
    rank = {n: i for i, n in enumerate(stepping_order(sc))}
    groups: dict[tuple[str, str, int, str], list[tuple[str, str, Transformation | None]]] = {}
    for cn in sc.connections:
        out = variables[cn.start_component][cn.start_connector]
        inp = variables[cn.end_component][cn.end_connector]
        kind = value_kind(out, caps[cn.start_component].fmi_version)
        order_ = sc.component(cn.end_component).extrapolation_order
        order_ = order_ if cn.extrapolation_order is None else cn.extrapolation_order
        if kind not in CONTINUOUS:
            order_ = 0  # discrete signals (integers, Booleans, Strings) are held between communication points
        # an array drives an array of the same shape element by element: a pair per element
        outs, ins = element_names(cn.start_connector, out.shape), element_names(cn.end_connector, inp.shape)
        pairs = [(o, i, cn.transformation) for o, i in zip(outs, ins, strict=True)]
        groups.setdefault((cn.start_component, cn.end_component, order_, kind), []).extend(pairs)
    return [
        Link(
            src,
            dst,
            tuple(p[0] for p in pairs),
            tuple(p[1] for p in pairs),
            order_,
            sc.coupling == Scheme.GAUSS_SEIDEL and rank[src] < rank[dst],
            comps[src].step_ratio,
            comps[dst].step_ratio,
            kind,
            tuple(p[2] for p in pairs) if any(p[2] for p in pairs) else (),
        )
        for (src, dst, order_, kind), pairs in groups.items()
    ]


def _startup(
    sc: Scenario, caps: dict[str, Capability], links: list[Link], notes: list[str]
) -> tuple[int, int]:
    """(start-up macro steps, sweeps of each): the paper's step 3, where the links' orders are not
    yet reached and every FMU can save its state."""
    startup_steps = 0
    start, H = Fraction(sc.start_time), Fraction(sc.macro_step)
    for lk in links:
        su = lk.startup()
        startup_steps = max(startup_steps, len(su))
        if su:
            steps = ", ".join(f"order {o} in macro step {n}" for n, o in su)
            notes.append(
                f"start-up: {lk.source} -> {lk.consumer} ({', '.join(lk.inputs)}) uses {steps}; "
                f"full order {lk.order} from t = {float(start + len(su) * H):g} s"
            )
    if not startup_steps:
        return 0, 0
    if not all(cap.can_get_set_state for cap in caps.values()):
        notes.append("start-up: not every FMU can save its state, so start-up steps are not repeated")
        return startup_steps, 0
    sweeps = max(lk.order for lk in links)
    if sc.iteration is None:  # iterated, every macro step is repeated until it settles
        notes.append(
            f"start-up: macro steps 0..{startup_steps - 1} are repeated {sweeps} time(s) from "
            "saved FMU states with interpolation over the step (whole system integrated together)"
        )
    return startup_steps, sweeps


def _loops(
    sc: Scenario,
    variables: dict[str, dict[str, Variable]],
    caps: dict[str, Capability],
    links: list[Link],
    notes: list[str],
) -> tuple[tuple[Loop, ...], tuple[tuple[str, str], ...]]:
    """The algebraic loops (cycles of ports through connections and direct feedthrough, merged where
    they share a component) and, once per FMU file, a note on the dependencies it does not declare."""
    pairs = [
        (lk.source, o, lk.consumer, i, t)
        for lk in links
        for n, (o, i) in enumerate(zip(lk.outputs, lk.inputs, strict=True))
        for t in [lk.transformations[n] if lk.transformations else None]
    ]
    driven = {(dst, i) for _, _, dst, i, _ in pairs}
    feedthrough = {  # per component, each output (an array: each element) -> the driven inputs it reads
        c.name: {
            o: [i for comp, i in driven if comp == c.name and i.split("[")[0] in depends]  # y[2]: y's
            for out in variables[c.name].values()
            if out.causality == "output"
            for depends in [caps[c.name].depends(out.name, variables[c.name])]
            for o in element_names(out.name, out.shape)
        }
        for c in sc.components
    }
    edges = port_graph(((s, o, d, i) for s, o, d, i, _ in pairs), feedthrough)
    cycles = [scc for scc in strongly_connected(edges) if len(scc) > 1 or scc[0] in edges.get(scc[0], [])]
    groups: list[set[str]] = []
    described: list[str] = []
    for scc in cycles:  # components of port cycles that share a component form one loop
        members = {c for c, _ in scc}
        joined = [g for g in groups if g & members]
        for g in joined:
            groups.remove(g)
            members |= g
        groups.append(members)
        described.append(" -> ".join(f"{c}.{v}" for c, v in cycle_in(scc, edges)))
    order = stepping_order(sc)
    loops = []
    for members in groups:
        ranked = tuple(n for n in order if n in members)
        unknowns = tuple(dict.fromkeys((s, o) for s, o, d, _, _ in pairs if s in members and d in members))
        index = {u: n for n, u in enumerate(unknowns)}
        inputs = tuple(
            (d, i, index[(s, o)], t.factor if t is not None and t.kind == "linear" else 1.0)
            for s, o, d, i, t in pairs
            if s in members and d in members
        )
        structure = [[EDGE_NONE] * len(unknowns) for _ in unknowns]
        for row, (comp, out) in enumerate(unknowns):
            depends = caps[comp].depends(out.split("[")[0], variables[comp])
            assumed = caps[comp].dependencies is None or out.split("[")[0] in caps[comp].assumed
            for d, i, col, _ in inputs:
                if d == comp and i.split("[")[0] in depends:
                    structure[row][col] = EDGE_ASSUMED if assumed else EDGE_DECLARED
        scalar = all("[" not in o for _, o in unknowns) and all("[" not in i for _, i, _, _ in inputs)
        derivatives = scalar and all(caps[m].directional_derivatives for m in ranked)
        cycle = next(d for d, scc in zip(described, cycles, strict=True) if {c for c, _ in scc} <= members)
        loops.append(Loop(ranked, unknowns, inputs, tuple(tuple(r) for r in structure), cycle, derivatives))
    how = {"newton": "Newton's method", "fixed-point": "Anderson-accelerated fixed-point iteration"}
    for lp in loops:
        jacobian = "directional derivatives" if lp.derivatives else "finite differences"
        jacobian = f", the Jacobian from {jacobian}" if sc.loops.method == "newton" else ""
        notes.append(
            f"algebraic loop {lp.cycle}: solved at every communication point by {how[sc.loops.method]}"
            f"{jacobian} to a tolerance of {sc.loops.tolerance:g}, "
            f"at most {sc.loops.max_iterations} iterations"
        )
    fmu_notes: dict[str, str] = {}
    for lp in loops:
        for m in lp.members:
            open_outputs = sorted(
                out for row, (comp, out) in enumerate(lp.unknowns)
                if comp == m and EDGE_ASSUMED in lp.structure[row]
            )  # fmt: skip
            if open_outputs:
                path = str(sc.component(m).fmu_path)
                fmu_notes.setdefault(
                    path,
                    f"{m}: {Path(path).name} declares no dependencies of {', '.join(open_outputs)}: "
                    "taken, as FMI says, to depend directly on every input, which closes an algebraic "
                    "loop; the run tests it at the start and iterates only the dependencies it finds",
                )
    return tuple(loops), tuple(fmu_notes.items())


def _recording(
    sc: Scenario, variables: dict[str, dict[str, Variable]], caps: dict[str, Capability], notes: list[str]
) -> tuple[tuple[tuple[str, str], ...], tuple[str, ...]]:
    """The recorded columns (an array a column per element) and how the results hold each."""

    def can_record(comp: str, v: Variable) -> bool:
        return recordable(v.fmi_type or v.type, caps[comp].fmi_version, v.shape)

    record = tuple(sc.record)
    if not record:  # every output the runtime can record (arrays too); a note names the others
        outputs = [
            (c.name, v) for c in sc.components for v in variables[c.name].values() if v.causality == "output"
        ]
        record = tuple((c, v.name) for c, v in outputs if can_record(c, v))
        skipped = [f"{c}.{v.name} ({v.fmi_type or v.type})" for c, v in outputs if not can_record(c, v)]
        if skipped:
            notes.append(f"not recorded: {', '.join(skipped)}; the runtime records {RECORDED}")
    columns: list[tuple[str, str]] = []  # an array: a column per element, y[1], y[2], ...
    types: list[str] = []  # how the results hold each (fmuinfo.recorded_as)
    for comp, var in record:
        v, position = lookup(variables[comp], var)  # a variable, or one element of an array
        names = element_names(v.name, v.shape) if position is None else [var]
        columns.extend((comp, name) for name in names)
        types.extend([recorded_as(v.fmi_type or v.type)] * len(names))
    return tuple(columns), tuple(types)


def _processes(
    sc: Scenario, caps: dict[str, Capability], notes: list[str]
) -> tuple[tuple[tuple[str, ...], ...], tuple[tuple[str, str], ...]]:
    """(components whose FMU may be instantiated once per process, by FMU file; notes on FMUs that
    need their tool)."""
    by_file: dict[str, list[str]] = {}
    needs_tool: dict[str, list[str]] = {}
    for c in sc.components:
        cap = caps[c.name]
        if cap.once_per_process:
            by_file.setdefault(str(c.fmu_path), []).append(c.name)
        if cap.needs_execution_tool:
            needs_tool.setdefault(str(c.fmu_path), []).append(c.name)
    tool_notes = tuple(
        (fmu, f"{', '.join(names)}: {Path(fmu).name} declares needsExecutionTool=\"true\": the run fails "
         "unless that tool is installed here")
        for fmu, names in needs_tool.items()
    )  # fmt: skip
    exclusive = tuple(tuple(names) for names in by_file.values() if len(names) > 1)
    for names in exclusive:
        notes.append(
            f"{', '.join(names)}: their FMU can be instantiated only once per process: one worker each"
        )
    return exclusive, tool_notes
