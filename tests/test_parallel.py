"""Parallel backend: bit-identical to the serial backend, failures isolated and reported.

Real FMUs built from C run in real worker processes; no child process may outlive a run.
"""

import dataclasses
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from fractions import Fraction
from pathlib import Path

import numpy as np
import psutil
import pytest
from fmpy.util import read_csv
from helpers import started

import master.api as api
from master.backends.auto import MARGIN, choose_backend, decide
from master.backends.component import SimulationError
from master.backends.workers import WorkerBackend, worker_groups
from master.evidence.oscillator import scene
from master.fmubuild import fmu_path
from master.scenario.model import Component, Connection, Scenario
from master.solvers import EULER, RK4

REPO = Path(__file__).resolve().parent.parent


def helper_pids() -> set[int]:
    """multiprocessing's own helpers (resource tracker, fork server) may stay; workers may not."""
    from multiprocessing import forkserver, resource_tracker

    pids = {getattr(resource_tracker._resource_tracker, "_pid", None)}
    pids.add(getattr(forkserver._forkserver, "_forkserver_pid", None))
    return {p for p in pids if p}


def assert_no_children() -> None:
    deadline = time.monotonic() + 10.0  # a loaded machine may take a while to reap them
    while True:
        left = [p for p in psutil.Process().children(recursive=True) if p.pid not in helper_pids()]
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    assert left == [], f"processes left behind: {left}"


def oscillator(H=Fraction(1, 100), order=2, coupling="jacobi", ratios=(1, 1), interpolate=(True, True)):
    """Two-mass oscillator, parameter set A, split in two msd FMUs (as tests/test_oscillator.py)."""
    return scene(
        split="force",
        macro_step=H,
        stop_time=Fraction(3),
        order=order,
        step_ratios=ratios,
        coupling=coupling,
        interpolate=interpolate,
        substeps=20,
        path=Path("oscillator.ssd"),
    )


def lags(n=2, stop=Fraction(2), H=Fraction(1, 100), params=None, ratios=None, xorder=2, **kw) -> Scenario:
    """n crashtest lags in a ring (c0.y -> c1.u -> ... -> c0.u); params per component name."""
    ct = fmu_path("crashtest")
    params = params or {}
    ratios = ratios or [1] * n
    comps = tuple(
        Component(
            f"c{i}", ct, {"solver": RK4, "y": float(i) - 0.5, **params.get(f"c{i}", {})}, ratios[i], xorder
        )
        for i in range(n)
    )
    conns = tuple(Connection(f"c{i}", "y", f"c{(i + 1) % n}", "u") for i in range(n))
    base = dict(
        path=Path("lags.ssd"),
        name="lags",
        components=comps,
        connections=conns,
        start_time=Fraction(0),
        stop_time=stop,
        macro_step=H,
    )
    base.update(kw)
    return Scenario(**base)


def assert_identical(sc: Scenario) -> np.ndarray:
    a = api.run(sc, backend="serial")
    b = api.run(sc, backend="parallel")
    da, db = a.data, b.data
    assert da.dtype.names == db.dtype.names
    every = 1 if sc.record_interval is None else int(sc.record_interval / sc.macro_step)
    assert len(da) == 1 + int((sc.stop_time - sc.start_time) / sc.macro_step) // every
    for name in da.dtype.names:
        assert np.array_equal(da[name], db[name]), f"{name} differs"
    assert a.summary.steps == b.summary.steps
    assert_no_children()
    return da


@pytest.mark.parametrize(
    "variant",
    [
        dict(),
        dict(order=3, interpolate=(False, False)),
        dict(ratios=(1, 4), order=1, interpolate=(False, False)),
        dict(coupling="gauss-seidel", order=2),
        dict(coupling="gauss-seidel", order=1, ratios=(1, 3), interpolate=(True, False)),
    ],
    ids=["jacobi-interpolating", "jacobi-order3", "multirate-1-4", "gauss-seidel", "gauss-seidel-1-3"],
)
def test_oscillator_bitwise_equal_to_serial(variant):
    d = assert_identical(oscillator(**variant))
    assert np.ptp(d["mass1.x"]) > 0.5  # it really oscillates


def test_oscillator_scenario_file_bitwise_equal():
    sc = api.load_scenario(REPO / "tests" / "scenarios" / "oscillator" / "oscillator.ssd")
    assert_identical(dataclasses.replace(sc, stop_time=sc.start_time + 200 * sc.macro_step))


