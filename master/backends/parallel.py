"""Parallel backend: each component (or each scenario group) in its own worker process.

The workers run exactly the serial backend's per-component code (`ComponentRunner`): the
output histories it reads and writes are numpy views on shared memory, so a consumer in one
process extrapolates from the very samples its source wrote in another, and the results are
bit for bit those of the serial backend.  The paper copies shared values into locals before
a step so that a concurrent producer cannot change them; here each output ring holds more
than k + p samples (`history_capacity`), so a producer writing macro step n never touches
the samples its consumers of order p are reading, and no copy is needed.

Per macro step the master sends one command to all workers and waits once (`WorkerPool`);
with Gauss-Seidel links (a source that must finish the macro step before its consumer
starts it) the step runs in dependency levels, one synchronisation per level.

A worker that crashes, hangs past the step timeout or raises ends the run with a
`SimulationError` naming the component, the simulation time and the cause; the driver then
writes the rows of the completed macro steps.  Times are in seconds.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from functools import partial

import numpy as np

from master.backends.component import (
    ComponentRunner,
    SimulationError,
    history_capacity,
    open_fmu,
    output_names,
)
from master.backends.shm import SharedArrays
from master.backends.worker import NOP, WorkerFailure, WorkerPool, cpu_count
from master.coupling import History
from master.fmu import FmuError, read_description, variables_of
from master.recorder import Recorder
from master.schedule import Plan

# worker commands (see _GroupTask.command and _TrialTask.command)
OP_SWEEP, OP_EXIT_INIT, OP_STEP, OP_SAVE, OP_SNAPSHOT, OP_RELAXED, OP_FREE, OP_RECORD, OP_TRIAL = range(1, 10)

DEFAULT_STEP_TIMEOUT = 10.0  # s: a macro step taking longer than this is a hang


def worker_groups(plan: Plan) -> list[list[str]]:
    """Component names per worker, in stepping order: one worker per scenario group or lone component."""
    groups: dict[str, list[str]] = {}
    for pc in plan.components:
        g = plan.scenario.component(pc.name).group
        groups.setdefault(f"group:{g}" if g else f"component:{pc.name}", []).append(pc.name)
    return list(groups.values())


def levels(plan: Plan) -> dict[str, int]:
    """Dependency level of each component: 0, or one more than any source it must wait for."""
    out: dict[str, int] = {}
    for pc in plan.components:  # stepping order: sources that go first come first
        out[pc.name] = max(
            (out[lk.source] + 1 for lk in plan.links_into(pc.name) if lk.source_first), default=0
        )
    return out


class _GroupTask:
    """The components of one worker: built in the worker process by `WorkerPool`."""

    def __init__(
        self, plan: Plan, names: list[str], outs: dict[str, list[str]], data: SharedArrays, tmp: str
    ):
        self.plan = plan
        self.components = names
        self.outs = outs
        self.data = data
        self.tmp = tmp
        self.runners: list[ComponentRunner] = []
        self.histories: dict[str, History] = {}
        self.level = levels(plan)
        self.index = {pc.name: i for i, pc in enumerate(plan.components)}
        self.saved: dict[str, object] = {}  # start-up: FMU states by component
        self.previous: dict[str, History] = {}  # start-up: histories of the previous sweep

    def setup(self, where: np.ndarray) -> None:
        tempfile.tempdir = self.tmp  # extracted FMUs go where the master cleans up, even after a crash
        sc = self.plan.scenario
        for name in (pc.name for pc in self.plan.components):
            h = self.data[f"hist:{name}"]
            self.histories[name] = History(h.shape[1], h.shape[0], h)
        for i, name in enumerate(self.components):
            where[0] = i
            fmu = open_fmu(sc, sc.component(name))
            try:
                pc = self.plan.component(name)
                r = ComponentRunner(self.plan, pc, fmu, self.outs, self.histories[name])
            except BaseException:
                fmu.close()
                raise
            self.runners.append(r)

    def command(self, op: int, a: int, b: int, where: np.ndarray) -> None:
        """Run one command for the components of this worker, in stepping order.

        OP_SWEEP a: initial sweep of component a (plan index).  OP_EXIT_INIT: leave
        initialisation mode.  OP_STEP a b: macro step a for the components of
        level b, recording if due.  Start-up (as SerialBackend.step): OP_SAVE a saves FMU
        states, OP_SNAPSHOT copies every history, OP_RELAXED a repeats macro step a from the
        saved states on that copy, OP_FREE a frees the states, OP_RECORD a records.
        """
        steps, fmu_time, rec = self.data["steps"], self.data["fmu_time"], self.data["rec"]
        if op == OP_SNAPSHOT:
            self.previous = {name: h.copy() for name, h in self.histories.items()}
            return
        for i, r in enumerate(self.runners):
            k = self.index[r.name]
            if op == OP_SWEEP and k != a or op == OP_STEP and self.level[r.name] != b:
                continue
            where[0] = i
            if op == OP_SWEEP:
                r.initial_sweep(self.histories)
            elif op == OP_EXIT_INIT:
                r.exit_initialization()
            elif op == OP_STEP:
                r.macro_step(a, self.histories)
                if a >= self.plan.startup_steps and self.plan.record_due(a):
                    r.record(a, rec)
            elif op == OP_SAVE:
                self.saved[r.name] = r.fmu_call(a, r.fmu.get_state)
            elif op == OP_RELAXED:
                r.fmu_call(a, r.fmu.set_state, self.saved[r.name])
                r.macro_step(a, self.previous, relaxed=True)
            elif op == OP_FREE:
                r.fmu_call(a, r.fmu.free_state, self.saved.pop(r.name))
            elif op == OP_RECORD:
                r.record(a, rec)
            steps[k] = r.steps
            fmu_time[k] = r.fmu_time

    def close(self) -> None:
        for r in self.runners:
            r.fmu.close()


class ParallelBackend:
    """Executes a Plan with one worker process per component or group (see the module docstring).

    Use like the serial backend: `open()`, `initialize()`, `step(n)` ..., `close()`.
    start_method: "fork" (default; fastest start), "forkserver" or "spawn".
    """

    name = "parallel"

    def __init__(self, plan: Plan, step_timeout: float = DEFAULT_STEP_TIMEOUT, start_method: str = "fork"):
        self.plan = plan
        self.step_timeout = step_timeout
        self.start_method = start_method
        self.groups = worker_groups(plan)
        self.worker_of = {name: w for w, names in enumerate(self.groups) for name in names}
        self.level = levels(plan)
        self.n_levels = 1 + max(self.level.values(), default=0)
        self.data: SharedArrays | None = None
        self.pool: WorkerPool | None = None
        self.tmp: str | None = None
        self.pacer: Pacer | None = None
        self.position = 0  # the next macro step to run (after a failure: the one that failed)

    def _layout(self) -> tuple[dict, dict[str, list[str]]]:
        sc = self.plan.scenario
        outs: dict[str, list[str]] = {}
        layout: dict = {}
        for pc in self.plan.components:
            variables = variables_of(read_description(sc.component(pc.name).fmu_path))
            outs[pc.name] = output_names(self.plan, pc.name, variables)
        for pc in self.plan.components:
            cap = history_capacity(self.plan, pc.name)
            layout[f"hist:{pc.name}"] = ((cap, len(outs[pc.name])), "float64")
        n = len(self.plan.components)
        layout["rec"] = ((1 + len(self.plan.record),), "float64")
        layout["steps"] = ((n,), "int64")
        layout["fmu_time"] = ((n,), "float64")
        return layout, outs

    def open(self) -> None:
        """Start the workers; each loads, instantiates and parameterises its FMUs."""
        layout, outs = self._layout()
        self.tmp = tempfile.mkdtemp(prefix="master-parallel-")
        self.data = SharedArrays(layout)
        tasks = [
            (names, partial(_GroupTask, self.plan, names, outs, self.data, self.tmp)) for names in self.groups
        ]
        try:
            self.pool = WorkerPool(tasks, start_method=self.start_method, step_timeout=self.step_timeout)
        except WorkerFailure as e:  # loading is not simulating: the serial backend raises FmuError here
            raise FmuError(
                e.cause if e.raised else f"component {e.component}: {e.cause} while loading"
            ) from None

    def initialize(self, recorder: Recorder) -> None:
        """The serial backend's initialisation, component by component across the workers; records
        the row at the start time."""
        assert self.pool is not None
        t0 = float(self.plan.scenario.start_time)
        try:
            self._sweeps()
            self.pool.run(OP_EXIT_INIT)
            self._sweeps()  # as SerialBackend: sweeps in and after initialisation mode
            self.pool.run(OP_RECORD, -1)
        except WorkerFailure as e:
            raise self._error(e, t0, "during initialisation") from None
        self._record(-1, recorder)

    def pace(self, factor: float) -> None:
        """Pace the following macro steps to the wall clock: simulated time runs `factor` times as fast."""
        self.pacer = Pacer(factor, float(self.plan.scenario.macro_step))

    def pacing(self) -> dict | None:
        """Real-time statistics as SerialBackend.pacing gives them, None when unpaced."""
        return self.pacer.stats() if self.pacer is not None else None

    def run(self, n_from: int, n_to: int, recorder: Recorder, budget: float = 0.0) -> int:
        """Step macro steps n_from .. n_to - 1, for at most about `budget` s of wall time (0: no limit);
        rows go to `recorder`. Returns the next macro step."""
        end = time.perf_counter() + budget if budget > 0 else float("inf")
        n = n_from
        while n < n_to:
            self.position = n
            self.step(n)
            if self.plan.record_due(n):
                self._record(n, recorder)
            n += 1
            self.position = n
            if self.pacer is not None:
                self.pacer.wait(n)
            if time.perf_counter() > end:
                break
        return n

    def _record(self, n: int, recorder: Recorder) -> None:
        assert self.data is not None
        row = recorder.next_row()
        row[0] = self.plan.macro_clock.time(n + 1)
        row[1:] = self.data["rec"][1:]
        recorder.commit()

    def _sweeps(self) -> None:
        """One initial sweep per component, in stepping order, each in its own worker."""
        assert self.pool is not None
        for _ in range(len(self.plan.components)):
            for k, pc in enumerate(self.plan.components):
                self.pool.run(OP_SWEEP, k, 0, [self.worker_of[pc.name]])

    def step(self, n: int) -> None:
        """Advance every component through macro step n (one synchronisation per dependency level).

        Start-up steps are repeated from saved FMU states exactly as SerialBackend.step does.
        """
        assert self.pool is not None
        run = self.pool.run
        try:
            if n < self.plan.startup_steps:
                run(OP_SAVE, n)
            for lv in range(self.n_levels):
                run(OP_STEP, n, lv)
            if n < self.plan.startup_steps:
                for _ in range(self.plan.startup_sweeps):
                    run(OP_SNAPSHOT)
                    run(OP_RELAXED, n)
                run(OP_FREE, n)
                if self.plan.record_due(n):
                    run(OP_RECORD, n)
        except WorkerFailure as e:
            raise self._error(e, self.plan.macro_clock.time(n), self._span(n)) from None

    def _span(self, n: int) -> str:
        clock = self.plan.macro_clock
        return f"in the macro step from t={clock.time(n)} to t={clock.time(n + 1)}"

    def _error(self, e: WorkerFailure, t: float, when: str) -> SimulationError:
        """A SimulationError from a worker failure; the worker's own message if it raised one."""
        comp = e.component or "?"
        if e.raised:  # the component code raised: keep its words (and its time, if it said)
            return SimulationError(e.cause, comp, t if e.time is None else e.time)
        return SimulationError(f"component {comp}: {e.cause} {when}", comp, t)

    def stats(self) -> tuple[dict[str, int], dict[str, float]]:
        """(communication steps, wall time inside FMI calls in s) per component."""
        names = [pc.name for pc in self.plan.components]
        if self.data is None or not self.data.arrays:
            return {n: 0 for n in names}, {n: 0.0 for n in names}
        steps, ft = self.data["steps"], self.data["fmu_time"]
        return {n: int(steps[i]) for i, n in enumerate(names)}, {n: float(ft[i]) for i, n in enumerate(names)}

    def close(self) -> None:
        """Stop the workers (killing any that do not stop), free shared memory and temporary files."""
        try:
            if self.pool is not None:
                self.pool.close()
        finally:
            self.pool = None
            if self.data is not None:
                self.data.unlink()
            if self.tmp is not None:
                shutil.rmtree(self.tmp, ignore_errors=True)
                self.tmp = None


