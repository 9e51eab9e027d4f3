"""Scheduled Execution components (master/clocks.py, kernel.h: mk_scheduled): the master activates
an FMI 3 FMU's model partitions at its input clocks' ticks, on the component's grid, its inputs set
before and its outputs read after the activations of a point.

The project's model `clocks` (fmus/clocks/) has the interface and behaviour of the Reference FMUs'
Clocks model; tests/scenarios/clocks/ holds the reference output of that model as the Reference
FMUs' own synchronous Scheduled Execution importer ran it (ORIGIN.md).
"""

from __future__ import annotations

import csv
import dataclasses
import shutil
import zipfile
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from helpers import BACKENDS, run_everywhere, ssd

import master.api as api
from master.backends.component import SimulationError
from master.fmubuild import build_fmu
from master.scenario.model import Scheme

HERE = Path(__file__).parent
SCENE = HERE / "scenarios" / "clocks" / "clocks.ssd"
REFERENCE = HERE / "scenarios" / "clocks" / "Clocks_ref.csv"
TICKS = '<mm:Stimuli><mm:Step component="clocks" variable="inClock2">{}</mm:Step></mm:Stimuli>'


def ticks(*times: float) -> str:
    """mm:Settings children: inClock2 of component `clocks` ticks at `times`."""
    return TICKS.format("".join(f'<mm:Point time="{t:g}" value="1"/>' for t in times))


def alone(
    path: Path, macro_step: str = "1", stop: str = "9", settings: str = "", source: str = "project:clocks"
):
    """A scene of component `clocks` alone (FMU `source`), mm:Settings children `settings`."""
    return ssd(path, {"clocks": source}, [], settings, macro_step, stop)


def reference() -> dict[str, list[int]]:
    with REFERENCE.open() as f:
        rows = list(csv.DictReader(f))
    return {name: [int(float(r[name])) for r in rows] for name in rows[0]}


@pytest.mark.parametrize("backend", BACKENDS)
def test_clocks_scene_matches_the_reference_output_in_every_backend(backend):
    result = api.run(SCENE, backend=backend)
    data = result.data
    ref = reference()
    assert list(data["time"]) == ref["time"]  # a row per activation point, 0 .. 9 s
    for name in ("inClock1Ticks", "inClock2Ticks", "inClock3Ticks", "totalInClockTicks"):
        assert list(data[f"clocks.{name}"]) == ref[name], name
    # inClock3 ticks once, at 4 s (counted down by 0 s by inClock1's partition there): output3 from then
    assert list(data["clocks.output3"]) == [0] * 4 + [1000] * 6
    # the summary counts the activations; outClock ticked where the total became 5, 10 and 15
    ticks = {"clocks.inClock1": 10, "clocks.inClock2": 4, "clocks.inClock3": 1, "clocks.outClock": 3}
    assert result.summary.clock_ticks == ticks
    assert "clock activations and ticks: clocks.inClock1 10, clocks.inClock2 4" in str(result.summary)


def test_validate_accepts_the_scene_and_info_names_the_activations():
    assert api.validate(SCENE) == []
    plan = api.plan(api.load_scenario(SCENE))
    (pc,) = plan.components
    assert pc.interface == "ScheduledExecution"
    shown = plan.describe()
    assert "inClock1 every 1 s from 0 s" in shown and "inClock2 at 4 stimulus times" in shown
    assert "inClock3 when the FMU counts it down" in shown


def test_paced_in_real_time_the_same_rows():
    paced = api.run(SCENE, backend="serial", real_time=50.0).data
    plain = api.run(SCENE, backend="serial").data
    for name in plain.dtype.names:
        assert np.array_equal(paced[name], plain[name]), name


