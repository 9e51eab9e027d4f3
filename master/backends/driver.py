"""The run around any backend: initialisation, chunks of macro steps, progress, failure handling."""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol

from master.backends.component import SimulationError
from master.recorder import Recorder, ResultsError, RunSummary
from master.schedule import Plan


class Backend(Protocol):
    name: str
    position: int  # the next macro step to run (after a failure: the one that failed)

    def open(self) -> None: ...
    def initialize(self, recorder: Recorder) -> None: ...
    def pace(self, factor: float) -> None: ...
    def run(self, n_from: int, n_to: int, recorder: Recorder, budget: float = 0.0) -> int: ...
    def pacing(self) -> dict | None: ...
    def stats(self) -> tuple[dict[str, int], dict[str, float]]: ...
    def coupling_errors(self) -> dict[str, dict[str, float]]: ...
    def loop_stats(self) -> dict[str, dict[str, float]]: ...
    def clock_ticks(self) -> dict[str, int]: ...
    def event_counts(self) -> dict[str, int]: ...
    def iterations(self) -> dict[str, int] | None: ...
    def stopped(self) -> tuple[str, float] | None: ...
    def close(self) -> None: ...


BUDGET = 0.1  # s: the longest a backend runs before Python sees signals and shows progress


STOPS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def signals_deferred() -> Iterator[None]:
    """Within: the stop signals wait (blocked, then delivered on leaving), so that moving rows to
    the recorder and counting them as moved happen together: a stop between the two wrote some
    rows twice (or half a block) when the rows left over were drained at the stop."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, STOPS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


class Interrupted(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised where Python would raise KeyboardInterrupt for SIGINT."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def catch(signals: tuple[int, ...], handler) -> dict[int, object]:
    """`handler` for each of `signals` that is not ignored; the old handlers. An ignored one stays
    ignored: whoever started the process chose so (nohup ignores SIGHUP, a non-interactive shell
    SIGINT for a job started with &), as Python itself keeps an ignored SIGINT."""
    return {s: signal.signal(s, handler) for s in signals if signal.getsignal(s) != signal.SIG_IGN}


@contextmanager
def stop_signals() -> Iterator[None]:
    """Within: SIGTERM and SIGHUP stop a run as Ctrl-C does (rows kept, workers stopped, the
    SimulationError says which signal; exit code 128 + its number), unless they are ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: object) -> None:
        raise Interrupted(signum)

    old = catch((signal.SIGTERM, signal.SIGHUP), stop)
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


class Progress:
    """A one-line progress bar on stderr."""

    def __init__(self, total: int):
        self.total = total
        self.shown = -1

    def update(self, n: int) -> None:
        pct = 100 * n // self.total
        if pct != self.shown:
            self.shown = pct
            bar = "#" * (pct // 4)
            sys.stderr.write(f"\r[{bar:<25}] {pct:3d}% ({n}/{self.total} macro steps)")
            sys.stderr.flush()

    def done(self) -> None:
        sys.stderr.write(f"\r{' ' * 70}\r")
        sys.stderr.flush()


def interruption(e: KeyboardInterrupt, t: float, summary: RunSummary) -> SimulationError:
    """The SimulationError of a run stopped by a signal at simulation time t (s): it names the
    signal, carries its number (`.signal`) and the summary, whose stop reason says so."""
    signum = getattr(e, "signum", signal.SIGINT)
    err = SimulationError(f"interrupted ({signal.Signals(signum).name}) at t={t}", "", t)
    err.signal = signum  # type: ignore[attr-defined]
    summary.stop_reason = f"failed: {err}"
    err.summary = summary  # type: ignore[attr-defined]
    return err


def execute(
    plan: Plan,
    backend: Backend,
    recorder: Recorder,
    real_time: float | None = None,
    progress: bool = False,
) -> RunSummary:
    """Run the plan on an opened backend; rows go to `recorder`.

    On a SimulationError the rows computed so far are flushed, the summary records the reason
    and the error is re-raised with `.summary` attached.
    """
    sc = plan.scenario
    t_start = float(sc.start_time)
    summary = RunSummary(
        scenario=str(sc.name),
        backend=backend.name,
        stop_reason="finished",
        simulated_time=0.0,
        wall_time=0.0,
        macro_steps=0,
    )
    bar = Progress(plan.n_macro) if progress else None
    wall0 = time.perf_counter()
    try:
        backend.initialize(recorder)
        if real_time:
            backend.pace(real_time)
        n = 0
        loop0 = time.perf_counter()
        while n < plan.n_macro:
            n = backend.run(n, plan.n_macro, recorder, BUDGET)
            if bar is not None:
                bar.update(n)
            stop = backend.stopped()
            if stop is not None:  # an FMU ended the simulation: a normal end, earlier
                summary.stop_reason = f"finished: {stop[0]} ended the simulation at t={stop[1]}"
                break
        summary.stepping_time = time.perf_counter() - loop0
        pacing = backend.pacing()
        if pacing is not None:
            summary.overruns = pacing["overruns"]
            summary.worst_lateness = pacing["worst"]
            summary.idle_time = pacing["idle"]
            summary.lateness = {q: pacing[q] for q in ("p50", "p99", "p99.9")}
            summary.lateness_histogram = pacing.get("histogram")
            summary.notes += pacing.get("notes", [])
    except SimulationError as e:
        summary.stop_reason = f"failed: {e}"
        e.summary = summary  # type: ignore[attr-defined]
        raise
    except ResultsError as e:  # the run is fine, its results cannot be kept: stop it like a failure
        t = plan.macro_clock.time(backend.position)
        err = SimulationError(f"{e} at t={t}", "", t)
        summary.stop_reason = f"failed: {err}"
        err.summary = summary  # type: ignore[attr-defined]
        raise err from None
    except KeyboardInterrupt as e:  # Ctrl-C, SIGTERM, SIGHUP: keep the rows so far, like any other stop
        raise interruption(e, plan.macro_clock.time(backend.position), summary) from None
    finally:
        summary.wall_time = time.perf_counter() - wall0
        summary.macro_steps = backend.position
        summary.simulated_time = plan.macro_clock.time(backend.position) - t_start
        summary.steps, summary.fmu_time = backend.stats()
        summary.coupling_errors = backend.coupling_errors()
        summary.loops = backend.loop_stats()
        summary.clock_ticks = backend.clock_ticks()
        summary.events = backend.event_counts()
        summary.iterations = backend.iterations()
        recorder.close()
        summary.rows = recorder.rows
        if bar is not None:
            bar.done()
    return summary
