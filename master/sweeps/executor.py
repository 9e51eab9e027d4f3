"""Where many runs execute: a dask.distributed cluster, local or remote, through one code path.

Without a scheduler address a LocalCluster of worker processes (one thread each: every task is a
whole run, itself in a worker process of its own) starts with the executor and stops with it;
with one ("tcp://host:port") the tasks go to that cluster, whose workers must have this package
installed and see the scenario's files at the same paths.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import queue
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any
from uuid import uuid4

from master.sweeps.cases import SweepError

TASK_S = 0.2  # s a task should last: Dask's few ms per task weigh little, a lost worker loses little
MAX_BATCH = 64  # items per task at most
AHEAD = 2  # tasks in flight per worker thread: the next one waits in the worker while one runs
POLL_S = 0.02  # how often a held stop signal is looked at while no result comes


def usable_cpus() -> int:
    return len(os.sched_getaffinity(0))


class Executor:
    """`with Executor(workers=4) as ex: for i, outcome in ex.map(fn, items, shared): ...`"""

    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        if workers is not None and workers < 1:
            raise SweepError(f"--workers {workers}: at least 1")
        if workers is not None and scheduler is not None:
            raise SweepError("--workers sizes a local cluster; an existing one (--scheduler) has its own")
        self.workers = workers or usable_cpus()
        self.scheduler = scheduler
        self._stack = contextlib.ExitStack()
        self.client: Any = None
        self.held: int | None = None  # a stop signal that arrived, raised at the next poll

    def __enter__(self) -> Executor:
        self._stack.enter_context(self._holding_signals())
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            self._stack.close()
            raise SweepError(
                "sweeps run on dask.distributed, which is not installed: pip install 'master[sweep]'"
            ) from None
        try:
            if self.scheduler is None:
                cluster = self._stack.enter_context(
                    LocalCluster(
                        n_workers=self.workers,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=":0",  # any free port: several sweeps may run at once
                    )
                )
                self.client = self._stack.enter_context(Client(cluster))
            else:
                self.client = self._stack.enter_context(Client(self.scheduler, timeout="10s"))
        except OSError as e:
            self._stack.close()
            where = self.scheduler or "a local cluster"
            raise SweepError(f"--scheduler {where}: cannot connect ({e})") from None
        try:  # part of the start-up, not of the first cases' time
            self.client.run(_load_code)
        except Exception:  # a worker without this package: its cases say so
            pass
        return self

    def __exit__(self, *exc: object) -> None:
        if self.client is not None and self.scheduler is not None:  # workers that outlive the sweep
            try:
                self.client.run(_close_code)
            except Exception:
                pass
        self._stack.close()
        if exc[0] is None:
            self._raise_held()

    @contextlib.contextmanager
    def _holding_signals(self) -> Iterator[None]:
        """SIGINT, SIGTERM and SIGHUP (those not ignored) are held, not raised where they land:
        raised inside one of distributed's blocking calls, an interrupt leaves its event loop a
        broken callback (a traceback on stderr) and the cluster half closed. `map` raises them
        between polls."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        from master.backends.driver import STOPS, catch

        def hold(signum: int, frame: object) -> None:
            self.held = self.held or signum

        old = catch(STOPS, hold)
        try:
            yield
        finally:
            for s, handler in old.items():
                signal.signal(s, handler)

    def _raise_held(self) -> None:
        if self.held is not None:
            from master.backends.driver import Interrupted

            raise Interrupted(self.held)

    @property
    def dashboard(self) -> str | None:
        """The Dask dashboard's address (None without bokeh)."""
        try:
            return self.client.dashboard_link
        except (AttributeError, KeyError):
            return None

    @property
    def size(self) -> int:
        """Worker threads of the cluster now."""
        return sum(w["nthreads"] for w in self.client.scheduler_info()["workers"].values())

    def map(self, fn: Callable, items: Sequence, *shared: Any) -> Iterator[tuple[int, Any]]:
        """fn(*shared, item) for every item, as the results come: (index, result), or (index,
        exception) for an item that raised or that the cluster could not run (e.g. its worker
        died). `shared` objects travel to each worker once. Items travel in batches, `batch_size`
        items each, sent as results come back (AHEAD tasks in flight per worker thread): every
        Dask task costs a few ms of the scheduler's, the client's and the worker's processors."""
        # a task that returns them, not scattered data: the scheduler can make it again when a worker
        # holding it dies (scattered data would be lost, and every task needing it with it)
        held = self.client.submit(_same, shared, pure=False, key=f"shared-{uuid4().hex}")
        name = getattr(fn, "__name__", "task")
        futures: dict[Any, list[int]] = {}
        done: queue.SimpleQueue = queue.SimpleQueue()  # futures as they finish (Dask's callback thread)
        sent, per_item = 0, None  # items sent; s per item in the last task that came back

        def send() -> None:
            nonlocal sent
            threads = max(self.size, 1)
            while sent < len(items) and len(futures) < AHEAD * threads:
                batch = list(range(sent, sent + batch_size(len(items) - sent, per_item, threads)))
                sent += len(batch)
                future = self.client.submit(
                    _in_worker, fn, held, [items[i] for i in batch], pure=False,
                    key=f"{name}-{batch[0]}-{uuid4().hex}",
                )  # fmt: skip
                futures[future] = batch
                future.add_done_callback(done.put)

        try:
            send()
            while futures:
                self._raise_held()
                try:
                    future = done.get(timeout=POLL_S)
                except queue.Empty:
                    continue
                batch = futures.pop(future)
                try:
                    outcomes, elapsed = future.result()
                    per_item = elapsed / len(batch)
                except Exception as e:  # KilledWorker, CommClosedError, ...: the batch is lost
                    outcomes = [e] * len(batch)
                send()  # before the results are handed on: the workers need not wait for their consumer
                yield from zip(batch, outcomes, strict=True)
        finally:
            self.client.cancel([*futures, held])


