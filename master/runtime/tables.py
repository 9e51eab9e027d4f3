"""A Plan compiled into the kernel's flat tables for a set of opened FMUs.

`CompiledPlan` builds every array the kernel reads (value references, polynomial weights and
sample offsets per link and macro-step kind, clocks, stimulus tables, recorded columns), points
the ctypes mirror of kernel.h at them and keeps them alive. It turns the kernel's error record
into a `SimulationError` naming the component, the simulation time and the cause.
Times are in seconds.
"""

from __future__ import annotations

import ctypes as C
import math
import mmap
import weakref

import numpy as np
from fmpy.fmi1 import FMICallException

from master.backends.component import (
    GROWTH_LIMIT,
    UNSTABLE_HINT,
    SimulationError,
    history_capacity,
    samples_read,
    string_output_names,
)
from master.clocks import TICK_LINKED, TICK_PERIODIC, every_from_fmu
from master.coupling import weights
from master.description import FMI_FUNCTIONS, SCHEDULED_FUNCTIONS, intermediate_inputs, lookup
from master.fmu import Fmu, FmuError
from master.runtime import native
from master.scenario.fmuinfo import CONTINUOUS, TEXTS, recorded_as
from master.scenario.model import LOOP_METHODS, TRANSFORMATIONS, ModelExchange
from master.schedule import (
    KINDS,
    Clock,
    Link,
    Loop,
    Plan,
    PlanComponent,
    connection_name,
    value_kind,
)
from master.solvers import NUMBERS

ROW_CAPACITY = 4096  # rows of the results ring
ALIGN = 64  # bytes: arrays start on their own cache line
SPIN_S = 200e-6  # s a waiting worker spins before it sleeps in a futex (waking one costs ~50-100 us)

Layout = dict[str, tuple[tuple[int, ...], str]]  # array name -> (shape, numpy dtype)

ME_CALLS = (
    "set_time",
    "set_states",
    "get_states",
    "get_derivatives",
    "completed_step",
    "get_event_indicators",
    "enter_event_mode",
    "update_discrete_states",
    "enter_continuous_time_mode",
)


ANDERSON_MEMORY = 8  # earlier steps a fixed-point loop solve remembers (kernel.h mk_loop)


STATE_FUNCTIONS = ("get_state", "set_state", "free_state")  # what repeating a macro step calls


class Cancelled(Exception):
    """Another worker failed or the supervisor stopped the run: this worker has nothing to report."""


def _ptr(a: np.ndarray, ctype):
    return a.ctypes.data_as(C.POINTER(ctype))


def link_tables(
    lk: Link, blocks: list[tuple[int, int]]
) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray]:
    """(n_plain, n_relaxed, offsets, weights, zero) of a link as kernel.h lays them out.

    blocks: (step offset of the evaluation point, derivative order) of each block of the consumer's
    inputs. Step m of macro step n uses source samples j_end - i, i = 0..order, with
    (j_end, p) = `Link.window`; terms beyond p (start-up) get weight 0 on sample j_end, derivatives
    beyond p are exactly 0. From macro step n_plain (n_relaxed for relaxed sweeps) on, every macro
    step has the same table relative to n k_source.
    """
    ks, kc, terms = lk.k_source, lk.k_consumer, lk.order + 1

    def full(n: int, relaxed: bool) -> bool:
        return all(lk.window(n, n * kc + m, relaxed)[1] == lk.order for m in range(kc))

    def table(n: int, relaxed: bool):
        offsets = np.zeros((terms, kc), dtype=np.int64)
        w = np.zeros((len(blocks), terms, kc))
        zero = np.zeros((len(blocks), kc), dtype=np.uint8)
        for m in range(kc):
            j = n * kc + m
            j_end, p = lk.window(n, j, relaxed)
            offsets[:, m] = j_end - n * ks - np.minimum(np.arange(terms), p)
            for b, (shift, d) in enumerate(blocks):
                if d <= p:
                    w[b, : p + 1, m] = weights(p, (j + shift) * ks - j_end * kc, kc, d)
                zero[b, m] = d > p
        return offsets, w, zero

    n_plain = next(n for n in range(lk.order + 2) if full(n, False))
    n_relaxed = next(n for n in range(lk.order + 2) if full(n, True))
    tabs = [table(n, False) for n in range(n_plain + 1)] + [table(n, True) for n in range(n_relaxed + 1)]
    return (
        n_plain,
        n_relaxed,
        np.ascontiguousarray([t[0] for t in tabs]),
        np.ascontiguousarray([t[1] for t in tabs]),
        np.ascontiguousarray([t[2] for t in tabs]),
    )


def _function(fmu: Fmu, slot: str) -> int | None:
    name = fmu.function_name(FMI_FUNCTIONS[slot][fmu.fmi - 1])
    return None if name is None else _exported(fmu, name)


def _require(fmu: Fmu, slot: str, component: str) -> None:
    """FmuError unless the FMU exports the function of kernel slot `slot`."""
    if _function(fmu, slot) is None:
        name = fmu.function_name(FMI_FUNCTIONS[slot][fmu.fmi - 1])
        raise FmuError(f"{component}: {fmu.path.name} does not export {name}")


def _exported(fmu: Fmu, name: str) -> int | None:
    try:
        return C.cast(fmu.slave.dll[name], C.c_void_p).value
    except AttributeError:  # not exported: the kernel never calls it unless the plan needs it
        return None


def layout(
    plan: Plan, outs: dict[str, list[str]], n_workers: int, row_capacity: int = ROW_CAPACITY
) -> Layout:
    """The arrays a run's processes share (or one process keeps): per component its output history
    and the previous start-up sweep's copy (and, where it has coupled String outputs, its string
    ring and that ring's copy), the results ring, and with n_workers > 0 the synchronisation
    counters, the busy markers and the pacing statistics of each worker."""
    out: Layout = {}
    for pc in plan.components:
        cap = history_capacity(plan, pc.name)
        shape = (cap, len(outs[pc.name]))
        out[f"hist:{pc.name}"] = (shape, "float64")
        out[f"previous:{pc.name}"] = (shape, "float64")
        texts = string_output_names(plan, pc.name)
        if texts:
            out[f"strings:{pc.name}"] = ((cap, len(texts), native.STRING_SLOT), "uint8")
            out[f"strings_previous:{pc.name}"] = ((cap, len(texts), native.STRING_SLOT), "uint8")
    out["rows"] = ((row_capacity, len(plan.columns)), "float64")
    n_texts = len(text_columns(plan))  # (none: one slot, never written)
    out["texts"] = ((row_capacity if n_texts else 1, max(n_texts, 1), native.STRING_SLOT), "uint8")
    counter, pacing = C.sizeof(native.Counter), C.sizeof(native.Pacing)
    nc, nw = len(plan.components), max(n_workers, 1)
    out["published"] = ((nc, counter), "uint8")
    out["stepped"] = ((nc, counter), "uint8")
    out["consumed"] = ((nc, counter), "uint8")
    out["barrier"] = ((1, counter), "uint8")
    out["rows_written"] = ((nw, counter), "uint8")
    out["rows_drained"] = ((1, counter), "uint8")
    out["cancel"] = ((1, counter), "uint8")
    out["stop_at"] = ((1, counter), "uint8")  # set to native.NEVER by whoever creates the memory
    out["stopper"] = ((nc, 2), "int64")  # per component: its stop request and point (kernel.h)
    out["busy"] = ((nw, 8), "int64")  # one cache line per worker
    out["span"] = ((nw, 8), "int64")  # CLOCK_MONOTONIC ns at which each worker's last run began, ended
    out["pacing"] = ((nw, pacing), "uint8")
    out["pace"] = ((2,), "float64")  # real-time factor (0: unpaced), clock origin (ns)
    out["realtime"] = ((nw, 2), "int64")  # per worker: errno of SCHED_FIFO, of mlockall (-1: not tried)
    n_estimates = max(sum(len(lk.inputs) for lk in plan.links), 1)
    out["estimates"] = ((n_estimates, native.ERROR_FIELDS), "float64")  # see mk_link
    out["unsettled"] = ((1, counter), "uint8")  # iterated macro steps (kernel.h)
    out["swept"] = ((nc, counter), "uint8")
    out["iterations"] = ((8,), "int64")  # [0..3): sweeps, most in one macro step, macro steps iterated
    out["steps"] = ((nc, 8), "int64")  # [i, 0]: component i's; a cache line each (workers write them)
    out["fmu_time"] = ((nc, 8), "float64")
    out["loops"] = ((max(len(plan.loops), 1), 8), "int64")  # per loop its counters (kernel.h mk_loop)
    out["loop_worst"] = ((max(len(plan.loops), 1), 8), "float64")  # and its largest accepted residual
    out["clock_ticks"] = ((max(len(clock_names(plan)), 1),), "int64")  # mk_scheduled's counts
    return out


