"""Nested ssd:System elements, connections through system connectors, system-level parameters.

Real third-party files (OMSimulator's testsuite, tests/ssp/OpenModelica-OMSimulator/, laid out with
the project's FMUs of the same interface as theirs, with the values OMSimulator's own tests print)
and a nested scene of the project's gain FMU (tests/scenarios/nested/nested.ssd) whose results are
exact products.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import third_party_scene

import master.api as api
from master.fmubuild import fmu_path
from master.scenario import load, validate
from master.scenario.names import join, part, split

HERE = Path(__file__).parent
NESTED = HERE / "scenarios" / "nested" / "nested.ssd"
OMS = HERE / "ssp" / "OpenModelica-OMSimulator"
STAGE = "stage one.'g.1'"  # component "g.1" of system "stage one"

NS = """xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssb="http://ssp-standard.org/SSP1/SystemStructureSignalDictionary"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:mm="urn:org.multirate-master:settings:1\""""
GAIN = """<ssd:Component name="{name}" source="gain"><ssd:Connectors>
  <ssd:Connector name="u" kind="input"/><ssd:Connector name="y" kind="output"/>
  </ssd:Connectors></ssd:Component>"""


def scene(tmp_path: Path, system: str) -> Path:
    p = tmp_path / "scene.ssd"
    p.write_text(
        f'<ssd:SystemStructureDescription version="1.0" name="s" {NS}>{system}'
        '<ssd:DefaultExperiment stopTime="1"><ssd:Annotations>'
        '<ssc:Annotation type="org.multirate-master.settings"><mm:Settings macroStep="0.1"/>'
        "</ssc:Annotation></ssd:Annotations></ssd:DefaultExperiment></ssd:SystemStructureDescription>"
    )
    return p


def test_quoting_keeps_dotted_names_apart():
    assert part("plain name") == "plain name"
    assert part("g.1") == "'g.1'"
    assert part("it's") == "it's" and part("'q'") == "'\\'q\\''"
    assert join(join("", "a.b"), "c") == "'a.b'.c" != join(join("a", "b"), "c") == "a.b.c"
    comps = ["a.b.c", "'a.b'.c", "h"]
    assert split("a.b.c.x.y", comps) == ("a.b.c", "x.y")
    assert split("'a.b'.c.x", comps) == ("'a.b'.c", "x")
    assert split("a.b.x", comps) is None


def test_nested_components_are_named_by_their_path():
    sc = load(NESTED)
    assert [c.name for c in sc.components] == [STAGE, "outer.inner.g", "h"]
    links = {
        (c.start_component, c.start_connector, c.end_component, c.end_connector, c.extrapolation_order)
        for c in sc.connections
    }  # the settings name the resolved connection by the input it drives
    assert links == {(STAGE, "y", "outer.inner.g", "u", 1), ("outer.inner.g", "y", "h", "u", None)}


def test_system_level_parameters_follow_the_ssp_precedence():
    params = {c.name: c.parameters for c in load(NESTED).components}
    assert params[STAGE] == {"K": 3.0, "u": 2.0}  # "g.1.K" bound on "stage one"; u from the top's "drive"
    assert params["outer.inner.g"] == {"K": 10.0}  # the top's 10 beats outer's 7 and its own 5
    assert params["h"] == {"K": 0.5}  # the connection from "gain" replaces its own 9


@pytest.mark.parametrize("backend", ["serial", "parallel"])
def test_nested_scene_runs_to_the_exact_products(backend):
    result = api.run(NESTED, backend=backend)  # qualified names as worker and instance names
    # recorded: h.y as asked, and outer.inner.g.y behind the top system's output connector "result"
    assert result.columns == ["time", "h.y", "outer.inner.g.y"]
    last = result.data[-1]
    assert (last["outer.inner.g.y"], last["h.y"]) == (60.0, 30.0)  # 2 * 3 * 10, then * 0.5


def test_set_and_record_take_qualified_names_and_system_connectors():
    result = api.run(NESTED, set_values=[f"{STAGE}.K=4", "drive=3"], record=[f"{STAGE}.y", "h.y"])
    assert result.columns == ["time", f"{STAGE}.y", "h.y"]
    assert (result.data[-1][f"{STAGE}.y"], result.data[-1]["h.y"]) == (12.0, 60.0)  # 3 * 4 * 10 * 0.5


