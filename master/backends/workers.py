"""Worker backend: every FMU outside the master process, the kernel stepping in the workers.

Serial is one worker running the whole plan; parallel is one worker per component or scenario
group. Workers are forked after the master has mapped one block of anonymous shared memory
(master.runtime.tables.layout): the output histories, the synchronisation counters, the results
ring. During the run the workers synchronise with each other through the counters (dataflow:
each waits only for the producers of the samples it reads, see kernel.c); the master is not on
the per-step path: it drains completed rows from the ring to the recorder, watches for dead or
hung workers and for signals, and sleeps in between.

A worker that crashes (segfault, abort), hangs past the step timeout, or stops on an FMU error,
a NaN/Inf or a diverging output ends the run with one SimulationError naming the component, the
simulation time and the cause; the others are cancelled, every completed row is written and no
process is left behind (workers also die with the master, PR_SET_PDEATHSIG; should the master be
SIGKILLed, master.backends.janitor removes its temporary folders). Times in seconds.
"""

from __future__ import annotations

import ctypes as C
import os
import shutil
import tempfile
import time
from functools import partial

import numpy as np

from master.backends.component import SimulationError, Unpacked, open_fmu, output_names
from master.backends.driver import signals_deferred
from master.backends.in_process import initialize_sweeps
from master.backends.janitor import Janitor
from master.backends.worker import WorkerFailure, WorkerPool, cpu_count
from master.description import variables_of
from master.fmu import Fmu, FmuError, read_description
from master.recorder import Recorder
from master.runtime import native
from master.runtime.tables import (
    SPIN_S,
    Cancelled,
    CompiledPlan,
    Memory,
    clock_ticks,
    counter,
    coupling_errors,
    event_counts,
    iteration_counts,
    layout,
    loop_stats,
    pacing_stats,
    ring_rows,
    ring_texts,
    shared_stop,
    shared_view,
    text_columns,
)
from master.schedule import Plan

OP_SWEEP, OP_EXIT_INIT, OP_FINISH_INIT, OP_RUN, OP_REALTIME = range(1, 6)
FIFO_PRIORITY = 50  # SCHED_FIFO priority of paced workers, where permitted
MCL_CURRENT, MCL_FUTURE = 1, 2
DEFAULT_STEP_TIMEOUT = 10.0  # s: one component's macro step taking longer than this is a hang
SETTLE_S = 2.0  # s at most the other workers get to complete the macro steps before a failure
RING_BYTES = 16 << 20  # the results ring the master drains: at most this size ...
RING_ROWS = (256, 16384)  # ... and between these many rows


def worker_groups(plan: Plan) -> list[list[str]]:
    """Component names per worker, in stepping order: one worker per scenario group or lone component,
    the members of an algebraic loop in one (they are solved together, Plan.loops)."""
    key = {pc.name: plan.scenario.component(pc.name).group for pc in plan.components}
    key = {n: f"group:{g}" if g else f"component:{n}" for n, g in key.items()}
    for lp in plan.loops:  # every key of a loop's members becomes its first member's
        joined = {key[m] for m in lp.members}
        key = {n: key[lp.members[0]] if k in joined else k for n, k in key.items()}
    groups: dict[str, list[str]] = {}
    for pc in plan.components:
        groups.setdefault(key[pc.name], []).append(pc.name)
    return separate(list(groups.values()), plan)


def separate(groups: list[list[str]], plan: Plan) -> list[list[str]]:
    """`groups` with every second, third ... instance of an FMU that may be instantiated only
    once per process (Plan.exclusive) moved to a worker of its own."""
    out: list[list[str]] = []
    for names in groups:
        kept, moved, seen = [], [], set()
        for name in names:
            same = next((s for s in plan.exclusive if name in s), None)
            if same is not None and same in seen:
                moved.append([name])
            else:
                kept.append(name)
                seen.add(same)
        out += [kept] + moved
    return out