def test_multirate_ring_with_groups_bitwise_equal():
    """Three lags, step ratios 1/3/2, two of them sharing a worker (scenario groups)."""
    sc = lags(3, ratios=[1, 3, 2], xorder=2)
    comps = list(sc.components)
    comps[1] = dataclasses.replace(comps[1], group="g")
    comps[2] = dataclasses.replace(comps[2], group="g")
    sc = dataclasses.replace(sc, components=tuple(comps))
    p = api.plan(sc)
    assert worker_groups(p) == [["c0"], ["c1", "c2"]]
    d = assert_identical(sc)
    assert np.ptp(d["c1.y"]) > 0.1


def test_source_history_long_enough_for_a_higher_order_consumer():
    """c0 has no inputs, c1 (k = 3) extrapolates it with order 3: c0's ring must hold k + 3 + 1
    samples, else the source overwrites samples the consumer still reads (serial and parallel alike)."""
    sc = lags(2, xorder=3, ratios=[1, 3], record=(("c0", "y"), ("c1", "u"), ("c1", "y")))
    d = assert_identical(dataclasses.replace(sc, connections=(Connection("c0", "y", "c1", "u"),)))
    assert np.array_equal(d["c1.u"], d["c0.y"])  # a recorded input: its source's sample at the row
    # c1.y' = -c1.y + u, u held through each step of h = H/3 at the cubic through c0.y = -0.5 exp(-t)
    # at the step's start (RK4 is exact for a constant u to ~h^5): the exact recurrence with the
    # exact u differs only by the start-up's lower orders (3.7e-8, decaying) and the cubic's
    # error (H^4 / 24 ~ 4e-10 in u); samples overwritten too early would be off by ~1e-3 in u
    h, y = 0.01 / 3, [0.5]
    for j in range(len(d) * 3):
        y.append(y[-1] * np.exp(-h) + (1 - np.exp(-h)) * -0.5 * np.exp(-j * h))
    assert np.max(np.abs(d["c1.y"] - np.array(y[::3][: len(d)]))) < 1e-7


def test_gauss_seidel_chain_and_recorded_locals():
    """Gauss-Seidel chain c0 -> c1 -> c2 across workers; recorded Integer and local Real come from
    the workers."""
    rec = (("c0", "y"), ("c2", "y"), ("c1", "der(y)"), ("c2", "mode"), ("c0", "cost_us"))
    sc = lags(
        3, coupling="gauss-seidel", order=("c0", "c1", "c2"), record=rec, record_interval=Fraction(1, 20)
    )
    d = assert_identical(sc)
    assert np.all(d["c2.mode"] == 0) and np.ptp(d["c1.der(y)"]) > 0.1


@pytest.mark.parametrize("scene", ["dc-motor-arm", "hydraulic-manipulator"])
def test_paper_scene_bitwise_equal(scene):
    files = sorted((REPO / "models" / scene).glob("*.ssd"))
    if not files:
        pytest.skip(f"models/{scene} has no scenario yet")
    sc = api.load_scenario(files[0])
    n = int((sc.stop_time - sc.start_time) / sc.macro_step)
    assert_identical(dataclasses.replace(sc, stop_time=sc.start_time + min(n, 300) * sc.macro_step))


# -- failures ------------------------------------------------------------------------------------

CAUSES = {  # the FMU's own message formatted with its arguments
    1: "SIGSEGV",
    2: "hang",
    3: "SIGABRT",
    4: "crashtest: error requested at t = 0.5",
    5: "status 4 (fatal)",
}


def named_shm(procs: list) -> set[str]:
    """The files in /dev/shm that these processes map and that still have a name: what their death
    would leave behind. Looked up in the processes themselves, not by listing /dev/shm, where
    other work on the machine makes and removes entries of its own."""
    names = set()
    for p in procs:
        with open(f"/proc/{p.pid}/maps") as maps:
            names |= {line.split(maxsplit=5)[5].strip() for line in maps if " /dev/shm/" in line}
    return {n for n in names if not n.endswith("(deleted)")}


