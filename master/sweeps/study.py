"""`master.sweep`: run one scenario over many parameter values on a Dask cluster.

result = master.sweep("models/oscillator/oscillator.ssd", vary=["mass1.k=1:4:4"], out="results/k")
result.rows  # one dict per case: varied values, status, message, final(...), min(...), max(...)
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from master.backends.driver import stop_signals
from master.recorder import TEXT_TYPES
from master.scenario.model import Scenario
from master.sweeps.case import FINISHED, LOST, OK, CaseOptions, run_case
from master.sweeps.cases import SweepError, bind, case_key, parse_vary, points, scenario_hash
from master.sweeps.executor import Executor
from master.sweeps.metrics import parse_metric, unit_of
from master.sweeps.store import append_series, read_cases, series_keys, write_cases

FLUSH_S = 2.0  # s between rewrites of the table while cases finish


@dataclass
class SweepResult:
    """What a sweep left in `folder`: `rows` of this sweep's cases in order (dicts: "case" key,
    "index", the varied values, "status", "message", "wall_time", "t_end", "final(col)",
    "min(col)", "max(col)", metrics), and how many ran now, were skipped as done, or failed."""

    folder: Path
    rows: list[dict]
    scene: str = ""  # the scenario's name
    ran: int = 0
    skipped: int = 0
    failed: int = 0
    dashboard: str | None = None
    points: list[dict] = field(default_factory=list)  # the varied values of each case, in order
    # the unit of each varied variable, table column ("final(col)", ...) and metric; None: none known
    units: dict[str, str | None] = field(default_factory=dict)
    startup_time: float = 0.0  # s to start (or reach) the cluster
    cases_time: float = 0.0  # s from the first case sent to the last result back


def sweep(
    scenario: str | Path | Scenario,
    vary: list[str],
    *,
    method: str = "grid",
    samples: int | None = None,
    seed: int | None = None,
    metrics: list[str] | None = None,
    out: str | Path = "results/sweep",
    series: bool = False,
    scheduler: str | None = None,
    workers: int | None = None,
    stop_time: float | str | Fraction | None = None,
    macro_step: float | str | Fraction | None = None,
    set_values: list[str] | None = None,
    record: list[str] | None = None,
    output_interval: float | str | Fraction | None = None,
    step_timeout: float | None = None,
    progress: bool = False,
) -> SweepResult:
    """Run `scenario` once per case and write `out`/cases.parquet (and series.zarr with `series`).

    vary: "COMP.VAR=START:STOP:N" (grid: the cartesian product of the ranges) or
    "COMP.VAR=START:STOP" with method "lhs" or "sobol" and `samples` points drawn in that box
    with `seed`. metrics: "NAME=EXPR" over the recorded columns (master.sweeps.metrics). Without
    `scheduler` a local Dask cluster of `workers` processes (default: the usable CPUs) runs the
    cases; with "tcp://host:port" an existing cluster does. A failed case is kept with its status
    and message; a rerun with the same scenario skips the cases already in `out`.
    Raises SweepError for a bad argument, before anything runs.
    """
    from master import api

    sc = _scene(api, scenario, stop_time, set_values, record, output_interval, macro_step)
    plan = api.plan(sc)
    columns = [c for c in plan.columns[1:] if plan.column_types.get(c) not in TEXT_TYPES]  # numbers
    ranges = bind([parse_vary(v, method) for v in vary], sc)
    cases = points(ranges, method, samples, seed)
    checked = tuple(parse_metric(m, ["time", *columns]) for m in metrics or [])
    table = _table_columns([r.name for r in ranges], columns, [m.name for m in checked])
    folder = Path(out)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        earlier = read_cases(folder)
    except OSError as e:
        raise SweepError(f"--out {folder}: {e.strerror or e}") from None
    h = scenario_hash(sc)
    keys = [case_key(h, values) for values in cases]
    with_series = series_keys(folder) if series else None
    done = {
        r["case"]: r
        for r in earlier
        if r.get("status") in FINISHED and all(c in r for c in table)
        and (with_series is None or r["case"] in with_series)
    }  # fmt: skip
    ours = set(keys)
    others = [r for r in earlier if r["case"] not in ours]  # rows of other sweeps in the folder: kept
    rows: dict[str, dict] = {k: {**done[k], "index": i} for i, k in enumerate(keys) if k in done}
    todo = [i for i, k in enumerate(keys) if k not in done]
    result = SweepResult(folder, [], scene=sc.name, skipped=len(rows), points=cases)
    result.units = _units(api._units(sc, plan), ranges, columns, checked)
    grid = _time_grid(plan)
    options = CaseOptions(metrics=checked, series=series, step_timeout=step_timeout)
    pending: list[tuple[int, np.ndarray]] = []  # (case index, rows) not yet in the series store

    def flush() -> None:
        ordered = sorted(rows.values(), key=lambda r: r["index"])
        write_cases(folder, ordered + others, table)
        if pending:
            varied = {r.name: [float(cases[i][r.name]) for i, _ in pending] for r in ranges}
            append_series(folder, grid, [keys[i] for i, _ in pending], [s for _, s in pending], varied)
            pending.clear()

    shown = _Progress(len(todo), progress or sys.stderr.isatty())
    try:  # SIGTERM and SIGHUP stop it as Ctrl-C does: the finished cases are written
        with stop_signals():
            if todo:
                t0 = time.perf_counter()
                with Executor(workers, scheduler) as ex:
                    result.dashboard = ex.dashboard
                    shown.start(ex)
                    last = time.monotonic()
                    t1 = time.perf_counter()
                    result.startup_time = t1 - t0
                    for j, outcome in ex.map(run_case, [cases[i] for i in todo], sc, ranges, options):
                        i = todo[j]
                        row = _row(keys[i], i, cases[i], outcome, columns, checked)
                        rows[keys[i]] = row
                        result.ran += 1
                        result.failed += row["status"] != OK
                        if series and row["status"] != LOST:
                            s = outcome.get("series") if isinstance(outcome, dict) else None
                            pending.append((i, s if s is not None else _no_rows(columns)))
                        shown.update(result.ran, result.failed)
                        if time.monotonic() - last > FLUSH_S:
                            flush()
                            last = time.monotonic()
                    result.cases_time = time.perf_counter() - t1
    finally:
        flush()
        shown.end()
    result.rows = sorted(rows.values(), key=lambda r: r["index"])
    return result


def _scene(api, scenario, stop_time, set_values, record, output_interval, macro_step=None) -> Scenario:
    """The scenario as `master.run` would run it with these options."""
    if isinstance(scenario, Scenario):
        if macro_step is not None:  # as master.run: the step ratios are kept
            scenario = dataclasses.replace(scenario, macro_step=api._times(None, macro_step)["macro_step"])
        return api.apply_overrides(scenario, stop_time, record, set_values, output_interval)
    texts = dict(api._split_set(s) for s in set_values) if set_values else None  # checked by the reader
    sc = api.load_scenario(scenario, texts, stop_time, macro_step)  # a file from another tool needs them
    return api.apply_overrides(sc, stop_time, record, None, output_interval)


def _units(recorded: dict[str, str | None], ranges, columns: list[str], metrics) -> dict[str, str | None]:
    """The unit of each varied variable (its FMU's), statistic of a recorded column (the column's)
    and metric (`unit_of`)."""
    units = {r.name: r.var.unit if r.var is not None else None for r in ranges}
    units |= {f"{s}({c})": recorded.get(c) for c in columns for s in ("final", "min", "max")}
    return units | {m.name: unit_of(m, recorded) for m in metrics}


def _table_columns(varied: list[str], columns: list[str], metrics: list[str]) -> list[str]:
    stats = [f"{s}({c})" for c in columns for s in ("final", "min", "max")]
    return ["case", "index", *varied, "status", "message", "wall_time", "t_end", *stats, *metrics]


def _row(key: str, index: int, values: dict, outcome, columns: list[str], metrics) -> dict:
    """One table row from a case's outcome (a run_case dict, or the exception that lost it)."""
    nan = math.nan
    row = {"case": key, "index": index, **{k: float(v) for k, v in values.items()}}
    if not isinstance(outcome, dict):
        row.update(status=LOST, message=f"{type(outcome).__name__}: {outcome}", wall_time=nan, t_end=nan)
        outcome = {"columns": {}, "metrics": {}}
    else:
        row.update(status=outcome["status"], message=outcome["message"], wall_time=outcome["wall_time"],
                   t_end=outcome["t_end"])  # fmt: skip
    for c in columns:
        final, low, high = outcome["columns"].get(c, (nan, nan, nan))
        row.update({f"final({c})": final, f"min({c})": low, f"max({c})": high})
    row.update({m.name: outcome["metrics"].get(m.name, nan) for m in metrics})
    return row


