"""How soon a run stops: after a signal to the master, and after a component hangs (not a test:
the figures depend on the machine and its load, which the tests must not bound).

    .venv/bin/python benchmarks/stops.py [--repeats 3] [--load N]

Signal: a run of two crashtest lags (200 us of CPU per step, 1000 s) in a child process gets
SIGINT or SIGTERM once it has written rows; printed: the seconds from the signal to the child's
exit (rows written, workers stopped), median and worst of the repeats, serial and parallel.
Hang: one of three lags hangs at t = 0.5 s under a step timeout of 0.5 s; printed: the seconds
from the start of the run to its error, beside the same run without the hang, and the difference
in step timeouts. --load N runs N busy loops beside it (as a loaded machine), stopped at the end.
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import master.api as api
from master.fmubuild import fmu_path
from master.scenario.model import Component, Connection, Scenario
from master.solvers import RK4

STEP_TIMEOUT = 0.5


def ring(n: int, stop: Fraction, params: dict[str, dict] | None = None) -> Scenario:
    """n crashtest lags in a ring (c0.y -> c1.u -> ... -> c0.u), RK4, H = 10 ms."""
    ct, params = fmu_path("crashtest"), params or {}
    comps = tuple(
        Component(f"c{i}", ct, {"solver": RK4, "y": i - 0.5, **params.get(f"c{i}", {})}, 1, 2)
        for i in range(n)
    )
    conns = tuple(Connection(f"c{i}", "y", f"c{(i + 1) % n}", "u") for i in range(n))
    return Scenario(Path("ring.ssd"), "ring", comps, conns, Fraction(0), stop, Fraction(1, 100))


def child(backend: str, out: str) -> None:
    """The signalled run: SIGINT at Python's handler whoever started it (a & job ignores it)."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    costly = {"c0": {"cost_us": 200}, "c1": {"cost_us": 200}}
    try:
        api.run(ring(2, Fraction(1000), costly), backend=backend, output=out)
    except api.SimulationError as e:
        print("STOPPED", e, flush=True)


def stop_latency(backend: str, sig: signal.Signals) -> float:
    """Seconds from `sig` to the exit of a run that has written some rows."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.csv"
        cmd = [sys.executable, __file__, "--child", backend, str(out)]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env={**os.environ, "TMPDIR": tmp})
        try:
            while not (out.exists() and out.stat().st_size > 2000):
                if proc.poll() is not None:
                    raise SystemExit(f"the run ended before the signal: {proc.communicate()[0]}")
                time.sleep(0.05)
            t0 = time.monotonic()
            proc.send_signal(sig)
            said, _ = proc.communicate()
            latency = time.monotonic() - t0
        finally:
            proc.kill()
            proc.wait()
        if f"interrupted ({sig.name})" not in said:
            raise SystemExit(f"{backend} {sig.name}: the run said {said!r}")
        return latency


def hang_seconds(backend: str, mode: int) -> float:
    """Wall seconds of a run of three lags to t = 1 s in which c1 misbehaves (`mode`) from 0.5 s."""
    sc = ring(3, Fraction(1), {"c1": {"mode": mode, "at_time": 0.5}})
    t0 = time.monotonic()
    try:
        stop = Fraction(1, 2) if mode == 0 else None
        api.run(sc, backend=backend, step_timeout=STEP_TIMEOUT, stop_time=stop)
    except api.SimulationError as e:
        if "hang" not in str(e):
            raise
    return time.monotonic() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--load", type=int, default=0, help="busy loops to run beside it")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(*args.child)
        return 0
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.load)]
    try:
        time.sleep(1.0 if burners else 0.0)
        load = os.getloadavg()[0]
        print(f"{os.cpu_count()} CPUs, {args.load} busy loops beside it, load average {load:.2f}")
        for backend in ("serial", "parallel"):
            for sig in (signal.SIGINT, signal.SIGTERM):
                s = [stop_latency(backend, sig) for _ in range(args.repeats)]
                print(
                    f"{backend:8s} {sig.name:7s} stop after the signal: median {statistics.median(s):.2f} s, "
                    f"worst {max(s):.2f} s ({args.repeats} runs)"
                )
        for backend in ("serial", "parallel"):
            hung = [hang_seconds(backend, 2) for _ in range(args.repeats)]
            free = [hang_seconds(backend, 0) for _ in range(args.repeats)]
            h, f = statistics.median(hung), statistics.median(free)
            print(
                f"{backend:8s} hang at t = 0.5 s told after {h:.2f} s (worst {max(hung):.2f}); unhung to "
                f"t = 0.5 s {f:.2f} s: {(h - f) / STEP_TIMEOUT:.1f} step timeouts of {STEP_TIMEOUT} s"
            )
        print(f"load average {os.getloadavg()[0]:.2f} after")
    finally:
        for b in burners:
            b.kill()
            b.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