class _Task:
    """The components of one worker, opened and compiled in the worker process."""

    def __init__(
        self,
        plan: Plan,
        names: list[str],
        outs: dict,
        memory: Memory,
        worker: int,
        n_workers: int,
        cpu: int | None,
        spin: float,
        tmp: str,
    ):
        self.plan = plan
        self.cpu = cpu
        self.spin = spin
        self.tmp = tmp
        self.components = names
        self.outs = outs
        self.memory = memory
        self.worker = worker
        self.n_workers = n_workers
        self.fmus: dict[str, Fmu] = {}
        self.cp: CompiledPlan | None = None

    def setup(self, where: np.ndarray) -> None:
        tempfile.tempdir = self.tmp  # FMUs extract where the master cleans up, even after a crash
        if self.cpu is not None:
            os.sched_setaffinity(0, {self.cpu})
        self.memory.touch()
        sc = self.plan.scenario
        unpacked = Unpacked(self.tmp)  # removed with self.tmp by the master
        for i, name in enumerate(self.components):
            where[0] = i
            self.fmus[name] = open_fmu(sc, sc.component(name), unpacked)
        self.cp = CompiledPlan(
            self.plan, self.fmus, self.outs, self.memory, self.worker, self.n_workers, self.spin
        )

    def command(self, op: int, a: int, b: int, where: np.ndarray) -> None:
        """OP_SWEEP a: initial sweep of component a (plan index) if it is here. OP_EXIT_INIT: leave
        initialisation mode. OP_FINISH_INIT: divergence bounds, this worker's columns of the row at
        the start time. OP_REALTIME: SCHED_FIFO and locked memory where permitted. OP_RUN a b:
        macro steps a .. b - 1, paced if the master says so."""
        cp = self.cp
        assert cp is not None
        try:
            if op == OP_SWEEP and cp.names[a] in self.fmus:
                where[0] = self.components.index(cp.names[a])
                cp.initial_sweep(a)
            elif op == OP_EXIT_INIT:
                for i, (name, fmu) in enumerate(self.fmus.items()):
                    where[0] = i
                    cp.exit_initialization(name, fmu)
            elif op == OP_FINISH_INIT:
                cp.set_bounds()
                cp.record_row(-1)
            elif op == OP_REALTIME:  # before the clock starts: locking the memory takes a while
                self.memory["realtime"][self.worker] = realtime()
            elif op == OP_RUN:
                factor, origin = self.memory["pace"]
                if factor > 0:
                    cp.pace(float(factor), int(origin), a)
                span = self.memory["span"][self.worker]
                span[0] = time.monotonic_ns()
                try:
                    cp.run(a, b)
                finally:
                    span[1] = time.monotonic_ns()
        except Cancelled:
            return  # another worker failed or the master cancelled: they say why
        except SimulationError as e:
            if e.component in self.components:
                where[0] = self.components.index(e.component)
            # the others complete the macro steps before this one (their rows), then stop
            cp.lib.mk_stop(cp.kernel.shared, cp.kernel.n_now, len(cp.names), self.n_workers)
            raise

    def close(self) -> None:
        for f in self.fmus.values():
            f.close()


def arm(memory: Memory) -> None:
    """Fresh (zeroed) run memory made ready for a run: no stop requested."""
    counter(memory, "stop_at").value = native.NEVER
    memory["stopper"][:, 0] = native.NEVER


