"""Worker processes of the parallel backend: start, one synchronisation per macro step, isolation.

Each worker runs a `Task` (one or more components) in its own process.  Per macro step the
master writes a command (op, a, b) into shared memory and releases each worker's `go`
semaphore; each worker runs it (steps its components, publishes its outputs into shared
arrays) and releases its `done` semaphore.  That pair of semaphores is the one
synchronisation point per step.  A waiting process first polls its semaphore for up to
SPIN_S (yielding the processor between polls), then sleeps: waking a sleeping process
costs tens of microseconds on the 2-core machine this was measured on, more than the
whole exchange otherwise (benchmarks/parallel.py times the alternatives).

Isolation: a worker that dies (segfault, abort), overruns the step timeout (hang) or reports
an exception (e.g. an FMU returning fmi2Error) makes `WorkerPool.run` raise `WorkerFailure`
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

from master.backends.shm import SharedArrays

STOP = -1  # op: leave the loop
NOP = 0  # op: do nothing (measures the synchronisation cost)
MSG_BYTES = 2048  # room for one error message per worker
SPIN_S = 100e-6  # s: how long a waiting process polls before it sleeps (see WorkerPool)
POLL_S = 0.02  # s: how often a waiting master checks that the workers are alive

IDLE, RUNNING, FAILED = 0, 1, 2  # worker states in shared memory


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

    raised: the task raised an exception whose message is `cause` (else: crash or hang).
    """

    def __init__(self, component: str | None, cause: str, time: float | None = None, raised: bool = False):
        self.component = component
        self.cause = cause
        self.time = time
        self.raised = raised
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
    control: SharedArrays,
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
            if op != NOP:
                task.command(op, a, b, where)
            state[0] = IDLE
            done.release()
    except BaseException as e:  # report, then end: the master decides what happens next
        text = str(e) if str(e) else "".join(traceback.format_exception_only(e)).strip()
        raw = text.encode("utf-8", "replace")[: MSG_BYTES - 1]
        msg[: len(raw)] = np.frombuffer(raw, dtype=np.uint8)
        msg[len(raw)] = 0
        t = getattr(e, "time", None)
        err_time[0] = float(t) if isinstance(t, (int, float)) else np.nan
        state[0] = FAILED
        done.release()
    finally:
        if task is not None:
            try:
                task.close()
            except Exception:
                pass


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
    """Worker processes, each running one task, stepped in lock-step by the master.

    tasks: (component names, factory) per worker; the factory runs in the worker process and
    must be picklable under the spawn/forkserver start methods.  Times are in seconds:
    `step_timeout` bounds each command, `setup_timeout` the start-up.
    """

    def __init__(
        self,
        tasks: Sequence[tuple[Sequence[str], Callable[[], Task]]],
        start_method: str = "fork",
        step_timeout: float = 10.0,
        setup_timeout: float = 60.0,
    ):
        self.names = [list(names) for names, _ in tasks]
        self.step_timeout = step_timeout
        self.setup_timeout = setup_timeout
        ctx = mp.get_context(start_method)
        w = len(tasks)
        self.control = SharedArrays(
            {
                "cmd": ((3,), "int64"),
                "err_time": ((w,), "float64"),
                "state": ((w,), "int64"),
                "where": ((w,), "int64"),
                "msg": ((w, MSG_BYTES), "uint8"),
            }
        )
        self.go = [ctx.Semaphore(0) for _ in range(w)]
        self.done = [ctx.Semaphore(0) for _ in range(w)]
        self.procs: list = []
        self.closed = False
        self.last_wait = 0.0  # s: how long the master waited for the previous command
        try:
            parent = None if start_method == "forkserver" else os.getpid()  # forkserver: its server forks
            spin = SPIN_S if w <= cpu_count() else 0.0  # pollers must not take processors from workers
            for i, (_, factory) in enumerate(tasks):
                p = ctx.Process(
                    target=_worker_main,
                    args=(i, factory, self.control, self.go[i], self.done[i], parent, spin),
                    name=f"master-worker-{'+'.join(self.names[i])}",
                    daemon=True,
                )
                p.start()
                self.procs.append(p)
            self._wait(range(w), self.setup_timeout)
        except BaseException:
            self.close()
            raise

    def run(self, op: int, a: int = 0, b: int = 0, workers: Sequence[int] | None = None) -> None:
        """Run command (op, a, b) in `workers` (default: all) and wait until each has finished."""
        if self.closed:
            raise RuntimeError("worker pool is closed")
        cmd = self.control["cmd"]
        cmd[0], cmd[1], cmd[2] = op, a, b
        ids = range(len(self.procs)) if workers is None else workers
        for i in ids:
            self.go[i].release()
        self._wait(ids, self.step_timeout)

    def _wait(self, ids: Sequence[int], timeout: float) -> None:
        """Collect the `done` of workers `ids`; raise WorkerFailure on a crash, an error or a hang.

        After a short previous wait the master polls first (waking a sleeping process costs tens
        of microseconds); after a long one it sleeps at once, leaving the processors to the workers.
        """
        t0 = time.perf_counter()
        spin = SPIN_S if self.last_wait < SPIN_S else 0.0
        deadline = time.monotonic() + timeout
        poll = min(POLL_S, timeout)
        for i in ids:
            sem = self.done[i]
            got = False
            if spin:
                end = t0 + spin
                while not (got := sem.acquire(False)) and time.perf_counter() < end:
                    os.sched_yield()
            while not got and not sem.acquire(timeout=poll):
                self._check_alive()
                if time.monotonic() > deadline:
                    self.procs[i].kill()  # a hung FMU never returns to read the stop command
                    raise self._failure(i, f"hang: no answer within the step timeout of {timeout:g} s")
            self._check(i)
        self.last_wait = time.perf_counter() - t0

    def _check_alive(self) -> None:
        for j, p in enumerate(self.procs):
            code = p.exitcode
            if code is not None:
                self._check(j)  # it may have reported an exception before ending
                raise self._failure(j, f"worker process {_signal_name(code)}")

    def _check(self, i: int) -> None:
        if self.control["state"][i] == FAILED:
            t = float(self.control["err_time"][i])
            raise self._failure(i, self._message(i), None if np.isnan(t) else t, raised=True)

    def _message(self, i: int) -> str:
        raw = bytes(self.control["msg"][i])
        return raw.split(b"\0", 1)[0].decode("utf-8", "replace")

    def _component(self, i: int) -> str | None:
        names = self.names[i]
        k = int(self.control["where"][i])
        return names[k] if 0 <= k < len(names) else (names[0] if len(names) == 1 else None)

    def _failure(self, i: int, cause: str, t: float | None = None, raised: bool = False) -> WorkerFailure:
        return WorkerFailure(self._component(i), cause, t, raised)

    def close(self) -> None:
        """Stop all workers (SIGKILL for those that do not stop within 2 s) and free shared memory."""
        if self.closed:
            return
        self.closed = True
        if "cmd" in self.control.arrays:
            self.control["cmd"][0] = STOP
        for g in self.go:
            g.release()
        deadline = time.monotonic() + 2.0
        for p in self.procs:
            p.join(max(0.0, deadline - time.monotonic()))
        for p in self.procs:
            if p.is_alive():
                p.kill()
                p.join(5.0)
        for p in self.procs:
            if p.exitcode is not None:
                p.close()
        self.control.unlink()

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
