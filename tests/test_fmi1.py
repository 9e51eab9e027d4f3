"""FMI 1.0 Co-Simulation FMUs: the project's identity model (fmus/identity) built as FMI 1.0, with
the interface of ecos's and libcosim's identity FMU (tests/ssp/Ecos-platform-ecos/identity/ORIGIN.md),
whose every output equals its input, run in every backend against exact values; libcosim's linear
transformation scene with that FMU where the scene expects it; FMI 1.0 parameters."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from lxml import etree

from master import api
from master.description import feedthrough_outputs, parse, unsupported, variables_of
from master.fmu import Fmu, read_description
from master.fmubuild import fmu_path
from master.recorder import read_csv
from master.scenario.fmuinfo import read as read_info
from tests.helpers import libcosim_last_values, run_everywhere, ssd

SSP = Path(__file__).parent / "ssp"
IDENTITY = SSP / "Ecos-platform-ecos" / "identity"
LIBCOSIM = SSP / "open-simulation-platform-libcosim" / "linear_transformation"


@pytest.fixture(scope="module")
def identity_fmu() -> Path:
    return fmu_path("identity", fmi=1)


def _identity_scene(tmp_path: Path, fmu: Path) -> Path:
    """ecos's identity scene in tmp_path with `fmu` as the identity.fmu it names."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    if fmu != tmp_path / "identity.fmu":
        shutil.copy(fmu, tmp_path / "identity.fmu")
    (tmp_path / "identity.ssd").write_text((IDENTITY / "identity.ssd").read_text())
    return tmp_path / "identity.ssd"


def _edited(fmu: Path, target: Path, edit) -> Path:
    """A copy of `fmu` at `target` whose modelDescription.xml is `edit`(root element) applied."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(target, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                root = etree.fromstring(data)
                edit(root)
                data = etree.tostring(root, xml_declaration=True, encoding="UTF-8")
            dst.writestr(item, data)
    return target


def _variable(root, name: str):
    return root.find(f'ModelVariables/ScalarVariable[@name="{name}"]')


def test_the_identity_model_has_the_interface_of_the_ecos_identity_fmu(identity_fmu):
    """Names, types, causalities and start values of ecos's identity FMU (its ORIGIN.md); the
    project's two solver parameters besides."""
    variables = variables_of(parse(identity_fmu))
    for kind, type_, start in (("real", "Real", "0"), ("integer", "Integer", "0"),
                               ("boolean", "Boolean", "false"), ("string", "String", "")):  # fmt: skip
        assert (variables[f"{kind}In"].causality, variables[f"{kind}In"].type) == ("input", type_)
        assert variables[f"{kind}In"].start == start
        assert (variables[f"{kind}Out"].causality, variables[f"{kind}Out"].type) == ("output", type_)
    assert set(variables) - {
        f"{k}{d}" for k in ("real", "integer", "boolean", "string") for d in ("In", "Out")
    } == {
        "solver",
        "internal_step",
    }


def test_validate_and_run_agree_that_fmi1_co_simulation_runs(tmp_path, identity_fmu):
    md = parse(identity_fmu)
    assert md.fmiVersion == "1.0"
    assert unsupported(md, identity_fmu) is None  # the one rule of validate and run
    assert read_info(identity_fmu).unsupported is None
    assert read_description(identity_fmu) is md
    assert api.validate(_identity_scene(tmp_path, identity_fmu)) == []


def test_the_identity_scene_gives_its_input_exactly_in_every_backend(tmp_path, identity_fmu):
    """realIn follows the table 2 t; realOut equals it at every communication point (it depends on
    realIn directly: the output is read after the step-end input is set)."""
    d = run_everywhere(api.load_scenario(_identity_scene(tmp_path, identity_fmu)))
    t = d["time"]
    assert len(t) == 11
    assert np.array_equal(d["id.realOut"], 2 * t)


