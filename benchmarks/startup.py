"""What a short run costs besides its stepping: the serial worker's fixed costs piece by piece,
and the command line's start.

    .venv/bin/python benchmarks/startup.py [--repeat N] [--no-cli]

Part 1, in this process: a tiny scene (the two-mass oscillator, 10 macro steps of 10 ms) run
`--repeat` times with the serial backend and with the in-process one (medians). The serial run is
taken apart by wrapping the functions that make it (timestamps from both processes on one
monotonic clock): plan, recorder, the backend's open (descriptions, shared memory, janitor,
temporary folder, the fork, the worker's set-up: FMU extraction, loading, instantiation, the
compiled plan; the master's wait for it), initialisation (its commands and the first drain),
stepping, close (the stop command, the worker's FMU teardown, its exit, the reaping, the
temporary folder, the janitor).

Part 2, in fresh processes: `python -c pass`, `import numpy`, `import master`, `master --version`,
`master validate` and `master run` of the oscillator (1000 macro steps) from the shell, serial
and in-process (medians of wall time), with the modules' bytecode cached as an installed
package has it (PYTHONDONTWRITEBYTECODE, if set, is lifted for them), and whole `master.run`s of
the tiny scene and of the oscillator (1000 macro steps), serial and in-process (best of 3 per
process). --against DIR: part 2 for the checkout in DIR as well, the two alternating sample by
sample (before/after figures on a shared machine).

Every figure is a median over `--repeat` runs; the load average is printed with each part: the
machine may be shared.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import master
import master.api as api
import master.backends.component as component_mod
import master.backends.janitor as janitor_mod
import master.backends.worker as worker_mod
import master.backends.workers as workers_mod
import master.fmu as fmu_mod
from master.backends.driver import execute
from master.evidence.oscillator import scene
from master.recorder import Recorder

REPO = Path(__file__).resolve().parent.parent
OSCILLATOR = REPO / "models" / "oscillator" / "SystemStructure.ssd"

_FD: int | None = None  # where every process appends its timestamps


def _mark(label: str) -> None:
    if _FD is not None:
        os.write(_FD, f"{os.getpid()} {time.perf_counter_ns()} {label}\n".encode())


def _wrap(owner: object, attr: str, label: str) -> None:
    """Replace owner.attr by the same function stamping `label` at its start and end (nothing
    where owner has no attr: an older tree, compared with this one)."""
    fn = getattr(owner, attr, None)
    if fn is None:
        return

    @functools.wraps(fn)
    def timed(*args, **kwargs):
        _mark(f"{label}<")
        try:
            return fn(*args, **kwargs)
        finally:
            _mark(f"{label}>")

    setattr(owner, attr, timed)


def instrument() -> None:
    """Stamp the pieces of a serial run (both processes: the worker is forked after this)."""
    w, ws, f = worker_mod, workers_mod, fmu_mod
    _wrap(ws, "read_description", "open: read descriptions (cached)")
    _wrap(ws, "Memory", "open: shared memory")
    _wrap(janitor_mod.Janitor, "close", "close: end the janitor")
    _wrap(ws, "Janitor", "open: start the janitor")
    _wrap(ws.WorkerPool, "__init__", "open: start the worker, wait for its set-up")
    _wrap(w.mp.process.BaseProcess, "start", "open: fork the worker (master side)")
    _wrap(w, "_worker_main", "worker: alive")
    _wrap(w, "_die_with_parent", "worker: prctl")
    _wrap(ws._Task, "setup", "worker: set-up")
    _wrap(ws, "open_fmu", "worker: open an FMU")
    _wrap(f, "safe_extract", "worker: extract an FMU")
    _wrap(component_mod, "safe_extract", "worker: extract an FMU")
    _wrap(f.Fmu, "_load", "worker: load (dlopen, instantiate)")
    _wrap(f.Fmu, "set_values", "worker: set parameters")
    _wrap(f.Fmu, "enter_initialization", "worker: enter initialisation")
    _wrap(ws, "CompiledPlan", "worker: compile the plan")
    _wrap(ws._Task, "close", "worker: free the FMUs")
    _wrap(ws.WorkerBackend, "initialize", "initialise")
    _wrap(ws.WorkerBackend, "run", "step")
    _wrap(ws.WorkerPool, "close", "close: stop, reap the worker")
    _wrap(ws.shutil, "rmtree", "close: remove a folder")


def tiny():
    return scene(split="force", macro_step=Fraction(1, 100), stop_time=Fraction(1, 10), order=2)


def serial_pieces(sc, n: int) -> None:
    """The tiny serial run taken apart: the median of each piece over n runs."""
    global _FD
    instrument()
    pieces: dict[str, list[float]] = {}
    totals: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp:
        for i in range(n):
            stamps = Path(tmp) / f"stamps{i}"
            _FD = os.open(stamps, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
            t = time.perf_counter_ns
            t0 = t()
            p = api.plan(sc)
            t1 = t()
            rec = Recorder(p.columns, None, types=p.column_types)
            t2 = t()
            be = api._make_backend("serial", p)
            be.open()
            t3 = t()
            try:
                execute(p, be, rec)
            finally:
                t4 = t()
                be.close()
            t5 = t()
            os.close(_FD)
            _FD = None
            for k, v in (("plan", t1 - t0), ("recorder", t2 - t1), ("open", t3 - t2)):
                totals.setdefault(k, []).append(v)
            totals.setdefault("initialise + step", []).append(t4 - t3)
            totals.setdefault("close", []).append(t5 - t4)
            totals.setdefault("whole run", []).append(t5 - t0)
            for label, ns in _spans(stamps.read_text(), os.getpid()).items():
                pieces.setdefault(label, []).append(ns)
    print(f"\nserial run of the tiny scene, taken apart (medians of {n}; load {_load()})")
    for k, v in totals.items():
        print(f"  {k:<52} {_ms(v)}")
    print("  pieces (a piece inside another is indented):")
    for label, v in pieces.items():
        indent = "    " if label.startswith("worker:") else "  "
        print(f"  {indent}{label:<{50 - len(indent) + 2}} {_ms(v)}")


def _spans(text: str, master_pid: int) -> dict[str, int]:
    """Per label, the summed time between its start and end stamps; plus the gaps that no stamp
    covers: from the fork to the worker's first line, from its last line to the reaping."""
    open_at: dict[tuple[int, str], int] = {}
    out: dict[str, int] = {}
    firsts: dict[str, int] = {}
    for line in text.splitlines():
        pid, ns, label = line.split(" ", 2)
        kind, name = label[-1], label[:-1]
        if kind == "<":
            open_at[(int(pid), name)] = int(ns)
            firsts.setdefault(name + "<", int(ns))
        else:
            out[name] = out.get(name, 0) + int(ns) - open_at.pop((int(pid), name))
            firsts[name + ">"] = int(ns)
    fork = firsts.get("open: fork the worker (master side)<")
    alive = firsts.get("worker: alive<")
    if fork and alive:
        out["worker: from the fork to its first line"] = alive - fork
    gone, reaped = firsts.get("worker: alive>"), firsts.get("close: stop, reap the worker>")
    if gone and reaped:
        out["close: from the worker's last line to its reaping"] = reaped - gone
    return out


