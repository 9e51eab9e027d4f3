"""In-process backend: every FMU in the master's own process, the macro-step loop in the kernel.

The fastest way to run and the easiest to debug, but unprotected: an FMU that crashes takes the
master with it. `master run --in-process` selects it; the default runs the same kernel in a
worker process (master.backends.workers).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from collections.abc import Callable

from master.backends.component import Unpacked, open_fmu, output_names
from master.backends.driver import signals_deferred
from master.fmu import Fmu
from master.recorder import Recorder
from master.runtime.tables import (
    CompiledPlan,
    Memory,
    clock_ticks,
    coupling_errors,
    event_counts,
    iteration_counts,
    layout,
    loop_stats,
    pacing_stats,
)
from master.schedule import Plan


class InProcessBackend:
    """Executes a Plan in this process. Use: `open()`, `initialize(recorder)`, `run(...)` ..., `close()`."""

    name = "in-process"

    def __init__(self, plan: Plan):
        self.plan = plan
        self.fmus: dict[str, Fmu] = {}
        self.compiled: CompiledPlan | None = None
        self.tmp: str | None = None  # the extracted FMUs

    def open(self) -> None:
        """Load, instantiate and parameterise every FMU; enter initialisation mode; compile the plan."""
        sc = self.plan.scenario
        self.tmp = tempfile.mkdtemp(prefix="master-run-")
        unpacked = Unpacked(self.tmp)
        for pc in self.plan.components:
            self.fmus[pc.name] = open_fmu(sc, sc.component(pc.name), unpacked)
        outs = {name: output_names(self.plan, name, fmu.variables) for name, fmu in self.fmus.items()}
        self.compiled = CompiledPlan(self.plan, self.fmus, outs, Memory(layout(self.plan, outs, 0)))

    def initialize(self, recorder: Recorder) -> None:
        """Make inputs and outputs at the start time consistent (`initialize_sweeps`); record the
        row at the start time."""
        assert self.compiled is not None
        initialize(self.compiled, self.fmus)
        with signals_deferred():
            recorder.write(*self.compiled.take_rows())

    def pace(self, factor: float) -> None:
        """Pace the following macro steps to the wall clock: simulated time runs `factor` times as fast."""
        assert self.compiled is not None
        self.compiled.pace(factor, time.monotonic_ns(), self.compiled.position)

    def run(self, n_from: int, n_to: int, recorder: Recorder, budget: float = 0.0) -> int:
        """Step macro steps n_from .. n_to - 1, for at most about `budget` s of wall time (0: no limit);
        the rows go to `recorder`, also those before a failure. Returns the next macro step."""
        cp = self.compiled
        assert cp is not None
        try:
            return cp.run(n_from, n_to, budget)[1]
        finally:
            with signals_deferred():
                recorder.write(*cp.take_rows())

    @property
    def position(self) -> int:
        """The next macro step to run (after a failure: the one that failed)."""
        return self.compiled.position if self.compiled is not None else 0

    def pacing(self) -> dict | None:
        """Real-time statistics (see `pacing_stats`), None when unpaced."""
        return pacing_stats([self.compiled.pacing]) if self.compiled is not None else None

    def stopped(self) -> tuple[str, float] | None:
        """(component, time in s) if an FMU ended the simulation, else None."""
        return self.compiled.stopped() if self.compiled is not None else None

    def loop_stats(self) -> dict[str, dict[str, float]]:
        """The counters of each algebraic loop (`loop_stats`)."""
        return loop_stats(self.plan, self.compiled.memory) if self.compiled is not None else {}

    def clock_ticks(self) -> dict[str, int]:
        """Activations and ticks of Scheduled Execution components' clocks (`clock_ticks`)."""
        return clock_ticks(self.plan, self.compiled.memory) if self.compiled is not None else {}

    def coupling_errors(self) -> dict[str, dict[str, float]]:
        """The error estimate per extrapolated connection (`coupling_errors`)."""
        return coupling_errors(self.plan, self.compiled.memory) if self.compiled is not None else {}

    def event_counts(self) -> dict[str, int]:
        """Events handled per component that had any (`event_counts`)."""
        return event_counts(self.plan, self.compiled.memory) if self.compiled is not None else {}

    def iterations(self) -> dict[str, int] | None:
        """Iterated macro steps: the sweeps (`iteration_counts`), None when the plan does not iterate."""
        return iteration_counts(self.plan, self.compiled.memory) if self.compiled is not None else None

    def stats(self) -> tuple[dict[str, int], dict[str, float]]:
        """(communication steps, wall time inside FMI calls in s) per component."""
        if self.compiled is None:
            return {pc.name: 0 for pc in self.plan.components}, {pc.name: 0.0 for pc in self.plan.components}
        return self.compiled.stats()

    def close(self) -> None:
        for f in self.fmus.values():
            f.close()
        self.fmus.clear()
        self.compiled = None
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            self.tmp = None


def initialize(cp: CompiledPlan, fmus: dict[str, Fmu]) -> None:
    """Initial sweeps around the exit of initialisation mode (`initialize_sweeps`), then the
    divergence bounds and the row at the start time, all in this process."""
    initialize_sweeps(
        len(cp.names), cp.initial_sweep, lambda: [cp.exit_initialization(n, f) for n, f in fmus.items()]
    )
    cp.set_bounds()
    cp.record_row(-1)


def initialize_sweeps(
    n: int, sweep: Callable[[int], None], exit_initialization: Callable[[], object]
) -> None:
    """Make inputs and outputs at the start time consistent: the sequence every backend follows.

    One sweep per component (sweep(i): set component i's inputs from its sources' outputs, read
    its own outputs) settles any acyclic chain of direct feedthrough among n components. Sweeps
    run in initialisation mode (for FMUs that compute initial outputs there) and again after
    leaving it (for FMUs that compute them only on exit).
    """
    for _ in range(n):
        for i in range(n):
            sweep(i)
    exit_initialization()
    for _ in range(n):
        for i in range(n):
            sweep(i)