def test_every_type_passes_through_a_chain_of_fmi1_fmus(tmp_path, identity_fmu):
    """a -> b on all four types: Real, Integer, Boolean (FMI 1 Booleans are one byte), String; a's
    inputs from stimuli and a binding. b's outputs are a's inputs, exactly."""
    types = ("real", "integer", "boolean", "string")
    settings = (
        "<mm:Record>" + "".join(f'<mm:Variable component="b" name="{x}Out"/>' for x in types) + "</mm:Record>"
        '<mm:Stimuli><mm:Table component="a" variable="realIn"><mm:Point time="0" value="1"/>'
        '<mm:Point time="1" value="3"/></mm:Table>'
        '<mm:Step component="a" variable="integerIn"><mm:Point time="0.45" value="-7"/></mm:Step>'
        '<mm:Step component="a" variable="booleanIn"><mm:Point time="0.25" value="1"/>'
        '<mm:Point time="0.65" value="0"/></mm:Step></mm:Stimuli>'
    )
    path = ssd(
        tmp_path / "chain.ssd",
        {"a": str(identity_fmu), "b": str(identity_fmu)},
        [("a", f"{x}Out", "b", f"{x}In") for x in types],
        settings,
    )
    sc = api.load_scenario(path, {"a.stringIn": "legacy"})
    d = run_everywhere(sc)
    t = d["time"]
    # b holds a's output of each communication point (order 0): copies, exact
    assert np.array_equal(d["b.realOut"], 1 + 2 * t)
    assert np.array_equal(d["b.integerOut"], np.where(t >= 0.45, -7, 0))
    assert np.array_equal(d["b.booleanOut"], (t >= 0.25) & (t < 0.65))
    assert set(d["b.stringOut"]) == {"legacy"}


def _libcosim_layout(tmp_path: Path) -> Path:
    """libcosim's scene folder as libcosim lays it out, its FMU (the project's identity built as
    FMI 1.0) at ../../fmi1/identity.fmu, the original SystemStructure.ssd byte for byte; beside it
    with-settings.ssd, the original with only this project's settings and a stop time added."""
    scene = tmp_path / "ssp" / "linear_transformation"
    scene.mkdir(parents=True)
    for name in ("SystemStructure.ssd", "initial_values.ssv", "initial_values2.ssv"):
        shutil.copy(LIBCOSIM / name, scene / name)
    (tmp_path / "fmi1").mkdir()
    shutil.copy(fmu_path("identity", fmi=1), tmp_path / "fmi1" / "identity.fmu")
    record = "".join(f'<mm:Variable component="identity{i}" name="realOut"/>' for i in (1, 2))
    settings = (
        '<ssd:Annotations><ssc:Annotation type="org.multirate-master.settings">'
        f'<mm:Settings macroStep="0.001"><mm:Record>{record}</mm:Record></mm:Settings>'
        "</ssc:Annotation></ssd:Annotations>\n    </ssd:System>"
    )
    text = (scene / "SystemStructure.ssd").read_text().replace("</ssd:System>", settings)
    text = text.replace(
        "</ssd:SystemStructureDescription>",
        '<ssd:DefaultExperiment startTime="0" stopTime="0.01"/>\n</ssd:SystemStructureDescription>',
    )
    text = text.replace('xmlns:ssc="', 'xmlns:mm="urn:org.multirate-master:settings:1"\n  xmlns:ssc="', 1)
    (scene / "with-settings.ssd").write_text(text)
    return scene


def test_libcosim_linear_transformation_scene_with_its_fmi1_fmu(tmp_path):
    """identity2's input is 1.3 x + 50 of identity1's output, which is its input as the two .ssv
    files bind it, in order (4)."""
    scene = _libcosim_layout(tmp_path)
    d = run_everywhere(api.load_scenario(scene / "with-settings.ssd"))
    assert np.all(d["identity1.realOut"] == 4.0)
    assert np.all(d["identity2.realOut"] == 1.3 * 4.0 + 50)


