"""The automatic backend choice: serial or parallel, from a timed serial trial.

The trial runs the in-process backend on the first macro steps inside a worker process (so that a
crash or a hang stays there), times the workers' synchronisation, and predicts the parallel
backend's cost per macro step from the dependency levels of the plan. Times are in seconds.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from functools import partial

import numpy as np

from master.backends.worker import NOP, WorkerFailure, WorkerPool, cpu_count
from master.backends.workers import DEFAULT_STEP_TIMEOUT, worker_groups
from master.recorder import Recorder
from master.runtime.tables import Memory
from master.schedule import Plan

OP_TRIAL = 1


def levels(plan: Plan) -> dict[str, int]:
    """Dependency level of each component: 0, or one more than any source it must wait for."""
    out: dict[str, int] = {}
    for pc in plan.components:  # stepping order: sources that go first come first
        out[pc.name] = max(
            (out[lk.source] + 1 for lk in plan.links_into(pc.name) if lk.source_first), default=0
        )
    return out


TRIAL_STEPS = 50  # macro steps timed at most in the serial trial
TRIAL_BUDGET = 0.1  # s: wall time the trial may spend stepping
SYNC_ROUNDS = 200  # empty round trips timed to measure the synchronisation cost
MARGIN = 1.2  # parallel must be predicted this much faster per step to be chosen


class _TrialTask:
    """Times the serial backend on the first macro steps, in a worker so that a crash stays there."""

    def __init__(self, plan: Plan, out: Memory, tmp: str):
        self.plan = plan
        self.out = out
        self.tmp = tmp
        self.components = [pc.name for pc in plan.components]

    def setup(self, where: np.ndarray) -> None:
        tempfile.tempdir = self.tmp

    def command(self, op: int, a: int, b: int, where: np.ndarray) -> None:
        """OP_TRIAL: out = [open time, steps timed, wall of those steps, FMU time per component...]."""
        from master.backends.in_process import InProcessBackend as SerialBackend

        res = self.out["trial"]
        be = SerialBackend(self.plan)
        rec = Recorder(["time"] + [f"{c}.{v}" for c, v in self.plan.record])
        try:
            t0 = time.perf_counter()
            be.open()
            be.initialize(rec)
            res[0] = time.perf_counter() - t0
            n0 = min(self.plan.startup_steps, self.plan.n_macro)  # start-up steps repeat work: not typical
            be.run(0, n0, rec)
            ft0 = be.stats()[1]
            t0 = time.perf_counter()
            n = be.run(n0, min(n0 + TRIAL_STEPS, self.plan.n_macro), rec, TRIAL_BUDGET)
            res[2] = time.perf_counter() - t0
            res[1] = n - n0
            ft = be.stats()[1]
            for i, name in enumerate(self.components):
                res[3 + i] = ft[name] - ft0[name]
        finally:
            be.close()
            rec.discard()

    def close(self) -> None:
        pass


def predict_parallel(plan: Plan, cost: dict[str, float], sync: float, cpus: int) -> float:
    """Predicted wall time per macro step (s) of the parallel backend.

    cost: serial wall time per macro step attributable to each component (s).  Per dependency
    level the slowest worker sets the pace, unless the workers outnumber the processors.
    """
    lv = levels(plan)
    total = 0.0
    for level in range(1 + max(lv.values(), default=0)):
        loads = [sum(cost[n] for n in names if lv[n] == level) for names in worker_groups(plan)]
        total += max(max(loads), sum(loads) / cpus) + sync
    return total


def choose_backend(plan: Plan, step_timeout: float = DEFAULT_STEP_TIMEOUT) -> tuple[str, str]:
    """("serial" or "parallel", why): measured serial cost per macro step vs predicted parallel cost.

    The serial trial runs in a worker, so a crash or a hang (past `step_timeout` s) stays there.
    """
    groups = worker_groups(plan)
    cpus = cpu_count()
    if len(groups) < 2:
        return "serial", "one worker would run everything: nothing to overlap"
    if cpus < 2:
        return "serial", "one processor"
    n = len(plan.components)
    out = Memory({"trial": ((3 + n,), "float64")}, shared=True)
    tmp = tempfile.mkdtemp(prefix="master-trial-")
    idle = _IdleTask
    try:
        t0 = time.perf_counter()
        pool = WorkerPool(
            [(["trial"], partial(_TrialTask, plan, out, tmp))] + [(["idle"], idle)] * (len(groups) - 1),
            step_timeout=step_timeout,
        )
        start = time.perf_counter() - t0
        try:
            try:
                pool.run(OP_TRIAL, workers=[0])
            except WorkerFailure as e:
                return "parallel", f"the serial trial failed ({e.cause}): workers keep a failure isolated"
            t0 = time.perf_counter()
            for _ in range(SYNC_ROUNDS):
                pool.run(NOP)
            sync = (time.perf_counter() - t0) / SYNC_ROUNDS
        finally:
            pool.close()
        res = out["trial"].copy()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    opened, steps, wall = res[0], int(res[1]), res[2]
    if steps == 0:
        return "serial", "no macro step to time"
    serial = wall / steps
    fmu = {pc.name: res[3 + i] / steps for i, pc in enumerate(plan.components)}
    # master work outside the FMUs, shared out per communication step
    glue = max(serial - sum(fmu.values()), 0.0) / sum(pc.ratio for pc in plan.components)
    cost = {pc.name: fmu[pc.name] + glue * pc.ratio for pc in plan.components}
    parallel = predict_parallel(plan, cost, sync, cpus)
    remaining = plan.n_macro - plan.startup_steps
    gain = remaining * (serial - parallel) - start - opened / 2
    facts = (
        f"serial {serial * 1e6:.0f} us/step measured, parallel {parallel * 1e6:.0f} us/step predicted "
        f"(sync {sync * 1e6:.0f} us, {len(groups)} workers on {cpus} CPUs)"
    )
    if parallel * MARGIN < serial and gain > 0:
        return "parallel", facts
    return "serial", facts


class _IdleTask:
    """A worker that only answers (for timing the synchronisation)."""

    components = ("idle",)

    def setup(self, where: np.ndarray) -> None:
        pass

    def command(self, op: int, a: int, b: int, where: np.ndarray) -> None:
        pass

    def close(self) -> None:
        pass
