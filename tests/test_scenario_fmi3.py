"""FMI 3.0 FMUs in scenarios: read through fmpy like FMI 2.0 ones, Float64 connects to Real.

The FMU is real: tests/scenarios/fmi3/Lag3.py built with pythonfmu3 (binaries included)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import fmpy
import pytest

import master.api as api
from master.scenario import load, validate

SOURCE = Path(__file__).parent / "scenarios" / "fmi3"


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """lag_and_body.ssd beside a freshly built Lag3.fmu."""
    folder = tmp_path_factory.mktemp("fmi3")
    subprocess.run(
        [sys.executable, "-m", "pythonfmu3", "build", "-f", str(SOURCE / "Lag3.py"), "-d", str(folder)],
        check=True,
        capture_output=True,
        timeout=120,
    )
    shutil.copy(SOURCE / "lag_and_body.ssd", folder)
    return folder / "lag_and_body.ssd"


def variant(scene: Path, name: str, old: str, new: str) -> Path:
    text = scene.read_text()
    assert old in text
    path = scene.with_name(f"{name}.ssd")
    path.write_text(text.replace(old, new))
    return path


def test_fmi3_fmu_is_accepted_beside_fmi2(scene: Path):
    assert fmpy.read_model_description(str(scene.with_name("Lag3.fmu"))).fmiVersion == "3.0"
    assert validate(scene) == []
    sc = load(scene, {"body.m": "2"})
    lag, body = sc.components
    assert lag.fmu_path == scene.with_name("Lag3.fmu").resolve()
    assert lag.parameters == {"tau": 0.5} and lag.step_ratio == 2
    assert body.parameters == {"m": 2.0}
    assert load(scene, {"lag.tau": "3"}).components[0].parameters == {"tau": 3.0}


def test_fmi3_type_mismatch_names_both_types(scene: Path):
    path = variant(
        scene,
        "int_to_real",
        'startConnector="y" endElement="body"',
        'startConnector="steps" endElement="body"',
    )
    (problem,) = validate(path)
    assert problem.element == "ssd:Connection lag.steps -> body.F"
    assert problem.message == "type mismatch: lag.steps is Int32, body.F is Real"


def test_fmi3_output_without_dependencies_feeds_through_every_input(scene: Path):
    # Two lags in a ring: y lists no dependencies, so y depends directly on u: a loop.
    ring = variant(scene, "ring", 'source="msd"', 'source="Lag3.fmu"')
    text = ring.read_text()
    text = text.replace('<ssd:Connector name="F" kind="input"><ssc:Real unit="N"/></ssd:Connector>', "")
    text = text.replace('<ssd:Connector name="x" kind="output"><ssc:Real unit="m"/></ssd:Connector>', "")
    text = text.replace(
        '<ssd:Connection startElement="body" startConnector="x" endElement="lag" endConnector="u"/>',
        '<ssd:Connection startElement="body" startConnector="y" endElement="lag" endConnector="u"/>',
    )
    text = text.replace('endElement="body" endConnector="F"', 'endElement="body" endConnector="u"')
    text = text.replace(
        "</ssd:Connectors>\n      </ssd:Component>\n    </ssd:Elements>",
        '<ssd:Connector name="u" kind="input"/><ssd:Connector name="y" kind="output"/>'
        "</ssd:Connectors>\n      </ssd:Component>\n    </ssd:Elements>",
    )
    ring.write_text(text)
    assert validate(ring) == []  # solved, not refused: the loop is planned
    (loop,) = api.plan(api.load_scenario(ring)).loops
    assert loop.cycle == "body.u -> body.y -> lag.u -> lag.y -> body.u" and loop.assumed
    res = api.run(ring, backend="in-process", stop_time="0.05")
    (stats,) = res.summary.loops.values()
    assert stats["sequential"] == 1  # the lags' y is their state: the probe finds no cycle


def test_interpolate_inputs_only_where_the_fmu_can(scene: Path):
    # msd declares canInterpolateInputs; this FMI 3.0 co-simulation FMU no intermediate update.
    everywhere = variant(
        scene,
        "interp_all",
        '<mm:Settings macroStep="0.01">',
        '<mm:Settings macroStep="0.01" interpolateInputs="true">',
    )
    lag, body = load(everywhere).components
    assert (lag.interpolate_inputs, body.interpolate_inputs) == (False, True)
    forced = variant(
        scene, "interp_lag", 'name="lag" stepRatio="2"', 'name="lag" stepRatio="2" interpolateInputs="true"'
    )
    (problem,) = validate(forced)
    assert problem.element == 'mm:Component "lag"'
    assert "Lag3.fmu cannot interpolate inputs" in problem.message


def test_fmi3_integer_parameters_of_64_bits_travel_through_their_own_calls(tmp_path: Path):
    """Int64 and UInt64 parameters are set with fmi3SetInt64 / fmi3SetUInt64 (not SetInt32: the
    FMU refuses that), every bit of them: y holds their last three decimal digits; Int64 and
    UInt64 outputs are recorded through fmi3GetInt64 / fmi3GetUInt64 (exact below 2^53)."""
    from fractions import Fraction

    import master.api as api
    from master.scenario.model import Component, Scenario

    subprocess.run(
        [sys.executable, "-m", "pythonfmu3", "build", "-f", str(SOURCE / "Wide3.py"), "-d", str(tmp_path)],
        check=True, capture_output=True, timeout=120,
    )  # fmt: skip
    fmu = tmp_path / "Wide3.fmu"
    big, ubig = -(2**40) - 3, 2**63 + 5
    sc = Scenario(tmp_path / "wide.ssd", "wide", (Component("w", fmu, {"big": big, "ubig": ubig}),), (),
                  Fraction(0), Fraction(1, 10), Fraction(1, 100))  # fmt: skip
    d = api.run(sc, backend="serial").data
    assert d["w.y"][-1] == float(big % 1000 + ubig % 1000) and d["w.steps"][-1] == 10
    assert list(d["w.wide"]) == [0.0] + [float(big + k) for k in range(1, 11)]
    assert list(d["w.uwide"]) == [0.0] + [float(2**40 + k) for k in range(1, 11)]