def clock_names(plan: Plan) -> list[str]:
    """ "component.clock" of every Scheduled Execution component's input clocks, then its output
    clocks (the kernel counts their activations and ticks in this order, mk_scheduled)."""
    return [
        f"{pc.name}.{c.name}"
        for pc in plan.components
        if pc.scheduled
        for c in pc.scheduled.inputs + pc.scheduled.outputs
    ]


def clock_ticks(plan: Plan, memory: Memory) -> dict[str, int]:
    """Per clock of a Scheduled Execution component ("component.clock"): its activations (an
    input clock) or the ticks read (an output clock)."""
    return {name: int(memory["clock_ticks"][i]) for i, name in enumerate(clock_names(plan))}


class CompiledPlan:
    """The kernel tables of `plan` in one process.

    fmus: the opened FMUs (in initialisation mode) of the components this process steps, by name;
    outs: the output names of every component (`output_names`); memory: arrays of `layout`, private
    or shared with the other workers; worker, n_workers: this process's place (n_workers = 0: the
    only process, Python drains the results ring itself); spin: s a waiting worker spins before
    it sleeps (0 where workers outnumber the processors: a spinner would take one from a peer).
    """

    def __init__(
        self,
        plan: Plan,
        fmus: dict[str, Fmu],
        outs: dict[str, list[str]],
        memory: Memory,
        worker: int = 0,
        n_workers: int = 0,
        spin: float = SPIN_S,
    ):
        self.plan = plan
        self.lib = native.library()
        self.names = [pc.name for pc in plan.components]
        self.fmus = [fmus.get(n) for n in self.names]
        self.outs = outs
        self.memory = memory
        self._keep: list[object] = []  # every array and structure the kernel points into
        self.bound: dict[str, np.ndarray] = {}
        self.held: dict[str, np.ndarray] = {}  # per local component: which history columns are held signals
        self.every: dict[
            str, np.ndarray
        ] = {}  # Scheduled Execution: its input clocks' periods (mk_scheduled)
        self.resampled, order = resampling(plan, outs)
        comps = (native.Component * len(self.names))()
        for i, pc in enumerate(plan.components):
            comps[i] = self._component(pc, fmus.get(pc.name))
        self.components = comps
        k = native.Kernel()
        k.n_components = len(comps)
        k.components = comps
        k.n_macro = plan.n_macro
        k.startup_steps = plan.startup_steps
        k.startup_sweeps = plan.startup_sweeps
        k.record_every = plan.record_every
        self._iteration(k)
        k.n_resample_order = len(order)
        entries = [self.names.index(n) if isinstance(n, str) else -1 - n for n in order]
        k.resample_order = _ptr(self._array(entries, np.int32), C.c_int32)
        loops = (native.Loop * max(len(plan.loops), 1))()
        for i, lp in enumerate(plan.loops):
            loops[i] = self._loop(i, lp, fmus)
        k.n_loops, k.loops = len(plan.loops), loops
        self._keep.append(loops)
        mc = plan.macro_clock
        self._check_clock("the macro clock", mc, plan.n_macro)
        k.macro_num0, k.macro_dnum, k.macro_den = mc.num0, mc.dnum, mc.den
        local = [(i, c, v) for i, (c, v) in enumerate(plan.record) if c in fmus]
        self.record_index = [i for i, _, _ in local]  # plan.record index of each local column
        # a connection's coupling error: recorded by the process that steps its consumer
        errors = [(i, e) for i, e in enumerate(plan.record_errors) if e[2] in fmus]
        records = (native.Record * max(len(local) + len(errors), 1))()
        texts = text_columns(plan)
        for r, (i, comp, var) in enumerate(local):
            name = f"{comp}.{var}"
            records[r] = self._record(1 + i, comp, var, texts.index(name) if name in texts else -1)
        for r, (i, error) in enumerate(errors, len(local)):
            records[r] = self._error_record(1 + len(plan.record) + i, *error)
        k.n_records = len(local) + len(errors)
        k.records = records
        k.n_columns = len(plan.columns)
        self.rows = memory["rows"]
        k.rows = _ptr(self.rows, C.c_double)
        self.texts = memory["texts"]
        k.texts, k.n_texts = _ptr(self.texts, C.c_char), self.texts.shape[1]
        k.row_capacity = len(self.rows)
        self.pacing = native.Pacing.from_buffer(memory["pacing"][worker])
        k.pacing = C.pointer(self.pacing)
        k.stop_at = native.NEVER
        if n_workers:
            k.shared = C.pointer(shared_view(memory, worker, n_workers, spin))
        self._keep += [records]
        self.kernel = k
        self.ref = C.byref(k)
        self.position = 0  # the next macro step (after a failure: the one that failed)

    # -- building -------------------------------------------------------------------------------
    def _iteration(self, k: native.Kernel) -> None:
        """Iterated macro steps (kernel.h: mk_kernel.iterate): the sweeps allowed, the tolerance, the
        history columns whose settling ends the sweeps (those a link reads) and the counts."""
        it = self.plan.iteration
        for name, fmu in zip(self.names, self.fmus, strict=True):  # the scenario layer has said so already
            if it is not None and fmu is not None and any(_function(fmu, f) is None for f in STATE_FUNCTIONS):
                raise FmuError(f"{name}: {fmu.path.name} cannot save its state: iterated macro steps need it")
        k.iterate = it.max_iterations if it is not None else 0
        k.tolerance = it.tolerance if it is not None else 0.0
        read = {(lk.source, o) for lk in self.plan.links for o in lk.outputs}
        mask = [(n, o) in read for n in self.names for o in self.outs[n]]
        k.coupled = _ptr(self._array(mask, np.uint8), C.c_uint8)
        k.iterations = _ptr(self.memory["iterations"], C.c_int64)

    def _array(self, values, dtype) -> np.ndarray:
        a = np.ascontiguousarray(values, dtype=dtype)
        if a.size == 0:
            a = np.zeros(1, dtype=dtype)  # a valid pointer the kernel never reads
        self._keep.append(a)
        return a

    def _check_clock(self, what: str, clock: Clock, points: int) -> None:
        """Scenario files are checked at validate (master.scenario.settings); a Scenario built in
        Python is checked here, before the kernel computes times it cannot."""
        if not clock.exact_up_to(points):
            raise SimulationError(
                f"{self.plan.scenario.path}: {what} needs integers beyond 2^53; "
                "choose times with fewer decimals",
                "",
                float(self.plan.scenario.start_time),
            )

    def _component(self, pc: PlanComponent, fmu: Fmu | None) -> native.Component:
        """A component's tables; for one stepped by another process (fmu None) only what its
        consumers here read: its clock and its history."""
        plan = self.plan
        c = native.Component()
        self._check_clock(f"component {pc.name}", pc.clock, plan.n_macro * pc.step_ratio)
        c.num0, c.dnum, c.den = pc.clock.num0, pc.clock.dnum, pc.clock.den
        c.h = float(pc.step)
        c.step_ratio = pc.step_ratio
        i = self.names.index(pc.name)
        c.steps = _ptr(self.memory["steps"][i], C.c_int64)
        c.fmu_time = _ptr(self.memory["fmu_time"][i], C.c_double)
        out = self.outs[pc.name]
        hist, previous = self.memory[f"hist:{pc.name}"], self.memory[f"previous:{pc.name}"]
        c.n_out, c.cap = len(out), len(hist)
        c.hist, c.hist_previous = _ptr(hist, C.c_double), _ptr(previous, C.c_double)
        texts = string_output_names(plan, pc.name)
        if texts:  # its text ring (kernel.h), read by its consumers in any process: Strings, Binaries
            c.n_out_binary = len(set(texts) & _binaries(plan, pc.name))
            c.n_out_string = len(texts) - c.n_out_binary
            c.strings = _ptr(self.memory[f"strings:{pc.name}"], C.c_char)
            c.strings_previous = _ptr(self.memory[f"strings_previous:{pc.name}"], C.c_char)
        consumers = sorted({self.names.index(lk.consumer) for lk in plan.links if lk.source == pc.name})
        c.n_consumers = len(consumers)
        c.consumers = _ptr(self._array(consumers, np.int32), C.c_int32)
        if fmu is None:
            return c
        c.local = 1
        self._fmu_tables(c, pc, fmu)
        return c

    def _fmu_tables(self, c: native.Component, pc: PlanComponent, fmu: Fmu) -> None:
        plan = self.plan
        c.fmi = fmu.fmi
        c.instance = fmu.slave.component
        for slot in FMI_FUNCTIONS:
            setattr(c, slot, _function(fmu, slot))
        for name, kind in native.TYPED.items() if fmu.fmi3 else ():
            c.get_typed[kind] = _exported(fmu, f"fmi3Get{name}")
            c.set_typed[kind] = _exported(fmu, f"fmi3Set{name}")
        for slot in ME_CALLS if fmu.model_exchange else () if fmu.scheduled else ("do_step",):
            _require(fmu, slot, pc.name)
        for slot in ("set_real", "get_real"):
            _require(fmu, slot, pc.name)
        self._check_clock(f"component {pc.name}", pc.clock, plan.n_macro * pc.step_ratio)
        c.num0, c.dnum, c.den = pc.clock.num0, pc.clock.dnum, pc.clock.den
        c.h = float(pc.step)
        c.step_ratio = k = pc.step_ratio

        # inputs by kind (schedule.KINDS: Real, Integer, Boolean, then the FMI 3 kinds of their own
        # calls), of each kind the links' then the stimuli's: kernel.h
        links = plan.links_into(pc.name)
        stimuli = [s for s in plan.stimuli if s.component == pc.name]
        version = fmu.md.fmiVersion

        def kind_of(name: str) -> str | None:  # a variable or an element of an FMI 3 array, y[2]
            return value_kind(variable(fmu, name), version)

        in_names = []
        for kind in KINDS:
            in_names += [i for lk in links if lk.kind == kind for i in lk.inputs]
            in_names += [s.variable for s in stimuli if kind_of(s.variable) == kind]
        text_links = [lk for lk in links if lk.kind in TEXTS]  # String and Binary connections: kernel.h
        links = [lk for lk in links if lk.kind not in TEXTS]
        in_kinds = [kind_of(n) for n in in_names]
        in_vrs = [variable(fmu, n).vr for n in in_names]  # an array's in each of its elements' slots
        c.n_in_calls, c.in_calls = self._calls(fmu, in_names, in_kinds)
        c.n_in_real, c.n_in_integer = in_kinds.count("Real"), in_kinds.count("Integer")
        typed_in = [native.TYPED[k] for k in in_kinds if k in native.TYPED]
        c.n_in_typed, c.in_kinds = len(typed_in), _ptr(self._array(typed_in, np.int32), C.c_int32)
        out = self.outs[pc.name]
        out_kinds = [kind_of(o) for o in out]
        assert [KINDS.index(k) for k in out_kinds] == sorted(KINDS.index(k) for k in out_kinds), out_kinds
        c.n_out_real, c.n_out_integer = out_kinds.count("Real"), out_kinds.count("Integer")
        typed_out = [native.TYPED[k] for k in out_kinds if k in native.TYPED]
        c.n_out_typed, c.out_kinds = len(typed_out), _ptr(self._array(typed_out, np.int32), C.c_int32)
        c.n_out_calls, c.out_calls = self._calls(fmu, out, out_kinds)
        self.held[pc.name] = np.array([k not in CONTINUOUS for k in out_kinds], dtype=bool)
        for kind in set(typed_in) | set(typed_out):
            name = next(n for n, k in native.TYPED.items() if k == kind)
            for calls, verb, used in ((c.set_typed, "Set", typed_in), (c.get_typed, "Get", typed_out)):
                if kind in used and calls[kind] is None:
                    raise FmuError(f"{pc.name}: {fmu.path.name} does not export fmi3{verb}{name}")
        self._string_tables(c, pc, fmu, text_links)
        # an output read at communication points or rows that depends on inputs: the step-end inputs
        # are set after each step (a coupled String or Binary, or a recorded output of any type, too)
        fed = any(variable(fmu, o).name in fmu.feedthrough for o in outputs_read(plan, out, pc.name))
        # a Scheduled Execution component takes the inputs at its activations: the step-end block
        c.feedthrough = int(bool(in_names) and (fed or pc.scheduled is not None))
        nv = 2 if c.feedthrough else 1
        blocks = [(0, 0), (1, 0)][:nv] + [(0, d) for d in range(1, pc.derivative_order + 1)]
        c.n_in, c.n_values, c.n_blocks = len(in_names), nv, len(blocks)
        c.in_vrs = _ptr(self._array(in_vrs, np.uint32), C.c_uint32)
        n_deriv_blocks = len(blocks) - nv
        asks = fmu.intermediate is not None  # an FMI 3 FMU asks for its inputs inside doStep
        if n_deriv_blocks and c.set_derivatives is None and not fmu.model_exchange and not asks:
            raise FmuError(f"{pc.name}: inputs as polynomials need fmi2SetRealInputDerivatives")
        # discrete inputs are held: no derivatives; a Model Exchange component's polynomials are the
        # kernel's, and so are those of an FMU that asks for its inputs
        c.n_derivatives = 0 if fmu.model_exchange or asks else n_deriv_blocks * c.n_in_real
        c.derivative_vrs = _ptr(self._array(in_vrs[: c.n_in_real] * n_deriv_blocks, np.uint32), C.c_uint32)
        orders = [d for _, d in blocks[nv:] for _ in range(c.n_in_real)]
        c.derivative_orders = _ptr(self._array(orders, np.int32), C.c_int32)
        c.u = _ptr(self._array(np.zeros((k, len(blocks), len(in_names))), np.float64), C.c_double)

        c_links = (native.Link * max(len(links), 1))()
        for i, lk in enumerate(links):
            link_vrs = _vrs(fmu, lk.inputs)
            step_s = float(plan.component(lk.source).step)
            scale = [step_s**d for _, d in blocks]
            c_links[i] = self._link(
                lk,
                blocks,
                self.outs[lk.source],
                in_names.index(lk.inputs[0]),
                n_vrs=len(link_vrs),
                vrs=_ptr(self._array(link_vrs, np.uint32), C.c_uint32),
                scale=_ptr(self._array(scale, np.float64), C.c_double),
                **self._estimate(lk),
            )
        c.n_links, c.links = len(links), c_links
        c_stim = (native.Stimulus * max(len(stimuli), 1))()
        for i, s in enumerate(stimuli):
            start = fmu.variables[s.variable].start
            c_stim[i] = native.Stimulus(
                slot=in_names.index(s.variable),
                kind=0 if s.kind == "step" else 1,
                n=len(s.times),
                times=_ptr(self._array([float(t) for t in s.times], np.float64), C.c_double),
                values=_ptr(self._array([float(v) for v in s.values], np.float64), C.c_double),
                start_value=_start_number(start),
            )
        c.n_stimuli, c.stimuli = len(stimuli), c_stim
        self._keep += [c_links, c_stim]

        c.out_vrs = _ptr(self._array([variable(fmu, o).vr for o in out], np.uint32), C.c_uint32)
        c.reads = _ptr(self._array(samples_read(plan, pc.name), np.uint8), C.c_uint8)
        self.bound[pc.name] = bound = self._array(np.full(len(out), np.inf), np.float64)
        c.bound = _ptr(bound, C.c_double)
        again = self.resampled.get(pc.name, [])  # read outputs that depend on inputs (resampling)
        coupled = {o for lk in plan.links if lk.source == pc.name for o in lk.outputs}
        c.resample = int(bool(again))
        c.resample_always = int(bool(coupled & set(again)))  # else only where a row is recorded
        c.resample_outputs = int(any(o in out for o in again))
        c.resample_texts = int(any(o in again for o in string_output_names(plan, pc.name)))
        width = max([len(in_names)] + [len(lk.inputs) for lk in links])
        c.scratch = _ptr(self._array(np.zeros(width), np.float64), C.c_double)
        if fmu.model_exchange:
            self._model_exchange(c, pc, fmu, in_names)
        if asks:
            self._intermediate(c, fmu, in_names[: c.n_in_real])
        if pc.scheduled is not None:
            self._scheduled(c, pc, fmu, in_names)
        if fmu.event_mode:
            self._event_mode(c, pc, fmu, in_kinds)

    def _intermediate(self, c: native.Component, fmu: Fmu, real_inputs: list[str]) -> None:
        """An FMU that asks for its inputs inside doStep (kernel.h mk_intermediate): which of its Real
        inputs the kernel's callback sets, the FMU's intermediate-update ones (others are held)."""
        asked = set(intermediate_inputs(fmu.md))
        slots = [i for i, name in enumerate(real_inputs) if name in asked]
        iu = fmu.intermediate
        iu.n, iu.calls = len(slots), 0
        iu.slots = _ptr(self._array(slots, np.int32), C.c_int32)
        iu.vrs = _ptr(self._array([variable(fmu, real_inputs[i]).vr for i in slots], np.uint32), C.c_uint32)
        iu.values = _ptr(self._array(np.zeros(len(slots)), np.float64), C.c_double)
        c.intermediate = C.pointer(iu)

    def _scheduled(self, c: native.Component, pc: PlanComponent, fmu: Fmu, in_names: list[str]) -> None:
        """A Scheduled Execution component's clock tables (kernel.h: mk_scheduled, master.clocks)."""
        se = pc.scheduled
        t = native.Scheduled()
        ins = se.inputs
        t.n_clocks = len(ins)
        t.vrs = self._vrs([ck.vr for ck in ins])
        t.tick = _ptr(self._array([ck.tick for ck in ins], np.int32), C.c_int32)
        self.every[pc.name] = every = self._array([ck.every for ck in ins], np.int64)  # 0: from the FMU
        t.every = _ptr(every, C.c_int64)
        t.phase = _ptr(self._array([ck.phase for ck in ins], np.int64), C.c_int64)
        first = np.cumsum([0] + [len(ck.points) for ck in ins])
        t.first = _ptr(self._array(first, np.int64), C.c_int64)
        t.points = _ptr(self._array([p for ck in ins for p in ck.points], np.int64), C.c_int64)
        t.due = _ptr(self._array(np.full(len(ins), -1), np.int64), C.c_int64)
        first = clock_names(self.plan).index(f"{pc.name}.{ins[0].name}") if ins else 0  # in shared memory
        t.activations = _ptr(self.memory["clock_ticks"][first:], C.c_int64)
        slots = [in_names.index(ck.name) if ck.tick == TICK_LINKED else -1 for ck in ins]  # source's count
        t.slot = _ptr(self._array(slots, np.int32), C.c_int32)
        t.seen = _ptr(self._array(np.zeros(len(ins)), np.float64), C.c_double)
        out_ticks = self.memory["clock_ticks"][first + len(ins) :]
        self._out_clocks(c, pc, fmu, [ck.vr for ck in se.outputs], out_ticks)
        for slot, name in SCHEDULED_FUNCTIONS.items():
            f = _exported(fmu, name)
            if f is None:
                raise FmuError(f"{pc.name}: {fmu.path.name} does not export {name}")
            setattr(t, slot, f)
        self._keep.append(t)
        c.scheduled = C.pointer(t)

    def _out_clocks(self, c: native.Component, pc: PlanComponent, fmu: Fmu, vrs: list[int], ticks) -> None:
        """The output clocks whose ticks the kernel counts into `ticks` (kernel.h: out_clock_ticks)."""
        if vrs:
            _require(fmu, "get_clock", pc.name)
        c.n_out_clocks, c.out_clock_vrs, c.out_clock_ticks = len(vrs), self._vrs(vrs), _ptr(ticks, C.c_int64)

    def _event_mode(self, c: native.Component, pc: PlanComponent, fmu: Fmu, in_kinds: list[str]) -> None:
        """An FMI 3 Co-Simulation component in event mode (kernel.h: mk_component.cs_events): its
        discrete inputs as last set, whether each step's held inputs are samples of a later time,
        events counted beside its steps."""
        _require(fmu, "enter_event_mode", pc.name)
        _require(fmu, "update_discrete_states", pc.name)
        _require(fmu, "enter_step_mode", pc.name)
        c.cs_events = 1
        c.n_cs_held = held = sum(kind not in ("Real", "Float32") for kind in in_kinds)
        c.cs_late = _ptr(self._array(np.zeros((c.step_ratio, max(len(in_kinds), 1))), np.uint8), C.c_uint8)
        c.cs_held = _ptr(self._array(np.zeros(max(held, 1)), np.float64), C.c_double)
        c.cs_held_saved = _ptr(self._array(np.zeros(max(held, 1)), np.float64), C.c_double)
        c.me_event_count = _ptr(self.memory["steps"][self.names.index(pc.name), 1:], C.c_int64)
        outs = [v for v in fmu.md.modelVariables if v.causality == "output"]
        clocks = [v.valueReference for v in outs if v.type == "Clock"]  # read after its events
        self._out_clocks(c, pc, fmu, clocks, self._array(np.zeros(len(clocks)), np.int64))

    def _model_exchange(self, c: native.Component, pc: PlanComponent, fmu: Fmu, in_names: list[str]) -> None:
        """A Model Exchange component's tables (kernel.h: mk_component.me): its method, its internal
        steps per communication step, its states and their derivatives (for directional
        derivatives), the solver's history and work space."""
        me = pc.model_exchange or ModelExchange()
        if c.n_in_calls and c.n_in_real:
            raise FmuError(f"{pc.name}: a Model Exchange component with FMI 3 array inputs is not supported")
        c.me = 1
        c.me_solver = NUMBERS[me.solver]
        k = me.substeps(pc.step)
        if k is None:  # checked with the scenario (master.scenario.check)
            raise FmuError(f"{pc.name}: internal step {me.internal_step} s does not divide {pc.step} s")
        c.me_substeps = k
        states = [u.variable.derivative for u in fmu.md.derivatives]
        derivatives = [u.variable for u in fmu.md.derivatives]
        sizes = [variable(fmu, v.name).size for v in states]
        c.n_states = n = sum(sizes)
        interface = fmu.md.modelExchange
        # FMI 2 only: fmpy does not read FMI 3's providesDirectionalDerivatives (then by differences)
        provides = getattr(interface, "providesDirectionalDerivative", False)
        if provides and n and c.get_directional_derivative and all(s == 1 for s in sizes):
            c.me_state_vrs = self._vrs([v.valueReference for v in states])
            c.me_derivative_vrs = self._vrs([v.valueReference for v in derivatives])
        memory = int(self.lib.solver_memory_size(n))
        c.me_x = _ptr(self._array(np.zeros(n), np.float64), C.c_double)
        c.me_memory = _ptr(self._array(np.zeros(memory), np.float64), C.c_double)
        c.me_memory_saved = _ptr(self._array(np.zeros(memory), np.float64), C.c_double)
        work = self.lib.solver_work_new(n)
        if not work:
            raise MemoryError(f"{pc.name}: no memory for the solver's work space of {n} states")
        c.me_work = work
        weakref.finalize(self, self.lib.solver_work_free, work)
        # its events: the time event the initial event iteration asks for comes at exit_initialization
        c.n_event_indicators = nz = int(fmu.md.numberOfEventIndicators or 0)
        c.me_next_event = math.inf
        c.me_tolerance = 0.0  # EVENT_TOLERANCE (fmus/solvers/solvers.h)
        c.me_event_count = _ptr(self.memory["steps"][self.names.index(pc.name), 1:], C.c_int64)
        events = self.lib.event_work_new(n, nz)
        if not events:
            raise MemoryError(f"{pc.name}: no memory for the event indicators of {n} states, {nz} indicators")
        c.me_events = events
        weakref.finalize(self, self.lib.event_work_free, events)
        # inputs FMI lets change in event mode only: the FMU rests there between its steps (kernel.h)
        discrete = any(variable(fmu, name).variability != "continuous" for name in in_names)
        c.me_input_events = int(discrete or c.n_in_string + c.n_in_binary > 0)

    def _loop(self, index: int, lp: Loop, fmus: dict[str, Fmu]) -> native.Loop:
        """An algebraic loop's tables (kernel.h mk_loop); where another process steps it, only its
        members."""
        L = native.Loop()
        members = [self.names.index(m) for m in lp.members]
        L.n_members = len(members)
        L.members = _ptr(self._array(members, np.int32), C.c_int32)
        L.stats = _ptr(self.memory["loops"][index], C.c_int64)
        L.worst = _ptr(self.memory["loop_worst"][index], C.c_double)
        if lp.members[0] not in fmus:
            return L
        n, settings = len(lp.unknowns), self.plan.scenario.loops
        L.n_unknowns = n
        L.unknown_member = self._ints([lp.members.index(m) for m, _ in lp.unknowns])
        L.unknown_column = self._ints([self.outs[m].index(o) for m, o in lp.unknowns])
        L.unknown_vr = _ptr(
            self._array([variable(fmus[m], o).vr for m, o in lp.unknowns], np.uint32), C.c_uint32
        )
        L.structure = _ptr(self._array(lp.structure, np.uint8), C.c_uint8)
        L.n_inputs = len(lp.inputs)
        L.input_member = self._ints([lp.members.index(m) for m, _, _, _ in lp.inputs])
        L.input_vr = _ptr(
            self._array([variable(fmus[m], i).vr for m, i, _, _ in lp.inputs], np.uint32), C.c_uint32
        )
        L.input_unknown = self._ints([u for _, _, u, _ in lp.inputs])
        L.input_factor = _ptr(self._array([f for _, _, _, f in lp.inputs], np.float64), C.c_double)
        L.method = LOOP_METHODS.index(settings.method)
        L.derivatives = int(lp.derivatives and settings.directional_derivatives)
        L.tolerance, L.max_iterations = settings.tolerance, settings.max_iterations
        L.order = self._ints(np.zeros(len(members)))
        L.edges = _ptr(self._array(np.zeros(n * n), np.uint8), C.c_uint8)
        L.reset = _ptr(self._array(np.zeros(len(members)), np.uint8), C.c_uint8)
        L.memory = m = min(n, ANDERSON_MEMORY)
        L.work = _ptr(self._array(np.zeros(7 * n + 2 * n * n + 2 * m * n + m * m), np.float64), C.c_double)
        L.pivot = self._ints(np.zeros(n))
        L.probed = int(not lp.assumed)  # nothing to test: every entry declared
        return L

    def _ints(self, values):
        return _ptr(self._array(values, np.int32), C.c_int32)

    def _vrs(self, values):
        return _ptr(self._array(values, np.uint32), C.c_uint32)

    def _calls(self, fmu: Fmu, names: list[str], kinds: list[str | None]):
        """(n_calls, calls) of kernel.h's mk_call: the inputs or history columns `names` (of
        value kinds `kinds`, those of one kind together) set or read a kind per call, each FMI 3
        array by its one value reference with all its elements; (0, NULL) where no array is among
        them (the kernel's scalar calls then do it)."""
        if not any(variable(fmu, n).shape for n in names):
            return 0, None
        groups: list[tuple[int, int, list[str]]] = []  # (kernel kind, first value, names)
        for i, (n, kind) in enumerate(zip(names, kinds, strict=True)):
            code = native.TYPED.get(kind, native.KIND_CODES.get(kind, -1))
            if not groups or groups[-1][0] != code:
                groups.append((code, i, []))
            groups[-1][2].append(n)
        calls = (native.Call * len(groups))()
        for g, (code, first, members) in enumerate(groups):
            vrs = _vrs(fmu, members)
            calls[g] = native.Call(
                code, first, len(members), len(vrs), _ptr(self._array(vrs, np.uint32), C.c_uint32)
            )
        self._keep.append(calls)
        return len(groups), calls

    def _link(self, lk: Link, blocks: list[tuple[int, int]], source_columns: list[str], slot0: int, **extra):
        """kernel.h's mk_link of `lk`: its inputs from slot0 on, driven by `source_columns`
        (the source's history or string ring) through the polynomial tables of `blocks`."""
        n_plain, n_relaxed, offsets, w, zero = link_tables(lk, blocks)
        return native.Link(
            source=self.names.index(lk.source),
            k_source=lk.k_source,
            ahead=int(lk.source_first),
            final=int(any(o in self.resampled.get(lk.source, ()) for o in lk.outputs)),
            n_cols=len(lk.inputs),
            slot0=slot0,
            columns=_ptr(self._array([source_columns.index(o) for o in lk.outputs], np.int32), C.c_int32),
            terms=lk.order + 1,
            n_plain=n_plain,
            n_relaxed=n_relaxed,
            offsets=_ptr(self._array(offsets, np.int64), C.c_int64),
            weights=_ptr(self._array(w, np.float64), C.c_double),
            zero=_ptr(self._array(zero, np.uint8), C.c_uint8),
            transform=self._transforms(lk),
            **extra,
        )

    def _transforms(self, lk: Link):
        """kernel.h's mk_transform of each of `lk`'s columns, or NULL where none has one."""
        if not lk.transformations:
            return None
        table = (native.Transform * len(lk.transformations))()
        for i, t in enumerate(lk.transformations):
            if t is None:
                continue  # kind 0: MK_TRANSFORM_NONE
            pairs = np.array(t.mapping, dtype=np.float64).reshape(-1, 2)
            table[i] = native.Transform(
                kind=TRANSFORMATIONS.index(t.kind),
                n_map=len(pairs),
                factor=t.factor,
                offset=t.offset,
                from_=_ptr(self._array(pairs[:, 0], np.float64), C.c_double),
                to=_ptr(self._array(pairs[:, 1], np.float64), C.c_double),
            )
        self._keep.append(table)
        return table

    def _string_tables(self, c: native.Component, pc: PlanComponent, fmu: Fmu, links: list[Link]) -> None:
        """A component's String and Binary connections (kernel.h): its coupled text outputs (their
        ring is set in `_component`), its text inputs (Strings first) and the held links into
        them, of one term."""
        texts = string_output_names(self.plan, pc.name)
        links = sorted(links, key=lambda lk: TEXTS.index(lk.kind))  # Strings first (kernel.h)
        inputs = [i for lk in links for i in lk.inputs]
        if not texts and not inputs:
            return
        binary_in = [i for lk in links if lk.kind == "Binary" for i in lk.inputs]
        binary_out = set(texts) & _binaries(self.plan, pc.name)
        needed = {"get_string": len(texts) > len(binary_out), "get_binary": binary_out,
                  "set_string": len(inputs) > len(binary_in), "set_binary": binary_in}  # fmt: skip
        for slot, used in needed.items():
            if used:
                _require(fmu, slot, pc.name)
        c.out_string_vrs = _ptr(self._array([fmu.variables[o].vr for o in texts], np.uint32), C.c_uint32)
        c.n_in_binary = len(binary_in)
        c.n_in_string = len(inputs) - len(binary_in)
        c.in_string_vrs = _ptr(self._array([fmu.variables[i].vr for i in inputs], np.uint32), C.c_uint32)
        buffer = np.zeros((pc.step_ratio, max(len(inputs), 1), native.STRING_SLOT), np.uint8)
        c.string_u = _ptr(self._array(buffer, np.uint8), C.c_char)
        c_links = (native.Link * max(len(links), 1))()
        for i, lk in enumerate(links):  # held: one term of weight 1
            texts = string_output_names(self.plan, lk.source)
            c_links[i] = self._link(lk, [(0, 0)], texts, inputs.index(lk.inputs[0]))
        c.n_string_links, c.string_links = len(links), c_links
        self._keep.append(c_links)

    def _estimate(self, lk: Link) -> dict:
        """The error estimate's tables of an extrapolated link (kernel.h): the weights predicting
        the source's next macro-step sample, and its rows of the shared statistics, reset."""
        if not lk.estimated:  # a source that goes first; discrete signals are held, not predicted
            return {}
        rows = self.memory["estimates"][estimate_rows(self.plan, lk)]
        rows[:] = 0.0
        rows[:, 3], rows[:, 4] = np.inf, -np.inf
        return {
            "predict": _ptr(self._array(weights(lk.order, lk.k_source, 1), np.float64), C.c_double),
            "predicted": _ptr(self._array(np.zeros(len(lk.inputs)), np.float64), C.c_double),
            "error": _ptr(rows, C.c_double),
        }

    def _error_record(
        self, column: int, source: str, output: str, consumer: str, input_: str
    ) -> native.Record:
        """The column of a connection's latest coupling error (kernel.h: MK_COUPLING_ERROR): its
        place among the columns of the consumer's links, in the kernel's link order."""
        index = 0
        for lk in self.plan.links_into(consumer):
            if lk.source == source and (output, input_) in zip(lk.outputs, lk.inputs, strict=True):
                assert lk.estimated, lk
                return native.Record(column, self.names.index(consumer), native.COUPLING_ERROR,
                                     index + lk.inputs.index(input_))  # fmt: skip
            index += len(lk.inputs)
        raise KeyError(f"{source}.{output} -> {consumer}.{input_}: no such connection")

    def _record(self, column: int, comp: str, var: str, text: int) -> native.Record:
        """Column `column` of the rows: `comp`.`var` (a String or Binary: column `text` of the text
        ring), stored as `fmuinfo.recorded_as` says."""
        i = self.names.index(comp)
        fmu = self.fmus[i]
        v = variable(fmu, var)
        store = native.STORE.get(recorded_as(v.fmi_type or v.type), 0)
        if var in self.outs[comp]:  # a sample in the history (every element of an FMI 3 array is)
            return native.Record(column, i, native.REAL_SAMPLE, self.outs[comp].index(var), store)
        typed = "Int64" if v.fmi_type == "Enumeration" else v.fmi_type
        if v.type in TEXTS:
            _require(fmu, f"get_{v.type.lower()}", comp)
            kind = native.RECORD_STRING if v.type == "String" else native.RECORD_BINARY
            return native.Record(column, i, kind, v.vr, store, text)
        if fmu.fmi3 and typed in native.TYPED:
            kind = native.TYPED[typed]
        else:
            kind = native.BOOLEAN if v.type == "Boolean" else native.INTEGER
        return native.Record(column, i, kind, v.vr, store)

    # -- running --------------------------------------------------------------------------------
    def initial_sweep(self, i: int) -> None:
        """Component i in initialisation mode: inputs from the sources' sample 0, outputs to its own."""
        if self.lib.mk_initial_sweep(self.ref, i) != native.DONE:
            raise self.error(initial=True)

    def exit_initialization(self, name: str, fmu: Fmu) -> None:
        """Leave initialisation mode; a failure is named with the component and the start time."""
        try:
            fmu.exit_initialization()
        except FmuError as e:
            t = float(self.plan.scenario.start_time)
            raise SimulationError(f"{e} at t={t}", name, t) from e
        if fmu.scheduled:  # its partitions due at the start time (kernel.h: mk_scheduled_start)
            self._intervals(name, fmu)
            if self.lib.mk_scheduled_start(self.ref, self.names.index(name)) != native.DONE:
                raise self.error(initial=True)
        if fmu.event_mode:  # in step mode: its discrete inputs change in event mode from now on (kernel.h)
            self.components[self.names.index(name)].cs_stepping = 1
        if fmu.model_exchange:  # the time event its initial event iteration asked for
            c = self.components[self.names.index(name)]
            c.me_next_event = fmu.next_event_time
            if c.me_input_events:  # its inputs are set in event mode (kernel.h)
                try:
                    fmu.slave.enterEventMode()
                except FMICallException as e:
                    t = float(self.plan.scenario.start_time)
                    raise SimulationError(f"{fmu.describe(str(e))} at t={t}", name, t) from e

    def _intervals(self, name: str, fmu: Fmu) -> None:
        """The periods of a Scheduled Execution component's fixed and tunable clocks whose description
        gives no interval: fmi3GetIntervalDecimal after initialisation, on the component's grid."""
        from fmpy.fmi3 import fmi3Float64, fmi3IntervalQualifier, fmi3ValueReference

        pc = self.plan.component(name)
        t = float(self.plan.scenario.start_time)
        for i, clock in enumerate(pc.scheduled.inputs):
            if clock.tick != TICK_PERIODIC or clock.every:
                continue
            interval, qualifier = fmi3Float64(), fmi3IntervalQualifier()
            try:
                fmu.slave.fmi3GetIntervalDecimal(
                    fmu.slave.component, (fmi3ValueReference * 1)(clock.vr), 1, interval, qualifier
                )
            except FMICallException as e:
                raise SimulationError(f"{fmu.describe(str(e))} at t={t}", name, t) from e
            every, why = every_from_fmu(clock, interval.value, pc.step)
            if every is None:
                raise SimulationError(f"{name}: {why}", name, t)
            self.every[name][i] = every

    def pace(self, factor: float, origin_ns: int, n_origin: int = 0) -> None:
        """Pace macro steps n_origin on: macro step n is due at CLOCK_MONOTONIC origin_ns (ns, as
        time.monotonic_ns) + (n - n_origin) H / factor; simulated time runs `factor` times the wall clock."""
        if not factor > 0:
            raise ValueError(f"real-time factor must be positive, got {factor}")
        p = self.pacing
        p.factor, p.frame = factor, float(self.plan.scenario.macro_step) / factor
        p.origin_ns, p.n_origin = origin_ns, n_origin

    def set_bounds(self) -> None:
        """Divergence bounds of the local components from their samples at the start time (none for
        held signals: an integer or a Boolean is a value, not an unstable coupling)."""
        for name, bound in self.bound.items():
            start = self.memory[f"hist:{name}"][0]  # no outputs: bound is a placeholder of 1
            grown = GROWTH_LIMIT * np.maximum(1.0, np.abs(start))
            bound[: len(start)] = np.where(self.held[name], np.inf, grown)

    def record_row(self, n: int) -> None:
        """The row after macro step n (n = -1: the start time) into the results ring."""
        if self.lib.mk_record_row(self.ref, n) != native.DONE:
            raise self.error()

    def run(self, n_from: int, n_to: int, budget: float = 0.0) -> tuple[int, int]:
        """(code, next macro step): step n_from .. n_to - 1 (see kernel.h mk_run); raise on failure."""
        n_next = C.c_int64(n_from)
        try:
            code = self.lib.mk_run(self.ref, n_from, n_to, budget, C.byref(n_next))
        finally:
            self.position = n_next.value
        if code == native.ABORTED:
            raise Cancelled(f"cancelled before macro step {n_next.value}")
        if code == native.STOPPED:
            return code, n_next.value
        if code > native.YIELD:
            raise self.error()
        return code, n_next.value

    def stopped(self) -> tuple[str, float] | None:
        """(component, time in s) if an FMU ended the simulation, else None."""
        k = self.kernel
        if k.shared:
            return shared_stop(self.plan, self.memory)
        if k.stop_at >= native.NEVER:
            return None
        return stop_reason(self.plan, int(k.stopper[0]), int(k.stopper[1]))

    def take_rows(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The rows waiting in the results ring (the only process) and their recorded Strings and
        Binaries (`ring_texts`); empties it."""
        k = self.kernel
        rows = ring_rows(self.rows, k.rows_drained, k.rows_total)
        texts = ring_texts(self.plan, self.texts, k.rows_drained, k.rows_total)
        k.rows_drained = k.rows_total
        return rows, texts

    def stats(self) -> tuple[dict[str, int], dict[str, float]]:
        """(communication steps, wall time inside FMI calls in s) per component, as published."""
        steps, fmu_time = self.memory["steps"], self.memory["fmu_time"]
        return (
            {n: int(steps[i, 0]) for i, n in enumerate(self.names)},
            {n: float(fmu_time[i, 0]) for i, n in enumerate(self.names)},
        )

    # -- errors ---------------------------------------------------------------------------------
    def error(self, initial: bool = False) -> SimulationError:
        """The kernel's last error as a SimulationError (component, simulation time, cause);
        initial: it happened in an initial sweep, at the start time."""
        e = self.kernel.error
        name, fmu, pc = self.names[e.component], self.fmus[e.component], self.plan.components[e.component]
        t, t1 = pc.clock.time(e.point), pc.clock.time(e.point + 1)
        if e.code == native.NOT_CONVERGED:
            lp, settings = self.plan.loops[e.variable], self.plan.scenario.loops
            return SimulationError(
                f"algebraic loop {lp.cycle} not solved at t={t}: the largest change of its signals is "
                f"{e.value:.3g} (relative to 1 + |value|) after {int(e.integer)} iterations of "
                f"{settings.method}; tolerance {settings.tolerance:g}, at most {settings.max_iterations} "
                "iterations (mm:Loops)",
                name,
                t,
            )
        if e.code == native.NOT_SETTLED:
            outs = self.outs[name] + string_output_names(self.plan, name)
            it = self.plan.iteration
            end = pc.clock.time(e.point + pc.step_ratio)
            by = f" by {e.value:.3g}" if e.variable < len(self.outs[name]) else ""  # a String: no number
            sweeps = f"{int(e.integer)} sweep" + ("s" if e.integer != 1 else "")
            return SimulationError(
                f"iterated coupling did not converge in the macro step from t={t} to t={end}: after "
                f"{sweeps} {name}.{outs[e.variable]} still changed{by} "
                f"(tolerance {it.tolerance:g} (1 + |value|)); raise maxIterations of mm:Iteration or "
                "shorten the macro step",
                name,
                t,
                outs[e.variable],
            )
        if e.code in (native.NOT_FINITE, native.DIVERGED):
            bad = self.outs[name][e.variable]
            if e.code == native.DIVERGED:
                what = f"{e.value:.3g} is beyond {GROWTH_LIMIT:g} times its start magnitude"
            else:
                what = "NaN" if math.isnan(e.value) else ("+Inf" if e.value > 0 else "-Inf")
            return SimulationError(f"unstable: {name}.{bad} at t={t}: {what} ({UNSTABLE_HINT})", name, t, bad)
        if e.code == native.TOO_LONG:
            recording = e.call >= 0  # a row's read (MK_CALL_GET_STRING / _BINARY), else a connection's
            if recording:
                bad = self.plan.record[self.record_index[e.variable]][1]
            else:
                bad = string_output_names(self.plan, name)[e.variable]
            kind = variable(fmu, bad).type if fmu is not None else "String"
            what = f"a recorded {kind} holds" if recording else f"a {kind} connection carries"
            return SimulationError(
                f"{name}.{bad} is {int(e.integer)} bytes long at t={t}: {what} at most "
                f"{native.TEXT_MAX} bytes",
                name,
                t,
                bad,
            )
        if e.code == native.INEXACT:
            bad = self.outs[name][e.variable]
            typed = variable(fmu, bad).fmi_type
            value = int(e.integer)
            if typed != "UInt64" and value >= 2**63:  # an Int64 (or an Enumeration): two's complement
                value -= 2**64
            return SimulationError(
                f"{name}.{bad} = {value} ({typed}) at t={t}: beyond 2^53 in magnitude, which a connection "
                "cannot carry exactly (values travel as float64)",
                name,
                t,
                bad,
            )
        if e.code == native.CLOCK or native.CALLS[e.call] in SCHEDULED_FUNCTIONS:
            return self._clock_error(e, name, fmu, pc)
        step = f"in the step from t={t} to t={t1}"
        call = native.CALLS[e.call]
        if e.code == native.EVENT and call == "do_step":  # kernel.c cs_step
            why = f"returns early from fmi3DoStep without end ({native.EARLY_RETURNS} times)"
            return SimulationError(f"{name}: {why} {step}", name, t)
        if e.code == native.EVENT:
            new = FMI_FUNCTIONS["update_discrete_states"][fmu.fmi - 1]
            return SimulationError(
                f"{name}: its event iteration does not end (1000 rounds of {new}) {step}", name, t
            )
        if call == "solver":
            why = "a singular linear system" if e.status == 2 else f"solver code {e.status}"
            return SimulationError(f"{name}: the Model Exchange integration failed ({why}) {step}", name, t)
        if call in ME_CALLS or call in ("directional_derivative", "enter_step_mode"):
            slot = "get_directional_derivative" if call == "directional_derivative" else call
            failed = FMICallException(function=FMI_FUNCTIONS[slot][fmu.fmi - 1], status=e.status)
            cause = FmuError(fmu.describe(str(failed)))
            return SimulationError(f"{cause} {step}", name, t)
        if call in ("get_typed", "set_typed"):
            typed = next(n for n, k in native.TYPED.items() if k == e.kind)
            verb = "Get" if call == "get_typed" else "Set"
            cause = FmuError(fmu.describe(f"fmi3{verb}{typed} failed with status {e.status}"))
        else:
            cause = fmu.call_error(call, e.status)
        recording = ("get_integer", "get_boolean", "get_typed", "get_string", "get_binary")
        if call in recording and e.variable >= 0:  # reading a value to record
            _, var = self.plan.record[self.record_index[e.variable]]
            return SimulationError(f"{cause}: reading {var}", name, math.nan, var)
        if call in ("get_state", "set_state", "free_state") or initial:
            return SimulationError(f"{cause} at t={t}", name, t)
        return SimulationError(f"{cause} {step}", name, t)

    def _clock_error(self, e, name: str, fmu: Fmu, pc: PlanComponent) -> SimulationError:
        """A Scheduled Execution component's failure in its activations at point e.point (kernel.h:
        mk_scheduled), or a clock counted down off its grid."""
        t = pc.clock.time(e.point)
        if e.code == native.CLOCK:
            clock = pc.scheduled.inputs[e.variable].name
            return SimulationError(
                f"{name}: clock {clock} counted down by {e.value:g} s at t={t}, not a whole number of "
                f"its communication steps ({float(pc.step):g} s)",
                name,
                t,
            )
        function = SCHEDULED_FUNCTIONS[native.CALLS[e.call]]
        cause = FmuError(fmu.describe(str(FMICallException(function=function, status=e.status))))
        return SimulationError(f"{cause} at t={t}", name, t)


def _start_number(start: str | None) -> float:
    """A variable's start value as the number a step stimulus holds before its first time (a
    Boolean's "true" / "false": 1 / 0; none: 0)."""
    return {"true": 1.0, "false": 0.0}[start] if start in ("true", "false") else float(start or 0)


