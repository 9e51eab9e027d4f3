"""Serial vs parallel backend, measured side by side in one run (not a test: numbers vary by machine).

Run: .venv/bin/python benchmarks/parallel.py [--quick] [--compare-sync] [--start-methods]

Prints wall times of both backends for the paper scenes (when present in models/) and for a
heavy scene of two crashtest FMUs burning `cost_us` of CPU per step, the speed-up, the
synchronisation cost per macro step, and the crossover cost per step below which serial wins.
--compare-sync also times the candidate synchronisation primitives on bare processes;
--start-methods times starting workers with fork, forkserver and spawn.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import select
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np

import master.api as api
from master.backends.auto import choose_backend
from master.backends.worker import NOP, WorkerPool, cpu_count
from master.fmubuild import fmu_path
from master.scenario.model import Component, Connection, Scenario

REPO = Path(__file__).resolve().parent.parent


def heavy(cost_us: float, steps: int, n: int = 2) -> Scenario:
    """n crashtest lags in a ring, explicit Euler: one derivative (cost_us of CPU) per step."""
    ct = fmu_path("crashtest")
    comps = tuple(
        Component(f"c{i}", ct, {"solver": 1, "cost_us": cost_us, "y": float(i)}, 1, 1) for i in range(n)
    )
    conns = tuple(Connection(f"c{i}", "y", f"c{(i + 1) % n}", "u") for i in range(n))
    H = Fraction(1, 1000)
    return Scenario(Path("heavy.ssd"), "heavy", comps, conns, Fraction(0), steps * H, H)


def timed(sc: Scenario, backend: str) -> tuple[float, np.ndarray]:
    """End-to-end wall time of one run (s; worker start and FMU loading included) and its data."""
    t0 = time.perf_counter()
    r = api.run(sc, backend=backend)
    return time.perf_counter() - t0, r.data


def both(sc: Scenario, repeat: int) -> tuple[float, float, bool]:
    """Best serial and parallel wall times (s), runs interleaved so that both see the same load."""
    ts = tp = float("inf")
    same = True
    for _ in range(repeat):
        t, ds = timed(sc, "serial")
        ts = min(ts, t)
        t, dp = timed(sc, "parallel")
        tp = min(tp, t)
        same = same and all(np.array_equal(ds[k], dp[k]) for k in ds.dtype.names)
    return ts, tp, same


def compare(label: str, sc: Scenario, repeat: int) -> tuple[float, float]:
    ts, tp, same = both(sc, repeat)
    n = int((sc.stop_time - sc.start_time) / sc.macro_step)
    print(
        f"{label:<36} {n:>6} {ts:9.3f} {tp:9.3f} {ts / tp:8.2f}   {1e6 * ts / n:9.1f} {1e6 * tp / n:9.1f}"
        f"   {'yes' if same else 'NO'}"
    )
    return ts, tp


def sync_cost(workers: int, rounds: int = 2000) -> float:
    """Mean wall time (s) of one empty command round trip to `workers` workers."""
    from master.backends.auto import _IdleTask

    with WorkerPool([(["idle"], _IdleTask)] * workers) as pool:
        for _ in range(100):
            pool.run(NOP)
        t0 = time.perf_counter()
        for _ in range(rounds):
            pool.run(NOP)
        return (time.perf_counter() - t0) / rounds


# -- bare synchronisation primitives (--compare-sync) --------------------------------------------


def _burn(us: float) -> None:
    end = time.perf_counter() + us * 1e-6
    while time.perf_counter() < end:
        pass


def _w_sem(go, done, work: float) -> None:
    while True:
        go.acquire()
        _burn(work)
        done.release()


def _w_pipe(go_r: int, done_w: int, work: float) -> None:
    while os.read(go_r, 1) == b"g":
        _burn(work)
        os.write(done_w, b"d")


def _w_barrier(bar, work: float) -> None:
    while True:
        bar.wait()
        _burn(work)
        bar.wait()


def _w_spin(seq, i: int, work: float) -> None:
    k = 0
    while True:
        k += 1
        t0 = time.perf_counter()
        while seq[0] < k:
            if time.perf_counter() - t0 > 50e-6:
                time.sleep(0)  # spin 50 us, then yield
        _burn(work)
        seq[1 + i] = k


def primitive(kind: str, n: int, work: float, steps: int = 2000) -> float:
    """Wall time per step (s) of n workers doing `work` us each, synchronised with `kind`."""
    ctx = mp.get_context("fork")
    procs = []
    if kind == "semaphores":
        go = [ctx.Semaphore(0) for _ in range(n)]
        done = [ctx.Semaphore(0) for _ in range(n)]
        procs = [ctx.Process(target=_w_sem, args=(go[i], done[i], work), daemon=True) for i in range(n)]

        def step(k: int) -> None:
            for g in go:
                g.release()
            for d in done:
                d.acquire()
    elif kind == "pipes":
        pipes = [(os.pipe(), os.pipe()) for _ in range(n)]
        procs = [ctx.Process(target=_w_pipe, args=(g[0], d[1], work), daemon=True) for g, d in pipes]
        poll = select.poll()
        for _, d in pipes:
            poll.register(d[0], select.POLLIN)

        def step(k: int) -> None:
            for g, _ in pipes:
                os.write(g[1], b"g")
            pending = n
            while pending:
                for fd, _ in poll.poll():
                    os.read(fd, 1)
                    pending -= 1
    elif kind == "barrier":
        bar = ctx.Barrier(n + 1)
        procs = [ctx.Process(target=_w_barrier, args=(bar, work), daemon=True) for _ in range(n)]

        def step(k: int) -> None:
            bar.wait()
            bar.wait()
    else:  # spinning on a shared sequence counter
        seq = ctx.Array("q", n + 1, lock=False)
        procs = [ctx.Process(target=_w_spin, args=(seq, i, work), daemon=True) for i in range(n)]

        def step(k: int) -> None:
            seq[0] = k
            for i in range(n):
                while seq[1 + i] < k:
                    time.sleep(0)

    for p in procs:
        p.start()
    try:
        for k in range(1, 101):
            step(k)
        t0 = time.perf_counter()
        for k in range(101, 101 + steps):
            step(k)
        return (time.perf_counter() - t0) / steps
    finally:
        for p in procs:
            p.kill()
            p.join()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer steps and repetitions")
    ap.add_argument("--compare-sync", action="store_true", help="time bare synchronisation primitives")
    ap.add_argument(
        "--start-methods", action="store_true", help="time worker start with fork/forkserver/spawn"
    )
    args = ap.parse_args()
    repeat = 1 if args.quick else 3
    steps = 1000 if args.quick else 3000

    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"machine: {cpu_count()} CPUs usable, load average {load}, Python {sys.version.split()[0]}, fork")
    print(
        f"{'scene':<36} {'steps':>6} {'serial s':>9} {'paral s':>9} {'speed-up':>8}   "
        f"{'ser us/st':>9} {'par us/st':>9}   bitwise"
    )
    for scene in ("hydraulic-manipulator", "dc-motor-arm"):
        files = sorted((REPO / "models" / scene).glob("*.ssd"))
        if not files:
            print(f"{scene:<36} (no scenario in models/{scene})")
            continue
        sc = api.load_scenario(files[0])
        compare(scene, sc, repeat)
    for cost in (100, 200, 400):
        compare(f"heavy: 2 crashtest x {cost} us/step", heavy(cost, steps), repeat)

    s2 = min(sync_cost(2) for _ in range(repeat))
    print(
        f"\nsynchronisation: one empty macro step with 2 workers costs {1e6 * s2:.1f} us (best of {repeat})"
    )

    print("\ncrossover sweep (2 x crashtest, Euler, one derivative per step):")
    print(f"{'cost_us':>8} {'serial us/st':>13} {'parallel us/st':>15} {'speed-up':>9} {'auto picks':>11}")
    crossover = None
    previous = None
    for cost in (0, 10, 20, 30, 50, 75, 100, 150):
        sc = heavy(cost, steps // 2)
        n = steps // 2
        ts, tp, _ = both(sc, repeat)
        pick = choose_backend(api.plan(sc))[0]
        print(f"{cost:8d} {1e6 * ts / n:13.1f} {1e6 * tp / n:15.1f} {ts / tp:9.2f} {pick:>11}")
        if crossover is None and tp < ts and previous is not None:
            crossover = (previous, cost)
        previous = cost
    if crossover:
        print(
            f"crossover: parallel wins from a cost between {crossover[0]} and {crossover[1]} us per FMU step"
        )

    print(f"load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if args.compare_sync:
        print("\nbare synchronisation primitives, 2 workers, wall per step (us), best of 3:")
        for work in (0, 100):
            cells = [
                f"{k} {1e6 * min(primitive(k, 2, work) for _ in range(3)):7.1f}"
                for k in ("semaphores", "pipes", "barrier", "spin")
            ]
            print(f"  work {work:3d} us: " + " | ".join(cells))

    if args.start_methods:
        from master.backends.auto import _IdleTask

        print("\nworker start (2 workers, no FMU), best of 3:")
        for method in ("fork", "forkserver", "spawn"):
            best = float("inf")
            for _ in range(3):
                t0 = time.perf_counter()
                with WorkerPool([(["idle"], _IdleTask)] * 2, start_method=method) as pool:
                    pool.run(NOP)
                best = min(best, time.perf_counter() - t0)
            print(f"  {method:<10} {1e3 * best:7.1f} ms (start, one command, stop)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
