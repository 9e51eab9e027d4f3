"""The automatic backend choice: serial or parallel, from timed trials of both.

Both backends run the first macro steps after start-up (at most TRIAL_STEPS, at most TRIAL_BUDGET
s each) in their worker processes, so that a crash or a hang stays there. Parallel is chosen when
it steps at least MARGIN times faster and the time it saves over the rest of the run outweighs
the extra cost of starting its workers. Times are in seconds.
"""

from __future__ import annotations

import time

from master.backends.component import SimulationError
from master.backends.worker import WorkerFailure, cpu_count
from master.backends.workers import DEFAULT_STEP_TIMEOUT, WorkerBackend, separate, worker_groups
from master.fmu import FmuError
from master.recorder import Recorder
from master.schedule import Plan

TRIAL_STEPS = 2000  # macro steps timed at most per backend
TRIAL_BUDGET = 0.05  # s of stepping per backend at most
MARGIN = 1.2  # parallel must step this much faster to be chosen


def trial(plan: Plan, groups: list[list[str]], step_timeout: float) -> tuple[float, float, bool]:
    """(s to start the workers and initialise, s per macro step, whether an FMU ended the
    simulation meanwhile) of a worker backend with `groups`, timed on the macro steps after
    start-up."""
    be = WorkerBackend(plan, groups, step_timeout)
    rec = Recorder(plan.columns)
    try:
        t0 = time.perf_counter()
        be.open()
        be.initialize(rec)
        n0 = min(plan.startup_steps, plan.n_macro)  # start-up steps repeat work: not typical
        n = 0
        while n < n0:
            n = be.run(n, n0, rec)
        setup = time.perf_counter() - t0
        n1 = min(n0 + TRIAL_STEPS, plan.n_macro)
        t0 = time.perf_counter()
        while (time.perf_counter() - t0 < TRIAL_BUDGET or n == n0) and n < n1:
            n = be.run(n, n1, rec, TRIAL_BUDGET)
        if n < n1:  # the budget ran out: stop, and count what was done
            be.cancel()
            be.pool.wait(be._supervise)
            n = be.position
        return setup, be.stepping_span() / max(n - n0, 1), be.stopped() is not None
    finally:
        be.close()
        rec.discard()


def choose_backend(plan: Plan, step_timeout: float = DEFAULT_STEP_TIMEOUT) -> tuple[str, str]:
    """("serial" or "parallel", why), from timed trials of both."""
    groups = worker_groups(plan)
    cpus = cpu_count()
    if len(groups) < 2:
        return "serial", "one worker would run everything: nothing to overlap"
    if cpus < 2:
        return "serial", "one processor"
    if plan.n_macro <= plan.startup_steps:
        return "serial", "no macro step to time"
    try:
        setup_s, serial, ended = trial(
            plan, separate([[pc.name for pc in plan.components]], plan), step_timeout
        )
        setup_p, parallel, ended_p = trial(plan, groups, step_timeout)
    except (SimulationError, FmuError, WorkerFailure) as e:  # the run itself will say what fails, and where
        return "serial", f"a trial failed ({e})"
    if ended or ended_p:
        return "serial", "an FMU ended the simulation within the timed macro steps"
    facts = (
        f"serial {serial * 1e6:.1f} us/step, parallel {parallel * 1e6:.1f} us/step measured "
        f"({len(groups)} workers on {cpus} CPUs; parallel needs {MARGIN:g}x)"
    )
    return decide(serial, parallel, setup_p - setup_s, plan.n_macro - plan.startup_steps), facts


def decide(serial: float, parallel: float, extra_setup: float, remaining: int) -> str:
    """ "parallel" if it steps MARGIN times faster (s per macro step) and saves more over the
    `remaining` macro steps than its `extra_setup` s of starting costs; else "serial"."""
    if parallel * MARGIN < serial and remaining * (serial - parallel) > extra_setup:
        return "parallel"
    return "serial"
