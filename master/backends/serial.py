"""Serial backend: every component in this process, the macro-step loop in the compiled kernel.

Jacobi and Gauss-Seidel give the same code path: the schedule says which source samples each
consumer may use, so the order in which the kernel steps components only matters where the
plan says a source goes first.
"""

from __future__ import annotations

from master.backends.component import open_fmu
from master.fmu import Fmu
from master.recorder import Recorder
from master.runtime.tables import CompiledPlan
from master.schedule import Plan


class SerialBackend:
    """Executes a Plan in-process. Use: `open()`, `initialize(recorder)`, `run(...)` ..., `close()`."""

    name = "serial"

    def __init__(self, plan: Plan):
        self.plan = plan
        self.fmus: dict[str, Fmu] = {}
        self.compiled: CompiledPlan | None = None

    def open(self) -> None:
        """Load, instantiate and parameterise every FMU; enter initialisation mode; compile the plan."""
        sc = self.plan.scenario
        for pc in self.plan.components:
            self.fmus[pc.name] = open_fmu(sc, sc.component(pc.name))
        self.compiled = CompiledPlan(self.plan, self.fmus)

    def initialize(self, recorder: Recorder) -> None:
        """Make inputs and outputs at the start time consistent; record the row at the start time.

        One sweep per component (set inputs from the sources' outputs, read own outputs)
        settles any acyclic chain of direct feedthrough. Sweeps run in initialisation mode
        (for FMUs that compute initial outputs there) and again after leaving it (for FMUs
        that compute them only on exit).
        """
        cp = self.compiled
        assert cp is not None
        n = len(cp.names)
        for _ in range(n):
            for i in range(n):
                cp.initial_sweep(i)
        for name, fmu in zip(cp.names, cp.fmus, strict=True):
            cp.exit_initialization(name, fmu)
        for _ in range(n):
            for i in range(n):
                cp.initial_sweep(i)
        cp.set_bounds()
        cp.record_row(-1)
        recorder.write(cp.take_rows())

    def pace(self, factor: float) -> None:
        """Pace the following macro steps to the wall clock: simulated time runs `factor` times as fast."""
        assert self.compiled is not None
        self.compiled.pace(factor)

    def run(self, n_from: int, n_to: int, recorder: Recorder, budget: float = 0.0) -> int:
        """Step macro steps n_from .. n_to - 1, for at most about `budget` s of wall time (0: no limit);
        the rows go to `recorder`, also those before a failure. Returns the next macro step."""
        cp = self.compiled
        assert cp is not None
        try:
            return cp.run(n_from, n_to, budget)[1]
        finally:
            recorder.write(cp.take_rows())

    @property
    def position(self) -> int:
        """The next macro step to run (after a failure: the one that failed)."""
        return self.compiled.position if self.compiled is not None else 0

    def pacing(self) -> dict | None:
        """Real-time statistics (see CompiledPlan.pacing_stats), None when unpaced."""
        return self.compiled.pacing_stats() if self.compiled is not None else None

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