def _time_grid(plan) -> np.ndarray:
    """The times of the rows a run records (the start, every `record_every` macro steps, the stop),
    as the kernel computes them: (num0 + j dnum) / den in double precision."""
    from master.schedule import Clock

    sc = plan.scenario
    steps = np.arange(0, plan.n_macro + 1, plan.record_every, dtype=np.int64)
    if steps[-1] != plan.n_macro:
        steps = np.append(steps, plan.n_macro)
    clock = Clock.make(sc.start_time, sc.macro_step, 1)
    return (clock.num0 + steps * clock.dnum) / clock.den


def _no_rows(columns: list[str]) -> np.ndarray:
    return np.zeros(0, dtype=[("time", float)] + [(c, float) for c in columns])


class _Progress:
    """Cases done, failed, rate and time left, on one line of stderr (a terminal, or when asked)."""

    def __init__(self, total: int, shown: bool):
        self.total, self.shown, self.t0 = total, shown, time.monotonic()

    def start(self, ex: Executor) -> None:
        if self.shown:
            where = ex.scheduler or f"local cluster of {ex.workers} workers"
            print(f"{self.total} cases on {where}; dashboard: {ex.dashboard or 'none'}", file=sys.stderr)
            self.t0 = time.monotonic()

    def update(self, done: int, failed: int) -> None:
        if not self.shown:
            return
        rate = done / max(time.monotonic() - self.t0, 1e-9)
        left = (self.total - done) / rate if rate > 0 else math.inf
        print(f"\r{done}/{self.total} cases, {failed} failed, {rate:.1f}/s, {left:.0f} s left   ",
              end="", file=sys.stderr, flush=True)  # fmt: skip

    def end(self) -> None:
        if self.shown and self.total:
            print(file=sys.stderr)