def test_the_original_libcosim_file_runs_from_the_command_line_as_written(tmp_path):
    """No annotation of ours, no stop time in the file: the command line gives both."""
    scene = _libcosim_layout(tmp_path)
    out = tmp_path / "out.csv"
    run = subprocess.run([sys.executable, "-m", "master", "run", str(scene / "SystemStructure.ssd"), "-q",
                          "--stop-time", "0.01", "--macro-step", "0.001", "-o", str(out)],
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert run.returncode == 0, run.stderr
    d = read_csv(out)
    assert len(d) == 11 and np.all(d["identity2.realOut"] == 1.3 * 4.0 + 50)


def test_libcosim_runs_its_original_scene_with_the_same_values(tmp_path):
    """libcosim (libcosimpy) runs the original SystemStructure.ssd with its FMI 1.0 FMU; it reads
    the two bindings as alternative parameter sets and uses the first (identity1.realIn = 2),
    SSP applies both in order: this project's run is given libcosim's input to compare the rest."""
    pytest.importorskip("libcosimpy", reason="the peers extra: pip install libcosimpy")
    scene = _libcosim_layout(tmp_path)
    (scene / "with-settings.ssd").rename(tmp_path / "with-settings.ssd")  # libcosim reads the folder
    both = ("realIn", "realOut")
    peer = libcosim_last_values(scene, {"identity1": both, "identity2": both})
    assert peer["identity1.realOut"] == 2.0 and peer["identity2.realOut"] == 1.3 * 2.0 + 50.0
    (tmp_path / "with-settings.ssd").rename(scene / "with-settings.ssd")
    sc = api.load_scenario(scene / "with-settings.ssd", {"identity1.realIn": "2"})
    ours = api.run(sc, backend="serial").data
    assert ours["identity1.realOut"][-1] == peer["identity1.realOut"]
    assert ours["identity2.realOut"][-1] == peer["identity2.realOut"]


def test_fmi1_parameters_are_set_before_the_slave_is_initialised(identity_fmu):
    """FMI 1.0 variability="parameter" (causality "internal") reads as a parameter that bindings set
    (the FMU reads it back); nothing reads as an FMI 1 causality."""
    variables = variables_of(read_description(identity_fmu))
    assert variables["internal_step"].causality == "parameter"
    assert variables["internal_step"].start == "0"
    assert {v.causality for v in variables.values()} <= {"parameter", "input", "output", "local"}
    fmu = Fmu(identity_fmu, "id")
    try:
        fmu.set_values({"internal_step": 0.025})
        fmu.enter_initialization(0.0, 1.0)
        fmu.exit_initialization()
        assert fmu.slave.getReal([variables["internal_step"].vr]) == [0.025]
        fmu.do_step(0.0, 0.1)
    finally:
        fmu.close()


def test_a_failing_fmi1_call_names_the_exported_function_and_what_the_fmu_logged(identity_fmu):
    """The FMU's log messages reach its instance through FMI 1's callbacks (one logger for all)."""
    fmu = Fmu(identity_fmu, "id")
    other = Fmu(identity_fmu, "other")
    bad = "fmiGetReal: value reference 9999 out of range (model identity has 10 variables)"
    try:
        fmu.enter_initialization(0.0, 1.0)
        with pytest.raises(FMICallException):
            fmu.slave.getReal([9999])
        assert fmu.last_log == bad and other.last_log == ""
        error = str(fmu.call_error("do_step", 3))
        assert error.startswith("id: identity_fmiDoStep failed") and f"(FMU says: {bad})" in error
        with pytest.raises(Exception, match="FMI 1.0 cannot save the FMU state"):
            fmu.get_state()
    finally:
        fmu.close()
        other.close()


def test_the_plan_repeats_no_start_up_step_of_an_fmu_that_cannot_save_its_state(tmp_path, identity_fmu):
    path = ssd(
        tmp_path / "pair.ssd",
        {"a": str(identity_fmu), "b": str(identity_fmu)},
        [("a", "realOut", "b", "realIn")],
    )
    p = api.plan(api.load_scenario(path))
    assert p.startup_sweeps == 0


def test_master_info_and_run_from_the_cli(tmp_path, identity_fmu):
    cli = [sys.executable, "-m", "master"]
    info = subprocess.run([*cli, "info", str(identity_fmu)], capture_output=True, text=True, check=True)
    assert "FMI 1.0" in info.stdout
    out = tmp_path / "id.csv"
    run = subprocess.run(
        [*cli, "run", str(_identity_scene(tmp_path, identity_fmu)), "-o", str(out)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert np.array_equal(rows[:, 1], 2 * rows[:, 0])


def test_fmi1_capabilities_are_read_and_honoured(tmp_path, identity_fmu):
    """fmpy leaves FMI 1.0 Capabilities at their defaults: the master reads them, so an FMU that can
    be instantiated only once per process gets a worker per instance, as an FMI 2 one does. FMI 1
    causality "none" reads as local."""
    assert parse(identity_fmu).coSimulation.canHandleVariableCommunicationStepSize is True

    def once_only(root):
        root.find("Implementation/CoSimulation_StandAlone/Capabilities").set(
            "canBeInstantiatedOnlyOncePerProcess", "true"
        )
        _variable(root, "stringOut").set("causality", "none")

    once = _edited(identity_fmu, tmp_path / "identity.fmu", once_only)
    assert parse(once).coSimulation.canBeInstantiatedOnlyOncePerProcess is True
    assert variables_of(parse(once))["stringOut"].causality == "local"
    assert read_info(once).variables["stringOut"].causality == "local"
    path = ssd(tmp_path / "pair.ssd", {"a": str(once), "b": str(once)}, [("a", "realOut", "b", "realIn")])
    sc = api.load_scenario(path)
    assert api.plan(sc).exclusive == (("a", "b"),)
    with pytest.raises(api.UsageError, match="can be instantiated only once per process"):
        api.run(sc, backend="in-process")
    assert len(api.run(sc, backend="serial").data) == 11


def _with_dependency(fmu: Path, target: Path, dependency: str | None) -> Path:
    """`fmu` with realOut's DirectDependency element replaced by `dependency` (None: left out)."""

    def edit(root):
        out = _variable(root, "realOut")
        out.remove(out.find("DirectDependency"))
        if dependency is not None:
            out.append(etree.fromstring(dependency))

    return _edited(fmu, target, edit)


def test_fmi1_direct_dependencies_say_which_outputs_depend_on_inputs(tmp_path, identity_fmu):
    """Without DirectDependency an FMI 1.0 output depends on every input; an empty one: on none,
    and the master then reads it without setting the step-end input first (this FMU's realOut is
    its realIn all the same, so it lags a step: 2 (t - H))."""
    assert read_info(identity_fmu).feedthrough["realOut"] == {"realIn"}  # as the project's FMU lists it
    every = _with_dependency(identity_fmu, tmp_path / "every" / "identity.fmu", None)
    assert read_info(every).feedthrough["realOut"] == {"realIn", "integerIn", "booleanIn", "stringIn"}
    none = _with_dependency(identity_fmu, tmp_path / "none" / "identity.fmu", "<DirectDependency/>")
    assert read_info(none).feedthrough["realOut"] == frozenset()
    assert "realOut" not in feedthrough_outputs(parse(none))
    assert "integerOut" in feedthrough_outputs(parse(none))
    d = run_everywhere(api.load_scenario(_identity_scene(tmp_path / "none", none)))
    t = d["time"]
    assert np.array_equal(d["id.realOut"], 2 * np.concatenate(([0.0], t[:-1])))  # the previous point's input
