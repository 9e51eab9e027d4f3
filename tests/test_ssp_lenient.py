"""Other tools' files, read where peer masters read them (issue 19, items 7 and 9).

Real third-party FMUs and files under tests/ssp/ (each folder's ORIGIN.md says where from):
- an FMU whose description fails fmpy's strict validation but runs (the project's model of it,
  its description given the original's defect: tests/helpers.py): a warning, and its results agree
  with the same FMU driven through fmpy directly;
- FMI 1.0 FMUs: `validate` and `run` give the same verdict (Co-Simulation runs, Model Exchange does not).
"""

from __future__ import annotations

import logging
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import third_party_scene

import master.api as api
from master.description import defects, parse
from master.fmu import FmuError, read_description
from master.fmubuild import fmu_path
from master.scenario import ScenarioError, load, validate
from tests.helpers import ssd

SSP = Path(__file__).parent / "ssp"
ECS = SSP / "OpenModelica-OMSimulator" / "embrace"
IDENTITY = SSP / "Ecos-platform-ecos" / "identity"


def ecs(tmp_path: Path) -> tuple[Path, Path]:
    """The scene and its FMU, laid out in tmp_path."""
    folder = third_party_scene(ECS, tmp_path)
    return folder / "ecs_sw_alone.ssd", folder / "resources" / "0002_ECS_SW.fmu"


def test_a_description_peers_accept_is_a_warning_naming_the_defect(tmp_path: Path, caplog):
    scene, fmu = ecs(tmp_path)
    with zipfile.ZipFile(fmu) as z:
        lines = z.read("modelDescription.xml").decode().splitlines()
    line = 1 + next(i for i, text in enumerate(lines) if 'name="Input.Aircraft_State"' in text)
    with caplog.at_level(logging.WARNING, logger="master"):
        assert validate(scene) == []
    (warning,) = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warning.startswith(f'{scene}:11: ssd:Component "ecs_sw": modelDescription.xml of 0002_ECS_SW.fmu:')
    assert f'variable "Input.Aircraft_State" (line {line}) is of type Enumeration' in warning


