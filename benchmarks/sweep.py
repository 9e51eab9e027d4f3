"""Sweep engine: 200 oscillator cases as a loop of `master.run` and as sweeps on local Dask
clusters of 1 and 2 workers, measured side by side in one run (not a test: numbers vary by
machine).

    .venv/bin/python benchmarks/sweep.py [--cases 200] [--stop-time 10] [--repeat 3] [--loops 2]
                                         [--workers 1 2] [--task-s 0.2]

The first `--loops` rounds time the loop (each case a `master.run` of its own, serial backend: a
worker process started, the FMUs extracted and loaded, the run, the process ended); every round
times each sweep's cases (cluster start-up apart: the cases of a Dask worker share one warm
worker process, master.backends.session) and checks that its final, min and max of every
recorded column equal the loop's bit for bit. It prints the speed-ups (the issue's targets: >= 5x the loop
on one worker, >= 1.8x one worker's rate on two workers with two cores) and the overhead per case
of one worker: its time per case less the kernel's stepping time per case (the loop's runs say
how long the stepping takes; target < 2 ms), and the processor time per case of each sweep (all its
processes; less changed by other work than wall time). The load average is printed before every
measurement: the machine may be shared.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil

import master
import master.api as api
from master.sweeps import executor
from master.sweeps.cases import parse_vary, points

SCENE = Path(__file__).resolve().parent.parent / "tests" / "scenarios" / "oscillator" / "oscillator.ssd"


def load() -> str:
    return f"load {os.getloadavg()[0]:.2f}"


def loop(cases: list[dict], stop_time: str) -> tuple[float, float, list[dict]]:
    """(wall s, stepping s, per case {column: (final, min, max)}) of master.run case after case."""
    stepping, stats = 0.0, []
    t0 = time.perf_counter()
    for values in cases:
        r = api.run(SCENE, stop_time=stop_time, set_values={k: repr(v) for k, v in values.items()})
        stepping += r.summary.stepping_time
        d = r.data
        stats.append({c: (d[c][-1], np.min(d[c]), np.max(d[c])) for c in d.dtype.names if c != "time"})
    return time.perf_counter() - t0, stepping, stats


def tree_cpu() -> float:
    """Processor s of this process (client, scheduler) and its descendants alive now (the Dask
    workers, their worker processes): unlike wall time, little changed by other work on the machine."""
    total = 0.0
    for p in [psutil.Process(), *psutil.Process().children(recursive=True)]:
        with contextlib.suppress(psutil.NoSuchProcess):
            t = p.cpu_times()
            total += t.user + t.system
    return total


cases_cpu: list[float] = []  # processor s of each sweep's cases: Executor.map, first task to last result
_map = executor.Executor.map


def _measured_map(self, *args):
    c0 = tree_cpu()
    yield from _map(self, *args)
    cases_cpu.append(tree_cpu() - c0)


executor.Executor.map = _measured_map


def sweep(vary: list[str], workers: int, stop_time: str, reference: list[dict]) -> float:
    """s of the cases of a sweep on `workers` workers; checks its rows against `reference`."""
    with tempfile.TemporaryDirectory() as out:
        r = master.sweep(SCENE, vary, out=out, workers=workers, stop_time=stop_time)
    assert r.ran == len(reference) and r.failed == 0, r.rows[0]["message"]
    for row, ref in zip(r.rows, reference, strict=True):
        for c, (final, low, high) in ref.items():
            got = (row[f"final({c})"], row[f"min({c})"], row[f"max({c})"])
            assert got == (final, low, high), f"case {row['index']} {c}: {got} != {(final, low, high)}"
    return r.cases_time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=200)
    ap.add_argument("--stop-time", default="10", help="s simulated per case (10: 1000 macro steps)")
    ap.add_argument("--repeat", type=int, default=3, help="rounds of the sweeps")
    ap.add_argument("--loops", type=int, default=2, help="rounds that time the loop too (at least 1)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--task-s", type=float, help="the executor's TASK_S, s a batch of cases should last")
    a = ap.parse_args()
    if a.task_s is not None:
        executor.TASK_S = a.task_s
    cpus = len(os.sched_getaffinity(0))
    vary = [f"mass1.c=0.5:2:{a.cases // 10}", "mass2.m=0.5:2:10"]
    cases = points([parse_vary(v, "grid") for v in vary], "grid", None, None)
    n = len(cases)
    print(f"{cpus} usable CPUs; {n} oscillator cases, {a.stop_time} s each; batches of "
          f"{getattr(executor, 'TASK_S', '?')} s; {load()}")  # fmt: skip
    sizes = sorted(set(a.workers) | {1})
    loops, steps, sweeps, cpus = [], [], {w: [] for w in sizes}, {w: [] for w in sizes}
    for k in range(a.repeat):
        print(f"round {k + 1}:")
        if k < max(a.loops, 1):
            before = load()
            wall, stepping, reference = loop(cases, a.stop_time)
            loops.append(wall)
            steps.append(stepping)
            print(f"  loop of master.run: {wall:.2f} s = {1e3 * wall / n:.1f} ms per case "
                  f"(stepping {1e3 * stepping / n:.2f} ms per case; {before})")  # fmt: skip
        for w in sizes:
            before = load()
            t = sweep(vary, w, a.stop_time, reference)
            sweeps[w].append(t)
            cpus[w].append(cases_cpu[-1])
            print(f"  sweep, {w} worker{'s' if w > 1 else ' '}: {t:.2f} s = {1e3 * t / n:.2f} ms per case, "
                  f"{min(loops) / t:.1f}x the loop, bit-identical, processors {1e3 * cases_cpu[-1] / n:.2f} "
                  f"ms per case ({before})")  # fmt: skip
    best = {w: min(ts) for w, ts in sweeps.items()}
    loop_best, step_case = min(loops), statistics.median(steps) / n
    print(f"best of {a.repeat} rounds, the loop's of {len(loops)} (load now {os.getloadavg()[0]:.2f}):")
    print(f"  loop of master.run {1e3 * loop_best / n:.1f} ms per case")
    for w in sizes:
        print(f"  {w} worker{'s' if w > 1 else ' '}: {1e3 * best[w] / n:.2f} ms per case, "
              f"{loop_best / best[w]:.1f}x the loop, {best[1] / best[w]:.2f}x one worker; processors "
              f"{1e3 * statistics.median(cpus[w]) / n:.2f} ms per case (median)")  # fmt: skip
    overhead = best[1] / n - step_case
    print(f"  overhead per case on one worker: {1e3 * overhead:.2f} ms "
          f"({1e3 * best[1] / n:.2f} ms per case less {1e3 * step_case:.2f} ms of stepping)")  # fmt: skip


if __name__ == "__main__":
    main()
