"""Warm sessions (master.backends.session): the cases of a sweep run one after another in one worker
process whose FMUs are loaded once and reset between cases, each bit for bit the single run of
`master.run`; a failed case ends the session and the next case runs in a fresh one."""

import dataclasses
import os
from fractions import Fraction
from pathlib import Path

import numpy as np
import psutil
import pytest
from test_clocks import SCENE as CLOCKS
from test_cs_events import network
from test_iterated import set_b
from test_loops import ring
from test_model_exchange import oscillator as me_oscillator
from test_parallel import assert_no_children, lags
from test_sweep import dask_cluster  # noqa: F401  (a fixture)

import master
import master.api as api
from master.backends import session
from master.backends.component import SimulationError
from master.fmu import Fmu
from master.fmubuild import fmu_path
from master.recorder import Recorder
from master.scenario.model import Scenario, Scheme

REPO = Path(__file__).resolve().parent.parent
OSCILLATOR = REPO / "tests" / "scenarios" / "oscillator" / "oscillator.ssd"


@pytest.fixture(autouse=True)
def no_session_left():
    yield
    session.close_warm()
    assert_no_children()


def varied(sc: Scenario, values: dict[str, dict]) -> Scenario:
    """`sc` with these parameter values per component (as a sweep's case sets them)."""
    comps = tuple(
        dataclasses.replace(c, parameters={**c.parameters, **values.get(c.name, {})}) for c in sc.components
    )
    return dataclasses.replace(sc, components=comps)


def worker_pid() -> int:
    (s,) = session._warm.values()
    return s.pid


def assert_same_run(warm, fresh) -> None:
    assert warm.data.dtype == fresh.data.dtype and len(warm.data) == len(fresh.data)
    for name in fresh.data.dtype.names:  # bit for bit: the same kernel, the same arithmetic
        assert np.array_equal(warm.data[name], fresh.data[name]), name
    assert warm.summary.steps == fresh.summary.steps
    assert warm.summary.stop_reason == fresh.summary.stop_reason
    assert warm.summary.iterations == fresh.summary.iterations


def built(sc: Scenario, fmi: int) -> Scenario:
    """`sc` with the FMI `fmi` build of each component's FMU."""
    comps = tuple(
        dataclasses.replace(c, fmu_path=fmu_path(Path(c.fmu_path).stem, fmi)) for c in sc.components
    )
    return dataclasses.replace(sc, components=comps)


SCENES = {  # a scene and, per case, the values of its parameters
    "oscillator": (
        lambda tmp: api.load_scenario(OSCILLATOR, None, "2"),
        [{"mass1": {"c": c}, "mass2": {"m": m}} for c, m in ((1.0, 1.0), (2.5, 0.5), (0.5, 2.0))],
    ),
    "multirate-ring": (
        lambda tmp: lags(3, stop=Fraction(1), ratios=[1, 3, 2]),
        [{"c1": {"y": y}} for y in (0.5, -2.0, 3.0)],
    ),
    "fmi1": (
        lambda tmp: built(lags(2, stop=Fraction(1), ratios=[1, 2]), 1),
        [{"c0": {"y": y}} for y in (0.5, -2.0, 3.0)],
    ),
    "fmi3": (
        lambda tmp: built(lags(2, stop=Fraction(1), ratios=[2, 1]), 3),
        [{"c1": {"y": y}} for y in (0.5, -2.0, 3.0)],
    ),
    "model-exchange": (
        lambda tmp: me_oscillator("rk4", True),
        [{"mass2": {"cc": cc}} for cc in (1.0, 4.0, 0.25)],
    ),
    "algebraic-loop": (
        lambda tmp: ring(tmp),
        [{"g1": {"k": k}} for k in (0.5, -0.3, 0.9)],
    ),
    "iterated": (
        lambda tmp: set_b(Fraction(1), stop=Fraction(10)),
        [{"mass1": {"c": c}} for c in (1.0, 2.0, 0.5)],
    ),
    "fmi3-event-mode": (  # stair -> latch -> latch, their events handled in event mode by the kernel
        lambda tmp: network(Scheme.GAUSS_SEIDEL),
        [{"clock": {"period": p}} for p in (1.0, 0.7, 1.3)],
    ),
    "scheduled-execution": (  # the Reference FMUs' Clocks: partitions activated by the kernel
        lambda tmp: api.load_scenario(CLOCKS),
        [{}, {}],
    ),
}