class Pacer:
    """Paces macro steps to the wall clock: simulated time t is due at wall t0 + t / factor."""

    def __init__(self, factor: float, macro_step: float):
        if factor <= 0:
            raise ValueError(f"real-time factor must be positive, got {factor}")
        self.factor = factor
        self.macro_step = macro_step
        self.t0 = time.perf_counter()
        self.late: list[float] = []  # s, per frame
        self.overruns = 0
        self.idle = 0.0  # s spent waiting for the wall clock

    def wait(self, n_done: int) -> None:
        """After n_done macro steps: sleep until they are due, or count an overrun."""
        due = self.t0 + n_done * self.macro_step / self.factor
        now = time.perf_counter()
        if now > due:
            self.overruns += 1
            self.late.append(now - due)
            return
        if due - now > 2e-3:
            time.sleep(due - now - 1e-3)  # sleep coarse, then spin the last millisecond for accuracy
        while (t := time.perf_counter()) < due:
            pass
        self.idle += t - now
        self.late.append(t - due)

    def stats(self) -> dict[str, float]:
        late = np.array(self.late or [0.0])
        q = np.quantile(late, [0.5, 0.99, 0.999])
        return {
            "frames": len(self.late),
            "overruns": self.overruns,
            "p50": float(q[0]),
            "p99": float(q[1]),
            "p99.9": float(q[2]),
            "worst": float(late.max()),
            "idle": self.idle,
        }