def test_cli_quotes_dotted_names(tmp_path):
    fmu_path("gain")
    out = tmp_path / "out.csv"
    r = subprocess.run(
        [sys.executable, "-m", "master", "run", str(NESTED), "-q", "-o", str(out),
         "--set", f"{STAGE}.K=4", "--record", f"{STAGE}.y"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == f'time,"{STAGE}.y"' and lines[-1] == "1,8"
    r = subprocess.run(
        [sys.executable, "-m", "master", "run", str(NESTED), "--set", "stage one.g.1.K=4"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert r.returncode != 0 and "a name with a dot in quotes: 'a.b'.variable" in r.stderr


@pytest.mark.parametrize("scene", ["import_export_parameters1", "import_export_parameters2"])
def test_omsimulator_parameter_connectors_drive_component_parameters(tmp_path, scene):
    """Parameter connectors k_cref and T_cref of the top system feed addP.k1 and addI.k2 over the
    values bound to those directly, and the undriven top input Input_cref feeds addP.u1, as
    OMSimulator's tests report (addP.k1 30, addI.k2 20); the values come from one .ssv on the system
    (1) or from an .ssv on each level, the nested system foo's included (2)."""
    path = third_party_scene(OMS / scene, tmp_path) / "with-settings.ssd"
    params = {c.name: c.parameters for c in load(path).components}
    assert params == {"addP": {"k1": 30.0, "k2": -1.0, "u1": -20.0}, "addI": {"k2": 20.0}, "P": {}}
    assert api.run(path).data[-1]["addP.y"] == 30.0 * -20.0  # k1 u1 + k2 u2 with u2 = 0


def test_omsimulator_output_figure_with_its_input(tmp_path):
    """OMSimulator's test sets Input_cref to -3.7 and prints addP.y = Output_cref = -111."""
    path = third_party_scene(OMS / "import_export_parameters1", tmp_path) / "with-settings.ssd"
    result = api.run(path, set_values=["Input_cref=-3.7"])
    assert result.data[-1]["addP.y"] == pytest.approx(-111.0, rel=1e-15)


def test_omsimulator_top_level_bindings_beat_component_ones(tmp_path):
    """toplevelparameter1: root.ssv on the system (addP.k1 -200, addP.k2 -300) beats addp.ssv on
    the component (10, 20), as OMSimulator prints; Input_cref, bound and unconnected, is accepted."""
    path = third_party_scene(OMS / "toplevelparameter1", tmp_path) / "with-settings.ssd"
    assert load(path).component("addP").parameters == {"k1": -200.0, "k2": -300.0}
    result = api.run(path, set_values=["addP.u1=1", "addP.u2=2"])
    assert np.all(result.data["addP.y"][1:] == -200.0 - 600.0)


def test_two_outputs_joined_through_a_system_connector(tmp_path):
    p = scene(
        tmp_path,
        '<ssd:System name="top"><ssd:Connectors><ssd:Connector name="o" kind="output"/></ssd:Connectors>'
        f"<ssd:Elements>{GAIN.format(name='a')}{GAIN.format(name='b')}</ssd:Elements><ssd:Connections>"
        '<ssd:Connection startElement="a" startConnector="y" endConnector="o"/>'
        '<ssd:Connection startElement="b" startConnector="y" endConnector="o"/>'
        "</ssd:Connections></ssd:System>",
    )
    (problem,) = validate(p)
    assert "joins the outputs a.y and b.y through system connectors" in problem.message


def test_unknown_system_connector_and_binding_name(tmp_path):
    p = scene(
        tmp_path,
        '<ssd:System name="top"><ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>'
        '<ssv:ParameterSet version="1.0" name="p"><ssv:Parameters>'
        '<ssv:Parameter name="sub.nope"><ssv:Real value="1"/></ssv:Parameter>'
        "</ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding>"
        '</ssd:ParameterBindings><ssd:Elements><ssd:System name="sub"><ssd:Elements>'
        f"{GAIN.format(name='g')}</ssd:Elements></ssd:System></ssd:Elements><ssd:Connections>"
        '<ssd:Connection startElement="sub" startConnector="missing" endConnector="x"/>'
        "</ssd:Connections></ssd:System>",
    )
    messages = sorted(str(q) for q in validate(p))
    assert any('system sub has no connector "missing"' in m for m in messages)
    assert any('the system has no connector "x"' in m for m in messages)
    assert any('"sub.nope" names neither a connector of system "top"' in m for m in messages)


def test_signal_dictionaries_are_refused_in_one_line(tmp_path):
    p = scene(
        tmp_path,
        '<ssd:System name="top"><ssd:Elements>'
        '<ssd:SignalDictionaryReference name="bus" dictionary="d"/>'
        f"{GAIN.format(name='g')}</ssd:Elements><ssd:Connections>"
        '<ssd:Connection startElement="bus" startConnector="s" endElement="g" endConnector="u"/>'
        "</ssd:Connections>"
        '<ssd:SignalDictionaries><ssd:SignalDictionary name="d" source="d.ssb"/></ssd:SignalDictionaries>'
        "</ssd:System>",
    )
    problems = validate(p)
    assert [q.element for q in problems] == ["ssd:SignalDictionaries", 'ssd:SignalDictionaryReference "bus"']
    assert all("signal dictionaries (SSP 1.0) are not supported" in q.message for q in problems)


def test_sweeps_vary_components_of_nested_systems():
    from master.sweeps.case import apply_case
    from master.sweeps.cases import bind, parse_vary

    sc = load(NESTED)
    ranges = bind([parse_vary(f"{STAGE}.K=1:2:2", "grid")], sc)
    case = apply_case(sc, ranges, {f"{STAGE}.K": 2.0})
    assert case.component(STAGE).parameters["K"] == 2.0


def flattened(path: Path):
    """The flattened structure of a file whose FMUs are left out, and the problems found."""
    from lxml import etree

    from master.scenario.context import Context
    from master.scenario.problems import NS_SSD, Problems
    from master.scenario.systems import flatten

    problems = Problems()
    top = etree.parse(str(path)).getroot().find(f"{{{NS_SSD}}}System")
    return flatten(Context(problems, str(path), path.parent, None), top), problems.items


def test_omsimulator_dcmotor_connections_resolve_through_both_systems():
    """A real nested file (its FMUs left out: the structure alone is read): the stimuli drive the
    components of SuT through SuT's input connectors, and the outputs of the top system name
    component outputs inside SuT, whichever way each connection is written."""
    flat, problems = flattened(OMS / "dcmotor" / "SystemStructure.ssd")
    assert problems == []
    assert [name for name, _ in flat.components] == ["SuT.edrive_mass", "SuT.emachine_model", "stimuli_model"]
    assert {link for link, _ in flat.links} == {
        ("SuT.emachine_model", "M", "SuT.edrive_mass", "M_A"),
        ("SuT.edrive_mass", "wA", "SuT.emachine_model", "w"),
        ("SuT.edrive_mass", "phiA", "SuT.emachine_model", "phi"),
        ("stimuli_model", "M_load", "SuT.edrive_mass", "M_B"),
        ("stimuli_model", "U", "SuT.emachine_model", "U"),
    }
    assert sorted(flat.outputs) == [
        ("I", "SuT.emachine_model", "I"),
        ("M_load", "stimuli_model", "M_load"),
        ("M_mot", "SuT.emachine_model", "M"),
        ("U", "stimuli_model", "U"),
        ("wB", "SuT.edrive_mass", "wB"),
    ]
    assert flat.fed == []


def test_settings_written_back_reach_components_of_nested_systems(tmp_path):
    import dataclasses

    from master.scenario.writer import write_settings

    sc = load(NESTED)
    changed = dataclasses.replace(
        sc,
        components=tuple(
            dataclasses.replace(c, parameters={**c.parameters, "K": 4.0}, step_ratio=2)
            if c.name == STAGE
            else c
            for c in sc.components
        ),
    )
    # beside the original: its relative FMU sources stay valid
    out = write_settings(sc, changed, tmp_path / "tuned.ssd", "test")
    again = load(out)
    assert again.component(STAGE).parameters["K"] == 4.0 and again.component(STAGE).step_ratio == 2
    assert again.component("outer.inner.g").parameters == {"K": 10.0}


def test_names_with_quotes_and_commas_survive_the_results_file(tmp_path):
    from master.recorder import read_csv

    fmu_path("gain")
    odd = 'say "hi", twice'
    p = scene(
        tmp_path,
        f'<ssd:System name="top"><ssd:Elements><ssd:System name="s.1"><ssd:Elements>'
        f"{GAIN.format(name='say &quot;hi&quot;, twice')}</ssd:Elements></ssd:System></ssd:Elements>"
        "</ssd:System>",
    )
    column = f"'s.1'.{odd}.y"
    result = api.run(p, output=tmp_path / "out.csv", set_values=[f"'s.1'.{odd}.u=1.5"])
    assert result.columns == ["time", column]
    back = read_csv(tmp_path / "out.csv")
    assert back.dtype.names == ("time", column) and back[column][-1] == 3.0  # K = 2 by default


def test_omsimulator_composite_model_resolves_connections_written_input_to_output():
    """acvs_compositeModel: fuel's outputs reach the inputs of valve.valve_model through valve's
    input connectors, in connections written from the inputs; the connector kinds decide."""
    flat, problems = flattened(OMS / "acvs_compositeModel" / "SystemStructure.ssd")
    assert problems == []
    names = [name for name, _ in flat.components]
    assert names[-2:] == ["valve.interface_model", "valve.valve_model"] and len(names) == 8
    through = {link for link, _ in flat.links if (link[0] + link[2]).count("valve.") == 1}
    assert through == {
        ("fuel", "valve_p1", "valve.valve_model", "pA"),
        ("fuel", "valve_p1", "valve.valve_model", "pB"),
        ("fuel", "valve_p2", "valve.valve_model", "pTA"),
        ("fuel", "valve_p3", "valve.valve_model", "pTB"),
        ("fuel", "valve_u", "valve.interface_model", "u.out.y"),
        ("valve.interface_model", "mflowA.in.y", "fuel", "valve_mflowA"),
        ("valve.interface_model", "mflowB.in.y", "fuel", "valve_mflowB"),
    }
