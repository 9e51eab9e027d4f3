"""Serial backend: every component in this process, stepped one after the other.

Jacobi and Gauss-Seidel give the same code path: the schedule says which source samples each
consumer may use, so the order in which this loop steps components only matters where the
plan says a source goes first.
"""

from __future__ import annotations

import numpy as np

from master.backends.component import ComponentRunner, open_fmu, output_names
from master.coupling import History
from master.fmu import Fmu
from master.schedule import Plan


class SerialBackend:
    """Executes a Plan in-process. Use: `open()`, `initialize()`, `step(n)` ..., `close()`."""

    name = "serial"

    def __init__(self, plan: Plan):
        self.plan = plan
        self.fmus: dict[str, Fmu] = {}
        self.runners: list[ComponentRunner] = []
        self.histories: dict[str, History] = {}

    def open(self) -> None:
        """Load, instantiate and parameterise every FMU; enter initialisation mode."""
        sc = self.plan.scenario
        for pc in self.plan.components:
            self.fmus[pc.name] = open_fmu(sc, sc.component(pc.name))
        names = {
            pc.name: output_names(self.plan, pc.name, self.fmus[pc.name].variables)
            for pc in self.plan.components
        }
        for pc in self.plan.components:
            r = ComponentRunner(self.plan, pc, self.fmus[pc.name], names)
            self.runners.append(r)
            self.histories[pc.name] = r.history

    def initialize(self) -> None:
        """Make inputs and outputs at the start time consistent.

        One sweep per component (set inputs from the sources' outputs, read own outputs)
        settles any acyclic chain of direct feedthrough. Sweeps run in initialisation mode
        (for FMUs that compute initial outputs there) and again after leaving it (for FMUs
        that compute them only on exit).
        """
        for _ in range(len(self.runners)):
            for r in self.runners:
                r.initial_sweep(self.histories)
        for r in self.runners:
            r.exit_initialization()
        for _ in range(len(self.runners)):
            for r in self.runners:
                r.initial_sweep(self.histories)

    def step(self, n: int) -> None:
        """Advance every component through macro step n (repeated at start-up, see Plan)."""
        if n >= self.plan.startup_steps:
            histories = self.histories
            for r in self.runners:
                r.macro_step(n, histories)
            return
        saved = {r.name: r.fmu_call(n, r.fmu.get_state) for r in self.runners}
        try:
            for r in self.runners:
                r.macro_step(n, self.histories)
            for _ in range(self.plan.startup_sweeps):
                previous = {r.name: r.history.copy() for r in self.runners}
                for r in self.runners:
                    r.fmu_call(n, r.fmu.set_state, saved[r.name])
                    r.macro_step(n, previous, relaxed=True)
        finally:
            for r in self.runners:
                r.fmu_call(n, r.fmu.free_state, saved[r.name])

    def record(self, n: int, row: np.ndarray) -> None:
        """Recorded values at the end of macro step n (n = -1: start time) into row[1:]."""
        for r in self.runners:
            r.record(n, row)

    def stats(self) -> tuple[dict[str, int], dict[str, float]]:
        """(communication steps, wall time inside FMI calls in s) per component."""
        return {r.name: r.steps for r in self.runners}, {r.name: r.fmu_time for r in self.runners}

    def close(self) -> None:
        for f in self.fmus.values():
            f.close()
        self.fmus.clear()