# -- automatic choice -------------------------------------------------------------------------

TRIAL_STEPS = 50  # macro steps timed at most in the serial trial
TRIAL_BUDGET = 0.1  # s: wall time the trial may spend stepping
SYNC_ROUNDS = 200  # empty round trips timed to measure the synchronisation cost
MARGIN = 1.2  # parallel must be predicted this much faster per step to be chosen


class _TrialTask:
    """Times the serial backend on the first macro steps, in a worker so that a crash stays there."""

    def __init__(self, plan: Plan, out: SharedArrays, tmp: str):
        self.plan = plan
        self.out = out
        self.tmp = tmp
        self.components = [pc.name for pc in plan.components]

    def setup(self, where: np.ndarray) -> None:
        tempfile.tempdir = self.tmp

    def command(self, op: int, a: int, b: int, where: np.ndarray) -> None:
        """OP_TRIAL: out = [open time, steps timed, wall of those steps, FMU time per component...]."""
        from master.backends.in_process import InProcessBackend as SerialBackend

        res = self.out["trial"]
        be = SerialBackend(self.plan)
        rec = Recorder(["time"] + [f"{c}.{v}" for c, v in self.plan.record])
        try:
            t0 = time.perf_counter()
            be.open()
            be.initialize(rec)
            res[0] = time.perf_counter() - t0
            n0 = min(self.plan.startup_steps, self.plan.n_macro)  # start-up steps repeat work: not typical
            be.run(0, n0, rec)
            ft0 = be.stats()[1]
            t0 = time.perf_counter()
            n = be.run(n0, min(n0 + TRIAL_STEPS, self.plan.n_macro), rec, TRIAL_BUDGET)
            res[2] = time.perf_counter() - t0
            res[1] = n - n0
            ft = be.stats()[1]
            for i, name in enumerate(self.components):
                res[3 + i] = ft[name] - ft0[name]
        finally:
            be.close()
            rec.discard()

    def close(self) -> None:
        pass


