"""Worker processes: start, commands, isolation.

Each worker runs a `Task` (one or more components) in its own forked process. The master writes a
command (op, a, b) into shared memory and releases each worker's `go` semaphore; each worker runs
it and releases its `done` semaphore. Commands are few: loading, the initial sweeps, and one command
for the whole run (master.backends.workers), during which the workers synchronise with each
other in the kernel and the master only supervises (`wait` with a `supervise` callback). A
waiting process first polls its semaphore for up to SPIN_S (yielding the processor between
polls), then sleeps.

Isolation: a worker that dies (segfault, abort), overruns the step timeout (hang) or reports
an exception (e.g. an FMU returning fmi2Error) makes `WorkerPool.wait` raise `WorkerFailure`
naming the component and the cause.  `close()` always leaves no process
behind: workers get SIGKILL if they do not stop in time, and they die with the master
(PR_SET_PDEATHSIG) should the master itself be killed.
"""

from __future__ import annotations

import ctypes
import multiprocessing as mp
import os
import signal
import time
import traceback
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from master.runtime.tables import Memory

STOP = -1  # op: leave the loop
MSG_BYTES = 2048  # room for one error message per worker
SPIN_S = 100e-6  # s: how long a waiting process polls before it sleeps (see WorkerPool)
POLL_S = 0.02  # s: how often a waiting master checks that the workers are alive
KILL_WAIT_S = 1.0  # s at most for a SIGKILLed worker to be reaped (it takes milliseconds)

IDLE, RUNNING, FAILED, CLOSED = 0, 1, 2, 3  # worker states in shared memory (CLOSED: task freed at STOP)


class Task(Protocol):
    """What a worker runs: built in the worker process, then stepped once per macro step."""

    def setup(self, where: np.ndarray) -> None:
        """Instantiate; store the index of the component being worked on in where[0]."""

    def command(self, op: int, a: int, b: int, where: np.ndarray) -> None:
        """Run command `op` with arguments a, b (e.g. a macro step); keep where[0] up to date."""

    def close(self) -> None:
        """Free what setup() made."""


class WorkerFailure(RuntimeError):
    """A worker failed: `component` (name or None), `cause`; `time` (s) if the failing code said.

    raised: the task raised an exception whose message is `cause` (else: crash or hang);
    variable: the variable it named, if any; worker: the index of the failed worker, if known.
    """

    def __init__(
        self,
        component: str | None,
        cause: str,
        time: float | None = None,
        raised: bool = False,
        variable: str | None = None,
        worker: int | None = None,
    ):
        self.component = component
        self.worker = worker
        self.cause = cause
        self.time = time
        self.raised = raised
        self.variable = variable
        where = f"component '{component}'" if component else "a worker"
        super().__init__(f"{where}: {cause}")


