"""Runs through the serial backend with FMUs this project did not build (made with pythonfmu)."""

import subprocess
import sys
import zipfile
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from fmpy.util import read_csv

import master.api as api
from master.backends.component import SimulationError
from master.fmu import Fmu, FmuError
from master.fmubuild import fmu_path
from master.recorder import read_csv as read_results
from master.scenario.model import Component, Connection, Scenario, Stimulus

LAG = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Lag(Fmi2Slave):
    """y' = -a y + u by explicit Euler over each communication step; y = nan once t >= t_fail."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.a = 1.0
        self.t_fail = 1e9
        self.u = 0.0
        self.y = 1.0
        self.register_variable(Real("a", causality=Fmi2Causality.parameter, variability="fixed"))
        self.register_variable(Real("t_fail", causality=Fmi2Causality.parameter, variability="fixed"))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.y += step_size * (-self.a * self.y + self.u)
        if current_time + step_size >= self.t_fail - 1e-12:
            self.y = float("nan")
        return True
'''

REFUSE = LAG.replace("class Lag", "class Refuse").replace('self.y = float("nan")', "return False")


def build_pythonfmu(name: str, source: str, folder: Path) -> Path:
    """folder/<name>.fmu built by pythonfmu from the Python `source` of class `name`."""
    script = folder / f"{name}.py"
    script.write_text(source)
    cmd = [sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(folder)]
    subprocess.run(cmd, check=True, capture_output=True)
    return folder / f"{name}.fmu"


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("pyfmu")
    return {name: build_pythonfmu(name, src, d) for name, src in (("Lag", LAG), ("Refuse", REFUSE))}


def scene(components, connections=(), **kw) -> Scenario:
    base = dict(
        path=Path("lag.ssd"),
        name="lag",
        components=tuple(components),
        connections=tuple(connections),
        start_time=Fraction(0),
        stop_time=Fraction(1),
        macro_step=Fraction(1, 10),
    )
    base.update(kw)
    return Scenario(**base)


def test_third_party_fmu_chain_matches_hand_computation(fmus, tmp_path):
    """g1 (a = 2) drives g2 (k = 2, linear extrapolation); a step stimulus drives g1."""
    sc = scene(
        [
            Component("g1", fmus["Lag"], {"a": 2.0}),
            Component("g2", fmus["Lag"], {}, step_ratio=2, extrapolation_order=1),
        ],
        [Connection("g1", "y", "g2", "u")],
        stimuli=(Stimulus("g1", "u", "step", (0.5,), (3.0,)),),
        record=(("g1", "y"), ("g2", "y"), ("g2", "u")),
    )
    csv = tmp_path / "out.csv"
    res = api.run(sc, output=csv)
    # hand computation of the same scheme
    H, h2 = 0.1, 0.05
    y1 = [1.0]
    for n in range(10):
        u = 3.0 if n / 10 >= 0.5 else 0.0
        y1.append(y1[-1] + H * (-2.0 * y1[-1] + u))
    y2 = [1.0]
    for j in range(20):
        n, m = divmod(j, 2)
        if m == 0 or n == 0:  # at a sample, or start-up (order 0)
            u = y1[n]
        else:  # linear through the samples at t_n and t_n - H, half a step ahead
            u = 1.5 * y1[n] - 0.5 * y1[n - 1]
        y2.append(y2[-1] + h2 * (-y2[-1] + u))
    d = res.data
    assert d["time"][-1] == 1.0 and len(d) == 11
    np.testing.assert_allclose(d["g1.y"], y1, rtol=1e-14)
    np.testing.assert_allclose(d["g2.y"], y2[::2], rtol=1e-14)
    back = read_csv(str(csv))
    assert back.dtype.names == ("time", "g1.y", "g2.y", "g2.u")
    np.testing.assert_array_equal(back["g2.y"], d["g2.y"])
    s = res.summary
    assert s.steps == {"g1": 10, "g2": 20}
    assert s.macro_steps == 10 and s.simulated_time == 1.0
    assert s.wall_time > sum(s.fmu_time.values()) > 0


@pytest.mark.parametrize("backend", ["serial", "parallel", "in-process"])
def test_non_finite_output_stops_the_run_and_keeps_earlier_results(fmus, tmp_path, backend):
    sc = scene(
        [Component("src", fmus["Lag"]), Component("sink", fmus["Lag"], {"t_fail": 0.6})],
        [Connection("src", "y", "sink", "u")],
    )
    csv = tmp_path / "out.csv"
    with pytest.raises(SimulationError) as e:
        api.run(sc, output=csv, backend=backend)
    msg = str(e.value)
    assert "unstable: sink.y at t=0.6" in msg and "smaller macro step" in msg and "NaN" in msg
    assert e.value.component == "sink" and e.value.variable == "y"
    rows = read_csv(str(csv))
    assert rows["time"][-1] == pytest.approx(0.5)
    assert np.isfinite(rows["sink.y"]).all()
    assert e.value.result.summary.macro_steps == 5


def test_fmu_ending_the_simulation_ends_the_run_normally(fmus, tmp_path):
    """pythonfmu's do_step returning False is fmi2Discard with fmi2Terminated: the FMU ends the
    simulation; its step from 0.25 s was discarded, so the run ends at t = 0.2, the last complete
    macro step, as fmpy ends it: no error, the rows up to there."""
    sc = scene([Component("r", fmus["Refuse"], {"t_fail": 0.3}, step_ratio=2)])
    r = api.run(sc, output=tmp_path / "out.csv")
    assert r.summary.stop_reason == "finished: r ended the simulation at t=0.25"
    assert len(read_csv(str(tmp_path / "out.csv"))) == 3  # t = 0, 0.1, 0.2


def test_bad_parameter_names_component_and_variable(fmus):
    sc = scene([Component("g", fmus["Lag"], {"nope": 1.0})])
    with pytest.raises(FmuError, match="g: no variable 'nope'"):
        api.run(sc)


def test_unsafe_archive_is_refused(fmus, tmp_path):
    evil = tmp_path / "evil.fmu"
    with zipfile.ZipFile(fmus["Lag"]) as src, zipfile.ZipFile(evil, "w") as dst:
        for item in src.infolist():
            dst.writestr(item, src.read(item))
        dst.writestr("../../escaped.txt", "x")
    with pytest.raises(FmuError, match="escapes the archive"):
        Fmu(evil, "evil")
    assert not (tmp_path.parent / "escaped.txt").exists()


def test_record_interval_and_overrides(fmus):
    sc = scene([Component("g", fmus["Lag"])], stop_time=Fraction(2))
    res = api.run(sc, output_interval="0.5", set_values=["g.a=0"], stop_time=1)
    assert list(res.data["time"]) == [0.0, 0.5, 1.0]
    np.testing.assert_array_equal(res.data["g.y"], 1.0)  # a = 0: y stays at 1


def test_real_time_pacing_reports_frames(fmus):
    sc = scene([Component("g", fmus["Lag"])], stop_time=Fraction(1, 5), macro_step=Fraction(1, 50))
    res = api.run(sc, real_time=1.0)
    s = res.summary
    assert s.overruns is not None and s.worst_lateness is not None
    # paced to 0.2 s of wall clock (unpaced it takes milliseconds), not faster; how close to it a
    # paced run ends is measured by benchmarks/realtime.py, not bounded here (load makes it later)
    assert s.wall_time > 0.19


def test_fmi3_fmu_runs_through_the_same_interface(tmp_path):
    """Lag3 (FMI 3.0, pythonfmu3): y' = (u - y) / tau by Euler, u a step stimulus, Int32 output recorded."""
    src = Path(__file__).parent / "scenarios" / "fmi3" / "Lag3.py"
    subprocess.run(
        [sys.executable, "-m", "pythonfmu3", "build", "-f", str(src), "-d", str(tmp_path)],
        check=True,
        capture_output=True,
    )
    sc = scene(
        [Component("lag", tmp_path / "Lag3.fmu", {"tau": 0.5}, step_ratio=2)],
        stimuli=(Stimulus("lag", "u", "step", (0.0,), (1.0,)),),
        record=(("lag", "y"), ("lag", "steps")),
    )
    d = api.run(sc).data
    h = 0.05
    expected = [1 - (1 - h / 0.5) ** (2 * n) for n in range(11)]
    np.testing.assert_allclose(d["lag.y"], expected, rtol=1e-13, atol=1e-15)
    assert list(d["lag.steps"]) == [2.0 * n for n in range(11)]


