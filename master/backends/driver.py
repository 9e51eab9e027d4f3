"""The macro-step loop around any backend: recording, real-time pacing, progress, failure handling."""

from __future__ import annotations

import sys
import time
from typing import Protocol

import numpy as np

from master.backends.component import SimulationError
from master.recorder import Recorder, RunSummary
from master.schedule import Plan


class Backend(Protocol):
    name: str

    def open(self) -> None: ...
    def initialize(self) -> None: ...
    def step(self, n: int) -> None: ...
    def record(self, n: int, row: np.ndarray) -> None: ...
    def stats(self) -> tuple[dict[str, int], dict[str, float]]: ...
    def close(self) -> None: ...


class Pacer:
    """Paces macro steps to the wall clock: simulated time t is due at wall t0 + t / factor."""

    def __init__(self, factor: float, macro_step: float):
        if factor <= 0:
            raise ValueError(f"real-time factor must be positive, got {factor}")
        self.factor = factor
        self.macro_step = macro_step
        self.t0 = time.perf_counter()
        self.overruns = 0
        self.worst = 0.0  # s
        self.idle = 0.0  # s spent waiting for the wall clock

    def wait(self, n_done: int) -> None:
        """After n_done macro steps: sleep until they are due, or count an overrun."""
        due = self.t0 + n_done * self.macro_step / self.factor
        now = time.perf_counter()
        late = now - due
        if late > 0:
            self.overruns += 1
            self.worst = max(self.worst, late)
            return
        if late < -2e-3:
            time.sleep(-late - 1e-3)  # sleep coarse, then spin the last millisecond for accuracy
        while time.perf_counter() < due:
            pass
        self.idle += time.perf_counter() - now


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
    H = float(sc.macro_step)
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
    n = 0
    try:
        backend.initialize()
        row = recorder.next_row()
        row[0] = t_start
        backend.record(-1, row)
        recorder.commit()
        pacer = Pacer(real_time, H) if real_time else None
        step, record, due, time_of = backend.step, backend.record, plan.record_due, plan.macro_clock.time
        for n in range(plan.n_macro):
            step(n)
            if due(n):
                row = recorder.next_row()
                row[0] = time_of(n + 1)
                record(n, row)
                recorder.commit()
            if pacer is not None:
                pacer.wait(n + 1)
            if bar is not None and (n & 63) == 0:
                bar.update(n + 1)
        n = plan.n_macro
        if pacer is not None:
            summary.overruns = pacer.overruns
            summary.worst_lateness = pacer.worst
            summary.idle_time = pacer.idle
    except SimulationError as e:
        summary.stop_reason = f"failed: {e}"
        e.summary = summary  # type: ignore[attr-defined]
        raise
    except KeyboardInterrupt:  # Ctrl-C: keep the rows so far, like any other stop
        t = plan.macro_clock.time(n)
        err = SimulationError(f"interrupted (SIGINT) at t={t}", "", t)
        summary.stop_reason = f"failed: {err}"
        err.summary = summary  # type: ignore[attr-defined]
        raise err from None
    finally:
        summary.wall_time = time.perf_counter() - wall0
        summary.macro_steps = n
        summary.simulated_time = plan.macro_clock.time(n) - t_start
        summary.steps, summary.fmu_time = backend.stats()
        recorder.close()
        summary.rows = recorder.rows
        if bar is not None:
            bar.done()
    return summary