@pytest.mark.parametrize("name", SCENES)
def test_cases_run_in_one_worker_process_equal_single_runs(name, tmp_path):
    build, cases = SCENES[name]
    base = build(tmp_path)
    pids = []
    for values in cases + cases[:1]:  # the first case again last: after two resets as fresh
        sc = varied(base, values)
        assert_same_run(session.warm_run(sc), api.run(sc))
        pids.append(worker_pid())
    assert len(set(pids)) == 1  # one worker process, its FMUs loaded once


@pytest.mark.parametrize("mode", [1, 4], ids=["segfault", "error"])
def test_a_failed_case_is_the_single_runs_failure_and_the_next_case_runs_fresh(mode):
    base = lags(3, stop=Fraction(1))
    ok = varied(base, {"c1": {"y": 2.0}})
    failing = varied(base, {"c1": {"mode": mode, "at_time": 0.5}})
    session.warm_run(ok)
    first = worker_pid()
    with pytest.raises(SimulationError) as warm:
        session.warm_run(failing)
    with pytest.raises(SimulationError) as fresh:
        api.run(failing)
    assert str(warm.value) == str(fresh.value)
    assert (warm.value.component, warm.value.time) == (fresh.value.component, fresh.value.time)
    assert_same_run(warm.value.result, fresh.value.result)  # the rows up to the failure
    assert session._warm == {} and not psutil.pid_exists(first)  # the session ended with its worker
    assert_same_run(session.warm_run(ok), api.run(ok))
    assert worker_pid() != first


def test_the_structure_decides_which_cases_share_a_session():
    sc = api.load_scenario(OSCILLATOR, None, "2")
    key = session.structure(sc)
    assert session.structure(varied(sc, {"mass1": {"c": 7.0}, "mass2": {"solver": 2}})) == key
    for other in (
        dataclasses.replace(sc, macro_step=sc.macro_step / 2),
        dataclasses.replace(
            sc, components=(dataclasses.replace(sc.components[0], step_ratio=2),) + sc.components[1:]
        ),
        api.apply_overrides(sc, record=["mass1.x"]),
        api.apply_overrides(sc, stop_time="3"),
    ):
        assert session.structure(other) != key
    assert session.structure(sc, step_timeout=1.0) != key

    # a case of another structure replaces the session: a new worker, the old one gone
    session.warm_run(sc)
    first = worker_pid()
    longer = api.apply_overrides(sc, stop_time="3")
    assert_same_run(session.warm_run(longer), api.run(longer))
    assert worker_pid() != first and not psutil.pid_exists(first)


def test_cases_that_change_a_stimulus_value_share_the_session_and_equal_single_runs():
    sc = api.load_scenario(REPO / "tests" / "scenarios" / "step_force.ssd")
    step = next(s for s in sc.stimuli if s.kind == "step")
    pids = []
    for value in (1.0, -2.0, 5.0):
        values = (value,) + step.values[1:]
        case = dataclasses.replace(
            sc, stimuli=tuple(dataclasses.replace(s, values=values) if s is step else s for s in sc.stimuli)
        )
        assert session.structure(case) == session.structure(sc)
        assert_same_run(session.warm_run(case), api.run(case))
        pids.append(worker_pid())
    assert len(set(pids)) == 1


@pytest.mark.parametrize("fmi", [1, 2, 3])
def test_a_renewed_fmu_is_back_at_its_start_values_and_steps_as_a_fresh_one(fmi):
    """fmiResetSlave / fmi2Reset / fmi3Reset of the project's FMI layer: the instance is back in
    its state after instantiation, every parameter at its start value; run again, it gives what a
    new instance gives, bit for bit (the bouncing ball: events inside its steps)."""

    def get(fmu: Fmu):
        return fmu.slave.getFloat64 if fmu.fmi3 else fmu.slave.getReal

    def trajectory(fmu: Fmu, values: dict) -> list[float]:
        fmu.set_values(values)
        fmu.enter_initialization(0.0, 2.0)
        fmu.exit_initialization()
        out = []
        for n in range(200):
            fmu.do_step(n * 0.01, 0.01)
            out += get(fmu)([fmu.variables["h"].vr, fmu.variables["v"].vr])
        return out

    path = fmu_path("bouncing_ball", fmi)
    used = Fmu(path, "ball", event_mode=False)  # steps driven here, events inside them
    try:
        trajectory(used, {"h0": 3.0, "e": 0.5})
        assert used.renew() is False  # reset: the same instance
        used.enter_initialization(0.0, 2.0)
        starts = {n: float(used.variables[n].start) for n in ("h0", "e", "g")}
        assert get(used)([used.variables[n].vr for n in starts]) == list(starts.values())
        used.renew()
        again = trajectory(used, {"h0": 2.0, "e": 0.8})
    finally:
        used.close()
    fresh = Fmu(path, "ball", event_mode=False)
    try:
        assert again == trajectory(fresh, {"h0": 2.0, "e": 0.8})
    finally:
        fresh.close()