def text_columns(plan: Plan) -> list[str]:
    """The recorded String and Binary columns, in column order: the columns of the results' text
    ring (kernel.h)."""
    return [name for name, t in plan.column_types.items() if t in TEXTS]


def _binaries(plan: Plan, name: str) -> set[str]:
    """The coupled Binary outputs of component `name`."""
    return {o for lk in plan.links if lk.source == name and lk.kind == "Binary" for o in lk.outputs}


def variable(fmu: Fmu, name: str):
    """The variable (master.description.Variable) of a history column or input slot: a variable's
    name, or an element y[i,j] of an FMI 3 array y (master.description.element_names)."""
    return lookup(fmu.variables, name)[0]


def _vrs(fmu: Fmu, names: list[str]) -> list[int]:
    """The value references of consecutive inputs or columns `names`: one per variable, an FMI 3
    array's elements (which lie in a row) sharing it."""
    vrs: list[int] = []
    last = None
    for n in names:
        v = variable(fmu, n)
        if v.name != last:
            vrs.append(v.vr)
            last = v.name
    return vrs


def ring_rows(rows: np.ndarray, first: int, end: int) -> np.ndarray:
    """Rows first .. end - 1 of a results ring (row r in slot r % len(rows)), in order."""
    cap = len(rows)
    a, b = first % cap, end % cap
    if end - first <= 0:
        return rows[:0]
    if a < b or b == 0:
        return rows[a : b or cap]
    return np.concatenate([rows[a:], rows[:b]])


