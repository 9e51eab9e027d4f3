"""Warm runs: one worker process keeps a scene's FMUs loaded and runs case after case.

Run by `master.run`, every case of a sweep starts a worker process, extracts and loads each FMU
and compiles the kernel tables: about 25 ms for the oscillator, against 1 ms of stepping. A
`Session` is the serial backend kept open: for each later case its worker renews the FMUs
(`Fmu.renew`: fmi2Reset, fmi3Reset or fmiResetSlave; a new instance of the loaded binary where
that fails), sets the case's parameters and start values, enters initialisation and restores the
kernel tables as they were compiled (recompiles them where an instance is new or the stimuli
differ); the run then goes as any serial run: the same kernel, supervision and rows, bit for bit.

What a session may serve is `structure`: one rule for what cases of one session may differ in.
A case that fails ends the session (the next case starts a fresh one); a worker that cannot renew
its FMUs ends it too, and that case runs afresh through `master.run`.

`warm_run` keeps one session per process (a Dask worker's), closed when the structure changes and
at exit; its worker dies with the process in any case (PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import atexit
import ctypes as C
import dataclasses
import hashlib
import multiprocessing as mp
import pickle
import threading
import time
from functools import partial
from pathlib import Path

import numpy as np

from master.backends.component import SimulationError
from master.backends.driver import execute
from master.backends.in_process import initialize_sweeps
from master.backends.worker import WorkerFailure
from master.backends.workers import (
    DEFAULT_STEP_TIMEOUT,
    OP_EXIT_INIT,
    OP_FINISH_INIT,
    OP_SWEEP,
    WorkerBackend,
    _Task,
    arm,
    separate,
)
from master.recorder import Recorder, RunResult
from master.runtime.tables import CompiledPlan
from master.scenario.model import Scenario
from master.schedule import Plan

# worker commands beside workers.OP_*: renew the FMUs for the plan that follows; initialise (the
# serial sequence of OP_SWEEP, OP_EXIT_INIT, OP_FINISH_INIT, in the worker: one round trip, not 2 n^2 + 2)
OP_RENEW, OP_INIT = 100, 101


class Stale(Exception):
    """The session's worker could not make its FMUs fresh for the next case."""


def structure(sc: Scenario, step_timeout: float | None = None) -> bytes:
    """What a session depends on: the scenario without its components' parameter values and its
    stimuli's values (both set anew for every case), the FMU files as they are now, the step
    timeout. Cases with equal keys may share a session; a step ratio, a macro step, a solver
    setting, a recorded variable ... each make another key."""
    bare = dataclasses.replace(
        sc,
        components=tuple(dataclasses.replace(c, parameters={}) for c in sc.components),
        stimuli=tuple(dataclasses.replace(s, values=()) for s in sc.stimuli),
    )
    files = []
    for c in sc.components:
        st = Path(c.fmu_path).stat()
        files.append((str(c.fmu_path), st.st_mtime_ns, st.st_size))
    return hashlib.sha256(pickle.dumps((bare, files, step_timeout))).digest()


def reusable(plan: Plan) -> bool:
    """Whether a session can run the plan: one worker holds every component (not so where an FMU
    may be instantiated only once per process and appears twice)."""
    return len(separate([[pc.name for pc in plan.components]], plan)) == 1


class Session:
    """The serial backend of one structure kept open: `run(plan)` for each case, `close()`."""

    def __init__(self, plan: Plan, step_timeout: float | None = None):
        self.backend = _WarmBackend(plan, step_timeout or DEFAULT_STEP_TIMEOUT)
        self.runs = 0

    def run(self, plan: Plan) -> RunResult:
        """Run one case's plan (of the session's structure) as `master.run` does with the serial
        backend: its result, or its SimulationError carrying `.result`. Raises Stale where the
        worker could not renew its FMUs, the errors of loading them for the first case; after any
        of these, and after a failed run, the session must be closed."""
        be = self.backend
        recorder = Recorder(plan.columns, None, types=plan.column_types, in_memory=True)
        try:
            if self.runs == 0:
                be.open()
            else:
                be.renew(plan)
            self.runs += 1
            summary = execute(plan, be, recorder)
        except SimulationError as e:
            e.result = RunResult(recorder, e.summary)  # type: ignore[attr-defined]
            raise
        except BaseException:
            recorder.discard()
            raise
        return RunResult(recorder, summary)

    @property
    def pid(self) -> int | None:
        """The process id of its worker (None before the first case)."""
        pool = self.backend.pool
        return pool.procs[0].pid if pool is not None else None

    def close(self) -> None:
        self.backend.close()


class _WarmBackend(WorkerBackend):
    """The serial WorkerBackend whose worker (a `_WarmTask`) takes further plans."""

    def __init__(self, plan: Plan, step_timeout: float):
        super().__init__(plan, [[pc.name for pc in plan.components]], step_timeout, None, "serial")
        reader, self.cases = mp.get_context("fork").Pipe(duplex=False)
        self.task = partial(_WarmTask, reader)
        self.poll = False  # a sweep runs a session per processor: a poller would take its partner's

    def initialize(self, recorder: Recorder) -> None:
        """As WorkerBackend.initialize, in one command to the worker."""
        assert self.pool is not None and self.janitor is not None
        if recorder.tmpdir is not None:
            self.janitor.watch(recorder.tmpdir)
        try:
            self.pool.run(OP_INIT)
        except WorkerFailure as e:
            raise self._error(e, float(self.plan.scenario.start_time), "during initialisation") from None
        self._drain(recorder)

    def renew(self, plan: Plan) -> None:
        """Make the worker and the run memory as a fresh `open` of `plan` leaves them."""
        assert self.pool is not None and self.memory is not None
        self.plan = plan
        np.frombuffer(self.memory.buffer, dtype=np.uint8)[:] = 0
        arm(self.memory)
        self.position = self.drained = 0
        self.running, self.recorder = False, None
        self._rate = (time.perf_counter(), 0)
        # pickled before the command (the worker waits no longer than it must), sent after it (a
        # large plan fills the pipe until the worker reads)
        data = pickle.dumps(plan)
        try:
            self.pool.start(OP_RENEW)
            self.cases.send_bytes(data)
            self.pool.wait(timeout=self.pool.setup_timeout)
        except (WorkerFailure, OSError) as e:
            raise Stale(str(e)) from None