@pytest.mark.parametrize("backend", ["serial", "parallel"])
@pytest.mark.parametrize("mode", [1, 2, 3, 4, 5], ids=["segfault", "hang", "abort", "error", "fatal"])
def test_failure_is_reported_with_component_time_and_cause(mode, backend, tmp_path, monkeypatch):
    """c1 of three (not the last one a serial worker loaded) misbehaves from t = 0.5 s: the run
    stops there, every row before it is kept (a lagging peer completes the macro steps before the
    failing one first), readable by fmpy, and no process or temporary folder is left (nor named
    shared memory: test_signal_stops_cleanly_with_partial_results)."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    sc = lags(3, params={"c1": {"mode": mode, "at_time": 0.5}})
    out = tmp_path / "out.csv"
    with pytest.raises(SimulationError) as info:  # how soon a hang is told: benchmarks/stops.py
        api.run(sc, backend=backend, output=out, step_timeout=0.5)
    e = info.value
    msg = str(e)
    assert e.component == "c1" and "c1" in msg
    assert CAUSES[mode] in msg
    assert e.time == pytest.approx(0.5, abs=0.011), msg
    assert "0.5" in msg
    data = e.result.data
    assert data["time"][-1] == pytest.approx(0.5, abs=0.011)
    assert len(data) >= 50
    assert "failed" in e.result.summary.stop_reason
    rows = out.read_text().splitlines()
    assert len(rows) == 1 + len(data)
    assert np.array_equal(read_csv(str(out))["c0.y"], data["c0.y"])
    assert list(tmp_path.glob("master-run-*")) == []  # the dead worker's extracted FMU too
    assert_no_children()


@pytest.mark.parametrize("backend", ["serial", "parallel"])
@pytest.mark.parametrize("mode", [1, 2], ids=["segfault", "hang"])
def test_the_summary_of_a_crashed_run_counts_the_steps_done_before(mode, backend):
    """c1 of three crashes or hangs in its step from t = 0.49 s: every component has done 49
    steps (H = 0.01 s, one step per macro step) and spent time inside its FMU by then; the summary
    says so instead of "0 steps, 0.000 s inside the FMU"."""
    sc = lags(3, params={"c1": {"mode": mode, "at_time": 0.5}})
    with pytest.raises(SimulationError) as info:
        api.run(sc, backend=backend, step_timeout=0.5)
    summary = info.value.result.summary
    assert all(summary.steps[c] >= 49 for c in ("c0", "c1", "c2")), summary.steps
    assert all(summary.fmu_time[c] > 0 for c in ("c0", "c1", "c2")), summary.fmu_time
    assert "c1: 0 steps" not in str(summary)
    assert_no_children()


def test_an_fmu_ending_the_simulation_ends_the_run_normally():
    """crashtest mode 6 discards its step reaching t = 0.5 s with fmi2Terminated (FMI 2: the
    step's results are not valid): every backend ends at that step's start, t = 0.49 s, without
    an error, with the same rows up to there (as fmpy ends such an FMU)."""
    sc = lags(3, params={"c1": {"mode": 6, "at_time": 0.5}})
    runs = {be: api.run(sc, backend=be) for be in ("in-process", "serial", "parallel")}
    ref = runs["in-process"].data
    assert ref["time"][-1] == pytest.approx(0.49) and len(ref) == 50
    for be, r in runs.items():
        assert r.summary.stop_reason == "finished: c1 ended the simulation at t=0.49", be
        assert r.summary.macro_steps == 49
        assert all(np.array_equal(ref[k], r.data[k]) for k in ref.dtype.names), be
    # inside a macro step (c1 steps twice per macro step and ends in its second step of the one
    # from 0.49 s): the run ends at that macro step's start, its last complete one
    half = lags(2, params={"c1": {"mode": 6, "at_time": 0.5}}, ratios=[1, 2])
    for be in ("in-process", "parallel"):
        r = api.run(half, backend=be)
        assert r.data["time"][-1] == pytest.approx(0.49) and "t=0.495" in r.summary.stop_reason, be
    # a worker still far behind when the stop comes (independent components, a slow one; longer
    # than the driver's 0.1 s budget): its rows up to the stop are kept all the same
    apart = dataclasses.replace(lags(2, params={"c0": {"mode": 6, "at_time": 0.5}, "c1": {"cost_us": 3000}}),
                                connections=())  # fmt: skip
    r = api.run(apart, backend="parallel")
    assert len(r.data) == 50 and r.summary.macro_steps == 49 and "c0 ended" in r.summary.stop_reason
    assert_no_children()


def test_a_worker_of_several_slow_components_is_not_a_hang():
    """The step timeout bounds one component's macro step, not a worker's: three components of
    0.4 s per step in one worker (1.2 s per macro step) under a 1 s timeout finish (each 0.6 s
    below it, room for a loaded machine)."""
    slow = {f"c{i}": {"cost_us": 400_000, "solver": EULER} for i in range(3)}
    r = api.run(lags(3, stop=Fraction(3, 100), params=slow), backend="serial", step_timeout=1.0)
    assert r.summary.macro_steps == 3
    assert_no_children()


@pytest.mark.parametrize(
    "params",
    [{"c1": {"mode": 7}}, {"c1": {"no_such": 1.0}}, {"c1": {"mode": 4, "at_time": 0.25}}],
    ids=["out-of-range", "unknown-variable", "fmi2Error"],
)
def test_errors_read_as_in_the_serial_backend(params):
    """Errors raised by the component code cross the process boundary word for word."""
    sc = lags(2, params=params)
    errors = []
    for backend in ("serial", "parallel"):
        with pytest.raises(Exception) as info:
            api.run(sc, backend=backend)
        errors.append(info.value)
    assert type(errors[0]) is type(errors[1])
    assert str(errors[0]) == str(errors[1])
    assert "c1" in str(errors[1])
    assert_no_children()


def test_exclusive_fmu_runs_twice_only_in_workers():
    """An FMU allowing one instance per process that does not say so: serial (one worker) fails,
    one worker per instance works."""
    sc = lags(2, params={"c0": {"exclusive": True}, "c1": {"exclusive": True}})
    with pytest.raises(Exception, match="another exclusive instance"):
        api.run(sc, backend="serial")
    d = api.run(sc, backend="parallel").data
    assert len(d) == 201
    assert_no_children()


def flagged(tmp_path: Path, flag: str) -> Path:
    """The crashtest FMU with a capability flag of its CoSimulation element set to "true"."""
    import zipfile

    out = tmp_path / f"{flag}.fmu"
    with zipfile.ZipFile(fmu_path("crashtest")) as zin, zipfile.ZipFile(out, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b"<CoSimulation ", f'<CoSimulation {flag}="true" '.encode())
            zout.writestr(item, data)
    return out


def test_declared_once_per_process_gets_a_worker_per_instance(tmp_path):
    """canBeInstantiatedOnlyOncePerProcess="true": every backend with workers gives each instance
    its own, with the serial results; the in-process backend refuses in one line."""
    once = flagged(tmp_path, "canBeInstantiatedOnlyOncePerProcess")
    sc = lags(3, params={f"c{i}": {"exclusive": True} for i in range(3)})
    sc = dataclasses.replace(
        sc, components=tuple(dataclasses.replace(c, fmu_path=once) for c in sc.components)
    )
    p = api.plan(sc)
    assert p.exclusive == (("c0", "c1", "c2"),) and any("once per process" in n for n in p.notes)
    serial = api.run(sc, backend="serial")
    assert serial.summary.backend == "serial" and len(serial.data) == 201
    parallel = api.run(sc, backend="parallel").data
    assert all(np.array_equal(serial.data[k], parallel[k]) for k in parallel.dtype.names)
    with pytest.raises(api.UsageError, match="only once per process"):
        api.run(sc, backend="in-process")
    assert_no_children()


def test_an_fmu_that_needs_its_execution_tool_is_run_with_a_note_said_once(tmp_path, caplog):
    """needsExecutionTool="true" (every pythonfmu FMU): the run goes on (the tool may be there),
    with a note naming the components of that FMU, said once per process however many runs use
    it, and at INFO level: --quiet (WARNING) silences it."""
    sc, tool = lags(3), flagged(tmp_path, "needsExecutionTool")
    flagged_ones = tuple(dataclasses.replace(c, fmu_path=tool) for c in sc.components[:2])
    sc = dataclasses.replace(sc, components=(*flagged_ones, *sc.components[2:]))
    with caplog.at_level("INFO", logger="master"):
        for backend in ("serial", "parallel", "serial"):
            assert len(api.run(sc, backend=backend).data) == 201
    said = [r for r in caplog.records if "needsExecutionTool" in r.getMessage()]
    assert [(r.levelname, r.getMessage()) for r in said] == [
        ("INFO", 'c0, c1: needsExecutionTool.fmu declares needsExecutionTool="true": the run fails unless '
         "that tool is installed here")
    ]  # fmt: skip
    assert_no_children()


@contextmanager
def long_run(
    tmp_path: Path, backend: str = "parallel", under: tuple[str, ...] = ()
) -> Iterator[tuple[subprocess.Popen, list[psutil.Process], Path]]:
    """A run of 1000 s in a child process (started by the command `under`, e.g. nohup), once its
    workers are busy; killed with all it started when the block ends."""
    script, out = tmp_path / "run.py", tmp_path / "out.csv"
    here, costly = str(Path(__file__).parent), "{'c0': {'cost_us': 200}, 'c1': {'cost_us': 200}}"
    script.write_text(
        f"import sys\nfrom fractions import Fraction\nsys.path.insert(0, {here!r})\n"
        "import test_parallel as t\nimport master.api as api\n"
        f"sc = t.lags(2, stop=Fraction(1000), params={costly})\n"
        f"try:\n    api.run(sc, backend={backend!r}, output={str(out)!r})\n"
        "except api.SimulationError as e:\n    print('STOPPED', e, flush=True)\n"
    )
    env = {**os.environ, "TMPDIR": str(tmp_path)}  # what a killed master cannot remove stays in tmp_path
    with started([*under, sys.executable, script], stdout=subprocess.PIPE, text=True, env=env) as proc:
        ps = psutil.Process(proc.pid)
        workers = 1 if backend == "serial" else 2
        deadline = time.monotonic() + 120  # how long a loaded machine may take to start it
        while len(ps.children()) < workers and time.monotonic() < deadline:
            time.sleep(0.1)
        while not (out.exists() and out.stat().st_size > 2000) and time.monotonic() < deadline:
            time.sleep(0.05)  # until it has computed (and drained) some macro steps
        assert out.exists() and out.stat().st_size > 2000, "the run did not start within 120 s"
        yield proc, ps.children(recursive=True), out


def assert_clean_stop(proc, children, out: Path, tmp_path: Path, said: str) -> None:
    """The run said `said`, wrote fmpy-readable rows so far, and left no process and no temp folder."""
    stdout, _ = proc.communicate(timeout=60)  # it takes 0.1-2 s, loaded: benchmarks/stops.py
    assert said in stdout
    data = read_csv(str(out))
    assert len(data) > 10 and np.all(np.diff(data["time"]) > 0)
    assert list(tmp_path.glob("master-run-*")) == []  # extracted FMUs removed
    gone, alive = psutil.wait_procs(children, timeout=10)
    assert alive == []


@pytest.mark.parametrize("backend", ["serial", "parallel"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["INT", "TERM", "HUP"])
def test_signal_stops_cleanly_with_partial_results(tmp_path, backend, sig):
    """Ctrl-C, SIGTERM or SIGHUP to the master: the signal named, rows so far written, no worker
    left, and no shared memory with a name in /dev/shm that could outlive them."""
    with long_run(tmp_path, backend) as (proc, children, out):
        assert len(children) >= 1
        assert named_shm([proc, *children]) == set()
        os.kill(proc.pid, sig)
        assert_clean_stop(proc, children, out, tmp_path, f"STOPPED interrupted ({sig.name})")


def test_a_run_under_nohup_goes_on_after_a_hangup(tmp_path):
    """nohup ignores SIGHUP for the command it starts: the run keeps that choice (it goes on),
    and the SIGTERM sent after the SIGHUP is the one that stops it."""
    with long_run(tmp_path, "serial", under=("nohup",)) as (proc, children, out):
        os.kill(proc.pid, signal.SIGHUP)
        size = out.stat().st_size
        while out.stat().st_size < size + 20000 and proc.poll() is None:
            time.sleep(0.05)  # rows written after the hangup (a stop would not get that far)
        assert proc.poll() is None, f"the hangup stopped it: {proc.communicate()[0]}"
        os.kill(proc.pid, signal.SIGTERM)
        assert_clean_stop(proc, children, out, tmp_path, "STOPPED interrupted (SIGTERM)")


@pytest.mark.parametrize("backend", ["serial", "parallel"])
def test_killed_worker_is_reported_with_its_component(tmp_path, backend):
    with long_run(tmp_path, backend) as (proc, children, out):
        victim = children[-1]
        victim.kill()
        assert_clean_stop(proc, children, out, tmp_path, "worker process killed by signal SIGKILL")


def test_cli_exit_code_follows_the_signal(tmp_path):
    """SIGTERM to `master run`: exit code 143 (128 + 15), the rows so far in the CSV file."""
    out = tmp_path / "out.csv"
    scene = REPO / "tests" / "scenarios" / "oscillator" / "oscillator.ssd"
    cmd = [
        sys.executable,
        "-m",
        "master",
        "run",
        str(scene),
        "--stop-time",
        "100000",
        "-o",
        str(out),
        "--serial",
    ]
    with started(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        deadline = time.monotonic() + 120
        while not (out.exists() and out.stat().st_size > 10000) and time.monotonic() < deadline:
            time.sleep(0.1)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "interrupted (SIGTERM)" in err
    assert len(read_csv(str(out))) > 100


@pytest.mark.parametrize("backend", ["serial", "parallel"])
def test_workers_die_with_a_killed_master_and_its_folders_go(tmp_path, backend):
    """SIGKILL to the master alone (no clean-up possible there): the workers still end
    (PR_SET_PDEATHSIG), nothing is left in /dev/shm (the shared memory is anonymous, semaphores
    unlinked at once), and the janitor removes the run's temporary folders (extracted FMUs, raw
    results) from TMPDIR; the rows written to the CSV file stay."""
    with long_run(tmp_path, backend) as (proc, children, out):
        assert len(children) >= 2  # the workers and the janitor
        assert named_shm([proc, *children]) == set()
        assert list(tmp_path.glob("master-run-*")) and list(tmp_path.glob("master_results_*"))
        proc.kill()
        proc.communicate(timeout=60)
        gone, alive = psutil.wait_procs(children, timeout=10)
        assert alive == []  # before the block's end kills what is left of the process group
    assert list(tmp_path.glob("master-run-*")) == [] and list(tmp_path.glob("master_results_*")) == []
    data = read_csv(str(out))
    assert len(data) > 10 and np.all(np.diff(data["time"]) > 0)


def test_auto_decides_from_the_timed_trials():
    """The rule on given figures (s per macro step), then the trials on a real scene: the choice
    follows the rule on what they measured (which depends on the machine's load, the rule not)."""
    assert decide(100e-6, 50e-6, 0.01, 1000) == "parallel"
    assert decide(100e-6, 90e-6, 0.0, 10**6) == "serial"  # not MARGIN times faster
    assert decide(100e-6, 50e-6, 0.1, 1000) == "serial"  # 50 ms saved, 100 ms more to start
    assert choose_backend(api.plan(lags(1)))[0] == "serial"  # one worker: nothing to overlap
    heavy = api.plan(lags(2, stop=Fraction(20), params={f"c{i}": {"cost_us": 400} for i in range(2)}))
    choice, why = choose_backend(heavy)
    serial, parallel = (float(x) * 1e-6 for x in re.findall(r"([0-9.]+) us/step", why))
    if choice == "parallel":
        assert parallel * MARGIN < serial
    r = api.run(lags(2, stop=Fraction(1, 10)), backend="auto")
    assert r.summary.backend.split()[0] in ("serial", "parallel") and "(auto:" in r.summary.backend
    assert_no_children()


def test_backend_close_without_open_and_twice():
    p = api.plan(lags(2))
    be = WorkerBackend(p, worker_groups(p))
    be.close()
    be.open()
    be.close()
    be.close()
    assert_no_children()


def test_pinned_and_paced_workers_give_the_same_results():
    """--cpus pins the workers (all on the first allowed processor here), --real-time paces them
    on one clock: the same bits as a free run, every frame of the paced one counted."""
    sc = lags(2, stop=Fraction(1, 10))
    free = api.run(sc, backend="parallel").data
    cpu = min(os.sched_getaffinity(0))
    pinned = api.run(sc, backend="parallel", cpus=[cpu])
    paced = api.run(sc, backend="parallel", real_time=1.0)
    for r in (pinned, paced):
        assert all(np.array_equal(free[k], r.data[k]) for k in free.dtype.names)
    assert paced.summary.wall_time > 0.09 and paced.summary.lateness is not None
    assert paced.summary.overruns is not None
    assert_no_children()


class _Hangs:
    """A worker task whose every command hangs (as an FMU that never returns)."""

    def setup(self, where):
        pass

    def command(self, op, a, b, where):
        time.sleep(3600)

    def close(self):
        pass


def test_a_killed_worker_is_reaped_so_the_failure_does_not_wait_for_its_answer():
    """Hang detection: the supervisor kills the hung worker and the others settle; a killed worker
    not yet reaped looked alive to `settle`, which then waited SETTLE_S (2 s) for its answer on
    top of the step timeout. `kill` reaps it: its exit code is known at once."""
    from master.backends.worker import WorkerPool

    pool = WorkerPool([(["a"], _Hangs), (["b"], _Hangs)], step_timeout=60)
    try:
        pool.start(1)
        pool.kill(0)
        assert pool.procs[0].exitcode == -signal.SIGKILL
        assert pool.procs[1].exitcode is None  # the other one is still in its command
    finally:
        pool.close()
    assert_no_children()