def ring_texts(plan: Plan, texts: np.ndarray, first: int, end: int) -> np.ndarray | None:
    """The text ring's slots of rows first .. end - 1 (rows x text columns x native.STRING_SLOT
    bytes: each a length, the bytes, a zero), None where no String or Binary is recorded."""
    return ring_rows(texts, first, end) if text_columns(plan) else None


def counter(memory: Memory, name: str, i: int = 0) -> native.Counter:
    """The i-th synchronisation counter of array `name` (a view into the memory)."""
    return native.Counter.from_buffer(memory[name][i])


def shared_view(memory: Memory, worker: int, n_workers: int, spin: float = SPIN_S) -> native.Shared:
    """kernel.h's mk_shared for `worker` over the counters in `memory` (spin: s before a waiter sleeps)."""
    sh = native.Shared()
    for name in (
        "published",
        "stepped",
        "consumed",
        "barrier",
        "rows_written",
        "rows_drained",
        "cancel",
        "stop_at",
        "unsettled",
        "swept",
    ):
        setattr(sh, name, C.cast(memory[name].ctypes.data, C.POINTER(native.Counter)))
    sh.stopper = C.cast(memory["stopper"].ctypes.data, C.POINTER(C.c_int64))
    sh.busy = C.cast(memory["busy"][worker].ctypes.data, C.POINTER(C.c_int64))
    sh.worker, sh.n_workers, sh.spin_ns = worker, n_workers, int(spin * 1e9)
    return sh