def test_a_sweep_on_one_worker_reuses_its_process_and_matches_single_runs(tmp_path):
    """Through Dask: a failing case among others (the worker process of its session dies with
    it); every case's row is the single run's, the failed one's message too."""
    sc = lags(3, stop=Fraction(1))
    result = master.sweep(sc, ["c1.mode=0:1:2", "c1.y=-1:1:3"], out=tmp_path, workers=1)
    for row, values in zip(result.rows, result.points, strict=True):
        case = varied(sc, {"c1": {"mode": int(values["c1.mode"]), "y": values["c1.y"], "at_time": 0.0}})
        if values["c1.mode"] == 0:
            data = api.run(case).data
            assert row["status"] == "ok" and row["final(c0.y)"] == data["c0.y"][-1]
            assert row["min(c2.y)"] == data["c2.y"].min() and row["max(c2.y)"] == data["c2.y"].max()
        else:
            with pytest.raises(SimulationError) as fresh:
                api.run(case)
            assert row["status"] == "failed" and row["message"] == str(fresh.value)


def test_a_recorder_in_memory_gives_the_rows_a_file_gives():
    """A warm run's rows stay in memory (no folder per case); where a column holds Strings they
    go to the side file as ever."""
    rows = np.arange(12.0).reshape(4, 3)
    rows[:, 2] = np.array([-1, 2**40, 3, 4], dtype=np.int64).view(np.float64)  # an int64's bits
    types = {"n": "int64"}
    kept, filed = (
        Recorder(["time", "x", "n"], types=types, in_memory=True),
        Recorder(["time", "x", "n"], types=types),
    )
    for r in (kept, filed):
        r.write(rows[:1])
        r.next_row()[:] = rows[1]
        r.commit()
        r.write(rows[2:])
        r.close()
    assert kept.tmpdir is None and kept.rows == filed.rows == 4
    assert kept.data().dtype == filed.data().dtype and kept.data().tobytes() == filed.data().tobytes()
    filed.discard()
    texts = Recorder(["time", "s"], types={"s": "String"}, in_memory=True)
    assert texts.tmpdir is not None  # Strings: the side file
    texts.discard()


def test_a_plan_depends_on_parameter_values_only_through_its_scenario():
    """What lets a session reuse the last case's plan for a case that differs in parameter values
    only (session._plan): the checks and the planner read none of them."""
    sc = api.load_scenario(OSCILLATOR, None, "2")
    other = varied(sc, {"mass1": {"c": 7.0, "solver": 2}, "mass2": {"m": 0.1}})
    a, b = api.plan(sc), api.plan(other)
    assert dataclasses.replace(a, scenario=None) == dataclasses.replace(b, scenario=None)


def test_a_sweep_on_workers_that_outlive_it_ends_their_sessions(tmp_path, dask_cluster):  # noqa: F811
    from distributed import Client

    master.sweep(OSCILLATOR, ["mass1.c=1:2:4"], out=tmp_path, scheduler=dask_cluster, stop_time="1")
    with Client(dask_cluster, timeout="30s") as client:
        pids = client.run(os.getpid)
    for pid in pids.values():  # no worker process of a session left (the resource tracker aside)
        left = [p for p in psutil.Process(pid).children() if "resource_tracker" not in " ".join(p.cmdline())]
        assert left == []


def test_an_fmu_without_a_working_reset_gets_a_new_instance_of_its_loaded_binary(monkeypatch):
    """Where fmi2Reset is missing (here: looked up under a name the FMU does not export) the
    worker frees the instance and instantiates the loaded binary again; the cases stay in one
    process and equal single runs."""
    import master.fmu as fmu_module

    monkeypatch.setitem(fmu_module._RESET, 2, "fmi2ResetMissing")  # before the worker is forked
    used = Fmu(fmu_path("bouncing_ball"), "ball")
    try:
        assert used.renew() is True  # a new instance (malloc may well give it the old address)
    finally:
        used.close()
    base = api.load_scenario(OSCILLATOR, None, "2")
    pids = []
    for c in (1.0, 2.5, 0.5):
        sc = varied(base, {"mass1": {"c": c}})
        assert_same_run(session.warm_run(sc), api.run(sc))
        pids.append(worker_pid())
    assert len(set(pids)) == 1