def _die_with_parent(parent: int | None) -> None:
    """Ask Linux to SIGKILL this process when its parent (pid `parent`, if known) dies."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        pass  # not Linux: the master's close() still ends the workers
    if parent is not None and os.getppid() != parent:  # it died before prctl took effect
        os._exit(1)


def _worker_main(
    index: int,
    factory: Callable[[], Task],
    control: Memory,
    go,
    done,
    parent: int | None,
    spin: float,
) -> None:
    """Body of worker `index`: build the task, then step on command until STOP."""
    _die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the master's to handle
    try:
        import faulthandler

        faulthandler.disable()  # a crash is reported by the master, not as a traceback dump
    except ImportError:
        pass
    state = control["state"][index : index + 1]
    where = control["where"][index : index + 1]
    msg = control["msg"][index]
    cmd = control["cmd"]
    err_time = control["err_time"][index : index + 1]
    task = None
    try:
        state[0] = RUNNING
        task = factory()
        task.setup(where)
        state[0] = IDLE
        done.release()
        while True:
            _spin_acquire(go, spin)
            op, a, b = cmd.tolist()
            if op == STOP:
                break
            state[0] = RUNNING
            task.command(op, a, b, where)
            state[0] = IDLE
            done.release()
        task, closing = None, task
        _close(closing)
        state[0] = CLOSED  # no more FMU calls: the master may remove the task's files while this process ends
        done.release()
    except BaseException as e:  # report, then end: the master decides what happens next
        text = str(e) if str(e) else "".join(traceback.format_exception_only(e)).strip()
        variable = getattr(e, "variable", None)
        raw = f"{variable or ''}\0{text}".encode("utf-8", "replace")[: MSG_BYTES - 1]
        msg[: len(raw)] = np.frombuffer(raw, dtype=np.uint8)
        msg[len(raw)] = 0
        t = getattr(e, "time", None)
        err_time[0] = float(t) if isinstance(t, (int, float)) else np.nan
        state[0] = FAILED
        done.release()
    finally:
        if task is not None:
            _close(task)


def _close(task: Task) -> None:
    try:
        task.close()
    except Exception:
        pass  # the process ends: what it held goes with it


def _spin_acquire(sem, spin: float) -> None:
    """Acquire `sem`, polling it for up to `spin` s (yielding the CPU) before blocking."""
    if spin > 0:
        end = time.perf_counter() + spin
        while not sem.acquire(False):
            if time.perf_counter() > end:
                break
            os.sched_yield()
        else:
            return
    sem.acquire()


def cpu_count() -> int:
    """Processors this process may run on (its affinity mask, where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _signal_name(exitcode: int) -> str:
    if exitcode < 0:
        try:
            return f"killed by signal {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exited with code {exitcode}"


class WorkerPool:
    """Worker processes, each running one task on the master's commands.

    tasks: (component names, factory) per worker; the factory runs in the worker process.
    Workers are forked, so that they inherit anonymous shared memory (no name in /dev/shm to
    leave behind). Times are in seconds: `step_timeout` bounds each command unless a supervisor
    watches it (see `run`), `setup_timeout` the start-up. poll: whether a waiting process polls
    before it sleeps (False for pools beside others on the same processors: a sweep's, where a
    poller takes the processor its partner needs).
    """

    def __init__(
        self,
        tasks: Sequence[tuple[Sequence[str], Callable[[], Task]]],
        step_timeout: float = 10.0,
        setup_timeout: float = 60.0,
        poll: bool = True,
    ):
        self.names = [list(names) for names, _ in tasks]
        self.step_timeout = step_timeout
        self.setup_timeout = setup_timeout
        self.poll = poll
        ctx = mp.get_context("fork")
        w = len(tasks)
        self.control = Memory(
            {
                "cmd": ((3,), "int64"),
                "err_time": ((w,), "float64"),
                "state": ((w,), "int64"),
                "where": ((w,), "int64"),
                "msg": ((w, MSG_BYTES), "uint8"),
            },
            shared=True,
        )
        self.go = [ctx.Semaphore(0) for _ in range(w)]
        self.done = [ctx.Semaphore(0) for _ in range(w)]
        self.procs: list = []
        self.closed = False
        self.last_wait = 0.0  # s: how long the master waited for the previous command
        self.pending: list[int] = []  # workers yet to answer the last command
        self.started = 0.0  # time.monotonic() at which the last command was sent
        try:
            parent = os.getpid()
            spin = SPIN_S if poll and w <= cpu_count() else 0.0  # pollers must not take workers' processors
            for i, (_, factory) in enumerate(tasks):
                p = ctx.Process(
                    target=_worker_main,
                    args=(i, factory, self.control, self.go[i], self.done[i], parent, spin),
                    name=f"master-worker-{'+'.join(self.names[i])}",
                    daemon=True,
                )
                p.start()
                self.procs.append(p)
            self.pending, self.started = list(range(w)), time.monotonic()
            self.wait(timeout=self.setup_timeout)
        except BaseException:
            self.close()
            raise

    def run(self, op: int, a: int = 0, b: int = 0, workers: Sequence[int] | None = None) -> None:
        """Run command (op, a, b) in `workers` (default: all) and wait until each has finished."""
        self.start(op, a, b, workers)
        self.wait()

    def start(self, op: int, a: int = 0, b: int = 0, workers: Sequence[int] | None = None) -> None:
        """Send command (op, a, b) to `workers` (default: all); `wait` collects their answers."""
        if self.closed:
            raise RuntimeError("worker pool is closed")
        cmd = self.control["cmd"]
        cmd[0], cmd[1], cmd[2] = op, a, b
        self.pending = list(range(len(self.procs)) if workers is None else workers)
        self.started = time.monotonic()
        for i in self.pending:
            self.go[i].release()

    def wait(
        self, supervise: Callable[[], float] | None = None, budget: float = 0.0, timeout: float | None = None
    ) -> bool:
        """Collect the answers to the last command; True once every worker has answered.

        Raises WorkerFailure on a crash, an error or a hang. Without `supervise`, a command taking
        longer than the step timeout is a hang; with it, `supervise()` is called between polls
        instead (it may raise, e.g. for a hang it detects, and returns the seconds until it wants
        to be called again). budget > 0: return False after about that many seconds. timeout:
        instead of the step timeout.
        After a short previous wait the master polls first (waking a sleeping process costs tens
        of microseconds); after a long one it sleeps at once, leaving the processors to the workers.
        """
        t0 = time.perf_counter()
        end = t0 + budget if budget > 0 else float("inf")
        spin = SPIN_S if self.poll and self.last_wait < SPIN_S else 0.0
        timeout = self.step_timeout if timeout is None else timeout
        deadline = self.started + timeout
        poll = min(POLL_S, timeout)
        while self.pending:
            i = self.pending[0]
            sem = self.done[i]
            got = False
            if spin:
                while not (got := sem.acquire(False)) and time.perf_counter() < t0 + spin:
                    os.sched_yield()
            while not got and not (got := sem.acquire(timeout=poll)):
                self._check_alive()
                if supervise is not None:
                    poll = supervise()
                elif time.monotonic() > deadline:
                    self.kill(i)
                    raise self._failure(
                        i, f"hang: no answer within the step timeout of {self.step_timeout:g} s"
                    )
                if time.perf_counter() > end:
                    break
            if not got:
                return False
            self.pending.pop(0)
            self._check(i)
        self.last_wait = time.perf_counter() - t0
        return True

    def settle(self, timeout: float) -> None:
        """After a failure: wait up to `timeout` s for the other workers to answer the last command
        (they stop by themselves once the failure's macro step is reached); what they answer is
        not reported."""
        deadline = time.monotonic() + timeout
        for i in self.pending:
            if self.control["state"][i] != FAILED and self.procs[i].exitcode is None:
                self.done[i].acquire(timeout=max(0.0, deadline - time.monotonic()))
        self.pending = []

    def kill(self, i: int) -> None:
        """SIGKILL worker i (a hung FMU never returns to read the stop command) and reap it, so that
        `settle` does not wait for its answer."""
        self.procs[i].kill()
        self.procs[i].join(KILL_WAIT_S)

    def _check_alive(self) -> None:
        for j, p in enumerate(self.procs):
            code = p.exitcode
            if code is not None:
                self._check(j)  # it may have reported an exception before ending
                raise self._failure(j, f"worker process {_signal_name(code)}")

    def _check(self, i: int) -> None:
        if self.control["state"][i] == FAILED:
            t = float(self.control["err_time"][i])
            variable, message = self._message(i)
            raise WorkerFailure(
                self._component(i), message, None if np.isnan(t) else t, True, variable or None
            )

    def _message(self, i: int) -> tuple[str, str]:
        """(variable or "", message) a failed worker reported."""
        variable, message = bytes(self.control["msg"][i]).split(b"\0")[:2]
        return variable.decode("utf-8", "replace"), message.decode("utf-8", "replace")

    def _component(self, i: int) -> str | None:
        names = self.names[i]
        k = int(self.control["where"][i])
        return names[k] if 0 <= k < len(names) else (names[0] if len(names) == 1 else None)

    def _failure(self, i: int, cause: str, t: float | None = None, raised: bool = False) -> WorkerFailure:
        return WorkerFailure(self._component(i), cause, t, raised, worker=i)

    def close(self, while_ending: Callable[[], None] | None = None) -> None:
        """Stop all workers (SIGKILL for those that do not stop within 2 s) and free shared memory.
        while_ending(): called once no task runs any more (each freed at STOP, or its process
        gone), while the processes end: removing the tasks' files then costs no extra time."""
        if self.closed:
            return
        self.closed = True
        self.control["cmd"][0] = STOP
        for g in self.go:
            g.release()
        deadline = time.monotonic() + 2.0
        state = self.control["state"]
        for i, p in enumerate(self.procs):  # a failed worker frees its task and ends by itself
            while state[i] not in (CLOSED, FAILED) and p.exitcode is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self.done[i].acquire(timeout=min(POLL_S, left))  # (an answer to an earlier command too)
        running = [p for i, p in enumerate(self.procs) if state[i] != CLOSED]
        self._end(running, deadline)
        if while_ending is not None:
            while_ending()
        self._end(self.procs, deadline)
        for p in self.procs:
            if p.exitcode is not None:
                p.close()

    @staticmethod
    def _end(procs: list, deadline: float) -> None:
        """Reap `procs`, SIGKILLing those still alive at the deadline."""
        for p in procs:
            p.join(max(0.0, deadline - time.monotonic()))
        for p in procs:
            if p.is_alive():
                p.kill()
                p.join(5.0)

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