def pacing_stats(pacings: list[native.Pacing]) -> dict[str, float] | None:
    """Real-time lateness (s) over the paced frames of every worker: p50, p99, p99.9 (upper edges
    of 1 us bins, over every worker's frames), worst; frames and overruns (frames whose work ended
    after they were due) of the worker with the most, idle (s spent waiting for the clock) of the
    worker that waited longest. None when unpaced."""
    paced = [p for p in pacings if p.factor > 0]
    if not paced:
        return None
    hist = sum(np.frombuffer(p.histogram, dtype=np.int64) for p in paced)
    cum = np.cumsum(hist)
    frames = int(cum[-1])  # worker-frames
    worst = max(p.worst_ns for p in paced) * 1e-9

    def quantile(q: float) -> float:
        return min(float(np.searchsorted(cum, q * frames) + 1) * 1e-6, worst) if frames else 0.0

    return {
        "frames": max(int(p.frames) for p in paced),
        "overruns": max(int(p.overruns) for p in paced),
        "p50": quantile(0.5),
        "p99": quantile(0.99),
        "p99.9": quantile(0.999),
        "worst": worst,
        "idle": max(p.idle_ns for p in paced) * 1e-9,
        "histogram": [(int(us), int(n)) for us, n in enumerate(hist) if n],  # (lateness us, frames)
    }


