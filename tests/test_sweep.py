"""Parameter sweeps on real dask.distributed clusters: a LocalCluster of worker processes, and a
scheduler with two workers started as separate processes on 127.0.0.1. Every case is a real run
of real FMUs; the tests stop every process they start."""

import os
import signal
import subprocess
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import psutil
import pyarrow.parquet as pq
import pytest
import xarray as xr
from helpers import finished, started
from test_parallel import assert_no_children, lags

import master
import master.api as api
from master.sweeps import SweepError
from master.sweeps.cases import parse_vary, points
from master.sweeps.metrics import parse_metric, unit_of
from master.sweeps.plot import sweep_figure

REPO = Path(__file__).resolve().parent.parent
OSCILLATOR = REPO / "tests" / "scenarios" / "oscillator" / "oscillator.ssd"
GRID = ["mass1.c=1:3:3", "mass2.m=0.5:2:4"]  # 3 x 4 cases
BIN = Path(sys.executable).parent


def single_run(values: dict, stop_time: str = "2") -> np.ndarray:
    return api.run(OSCILLATOR, stop_time=stop_time, set_values={k: repr(v) for k, v in values.items()}).data


def assert_matches_single_runs(result, series: bool) -> None:
    assert [r["status"] for r in result.rows] == ["ok"] * 12
    for row, values in zip(result.rows, result.points, strict=True):
        data = single_run(values)
        for col in ("mass1.x", "mass1.v"):  # bit for bit: the same kernel, the same arithmetic
            assert row[f"final({col})"] == data[col][-1]
            assert row[f"min({col})"] == data[col].min() and row[f"max({col})"] == data[col].max()
        assert row["peak"] == np.max(np.abs(data["mass1.x"]))
    if series:
        with xr.open_zarr(result.folder / "series.zarr") as ds:
            assert ds.sizes == {"case": 12, "time": len(data)}
            assert np.array_equal(ds["time"].values, data["time"])
            last = ds.sel(case=result.rows[-1]["case"])
            assert np.array_equal(last["mass1.x"].values, data["mass1.x"])
            assert float(last["mass2.m"]) == result.points[-1]["mass2.m"]


def test_grid_on_a_local_cluster_matches_single_runs_and_a_rerun_skips_it(tmp_path):
    kw = dict(metrics=["peak=max(abs(mass1.x))"], out=tmp_path, workers=2, stop_time="2")
    result = master.sweep(OSCILLATOR, GRID, series=True, **kw)
    assert (result.ran, result.skipped, result.failed) == (12, 0, 0), result.rows[0]["message"]
    assert_matches_single_runs(result, series=True)
    table = pq.read_table(tmp_path / "cases.parquet").to_pylist()
    assert [r["case"] for r in table] == [r["case"] for r in result.rows]
    assert [(r["mass1.c"], r["mass2.m"]) for r in table] == [
        (c, m) for c in (1, 2, 3) for m in (0.5, 1, 1.5, 2)
    ]

    # each axis of the plot says its unit: the FMU's for the parameter, the column's for a metric
    assert (result.units["mass1.c"], result.units["peak"], result.units["final(mass1.v)"]) == (
        "N/m",
        "m",
        "m/s",
    )
    (ax,) = sweep_figure(result, "oscillator").axes  # one metric: one panel, a line per mass2.m
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("mass1.c [N/m]", "peak [m]")
    assert ax.get_legend_handles_labels()[1][0] == "mass2.m = 0.5 kg"

    again = master.sweep(OSCILLATOR, GRID, series=True, **kw)
    assert (again.ran, again.skipped) == (0, 12)
    assert again.rows == result.rows
    wider = master.sweep(OSCILLATOR, ["mass1.c=1:5:5", "mass2.m=0.5:2:4"], **kw)  # 12 of 20 done
    assert (wider.ran, wider.skipped) == (8, 12)
    with xr.open_zarr(tmp_path / "series.zarr") as ds:
        assert ds.sizes["case"] == 12  # the wider sweep asked for no series
    assert_no_children()