class _WarmTask(_Task):
    """A serial worker's task that, on OP_RENEW, takes the next case's plan from `cases`."""

    def __init__(self, cases, *args):
        super().__init__(*args)
        self.cases = cases
        self.pristine: _Pristine | None = None

    def setup(self, where: np.ndarray) -> None:
        super().setup(where)
        self.pristine = _Pristine(self.cp)

    def command(self, op: int, a: int, b: int, where: np.ndarray) -> None:
        if op == OP_INIT:
            assert self.cp is not None
            initialize_sweeps(
                len(self.cp.names),
                lambda i: super(_WarmTask, self).command(OP_SWEEP, i, 0, where),
                lambda: super(_WarmTask, self).command(OP_EXIT_INIT, 0, 0, where),
            )
            return super().command(OP_FINISH_INIT, 0, 0, where)
        if op != OP_RENEW:
            return super().command(op, a, b, where)
        plan: Plan = pickle.loads(self.cases.recv_bytes())
        sc = plan.scenario
        renewed = False
        for i, name in enumerate(self.components):  # as component.open_fmu, with a renewed instance
            where[0] = i
            fmu = self.fmus[name]
            renewed |= fmu.renew()
            fmu.set_values(dict(sc.component(name).parameters))
            fmu.enter_initialization(float(sc.start_time), float(sc.stop_time))
        compiled, self.plan = self.plan, plan
        if renewed or plan.stimuli != compiled.stimuli:  # new instance handles or stimulus tables
            self.cp = CompiledPlan(
                plan, self.fmus, self.outs, self.memory, self.worker, self.n_workers, self.spin
            )
            self.pristine = _Pristine(self.cp)
            return
        assert self.cp is not None and self.pristine is not None
        self.pristine.restore()
        self.cp.plan, self.cp.position = plan, 0


class _Pristine:
    """The kernel tables of a CompiledPlan as compiled, restored before each later run: the kernel
    keeps its run state in them (positions, input polynomials, loop memory, event times)."""

    def __init__(self, cp: CompiledPlan):
        parts = [*cp._keep, cp.components, cp.kernel]
        if cp.kernel.shared:
            parts.append(cp.kernel.shared.contents)
        self.saved = []
        for p in parts:
            if isinstance(p, np.ndarray):
                address, size = p.ctypes.data, p.nbytes
            else:
                address, size = C.addressof(p), C.sizeof(p)
            self.saved.append((address, C.string_at(address, size), p))  # p: keeps the address valid

    def restore(self) -> None:
        for address, data, _ in self.saved:
            C.memmove(address, data, len(data))


_warm: dict[bytes, Session] = {}  # at most one: this process's session, by its structure
_plans: dict[tuple, Plan] = {}  # at most one: the last plan, by its structure and stimuli
_lock = threading.Lock()


def warm_run(sc: Scenario, backend: str = "serial", step_timeout: float | None = None) -> RunResult:
    """`master.run(sc, backend=backend, step_timeout=step_timeout)`, the same result or error; with
    the serial backend in this process's session for the scene's structure (opened, or replacing
    the one of another structure, as needed)."""
    from master import api

    if backend != "serial" or not _lock.acquire(blocking=False):  # busy: another thread's case
        return api.run(sc, backend=backend, step_timeout=step_timeout)
    try:
        try:
            key = structure(sc, step_timeout)
        except OSError:  # an FMU file gone: the run says so as it does
            return api.run(sc, step_timeout=step_timeout)
        plan = _plan(sc, key)
        if not reusable(plan):
            return api.run(sc, step_timeout=step_timeout)
        session = _warm.get(key)
        if session is None:
            close_warm()
            session = _warm[key] = Session(plan, step_timeout)
        try:
            return session.run(plan)
        except Stale:  # this case as a fresh run gives it, in a process of its own
            close_warm()
            return api.run(sc, step_timeout=step_timeout)
        except BaseException:
            close_warm()
            raise
    finally:
        _lock.release()


def _plan(sc: Scenario, key: bytes) -> Plan:
    """`master.api.plan(sc)`; for a scene that differs from the last one only in its parameter
    values, that one's plan with `sc` as its scenario: neither the checks nor the planner read
    parameter values (the FMUs get them from plan.scenario)."""
    from master import api

    last = _plans.get((key, sc.stimuli))
    if last is not None:
        return dataclasses.replace(last, scenario=sc)
    plan = api.plan(sc)
    _plans.clear()
    _plans[(key, sc.stimuli)] = plan
    return plan


def close_warm() -> None:
    """Close this process's session, if any."""
    while _warm:
        _warm.popitem()[1].close()


atexit.register(close_warm)