def test_activation_times_are_exact_multiples_of_the_period_without_drift(tmp_path):
    """10000 points of a 0.1 s grid: inClock1 (1 s) at every tenth, the time the FMU was activated
    with (its independent variable `time`) exactly the whole second, the counter exact."""
    path = alone(tmp_path / "fine.ssd", macro_step="0.1", stop="1000")
    result = api.run(path, record=["clocks.time", "clocks.inClock1Ticks"], backend="in-process")
    data = result.data
    j = np.arange(10001)
    assert np.array_equal(data["time"], j / 10)  # the rows' times: (0 + j 1) / 10 exactly
    assert np.array_equal(data["clocks.time"], (j // 10).astype(float))
    assert np.array_equal(data["clocks.inClock1Ticks"], j // 10 + 1)
    assert result.summary.steps["clocks"] == 10000


def _connected(tmp_path: Path, coupling: Scheme):
    """stair (Co-Simulation, counter(t) = 1 + floor(t)) drives clocks.input2, summed into result2 at
    the ticks of inClock2 (0, 3 and 7 s); result2 drives discrete.n_in (Co-Simulation)."""
    path = ssd(
        tmp_path / "connected.ssd",
        {"stair": "project:stair", "clocks": "project:clocks", "discrete": "project:discrete"},
        [("stair", "counter", "clocks", "input2"), ("clocks", "result2", "discrete", "n_in")],
        settings=ticks(0, 3, 7),
        macro_step="1",
        stop="9",
    )
    sc = api.load_scenario(path)
    if coupling == Scheme.GAUSS_SEIDEL:
        sc = dataclasses.replace(sc, coupling=coupling, order=("stair", "clocks", "discrete"))
    record = [("stair", "counter"), ("clocks", "input2"), ("clocks", "result2"), ("discrete", "n_in")]
    return run_everywhere(dataclasses.replace(sc, record=tuple(record)))


def test_a_scheduled_component_samples_and_holds_its_co_simulation_neighbours(tmp_path):
    counter = [1 + t for t in range(10)]
    # Gauss-Seidel, stair first: the input at an activation is stair's sample at that time
    data = _connected(tmp_path, Scheme.GAUSS_SEIDEL)
    assert list(data["stair.counter"]) == counter
    result2 = [1, 1, 1, 5, 5, 5, 5, 13, 13, 13]  # + counter(0), + counter(3), + counter(7)
    assert list(data["clocks.result2"]) == result2
    # a recorded input holds its source's sample at the row's time (resampling, README)
    assert list(data["discrete.n_in"]) == result2
    assert list(data["clocks.input2"]) == counter
    # Jacobi: every source's samples from the macro step's start, held: counter(t - 1) at t > 0
    data = _connected(tmp_path, Scheme.JACOBI)
    assert list(data["clocks.result2"]) == [1, 1, 1, 4, 4, 4, 4, 11, 11, 11]


def _problems(path: Path) -> list[str]:
    return [str(p) for p in api.validate(path)]


def test_an_interval_off_the_grid_is_one_clear_line(tmp_path):
    path = alone(tmp_path / "off.ssd", macro_step="0.3", stop="3")
    (problem,) = _problems(path)
    assert 'ssd:Component "clocks"' in problem
    assert (
        "clock inClock1: interval 1 s is not a multiple of the component's communication step 0.3 s"
        in problem
    )


def test_ticks_only_for_triggered_clocks_and_on_the_grid(tmp_path):
    bad = TICKS.replace("inClock2", "inClock1").format('<mm:Point time="2" value="1"/>')
    path = alone(tmp_path / "periodic.ssd", settings=bad)
    (problem,) = _problems(path)
    assert 'clock inClock1: a stimulus gives ticks to triggered clocks only, not "constant" ones' in problem
    path = alone(tmp_path / "between.ssd", settings=ticks(0.5))
    (problem,) = _problems(path)
    assert "clock inClock2: tick time 0.5 s is not a point of the component's grid (step 1 s)" in problem


def rewritten(tmp_path: Path, name: str, old: str, new: str) -> str:
    """The project's clocks FMU with `old` replaced by `new` in its model description, in tmp_path."""
    fmu = tmp_path / name
    with zipfile.ZipFile(build_fmu("clocks", fmi=3)) as src, zipfile.ZipFile(fmu, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "modelDescription.xml":
                assert old in data.decode()
                data = data.decode().replace(old, new).encode()
            dst.writestr(item, data)
    return name


INCLOCK1 = 'intervalVariability="constant" intervalDecimal="1"'


def test_an_unsupported_interval_variability_is_one_clear_line(tmp_path):
    source = rewritten(tmp_path, "changing.fmu", INCLOCK1, 'intervalVariability="changing"')
    (problem,) = _problems(alone(tmp_path / "changing.ssd", source=source))
    assert 'clock inClock1: intervalVariability "changing" is not supported' in problem


def test_a_fixed_interval_the_description_leaves_out_is_asked_of_the_fmu(tmp_path):
    source = rewritten(tmp_path, "fixed.fmu", INCLOCK1, 'intervalVariability="fixed"')
    path = alone(tmp_path / "fixed.ssd", source=source, settings=ticks(0, 1, 8, 9))
    assert api.validate(path) == []
    data = api.run(path, backend="serial").data  # fmi3GetIntervalDecimal: 1 s
    assert list(data["clocks.totalInClockTicks"]) == reference()["totalInClockTicks"]
    # off the grid: known only once the FMU says it, so the run stops at the start with one line
    path = alone(tmp_path / "fixed_off.ssd", source=source, macro_step="0.3", stop="3")
    assert api.validate(path) == []
    with pytest.raises(SimulationError) as err:
        api.run(path, backend="serial")
    assert str(err.value).startswith(
        "clocks: clock inClock1: interval 1 s (fmi3GetIntervalDecimal) is not a multiple of the "
        "component's communication step 0.3 s"
    )


def test_the_cli_validates_and_runs_the_scene(tmp_path):
    from master.cli import main

    scene = tmp_path / "clocks.ssd"
    shutil.copy(SCENE, scene)
    assert main(["validate", str(scene)]) == 0
    out = tmp_path / "out.csv"
    assert main(["run", str(scene), "--serial", "-q", "-o", str(out)]) == 0
    with out.open() as f:
        rows = list(csv.DictReader(f))
    assert [int(r["clocks.totalInClockTicks"]) for r in rows] == reference()["totalInClockTicks"]
    assert Fraction(rows[-1]["time"]) == 9


class Scheduled:
    """The project's clocks FMU instantiated for Scheduled Execution through fmpy, its clockUpdate
    callbacks counted and its log messages kept."""

    def __init__(self, tmp_path: Path) -> None:
        from fmpy import extract, read_model_description
        from fmpy.fmi3 import (
            FMU3ScheduledExecution,
            fmi3ClockUpdateCallback,
            fmi3InstanceEnvironment,
            fmi3LockPreemptionCallback,
            fmi3LogMessageCallback,
            fmi3UnlockPreemptionCallback,
        )

        path = build_fmu("clocks", fmi=3)
        md = read_model_description(path)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU3ScheduledExecution(
            guid=md.instantiationToken,
            unzipDirectory=extract(path, tmp_path / "clocks"),
            modelIdentifier="clocks",
            instanceName="c",
        )
        self.updates, self.messages = 0, []
        self._callbacks = (  # kept alive while the instance lives
            fmi3LogMessageCallback(lambda env, status, category, text: self.messages.append(text.decode())),
            fmi3ClockUpdateCallback(self._updated),
            fmi3LockPreemptionCallback(lambda: None),
            fmi3UnlockPreemptionCallback(lambda: None),
        )
        self.fmu.component = self.fmu.fmi3InstantiateScheduledExecution(
            b"c",
            md.instantiationToken.encode(),
            b"",
            False,
            False,
            fmi3InstanceEnvironment(),
            *self._callbacks,
        )
        assert self.fmu.component
        self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def _updated(self, env) -> None:  # noqa: ANN001
        self.updates += 1

    def activate(self, clock: str, t: float) -> None:
        self.fmu.activateModelPartition(self.vr[clock], t)

    def get(self, name: str) -> int:
        return self.fmu.getInt32([self.vr[name]])[0]

    def interval(self, clock: str) -> tuple[float, int]:
        from fmpy.fmi3 import fmi3Float64, fmi3IntervalQualifier, fmi3ValueReference

        interval, qualifier = (fmi3Float64 * 1)(), (fmi3IntervalQualifier * 1)()
        self.fmu.getIntervalDecimal((fmi3ValueReference * 1)(self.vr[clock]), interval, qualifier)
        return interval[0], qualifier[0]


def test_the_layer_runs_partitions_ticks_output_clocks_and_counts_clocks_down(tmp_path):
    from fmpy.fmi1 import FMICallException

    fmu = Scheduled(tmp_path)
    assert fmu.interval("inClock3") == (0.0, 0)  # fmi3IntervalNotYetKnown
    assert fmu.interval("inClock1") == (1.0, 1)  # its constant interval, unchanged
    for t in range(4):
        fmu.activate("inClock1", float(t))
    assert fmu.get("inClock1Ticks") == 4 and fmu.updates == 0
    fmu.activate("inClock1", 4.0)  # counts inClock3 down by 0 s; the total becomes 5: outClock ticks
    assert fmu.updates == 2
    assert fmu.interval("inClock3") == (0.0, 2)  # fmi3IntervalChanged, then read: unchanged
    assert fmu.interval("inClock3") == (0.0, 1)
    assert fmu.fmu.getClock([fmu.vr["outClock"]]) == [True]
    assert fmu.fmu.getClock([fmu.vr["outClock"]]) == [False]  # a tick is read once
    fmu.fmu.setInt32([fmu.vr["input2"]], [7])
    fmu.activate("inClock3", 4.0)
    fmu.activate("inClock2", 4.0)
    assert [fmu.get(n) for n in ("inClock3Ticks", "output3", "result2", "input2", "totalInClockTicks")] == [
        1, 1000, 7, 0, 7
    ]  # fmt: skip
    with pytest.raises(FMICallException):
        fmu.activate("outClock", 5.0)
    assert 'Clock "outClock" is not an input clock' in fmu.messages[-1]
    with pytest.raises(FMICallException):
        fmu.fmu.getClock([fmu.vr["inClock1"]])
    assert 'Clock "inClock1" is not an output clock' in fmu.messages[-1]
    fmu.fmu.terminate()
    fmu.fmu.freeInstance()


def test_the_layer_offers_a_model_with_clocks_for_scheduled_execution_only(tmp_path):
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    path = build_fmu("clocks", fmi=3)
    md = read_model_description(path)
    assert md.coSimulation is None and md.modelExchange is None and md.scheduledExecution is not None
    slave = FMU3Slave(
        guid=md.instantiationToken, unzipDirectory=extract(path, tmp_path / "cs"), modelIdentifier="clocks"
    )
    messages = []
    with pytest.raises(Exception, match="instantiate"):
        slave.instantiate(logMessage=lambda env, status, category, text: messages.append(text.decode()))
    assert messages == ["fmi3InstantiateCoSimulation: clocks offers Scheduled Execution only"]


def test_implementation_scheduled_execution_needs_that_interface(tmp_path):
    """SSP 2.0's implementation="ScheduledExecution" on an FMU that has no such interface."""
    path = ssd(tmp_path / "msd.ssd", {"a": "msd", "b": "msd"}, [("a", "x", "b", "x_in")])
    text = path.read_text().replace('Description version="1.0"', 'Description version="2.0"')
    path.write_text(
        text.replace('<ssd:Component name="a"', '<ssd:Component implementation="ScheduledExecution" name="a"')
    )
    (problem,) = _problems(path)
    assert 'implementation="ScheduledExecution": msd.fmu has no Scheduled Execution interface' in problem