class Memory:
    """Named arrays of a `layout` in one block: private to this process, or (shared=True) an
    anonymous shared mapping that processes forked afterwards see too. Being anonymous, it has no
    name in /dev/shm and vanishes with the last process that maps it, however that process ends."""

    def __init__(self, layout: Layout, shared: bool = False):
        offsets, size = {}, 0
        for name, (shape, dtype) in layout.items():
            offsets[name] = size
            nbytes = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
            size += -(-max(nbytes, 1) // ALIGN) * ALIGN
        self.buffer = mmap.mmap(-1, max(size, ALIGN)) if shared else bytearray(max(size, ALIGN))
        self.touch()
        self.arrays = {
            name: np.ndarray(shape, dtype=dtype, buffer=self.buffer, offset=offsets[name])
            for name, (shape, dtype) in layout.items()
        }

    def __getitem__(self, name: str) -> np.ndarray:
        return self.arrays[name]

    def touch(self) -> None:
        """Map every page into this process now (a forked worker calls it once too): page faults
        on the stepping path and in the master's drain cost up to a millisecond per run."""
        np.frombuffer(self.buffer, dtype=np.uint8)[::4096].sum()


def outputs_read(plan: Plan, history: list[str], name: str) -> list[str]:
    """Every variable of component `name` that the run reads: its history columns `history`, its
    coupled text outputs and its recorded variables (an FMI 3 array by its name), once each."""
    recorded = [v for c, v in plan.record if c == name]
    return list(dict.fromkeys(history + string_output_names(plan, name) + recorded))


def resampling(plan: Plan, outs: dict[str, list[str]]) -> tuple[dict[str, list[str]], list[str | int]]:
    """Which components resample after a macro step (kernel.h: resample), each with the variables
    it reads that depend on its linked inputs, and their order (a source of such outputs before their
    consumers). One rule for every type and whatever is recorded: a component driven by a link
    resamples where any variable it reads (coupled, recorded or in its history) is an output that
    depends on inputs by the model structure (none declared: all do) or a linked input (recorded:
    the source's sample at the row's time, as every peer master records it). Its step-end inputs
    were extrapolated (a link that is not ahead) or held from the macro step's start, a source's
    sample before that source was resampled, or, in start-up sweeps, the previous sweep's; where
    they were final already, reading again changes nothing. An algebraic loop (Plan.loops) is one
    entry of the order, its index (its members solved together), a component's is its name."""
    from master.description import feedthrough_outputs, variables_of
    from master.fmu import read_description

    through: dict[str, list[str]] = {}
    for pc in plan.components:
        if not plan.links_into(pc.name):
            continue
        md = read_description(plan.scenario.component(pc.name).fmu_path)
        depend, variables = feedthrough_outputs(md), variables_of(md)
        linked = {lookup(variables, i)[0].name for lk in plan.links_into(pc.name) for i in lk.inputs}
        read = outputs_read(plan, outs[pc.name], pc.name)
        chosen = [o for o in read if lookup(variables, o)[0].name in depend | linked]  # y[2]: y's
        if chosen:
            through[pc.name] = chosen

    for lp in plan.loops:  # a loop's members read its unknowns again at every solve
        for m in lp.members:
            through[m] = list(dict.fromkeys(through.get(m, []) + [o for c, o in lp.unknowns if c == m]))
    node = {m: i for i, lp in enumerate(plan.loops) for m in lp.members}  # a loop resamples as one
    order: list[str | int] = []
    waiting = dict.fromkeys(node.get(n, n) for n in through)
    while waiting:  # Kahn: an entry after every resampled source outside it whose resampled outputs it reads
        ready = [
            e for e in waiting
            if not any(node.get(lk.source, lk.source) in waiting and node.get(lk.source, lk.source) != e
                       and set(lk.outputs) & set(through[lk.source])
                       for n in through if node.get(n, n) == e for lk in plan.links_into(n))
        ]  # fmt: skip
        if not ready:  # a cycle through outputs that depend on inputs no link drives: left as it was
            for e in waiting:
                for n in [n for n in through if node.get(n, n) == e]:
                    through.pop(n)
            break
        for e in ready:
            order.append(e)
            waiting.pop(e)
    return through, order


def estimate_rows(plan: Plan, lk: Link) -> slice:
    """The rows of `lk`'s connections in memory["estimates"] (links in plan order)."""
    start = 0
    for other in plan.links:
        if other is lk:
            return slice(start, start + len(lk.inputs))
        start += len(other.inputs)
    raise KeyError(lk)


def loop_stats(plan: Plan, memory: Memory) -> dict[str, dict[str, float]]:
    """Per algebraic loop (by its cycle): its counters (native.LOOP_STATS: solves, iterations,
    evaluations of its members, Jacobians, the most iterations at one point, 1 if the first solve
    found no cycle) and "worst", the largest relative residual it accepted."""
    return {
        lp.cycle: {
            **{name: int(memory["loops"][i, n]) for n, name in enumerate(native.LOOP_STATS)},
            "worst": float(memory["loop_worst"][i, 0]),
        }
        for i, lp in enumerate(plan.loops)
    }


def coupling_errors(plan: Plan, memory: Memory) -> dict[str, dict[str, float]]:
    """Per extrapolated connection "source.output -> consumer.input": the largest ("max") and the
    RMS ("rms") difference between the sample its polynomial predicted for each macro step's end
    and the sample the source then produced, relative to the range of the macro-step samples
    from the first full-order macro step on (1 where they stayed constant). The last macro step
    is not estimated."""
    est = memory["estimates"]
    out = {}
    for lk in plan.links:
        if not lk.estimated:
            continue
        for o, i, row in zip(lk.outputs, lk.inputs, est[estimate_rows(plan, lk)], strict=True):
            if row[2] > 0:
                span = row[4] - row[3] if row[4] > row[3] else 1.0
                out[connection_name(lk.source, o, lk.consumer, i)] = {
                    "max": float(row[0] / span),
                    "rms": float(np.sqrt(row[1] / row[2]) / span),
                }
    return out


def event_counts(plan: Plan, memory: Memory) -> dict[str, int]:
    """Events handled per component that had any: a Model Exchange or FMI 3 Co-Simulation
    component in event mode (kernel.h: me_event_count, beside its steps)."""
    steps = memory["steps"]
    return {pc.name: int(steps[i, 1]) for i, pc in enumerate(plan.components) if steps[i, 1]}


def iteration_counts(plan: Plan, memory: Memory) -> dict[str, int] | None:
    """Iterated macro steps: "sweeps" (repetitions from saved states, in all), "max" (the most in
    one macro step), "macro_steps" (those iterated); None when the plan does not iterate."""
    if plan.iteration is None:
        return None
    counts = memory["iterations"]
    return {"sweeps": int(counts[0]), "max": int(counts[1]), "macro_steps": int(counts[2])}


def shared_stop(plan: Plan, memory: Memory) -> tuple[str, float] | None:
    """The earliest stop request of the workers' components (component, time in s), or None."""
    if counter(memory, "stop_at").value >= native.NEVER:
        return None
    requests = memory["stopper"]
    who = int(np.argmin(requests[:, 0]))
    return stop_reason(plan, who, int(requests[who, 1]))


def stop_reason(plan: Plan, component: int, point: int) -> tuple[str, float]:
    """(component name, time in s) of an FMU that ended the simulation after communication point
    `point` (the end of its step from there)."""
    pc = plan.components[component]
    return pc.name, pc.clock.time(point + 1)