def test_that_fmu_runs_as_fmpy_alone_runs_it(tmp_path: Path):
    # The peer: the same FMU driven through fmpy, with the values the scene's stimuli give at each
    # communication point (TLiquid a ramp 250 -> 350 over [0, 2] s, Aircraft_State 4 from 1 s).
    ecs_scene, ecs_fmu = ecs(tmp_path)
    result = api.run(ecs_scene, output=tmp_path / "ecs.csv").data
    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave

    md = read_description(ecs_fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(
        guid=md.guid,
        unzipDirectory=extract(str(ecs_fmu), str(tmp_path / "unzipped")),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="peer",
    )
    slave.instantiate()
    try:
        slave.setupExperiment(startTime=0.0, stopTime=2.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        h, expected = 0.1, []
        for k in range(20):
            t = k * h
            slave.setReal([vr["Input.TLiquid"]], [250 + 50 * t])
            slave.setInteger([vr["Input.Aircraft_State"]], [4 if k >= 10 else 0])
            slave.doStep(t, h)
            expected.append(slave.getReal([vr["TCoolingPack"]])[0])
    finally:
        slave.terminate()
        slave.freeInstance()
    got = result["ecs_sw.TCoolingPack"][1:]
    assert np.array_equal(got, expected)
    assert len(set(expected)) > 3  # the output follows its inputs: the comparison means something


def test_that_fmu_computes_what_the_originals_sources_say(tmp_path: Path):
    # OpenSW.c and OpenSW_data.c of the original: a PI controller with anti-windup sampled every
    # 1/30 s (three samples per 0.1 s step here, the inputs held), the output that of the last sample.
    ecs_scene, _ = ecs(tmp_path)
    got = api.run(ecs_scene, output=tmp_path / "ecs.csv").data["ecs_sw.TCoolingPack"][1:]
    ts, integral, windup, expected = 1 / 30, 0.0, 0.0, []
    for k in range(20):
        e = 293.0 - (250 + 50 * k * 0.1)
        for _ in range(3):
            v = 5.0 * e + (integral + 1.0 * (e + windup) * ts)
            sat = min(200.0, max(v, -200.0))
            integral, windup = integral + 1.0 * (e + windup) * ts, sat - v
        expected.append(sat + 293.0 if k >= 10 else 313.0)
    assert got == pytest.approx(expected, rel=1e-12, abs=1e-9)
    assert min(expected) == 93.0  # saturated at the lower limit: the anti-windup path is covered


def test_a_description_with_a_refused_defect_stays_refused_in_one_line(tmp_path: Path):
    # The FMU with the start value of its input removed: FMI requires one (kept a refusal).
    ecs_scene, ecs_fmu = ecs(tmp_path)
    broken = tmp_path / "nostart.fmu"
    with zipfile.ZipFile(ecs_fmu) as src, zipfile.ZipFile(broken, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'<Real start="0"/>', b"<Real/>", 1)
            dst.writestr(item, data)
    scene = tmp_path / "scene.ssd"
    scene.write_text(ecs_scene.read_text().replace("resources/0002_ECS_SW.fmu", "nostart.fmu"))
    problems = validate(scene)
    assert len(problems) >= 1
    first = str(problems[0])
    assert "\n" not in first
    assert 'cannot read the modelDescription.xml of nostart.fmu: Variable "Input.TLiquid"' in first
    assert "has no start value" in first
    assert "Enumeration" not in first  # the tolerated defect is not what refuses it


def _with_duplicate_local(fmu: Path, target: Path) -> Path:
    """`fmu` (FMI 1.0 msd) whose description names its local der(v) der(x) too: the defect of
    ecos's DPController.fmu, which declares internal variable names twice (dp_ship/ORIGIN.md)."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(target, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                assert data.count(b'name="der(v)"') == 1
                data = data.replace(b'name="der(v)"', b'name="der(x)"')
            dst.writestr(item, data)
    return target


def test_names_declared_twice_among_internal_variables_are_a_defect_not_a_refusal(tmp_path):
    """The FMU runs, with the results of the FMU whose names are unique."""
    intact = fmu_path("msd", fmi=1)
    twice = _with_duplicate_local(intact, tmp_path / "twice.fmu")
    assert defects(intact) == ()
    assert [d.split(" (")[0] for d in defects(twice)] == ['The variable name "der(x)"']
    assert parse(twice).modelName == "msd"
    # b's coupling input x_in does nothing (cc = dc = 0): the connection only makes the scene valid
    record = (
        '<mm:Record><mm:Variable component="a" name="x"/><mm:Variable component="b" name="x"/></mm:Record>'
    )
    scene = ssd(tmp_path / "pair.ssd", {"a": str(intact), "b": str(twice)}, [("a", "x", "b", "x_in")], record)
    d = api.run(api.load_scenario(scene, {"a.x0": "1", "b.x0": "1"}), backend="serial").data
    assert d["a.x"][0] == 1.0 and d["a.x"][-1] < 1.0  # it moved
    assert np.array_equal(d["b.x"], d["a.x"])


def test_fmi_1_0_validate_and_run_agree(tmp_path: Path):
    """FMI 1.0 Co-Simulation runs (tests/test_fmi1.py: the project's identity built as FMI 1.0, in
    ecos's identity scene); the same FMU stripped of its Co-Simulation implementation (FMI 1.0 Model
    Exchange) is refused alike by validate, load and run."""
    runs = tmp_path / "runs"
    runs.mkdir()
    (runs / "identity.ssd").write_text((IDENTITY / "identity.ssd").read_text())
    shutil.copy(fmu_path("identity", fmi=1), runs / "identity.fmu")
    assert validate(runs / "identity.ssd") == []
    assert api.run(runs / "identity.ssd", output=tmp_path / "out.csv").data["id.realOut"][-1] == 2.0
    exchange = tmp_path / "identity.fmu"
    with zipfile.ZipFile(runs / "identity.fmu") as src, zipfile.ZipFile(exchange, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                data = (
                    text[: text.index("<Implementation>")] + text[text.index("</Implementation>") + 17 :]
                ).encode()
            dst.writestr(item, data)
    (tmp_path / "identity.ssd").write_text((IDENTITY / "identity.ssd").read_text())
    problems = validate(tmp_path / "identity.ssd")
    assert [(p.line, p.element) for p in problems] == [(9, 'ssd:Component "id"')]
    assert "identity.fmu: model 'identity' has no co-simulation interface" in problems[0].message
    with pytest.raises(ScenarioError) as refused:
        load(tmp_path / "identity.ssd")
    assert refused.value.problems == problems
    with pytest.raises(ScenarioError) as run_refused:
        api.run(tmp_path / "identity.ssd", output=tmp_path / "out.csv")
    assert run_refused.value.problems == problems
    with pytest.raises(FmuError, match="has no co-simulation interface"):
        read_description(exchange)


def test_an_fmu_without_a_binary_for_this_platform_is_refused_by_validate(tmp_path: Path):
    # The FMU without its linux64 binary: `run` could not load it, so `validate` says so.
    ecs_scene, ecs_fmu = ecs(tmp_path)
    stripped = tmp_path / "nobinary.fmu"
    with zipfile.ZipFile(ecs_fmu) as src, zipfile.ZipFile(stripped, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/"):
                dst.writestr(item, src.read(item))
    scene = tmp_path / "scene.ssd"
    scene.write_text(ecs_scene.read_text().replace("resources/0002_ECS_SW.fmu", "nobinary.fmu"))
    problems = validate(scene)
    assert len(problems) == 1
    assert "nobinary.fmu: no binary for this platform" in problems[0].message
    with pytest.raises(FmuError, match="no binary for this platform"):
        read_description(stripped)


OSCILLATOR = Path(__file__).parent / "scenarios" / "oscillator"


def test_a_connection_written_input_to_output_is_turned_around_with_a_note(tmp_path: Path, caplog):
    # SSP 1.0: startElement/endElement do not fix the direction (a composite aircraft scene of
    # OMSimulator's test suite writes 25 of its connections input -> output). The oscillator with
    # its force connection written from the input end reads and runs as the original.
    for f in OSCILLATOR.iterdir():
        (tmp_path / f.name).write_bytes(f.read_bytes())
    scene = tmp_path / "oscillator.ssd"
    written = (
        '<ssd:Connection startElement="mass2" startConnector="F_c" endElement="mass1" endConnector="F"/>'
    )
    reversed_ = (
        '<ssd:Connection startElement="mass1" startConnector="F" endElement="mass2" endConnector="F_c"/>'
    )
    text = scene.read_text()
    assert written in text
    scene.write_text(text.replace(written, reversed_))
    with caplog.at_level(logging.INFO, logger="master"):
        turned = load(scene)
    (note,) = [r.getMessage() for r in caplog.records if "input -> output" in r.getMessage()]
    assert note == f"{scene}:58: ssd:Connection mass1.F -> mass2.F_c: " + (
        "written input -> output: read as mass2.F_c -> mass1.F"
    )
    original = load(OSCILLATOR / "oscillator.ssd")
    assert turned.connections == original.connections  # the mm:Connection order on mass1.F applies too
    a = api.run(turned, output=tmp_path / "turned.csv").data
    b = api.run(original, output=tmp_path / "original.csv").data
    assert a.dtype.names == b.dtype.names
    assert all(np.array_equal(a[n], b[n]) for n in a.dtype.names)
    # a transformation maps start to end: on a connection written input -> output it is refused
    transformed = reversed_.replace("/>", '><ssc:LinearTransformation factor="2"/></ssd:Connection>')
    scene.write_text(text.replace(written, transformed))
    assert [p.message for p in validate(scene)] == [
        "a transformation maps the start connector's value to the end's: write this connection "
        "mass2.F_c -> mass1.F (output to input) to use one"
    ]


@pytest.mark.parametrize(
    "start, end, problem",
    [
        (("mass1", "x"), ("mass2", "F_c"), "end mass2.F_c is an output, not an input"),
        (("mass1", "F"), ("mass2", "x_in"), "start mass1.F is an input, not an output"),
    ],
)
def test_two_outputs_or_two_inputs_stay_refused(tmp_path: Path, start, end, problem):
    for f in OSCILLATOR.iterdir():
        (tmp_path / f.name).write_bytes(f.read_bytes())
    scene = tmp_path / "oscillator.ssd"
    added = (
        f'<ssd:Connection startElement="{start[0]}" startConnector="{start[1]}" '
        f'endElement="{end[0]}" endConnector="{end[1]}"/>\n'
    )
    text = scene.read_text()
    at = text.index("<ssd:Connection ")
    scene.write_text(text[:at] + added + "      " + text[at:])
    problems = validate(scene)
    assert [p.message.split(":")[0] for p in problems if p.line == 56] == [problem]


QUARTER_TRUCK_SSV = SSP / "Ecos-platform-ecos" / "quarter_truck" / "ssv"


def test_an_ssv_using_ssps_own_prefix_undeclared_is_read_with_a_warning(caplog):
    from master.scenario import xmlio
    from master.scenario.problems import NS_SSV, Problems

    path = QUARTER_TRUCK_SSV / "initialValues_chassis.ssv"
    problems = Problems()
    with caplog.at_level(logging.WARNING, logger="master"):
        tree = xmlio.parse(path, str(path), problems)
    assert problems.items == []
    assert xmlio.check_schema(tree, xmlio.ssv_schema(), str(path), problems)
    values = {
        p.get("name"): float(p.find(f"{{{NS_SSV}}}Real").get("value"))
        for p in tree.getroot().iter(f"{{{NS_SSV}}}Parameter")
    }
    assert values == {"C.mChassis": 400.0, "C.kChassis": 15000.0, "R.dChassis": 1000.0}
    assert [r.getMessage() for r in caplog.records] == [
        f'{path}:2: ssv:ParameterSet: namespace prefix "ssv" is not declared; read as SSP\'s: declare '
        'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" on the root element'
    ]


def test_an_undeclared_prefix_that_is_not_ssps_is_one_problem_naming_it():
    scene = SSP / "open-simulation-platform-libcosim" / "demo" / "SystemStructure2.ssd"
    problems = validate(scene)
    assert [str(p) for p in problems] == [
        f'{scene}:15: osp:Algorithm: namespace prefix "osp" is not declared: declare it on the root '
        'element (xmlns:osp="its namespace URI")'
    ]


def test_other_syntax_errors_beside_an_undeclared_prefix_stay_syntax_errors(tmp_path: Path):
    bad = tmp_path / "bad.ssv"
    bad.write_text((QUARTER_TRUCK_SSV / "initialValues_wheel.ssv").read_text() + "<extra/>")
    from master.scenario import xmlio
    from master.scenario.problems import Problems

    problems = Problems()
    assert xmlio.parse(bad, str(bad), problems) is None
    (problem,) = problems.items
    assert problem.element == "XML"
    assert problem.message == "not well-formed XML: Extra content at the end of the document"