def in_process(sc, n: int) -> None:
    for be in ("serial", "in-process"):
        walls = []
        for _ in range(n):
            t0 = time.perf_counter_ns()
            api.run(sc, backend=be)
            walls.append(time.perf_counter_ns() - t0)
        print(f"  api.run, {be:<44} {_ms(walls)}   (load {_load()})")


PROBE = """
import json, time
from fractions import Fraction
import master.api as api
from master.evidence.oscillator import scene
cases = {"tiny": scene(split="force", stop_time=Fraction(1, 10), order=2),
         "oscillator": scene(split="force", stop_time=Fraction(10), order=2)}
out = {}
for name, sc in [*cases.items()] * 4:
    for be in ("serial", "in-process"):
        t0 = time.perf_counter_ns()
        api.run(sc, backend=be)
        out.setdefault(f"api.run {name} {be} (best of 3)", []).append(time.perf_counter_ns() - t0)
print(json.dumps({k: min(v[1:]) for k, v in out.items()}))  # the first of each: warming up
"""


def cli(n: int, trees: dict[str, str]) -> None:
    """The commands in fresh processes of each tree (PYTHONPATH; run from an empty folder, so
    that no checkout in the current one comes first), interleaved, the trees' order alternating
    from sample to sample; `api.run` (whole runs, best of 3) in a fresh process too."""
    py = sys.executable
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp:
        out = str(Path(tmp) / "o.csv")
        osc = str(OSCILLATOR)
        commands = {
            "python -c pass": [py, "-c", "pass"],
            "python -c 'import numpy'": [py, "-c", "import numpy"],
            "python -c 'import master'": [py, "-c", "import master"],
            "master --version": [py, "-m", "master", "--version"],
            "master validate oscillator": [py, "-m", "master", "validate", osc],
            "master run oscillator --serial": [py, "-m", "master", "run", osc, "-o", out, "-q", "--serial"],
            "master run oscillator --in-process": [
                *[py, "-m", "master", "run", osc, "-o", out, "-q", "--in-process"]
            ],
        }
        envs = {}
        for name, tree in trees.items():
            # compiled modules kept (in tmp), as an installed package has them
            env = {**os.environ, "PYTHONPATH": tree, "PYTHONPYCACHEPREFIX": str(Path(tmp) / name)}
            env.pop("PYTHONDONTWRITEBYTECODE", None)
            envs[name] = env
            for cmd in commands.values():  # warm: FMUs built, caches filled
                subprocess.run(cmd, check=True, capture_output=True, env=env, cwd=tmp)
        walls: dict[str, dict[str, list[int]]] = {name: {} for name in trees}
        loads = []
        for i in range(n):
            for name in list(trees)[:: 1 if i % 2 == 0 else -1]:
                for k, cmd in commands.items():
                    t0 = time.perf_counter_ns()
                    subprocess.run(cmd, check=True, capture_output=True, env=envs[name], cwd=tmp)
                    walls[name].setdefault(k, []).append(time.perf_counter_ns() - t0)
                probe = subprocess.run(
                    [py, "-c", PROBE], check=True, capture_output=True, text=True, env=envs[name], cwd=tmp
                )
                for k, ns in json.loads(probe.stdout).items():
                    walls[name].setdefault(k, []).append(ns)
            loads.append(os.getloadavg()[0])
    print(f"\nfresh processes, medians of {n} (min); load average {min(loads):.2f}-{max(loads):.2f}")
    print("  " + " " * 40 + "".join(f"{name:>28}" for name in trees))
    for k in walls[next(iter(trees))]:
        print(f"  {k:<40}" + "".join(f"{_ms(walls[name][k]):>28}" for name in trees))


def _ms(values: list[int]) -> str:
    return f"{statistics.median(values) / 1e6:7.2f} ms  (min {min(values) / 1e6:6.2f})"


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--no-cli", action="store_true", help="part 1 only")
    ap.add_argument(
        "--against",
        metavar="DIR",
        help="part 2 also for the checkout in DIR (e.g. a `git worktree` of an older commit)",
    )
    args = ap.parse_args(argv)
    sc = tiny()
    print(f"{os.cpu_count()} CPUs, load average {_load()}")
    api.run(sc, backend="serial")  # warm: FMU built, kernel compiled
    print(f"\ntiny scene ({api.plan(sc).n_macro} macro steps), whole api.run (medians of {args.repeat})")
    in_process(sc, args.repeat)
    if not args.no_cli:
        trees = {"this": str(Path(master.__file__).resolve().parent.parent)}  # the tree this process runs
        if args.against:
            trees["against"] = str(Path(args.against).resolve())
        cli(args.repeat, trees)
    serial_pieces(sc, args.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
