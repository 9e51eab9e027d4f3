"""One component's work in the multirate algorithm, written once for every backend.

`ComponentRunner.macro_step(n)` advances one FMU through macro step n: at each of its
communication points it evaluates its coupling polynomials from the source histories, sets
its inputs (one vectorised set), steps, reads its outputs (one vectorised get) and stores
them in its own history. Serial and parallel backends both call exactly this code, so they
produce bit-identical results. Times are in seconds.
"""

from __future__ import annotations

import math
import time

import numpy as np

from master.coupling import History, stimulus_value, weights
from master.fmu import Fmu, FmuError, RealPort
from master.scenario.model import Component, Scenario
from master.schedule import Link, Plan, PlanComponent


class SimulationError(Exception):
    """A run stopped: names the component, the variable or cause, and the simulation time (s)."""

    def __init__(self, message: str, component: str, time: float, variable: str | None = None):
        super().__init__(message)
        self.component = component
        self.variable = variable
        self.time = time


# An output beyond this many times its start magnitude (at least 1) has diverged.
GROWTH_LIMIT = 1e6

UNSTABLE_HINT = (
    "hint: the coupled system is unstable at these settings; try a smaller macro step, "
    "a semi-implicit solver in the stiff component, or a lower extrapolation order"
)


def output_names(plan: Plan, name: str, variables: dict) -> list[str]:
    """Real variables of `name` read at each communication point: coupled outputs, then recorded."""
    out: list[str] = []
    for lk in plan.links:
        if lk.source == name:
            out.extend(o for o in lk.outputs if o not in out)
    for comp, var in plan.record:
        if comp == name and var not in out and variables[var].type == "Real":
            out.append(var)
    return out


class _InLink:
    """A link as the consumer evaluates it: source history columns -> input port slots."""

    def __init__(self, link: Link, columns: np.ndarray, slots: np.ndarray, step_s: float):
        self.link = link
        self.columns = columns
        self.slots = slots
        self.value = np.zeros(len(slots))
        self.source_step = step_s  # h of the source (s)
        self.port: RealPort | None = None