def batch_size(left: int, per_item: float | None, threads: int) -> int:
    """Items in the next task, of `left` not yet sent: one while no item's time is known (the first
    tasks start every worker at once, each opening what its cases share); then as many as last
    TASK_S, at most MAX_BATCH (a lost worker loses no more, progress stays fine-grained) and at most
    a share 1 / (2 threads) of those left, so the batches shrink at the end and every worker stays
    busy to it."""
    if per_item is None:
        return 1
    return max(1, min(int(TASK_S / max(per_item, 1e-9)), MAX_BATCH, left // (2 * threads)))


def _load_code() -> None:
    """Import in a worker what running a case needs (a second or so the first time)."""
    import master.api  # noqa: F401
    import master.backends.session  # noqa: F401
    import master.sweeps.case  # noqa: F401


def _close_code() -> None:
    """End in a worker what the cases left open: the warm session's worker process."""
    from master.backends.session import close_warm

    close_warm()


def _same(shared: tuple) -> tuple:
    return shared


def _in_worker(fn: Callable, shared: tuple, batch: list) -> tuple[list, float]:
    """A task: `fn(*shared, item)` for each item of a batch in a Dask worker, where it may start
    worker processes of its own; an item that raises gives its exception, the others go on. With
    the s it took."""
    out: list = []
    t0 = time.perf_counter()
    with children_allowed():
        for item in batch:
            try:
                out.append(fn(*shared, item))
            except Exception as e:
                out.append(e)
    return out, time.perf_counter() - t0


_lifted = {"count": 0, "daemon": None}
_lift_lock = threading.Lock()


@contextlib.contextmanager
def children_allowed() -> Iterator[None]:
    """Let a run start its worker process inside a Dask worker.

    Dask runs its workers as daemonic processes, and multiprocessing refuses children to those
    (a daemon's children would be orphaned at its exit). A run's workers watch their parent and
    are stopped by it, so the rule does not apply to them; it is lifted while any run of this
    process (one per worker thread) starts or runs."""
    config = mp.current_process()._config  # the flag's only home; Process.daemon cannot be reset
    with _lift_lock:
        if _lifted["count"] == 0:
            _lifted["daemon"] = config.pop("daemon", None)
        _lifted["count"] += 1
    try:
        yield
    finally:
        with _lift_lock:
            _lifted["count"] -= 1
            if _lifted["count"] == 0 and _lifted["daemon"] is not None:
                config["daemon"] = _lifted["daemon"]