def realtime() -> tuple[int, int]:
    """Make this process a real-time one where permitted: SCHED_FIFO, and all its memory locked
    (no page fault in a frame). Returns the errno of each attempt (0: done)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FIFO_PRIORITY))
        fifo = 0
    except OSError as e:
        fifo = e.errno or -1
    libc = C.CDLL(None, use_errno=True)
    lock = 0 if libc.mlockall(MCL_CURRENT | MCL_FUTURE) == 0 else C.get_errno()
    return fifo, lock


class WorkerBackend:
    """Executes a Plan in worker processes (see the module docstring).

    groups: component names per worker (one group with all components: the serial backend);
    cpus: processors to pin the workers to, worker w on cpus[w % len(cpus)] (None: no pinning);
    name: what the run summary calls it (default: serial for one worker, else parallel).
    Use: `open()`, `initialize(recorder)`, `run(...)` ..., `close()`.
    """

    def __init__(
        self,
        plan: Plan,
        groups: list[list[str]],
        step_timeout: float = DEFAULT_STEP_TIMEOUT,
        cpus: list[int] | None = None,
        name: str | None = None,
    ):
        self.plan = plan
        self.cpus = cpus
        self.groups = groups
        self.name = name or ("serial" if len(groups) == 1 else "parallel")
        self.step_timeout = step_timeout
        self.names = [pc.name for pc in plan.components]
        self.worker_of = {name: w for w, names in enumerate(groups) for name in names}
        self.memory: Memory | None = None
        self.pool: WorkerPool | None = None
        self.tmp: str | None = None
        self.janitor: Janitor | None = None  # removes self.tmp and the raw results if the master is killed
        self.lib = native.library()
        self.ring_rows = RING_ROWS[1]
        self.position = 0  # macro steps every component has completed
        self.drained = 0  # rows taken out of the ring
        self.running = False
        self.recorder: Recorder | None = None
        self._rate = (time.perf_counter(), 0)  # (when, rows drained then): the drain period follows the rate
        self.task = _Task  # what a worker runs: called with the plan, its names, ... (see open)
        self.poll = True  # WorkerPool's poll

    def open(self) -> None:
        """Map the shared memory, start the workers; each loads and parameterises its FMUs."""
        sc = self.plan.scenario
        outs = {
            pc.name: output_names(
                self.plan, pc.name, variables_of(read_description(sc.component(pc.name).fmu_path))
            )
            for pc in self.plan.components
        }
        row_bytes = 8 * len(self.plan.columns) + native.STRING_SLOT * len(text_columns(self.plan))
        # a short run maps no more than its rows: the start's and at most one per macro step (record_due)
        rows = min(RING_BYTES // row_bytes, self.plan.n_macro + 1)
        self.ring_rows = min(max(rows, RING_ROWS[0]), RING_ROWS[1])
        self.memory = Memory(layout(self.plan, outs, len(self.groups), self.ring_rows), shared=True)
        arm(self.memory)
        self.janitor = Janitor()  # before the workers: they hold its pipe too, and die with the master
        self.tmp = tempfile.mkdtemp(prefix="master-run-")
        self.janitor.watch(self.tmp)
        cpu = (lambda w: self.cpus[w % len(self.cpus)]) if self.cpus else (lambda w: None)
        processors = len(set(self.cpus)) if self.cpus else cpu_count()
        spin = SPIN_S if len(self.groups) <= processors else 0.0  # a spinner must not take a peer's CPU
        tasks = [
            (
                names,
                partial(
                    self.task,
                    self.plan,
                    names,
                    outs,
                    self.memory,
                    w,
                    len(self.groups),
                    cpu(w),
                    spin,
                    self.tmp,
                ),
            )
            for w, names in enumerate(self.groups)
        ]
        try:
            self.pool = WorkerPool(tasks, step_timeout=self.step_timeout, poll=self.poll)
        except WorkerFailure as e:  # loading is not simulating: as in-process, an FmuError
            raise FmuError(
                e.cause if e.raised else f"component {e.component}: {e.cause} while loading"
            ) from None

    # -- initialisation ------------------------------------------------------------------------
    def initialize(self, recorder: Recorder) -> None:
        """The in-process initialisation (master.backends.in_process.initialize), component by
        component in the worker that holds it; records the row at the start time."""
        assert self.pool is not None and self.janitor is not None
        self.janitor.watch(recorder.tmpdir)
        t0 = float(self.plan.scenario.start_time)
        try:
            initialize_sweeps(len(self.names), self._sweep, lambda: self.pool.run(OP_EXIT_INIT))
            self.pool.run(OP_FINISH_INIT)
        except WorkerFailure as e:
            raise self._error(e, t0, "during initialisation") from None
        self._drain(recorder)

    def _sweep(self, i: int) -> None:
        assert self.pool is not None
        self.pool.run(OP_SWEEP, i, 0, [self.worker_of[self.names[i]]])

    # -- running -------------------------------------------------------------------------------
    def pace(self, factor: float) -> None:
        """Pace the following macro steps to the wall clock: simulated time runs `factor` times as fast."""
        if not factor > 0:
            raise ValueError(f"real-time factor must be positive, got {factor}")
        assert self.memory is not None and self.pool is not None
        self.memory["pace"][:] = factor, 0.0
        try:
            self.pool.run(OP_REALTIME)
        except WorkerFailure as e:
            raise self._error(e, self.plan.macro_clock.time(self.position), "preparing real time") from None

    def run(self, n_from: int, n_to: int, recorder: Recorder, budget: float = 0.0) -> int:
        """Step macro steps n_from .. n_to - 1 in the workers, returning after about `budget` s (0:
        at the end) with the next macro step every component still has to do; completed rows go
        to `recorder`, also on a failure."""
        assert self.pool is not None and self.memory is not None
        self.recorder = recorder
        if not self.running:
            pace = self.memory["pace"]
            if pace[0] > 0:
                pace[1] = float(time.monotonic_ns() + 1_000_000)  # every worker's frames from one origin
            self.running = True  # from here on, an interruption cancels the workers
            self.pool.start(OP_RUN, n_from, n_to)
        try:
            finished = self.pool.wait(self._supervise, budget)
        except WorkerFailure as e:
            self._settle(e)
            self.cancel()
            self._drain(recorder)
            raise self._error(e, self.plan.macro_clock.time(self.position), self._span()) from None
        except BaseException:  # Ctrl-C, SIGTERM: stop the workers, keep every completed row
            self.cancel()
            self._drain(recorder)
            raise
        self._drain(recorder)
        if finished:
            self.running = False
            return n_to
        return min(self.position, n_to - 1)  # not done until the workers have answered

    def _supervise(self) -> float:
        """Between polls of the workers: drain rows, look for a hang (a worker in the FMU calls of
        one component for longer than the step timeout: a macro step, a state save or restore, a
        recorded value). Returns the seconds until the next call: short enough that the ring
        stays at most a quarter full."""
        assert self.memory is not None and self.pool is not None
        if self.recorder is not None:
            self._drain(self.recorder)
        busy = self.memory["busy"]
        now = time.monotonic_ns()
        for w in range(len(self.groups)):
            since = int(busy[w, 0])
            if since and (now - since) * 1e-9 > self.step_timeout:
                comp = self.names[int(busy[w, 1])]
                self.pool.kill(w)
                raise WorkerFailure(
                    comp,
                    f"hang: its FMU calls took longer than the step timeout of {self.step_timeout:g} s",
                    worker=w,
                )
        t_then, rows_then = self._rate
        t = time.perf_counter()
        rate = (self.drained - rows_then) / max(t - t_then, 1e-6)
        self._rate = (t, self.drained)
        return min(0.02, max(1e-3, 0.25 * self.ring_rows / rate if rate > 0 else 0.02))

    def _drain(self, recorder: Recorder) -> None:
        """Move the rows every worker has completed from the ring to the recorder."""
        assert self.memory is not None
        done = min(counter(self.memory, "rows_written", w).value for w in range(len(self.groups)))
        if done > self.drained:
            with signals_deferred():
                rows = ring_rows(self.memory["rows"], self.drained, done)
                recorder.write(rows, ring_texts(self.plan, self.memory["texts"], self.drained, done))
                self.drained = done
            self.lib.mk_publish(counter(self.memory, "rows_drained"), done)
        done = min(counter(self.memory, "published", i).value for i in range(len(self.names)))
        self.position = min(done, counter(self.memory, "stop_at").value)

    def _settle(self, e: WorkerFailure) -> None:
        """After worker e.worker failed: the others complete the macro steps before the failing one
        (a worker that raised asked for that itself; for one that died or hung the first macro
        step its components did not complete is the stop), within the step timeout at most."""
        assert self.memory is not None and self.pool is not None
        if not e.raised and e.worker is not None:
            done = min(
                counter(self.memory, "published", self.names.index(n)).value for n in self.groups[e.worker]
            )
            shared = shared_view(self.memory, 0, len(self.groups))
            self.lib.mk_stop(C.byref(shared), done, len(self.names), len(self.groups))
        self.pool.settle(min(self.step_timeout, SETTLE_S))

    def cancel(self) -> None:
        """Make every worker stop at its next wait or macro step."""
        if self.memory is not None and self.running:
            shared = shared_view(self.memory, 0, len(self.groups))
            self.lib.mk_cancel(C.byref(shared), len(self.names), len(self.groups))
            self.running = False

    def _span(self) -> str:
        clock = self.plan.macro_clock
        return f"in the macro step from t={clock.time(self.position)} to t={clock.time(self.position + 1)}"

    def _error(self, e: WorkerFailure, t: float, when: str) -> SimulationError:
        """A SimulationError from a worker failure; the worker's own message if it raised one."""
        comp = e.component or "?"
        busy = self.memory["busy"] if self.memory is not None else None
        if not e.raised and e.worker is not None and busy is not None and busy[e.worker, 0]:
            comp = self.names[int(busy[e.worker, 1])]  # the component in an FMU call when it died
        if e.raised:  # the kernel or the FMU layer said what happened (and when)
            return SimulationError(e.cause, comp, t if e.time is None else e.time, e.variable)
        return SimulationError(f"component {comp}: {e.cause} {when}", comp, t)

    def stepping_span(self) -> float:
        """s from the first worker's start to the last worker's end of the last run command: the
        stepping alone, without the command's trip to the workers and back."""
        assert self.memory is not None
        span = self.memory["span"][: len(self.groups)]
        return float(span[:, 1].max() - span[:, 0].min()) * 1e-9

    def pacing(self) -> dict | None:
        """Real-time statistics over every worker's frames (see `pacing_stats`), None when unpaced."""
        if self.memory is None:
            return None
        stats = pacing_stats([native.Pacing.from_buffer(p) for p in self.memory["pacing"]])
        if stats is not None:
            fifo, lock = self.memory["realtime"][: len(self.groups)].max(axis=0)
            stats["notes"] = [
                f"{what} not permitted ({os.strerror(int(err))}): frames may be late under load"
                for what, err in (("SCHED_FIFO", fifo), ("mlockall", lock))
                if err > 0
            ]
        return stats

    def stopped(self) -> tuple[str, float] | None:
        """(component, time in s) if an FMU ended the simulation, else None."""
        if self.memory is None or self.running:  # known once every worker has come back
            return None
        return shared_stop(self.plan, self.memory)

    def loop_stats(self) -> dict[str, dict[str, float]]:
        """The counters of each algebraic loop (`loop_stats`)."""
        return loop_stats(self.plan, self.memory) if self.memory is not None else {}

    def clock_ticks(self) -> dict[str, int]:
        """Activations and ticks of Scheduled Execution components' clocks (`clock_ticks`)."""
        return clock_ticks(self.plan, self.memory) if self.memory is not None else {}

    def coupling_errors(self) -> dict[str, dict[str, float]]:
        """The error estimate per extrapolated connection (`coupling_errors`)."""
        return coupling_errors(self.plan, self.memory) if self.memory is not None else {}

    def event_counts(self) -> dict[str, int]:
        """Events handled per component that had any (`event_counts`)."""
        return event_counts(self.plan, self.memory) if self.memory is not None else {}

    def iterations(self) -> dict[str, int] | None:
        """Iterated macro steps: the sweeps (`iteration_counts`), None when the plan does not iterate."""
        return iteration_counts(self.plan, self.memory) if self.memory is not None else None

    def stats(self) -> tuple[dict[str, int], dict[str, float]]:
        """(communication steps, wall time inside FMI calls in s) per component."""
        if self.memory is None:
            return {n: 0 for n in self.names}, {n: 0.0 for n in self.names}
        steps, ft = self.memory["steps"], self.memory["fmu_time"]
        return {n: int(steps[i, 0]) for i, n in enumerate(self.names)}, {
            n: float(ft[i, 0]) for i, n in enumerate(self.names)
        }

    def _remove_files(self) -> None:
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            self.tmp = None

    def close(self) -> None:
        """Stop the workers (killing any that do not stop), remove the extracted FMUs."""
        try:
            self.cancel()
            if self.pool is not None:
                self.pool.close(while_ending=self._remove_files)  # while the workers' processes end
        finally:
            self.pool = None
            self._remove_files()
            if self.janitor is not None:
                self.janitor.close()
                self.janitor = None