def test_fmpy_default_logging_still_prints_after_a_run_in_this_process(capsys):
    """fmpy's message proxy keeps one logger per process: after a master run it is the master's,
    which must print the messages of FMUs that fmpy instantiated with its default callbacks."""
    import fmpy

    from master.evidence.oscillator import scene

    api.run(scene(stop_time=Fraction(1, 10)), backend="in-process")
    with pytest.raises(Exception, match="fmi2DoStep"):
        fmpy.simulate_fmu(str(fmu_path("crashtest")), stop_time=0.1, start_values={"mode": 4})
    assert "crashtest: error requested at t = 0" in capsys.readouterr().out


LABELLED = (
    LAG.replace("class Lag", "class Labelled")
    .replace(
        "from pythonfmu import Fmi2Causality, Fmi2Slave, Real",
        "from pythonfmu import Fmi2Causality, Fmi2Slave, Real, String",
    )
    .replace(
        '        self.register_variable(Real("y", causality=Fmi2Causality.output))',
        '        self.register_variable(Real("y", causality=Fmi2Causality.output))\n'
        '        self.label = "lag"\n'
        "        self.register_variable(\n"
        '            String("label", causality=Fmi2Causality.output, variability="discrete")\n'
        "        )",
    )
)


def test_a_string_output_of_a_third_party_fmu_is_recorded_as_text(tmp_path):
    fmu = build_pythonfmu("Labelled", LABELLED, tmp_path)
    sc = scene([Component("c", fmu)])
    assert api.plan(sc).record == (("c", "y"), ("c", "label"))  # every output, the String too
    result = api.run(sc, backend="serial", output=tmp_path / "out.csv")
    assert list(result.data["c.label"]) == ["lag"] * len(result.data)
    assert read_results(tmp_path / "out.csv")["c.label"].tolist() == ["lag"] * len(result.data)
    assert (tmp_path / "out.csv").read_text().splitlines()[1].endswith(',"lag"')