def predict_parallel(plan: Plan, cost: dict[str, float], sync: float, cpus: int) -> float:
    """Predicted wall time per macro step (s) of the parallel backend.

    cost: serial wall time per macro step attributable to each component (s).  Per dependency
    level the slowest worker sets the pace, unless the workers outnumber the processors.
    """
    lv = levels(plan)
    total = 0.0
    for level in range(1 + max(lv.values(), default=0)):
        loads = [sum(cost[n] for n in names if lv[n] == level) for names in worker_groups(plan)]
        total += max(max(loads), sum(loads) / cpus) + sync
    return total


def choose_backend(plan: Plan, step_timeout: float = DEFAULT_STEP_TIMEOUT) -> tuple[str, str]:
    """("serial" or "parallel", why): measured serial cost per macro step vs predicted parallel cost.

    The serial trial runs in a worker, so a crash or a hang (past `step_timeout` s) stays there.
    """
    groups = worker_groups(plan)
    cpus = cpu_count()
    if len(groups) < 2:
        return "serial", "one worker would run everything: nothing to overlap"
    if cpus < 2:
        return "serial", "one processor"
    n = len(plan.components)
    out = SharedArrays({"trial": ((3 + n,), "float64")})
    tmp = tempfile.mkdtemp(prefix="master-trial-")
    idle = _IdleTask
    try:
        t0 = time.perf_counter()
        pool = WorkerPool(
            [(["trial"], partial(_TrialTask, plan, out, tmp))] + [(["idle"], idle)] * (len(groups) - 1),
            step_timeout=step_timeout,
        )
        start = time.perf_counter() - t0
        try:
            try:
                pool.run(OP_TRIAL, workers=[0])
            except WorkerFailure as e:
                return "parallel", f"the serial trial failed ({e.cause}): workers keep a failure isolated"
            t0 = time.perf_counter()
            for _ in range(SYNC_ROUNDS):
                pool.run(NOP)
            sync = (time.perf_counter() - t0) / SYNC_ROUNDS
        finally:
            pool.close()
        res = out["trial"].copy()
    finally:
        out.unlink()
        shutil.rmtree(tmp, ignore_errors=True)
    opened, steps, wall = res[0], int(res[1]), res[2]
    if steps == 0:
        return "serial", "no macro step to time"
    serial = wall / steps
    fmu = {pc.name: res[3 + i] / steps for i, pc in enumerate(plan.components)}
    # master work outside the FMUs, shared out per communication step
    glue = max(serial - sum(fmu.values()), 0.0) / sum(pc.ratio for pc in plan.components)
    cost = {pc.name: fmu[pc.name] + glue * pc.ratio for pc in plan.components}
    parallel = predict_parallel(plan, cost, sync, cpus)
    remaining = plan.n_macro - plan.startup_steps
    gain = remaining * (serial - parallel) - start - opened / 2
    facts = (
        f"serial {serial * 1e6:.0f} us/step measured, parallel {parallel * 1e6:.0f} us/step predicted "
        f"(sync {sync * 1e6:.0f} us, {len(groups)} workers on {cpus} CPUs)"
    )
    if parallel * MARGIN < serial and gain > 0:
        return "parallel", facts
    return "serial", facts


class _IdleTask:
    """A worker that only answers (for timing the synchronisation)."""

    components = ("idle",)

    def setup(self, where: np.ndarray) -> None:
        pass

    def command(self, op: int, a: int, b: int, where: np.ndarray) -> None:
        pass

    def close(self) -> None:
        pass