def test_a_crashing_case_is_recorded_and_the_others_complete(tmp_path):
    # crashtest mode 1 segfaults from at_time on, 3 aborts; mode 7 is outside the variable's range
    sc = lags(2, stop=Fraction(1))
    result = master.sweep(sc, ["c0.mode=0:1:2", "c0.at_time=0.25:0.75:3"], out=tmp_path, workers=2)
    status = {(r["c0.mode"], r["c0.at_time"]): r for r in result.rows}
    for t in (0.25, 0.5, 0.75):
        assert status[0, t]["status"] == "ok" and status[0, t]["t_end"] == 1.0
        crashed = status[1, t]
        assert crashed["status"] == "failed"
        assert "c0" in crashed["message"] and "SIGSEGV" in crashed["message"]
        assert crashed["t_end"] < t + 1e-9  # the rows before the crash are kept in its summary
    bad = master.sweep(sc, ["c0.mode=3:7:2"], out=tmp_path / "b", workers=2)
    assert [r["status"] for r in bad.rows] == ["failed", "invalid"]
    assert "abort" in bad.rows[0]["message"].lower() or "SIGABRT" in bad.rows[0]["message"]
    assert "outside the range" in bad.rows[1]["message"]
    assert_no_children()


@pytest.fixture
def dask_cluster(tmp_path):
    """`dask scheduler` and two `dask worker` processes on 127.0.0.1, stopped after the test (the
    other tests check that no process of theirs is left)."""
    folder = tmp_path / "dask"
    folder.mkdir()
    file = folder / "scheduler.json"
    common = dict(cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    procs = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(file)], **common)]  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while not file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        for _ in range(2):
            procs.append(subprocess.Popen([str(BIN / "dask"), "worker", "--scheduler-file", str(file),
                                           "--nthreads", "1", "--no-dashboard", "--host", "127.0.0.1"],
                                          **common))  # fmt: skip
        from distributed import Client

        with Client(scheduler_file=str(file), timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
            address = client.scheduler_info()["address"]
        yield address
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs[::-1]:
            try:
                p.wait(15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def test_grid_on_a_separate_scheduler_and_workers(tmp_path, dask_cluster):
    result = master.sweep(OSCILLATOR, GRID, metrics=["peak=max(abs(mass1.x))"], out=tmp_path,
                          scheduler=dask_cluster, stop_time="2", series=True)  # fmt: skip
    assert_matches_single_runs(result, series=True)
    crash = master.sweep(
        lags(2, stop=Fraction(1)), ["c0.mode=0:1:2"], out=tmp_path / "c", scheduler=dask_cluster
    )
    assert [r["status"] for r in crash.rows] == ["ok", "failed"]


@pytest.mark.parametrize("method", ["lhs", "sobol"])
def test_random_designs_are_seeded_and_fill_the_box(method):
    ranges = [parse_vary("a.x=-1:3", method), parse_vary("a.y=10:20", method)]
    one = points(ranges, method, 16, seed=7)
    assert one == points(ranges, method, 16, seed=7)
    assert one != points(ranges, method, 16, seed=8)
    for r in ranges:  # both designs put exactly one point in each of the 16 strata of every axis
        unit = np.array([(p[r.name] - r.start) / (r.stop - r.start) for p in one])
        assert sorted(np.floor(unit * 16).astype(int)) == list(range(16))


def test_grid_is_the_cartesian_product_and_bad_specs_say_why():
    grid = points([parse_vary("a.x=0:1:3", "grid"), parse_vary("a.y=5:5:1", "grid")], "grid", None, None)
    assert grid == [{"a.x": 0.0, "a.y": 5.0}, {"a.x": 0.5, "a.y": 5.0}, {"a.x": 1.0, "a.y": 5.0}]
    for spec, method, words in [
        ("a.x=0:1", "grid", "START:STOP:N"),
        ("a.x=0:1:3", "lhs", "--samples"),
        ("x=0:1:3", "grid", "COMP.VAR"),
        ("a.x=0:one:3", "grid", "numbers"),
        ("a.x=0:1:0", "grid", "at least 1"),
    ]:
        with pytest.raises(SweepError, match=words):
            parse_vary(spec, method)
    with pytest.raises(SweepError, match="--samples"):
        points([parse_vary("a.x=0:1", "lhs")], "lhs", None, None)


def test_metrics_compute_what_they_say_and_run_no_python():
    t = np.linspace(0.0, 2.0, 201)
    data = np.zeros(len(t), dtype=[("time", float), ("m.x", float), ("m.v", float)])
    data["time"], data["m.x"], data["m.v"] = t, np.sin(np.pi * t), t
    cols = ["time", "m.x", "m.v"]
    value = {text: parse_metric(f"k={text}", cols)(data) for text in
             ["integral(m.v)", "at(m.v, 0.705)", "max(m.x) - min(m.x)", "final(m.v) ** 2 / 2",
              "time_of_max(m.x)", "rms(col('m.v'))", "mean(abs(m.x))"]}  # fmt: skip
    assert value["integral(m.v)"] == pytest.approx(2.0, rel=1e-12)  # exact for a linear signal
    assert value["at(m.v, 0.705)"] == pytest.approx(0.705, rel=1e-12)
    assert value["max(m.x) - min(m.x)"] == pytest.approx(2.0, rel=1e-12)
    assert value["final(m.v) ** 2 / 2"] == 2.0
    assert value["time_of_max(m.x)"] == pytest.approx(0.5)
    assert value["rms(col('m.v'))"] == pytest.approx(np.sqrt(np.mean(t**2)))
    assert value["mean(abs(m.x))"] == pytest.approx(
        np.mean(np.abs(np.sin(np.pi * t))), rel=1e-12
    )  # of samples
    units = {"m.x": "m", "m.v": "m/s"}
    unit = {text: unit_of(parse_metric(f"k={text}", cols), units) for text in value}
    assert unit == {"integral(m.v)": "m/s.s", "at(m.v, 0.705)": "m/s", "max(m.x) - min(m.x)": "m",
                    "final(m.v) ** 2 / 2": None, "time_of_max(m.x)": "s", "rms(col('m.v'))": "m/s",
                    "mean(abs(m.x))": "m"}  # fmt: skip
    assert unit_of(parse_metric("k=-2 * max(m.x) / 3", cols), units) == "m"
    assert unit_of(parse_metric("k=max(m.x) * max(m.v)", cols), units) is None  # the product's unit: unsaid
    assert unit_of(parse_metric("k=max(m.x) - max(m.v)", cols), units) is None
    for text, words in [
        ("k=__import__('os').system('true')", "is not allowed"),
        ("k=__import__('os')", "unknown function __import__"),
        ("k=m.x.__class__", "no recorded column"),
        ("k=m.x", "reduce it"),
        ("k=max(m.z)", "no recorded column 'm.z'"),
        ("k=[1][0]", "not allowed"),
        ("k=lambda: 1", "not allowed"),
        ("2k=final(m.x)", "plain name"),
        ("k=max(m.x", "not an expression"),
    ]:
        with pytest.raises(SweepError, match=words):
            parse_metric(text, cols)


def test_cli_sweep_writes_the_table_and_refuses_bad_input_in_one_line(tmp_path):
    out = tmp_path / "sw"
    png = tmp_path / "sw.png"
    cmd = [str(BIN / "master"), "sweep", str(OSCILLATOR), "--vary", "mass1.c=1:2:2",
           "--vary", "mass2.m=1:2:2", "--metric", "peak=max(abs(mass1.x))", "--workers", "2",
           "--stop-time", "1", "--out", str(out), "--plot", str(png)]  # fmt: skip
    far = tmp_path / "far"
    unreachable = cmd[:3] + ["--vary", "mass1.c=1:2:2", "--scheduler", "tcp://127.0.0.1:1", "--out", str(far)]
    # it waits out its 10 s connect timeout meanwhile, next to the other runs
    with started(unreachable, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                 text=True) as waiting:  # fmt: skip
        done = finished(cmd, 300, cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        assert "4 cases: 4 run (0 failed), 0 done earlier" in done.stdout
        assert len(pq.read_table(out / "cases.parquet")) == 4 and png.stat().st_size > 0
        for bad, words in [
            (["--vary", "mass1.nope=1:2:2"], "component mass1 has no variable 'nope'"),
            (["--vary", "mass1.x=1:2:2"], "causality output"),
            (["--vary", "mass1.c=1:2:2", "--metric", "p=open('f')"], "unknown function open"),
        ]:
            done = finished(cmd[:3] + bad + ["--out", str(tmp_path / "bad")], 120, cwd=tmp_path)
            _assert_one_line_error(done.returncode, done.stderr, words)
        _, err = waiting.communicate(timeout=120)
    _assert_one_line_error(waiting.returncode, err, "cannot connect")


def _assert_one_line_error(returncode: int, stderr: str, words: str) -> None:
    assert returncode == 1 and words in stderr, stderr
    assert "Traceback" not in stderr and len(stderr.strip().splitlines()) == 1


def _flaky(suffix: str, item: str) -> str:
    """A task for the executor test: fails for "boom", takes its Dask worker down for "die"."""
    if item == "boom":
        raise ValueError("boom")
    if item == "die":
        os._exit(3)
    return item + suffix


def test_the_executor_keeps_going_past_an_item_that_raises_or_kills_its_worker():
    from master.sweeps.executor import Executor

    with Executor(workers=2) as ex:
        outcomes = dict(ex.map(_flaky, ["a", "boom", "b"], "!"))
        assert outcomes[0] == "a!" and outcomes[2] == "b!"
        assert isinstance(outcomes[1], ValueError)
        # Dask retries a task whose worker died (allowed-failures), then gives it up as lost
        (lost,) = ex.map(_flaky, ["die"], "!")
        assert lost[0] == 0 and "KilledWorker" in type(lost[1]).__name__
        assert list(ex.map(_flaky, ["c"], "?")) == [(0, "c?")]  # the cluster goes on
    assert_no_children()


def test_a_batch_lasts_about_task_s_starts_at_one_item_and_shrinks_at_the_end():
    from master.sweeps.executor import MAX_BATCH, TASK_S, batch_size

    assert batch_size(1000, None, 2) == 1  # no item's time known yet: every worker starts at once
    for per_item in (TASK_S / 7, TASK_S / 30):
        k = batch_size(1000, per_item, 2)
        assert k * per_item <= TASK_S < (k + 1) * per_item  # short items: a task lasts TASK_S
    assert batch_size(1000, 3 * TASK_S, 2) == 1  # long items: one per task
    assert batch_size(10**6, 1e-9, 2) == MAX_BATCH  # never more than a lost worker may lose
    left, sizes = 1000, []
    while left:  # the whole sweep at one speed: each batch at most a quarter of those left on 2 threads
        sizes.append(batch_size(left, 1e-6, 2))
        assert 1 <= sizes[-1] <= max(1, left // 4)
        left -= sizes[-1]
    assert sizes[0] == MAX_BATCH and sizes[-3:] == [1, 1, 1]


def _tagged(tag: str, item: tuple[int, float]) -> tuple[str, int]:
    time.sleep(item[1])
    return tag, item[0]


def test_the_executor_runs_every_item_once_as_its_batches_change_size(monkeypatch):
    from master.sweeps import executor

    sizes: list[int] = []
    rule = executor.batch_size
    monkeypatch.setattr(executor, "batch_size", lambda *a: sizes.append(rule(*a)) or sizes[-1])
    items = [(i, 0.0 if i < 150 else 0.002) for i in range(300)]  # the items' time changes midway
    with executor.Executor(workers=2) as ex:
        got = list(ex.map(_tagged, items, "x"))
    assert sorted(i for i, _ in got) == list(range(300))  # each item once
    assert all(outcome == ("x", i) for i, outcome in got)  # under its own index
    assert sum(sizes) == 300 and sizes[0] == 1 and len(set(sizes)) > 2
    assert_no_children()


def _stopped(cmd: list[str], out: Path, sig: int, cwd: Path) -> set[str]:
    """Runs the sweep `cmd` until it (re)writes its table, stops it with `sig`; the cases it kept
    (their keys), after checking that it stopped as that signal says and left no process behind."""
    table = out / "cases.parquet"
    before = table.stat().st_mtime_ns if table.exists() else None
    with started(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # the table is written 2 s after the first case, atomically
            if table.exists() and table.stat().st_mtime_ns != before:
                break
            time.sleep(0.1)
        helpers = psutil.Process(proc.pid).children(recursive=True)  # the Dask cluster, the runs' workers
        assert helpers
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + sig, err
    assert "interrupted" in err and "Traceback" not in err
    kept = pq.read_table(table).to_pylist()
    assert all(r["status"] == "ok" for r in kept)
    _, alive = psutil.wait_procs(helpers, timeout=10)
    assert alive == []
    return {r["case"] for r in kept}


def test_a_stopped_sweep_keeps_its_finished_cases_and_the_same_command_goes_on(tmp_path):
    """Stopped by SIGINT, the same command goes on and is stopped by SIGTERM, and once more runs the
    rest: each stop keeps the cases finished so far (the second those of the first too), and the
    last run does only the cases not done earlier."""
    out = tmp_path / "sw"
    cmd = [str(BIN / "master"), "sweep", str(OSCILLATOR), "--vary", "mass1.c=0.5:2:50", "--vary",
           "mass2.m=0.5:2:2", "--stop-time", "4000", "--workers", "2", "--out", str(out)]  # fmt: skip
    first = _stopped(cmd, out, signal.SIGINT, tmp_path)
    assert 0 < len(first) < 100
    second = _stopped(cmd, out, signal.SIGTERM, tmp_path)
    assert first < second and len(second) < 100
    done = finished(cmd, 300, cwd=tmp_path)
    n = len(second)
    assert f"100 cases: {100 - n} run (0 failed), {n} done earlier" in done.stdout, done.stderr