class ComponentRunner:
    """Runs one FMU through the plan; owns its output history."""

    def __init__(self, plan: Plan, pc: PlanComponent, fmu: Fmu, out_names: dict[str, list[str]]):
        self.plan = plan
        self.pc = pc
        self.fmu = fmu
        self.name = pc.name
        self.clock = pc.clock
        self.h = float(pc.step)
        self.out = fmu.real_port(out_names[pc.name])
        links = plan.links_into(pc.name)
        stimuli = [s for s in plan.stimuli if s.component == pc.name]
        in_names = [i for lk in links for i in lk.inputs] + [s.variable for s in stimuli]
        self.inp = fmu.real_port(in_names)
        self.links: list[_InLink] = []
        pos = 0
        for lk in links:
            src_names = out_names[lk.source]
            cols = np.array([src_names.index(o) for o in lk.outputs], dtype=np.intp)
            slots = np.arange(pos, pos + len(lk.inputs), dtype=np.intp)
            pos += len(lk.inputs)
            il = _InLink(lk, cols, slots, float(plan.component(lk.source).step))
            il.port = fmu.real_port(list(lk.inputs))  # for fmi2SetRealInputDerivatives
            self.links.append(il)
        self.stimuli = [(pos + i, s, _start_value(fmu, s.variable)) for i, s in enumerate(stimuli)]
        # outputs that depend directly on driven inputs need those inputs at the end of each step
        self.feedthrough = self.inp.n > 0 and any(o in fmu.feedthrough for o in self.out.names)
        # a consumer of order p reads samples back to p before the macro step start, while this
        # component may already have written the whole macro step: k + p + 1 samples coexist
        max_order = max([lk.order for lk in plan.links if pc.name in (lk.source, lk.consumer)], default=0)
        self.history = History(self.out.n, pc.ratio + max_order + 2)
        self.fmu_time = 0.0  # wall time inside FMI calls (s)
        self.bound: np.ndarray | None = None  # divergence bound per output, from the start values
        self.steps = 0
        # (column in the result row, column in the history) / (column, variable name)
        self.record_real: list[tuple[int, int]] = []
        self.record_other: list[tuple[int, str]] = []
        for i, (c, v) in enumerate(plan.record):
            if c == pc.name and v in self.out.names:
                self.record_real.append((1 + i, self.out.names.index(v)))
            elif c == pc.name:
                self.record_other.append((1 + i, v))

    # -- inputs ---------------------------------------------------------------------------------
    def _fill_inputs(
        self, n: int, j: int, histories: dict[str, History], at: int | None = None, relaxed: bool = False
    ) -> None:
        """Input port values of step j (in macro step n) at communication point `at` (default j).

        at = j + 1 evaluates the same polynomials at the step's end: the inputs that go with
        the outputs read there, so that direct-feedthrough outputs are not a step stale.
        """
        vals = self.inp.values
        kc = self.pc.ratio
        at = j if at is None else at
        for il in self.links:
            lk = il.link
            j_end, p = lk.window(n, j, relaxed)
            w = weights(p, at * lk.k_source - j_end * kc, kc)
            histories[lk.source].combine(j_end, w, il.columns, il.value)
            vals[il.slots] = il.value
        if self.stimuli:
            t = self.clock.time(at)
            for slot, s, start in self.stimuli:
                vals[slot] = stimulus_value(s, t, start)

    def _set_derivatives(self, n: int, j: int, histories: dict[str, History], relaxed: bool = False) -> None:
        """Hand the polynomials' derivatives at the step start to the FMU (canInterpolateInputs)."""
        kc = self.pc.ratio
        for il in self.links:
            lk = il.link
            j_end, p = lk.window(n, j, relaxed)
            for d in range(1, min(p, self.pc.derivative_order) + 1):
                w = weights(p, j * lk.k_source - j_end * kc, kc, d)
                histories[lk.source].combine(j_end, w, il.columns, il.value)
                il.value /= il.source_step**d
                self.fmu.set_input_derivatives(il.port, d, il.value)

    # -- stepping -------------------------------------------------------------------------------
    def initial_sweep(self, histories: dict[str, History]) -> None:
        """In initialisation mode: set inputs from the sources' current outputs, read own outputs."""
        t0 = perf()
        try:
            self._fill_initial(histories)
            self.inp.set()
            self.out.get()
        except FmuError as e:
            raise SimulationError(f"{e} at t={self.clock.time(0)}", self.name, self.clock.time(0)) from e
        finally:
            self.fmu_time += perf() - t0
        self.history.push(0, self.out.values)

    def _fill_initial(self, histories: dict[str, History]) -> None:
        vals = self.inp.values
        for il in self.links:
            h = histories[il.link.source]
            vals[il.slots] = h.buf[0, il.columns]
        t = self.clock.time(0)
        for slot, s, start in self.stimuli:
            vals[slot] = stimulus_value(s, t, start)

    def macro_step(self, n: int, histories: dict[str, History], relaxed: bool = False) -> None:
        """Advance through macro step n: `ratio` communication steps of h each.

        relaxed: a start-up sweep (see Plan.startup_sweeps); `histories` then hold the sources'
        samples of macro step n from the previous sweep.
        """
        k = self.pc.ratio
        h = self.h
        fmu = self.fmu
        if self.bound is None:
            self.bound = GROWTH_LIMIT * np.maximum(1.0, np.abs(self.history.buf[0]))
        for j in range(n * k, n * k + k):
            t = self.clock.time(j)
            self._fill_inputs(n, j, histories, relaxed=relaxed)
            t0 = perf()
            try:
                self.inp.set()
                if self.pc.interpolate_inputs:
                    self._set_derivatives(n, j, histories, relaxed)
                fmu.do_step(t, h)
                if self.feedthrough:
                    self._fill_inputs(n, j, histories, j + 1, relaxed)
                    self.inp.set()
                vals = self.out.get()
            except FmuError as e:
                raise SimulationError(
                    f"{e} in the step from t={t} to t={self.clock.time(j + 1)}", self.name, t
                ) from e
            finally:
                self.fmu_time += perf() - t0
            self.steps += 1
            if not np.isfinite(vals).all():
                bad = self.out.names[int(np.flatnonzero(~np.isfinite(vals))[0])]
                t1 = self.clock.time(j + 1)
                raise SimulationError(
                    f"unstable: {self.name}.{bad} at t={t1} ({UNSTABLE_HINT})", self.name, t1, bad
                )
            if (np.abs(vals) > self.bound).any():
                i = int(np.flatnonzero(np.abs(vals) > self.bound)[0])
                bad, t1 = self.out.names[i], self.clock.time(j + 1)
                raise SimulationError(
                    f"unstable: {self.name}.{bad} at t={t1}: {vals[i]:.3g} is beyond {GROWTH_LIMIT:g} times "
                    f"its start magnitude ({UNSTABLE_HINT})",
                    self.name,
                    t1,
                    bad,
                )
            self.history.push(j + 1, vals)

    def record(self, n: int, row: np.ndarray) -> None:
        """Fill this component's recorded values at the end of macro step n into its columns of `row`."""
        vals = self.history.buf[((n + 1) * self.pc.ratio) % self.history.capacity]
        for i, col in self.record_real:
            row[i] = vals[col]
        for i, var in self.record_other:
            t0 = perf()
            try:
                row[i] = self.fmu.get_value(var)
            except FmuError as e:
                raise SimulationError(str(e), self.name, math.nan, var) from e
            finally:
                self.fmu_time += perf() - t0


def open_fmu(sc: Scenario, comp: Component) -> Fmu:
    """Load the FMU of `comp`, set its parameters and start values, enter initialisation mode."""
    fmu = Fmu(comp.fmu_path, comp.name)
    try:
        fmu.set_values(dict(comp.parameters))
        fmu.enter_initialization(float(sc.start_time), float(sc.stop_time))
    except BaseException:
        fmu.close()
        raise
    return fmu


def _start_value(fmu: Fmu, var: str) -> float:
    s = fmu.variables[var].start
    return float(s) if s is not None else 0.0


perf = time.perf_counter
