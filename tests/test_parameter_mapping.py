"""Parameter mappings (ssd:ParameterMapping, inline or an .ssm file): a binding's values renamed
to the parameters they set, with the mapping entry's transformation and unit conversion applied.

Real third-party files: five scenes of OMSimulator's testsuite (tests/ssp/OpenModelica-OMSimulator/,
ORIGIN.md there; LinearTransformation3 laid out with the project's FMUs of its FMUs' interface),
checked against the values OMSimulator's own tests print. A scene written here on the project's
discrete FMU covers what those do not: unit conversion, suppressUnitConversion,
the mapping transformations, and the problems, one line each.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import third_party_scene
from lxml import etree

import master.api as api
from master.scenario import ScenarioError, load, validate

OMS = Path(__file__).parent / "ssp" / "OpenModelica-OMSimulator"


def mapped_scene(tmp_path: Path) -> Path:
    """LinearTransformation3 with its FMUs, in tmp_path."""
    return third_party_scene(OMS / "LinearTransformation3", tmp_path) / "SystemStructure.ssd"


def connector_values(path: Path) -> dict[str, float]:
    """The values the bindings give the system connectors of a file without FMUs, by qualified name."""
    from master.scenario.bindings import system_values
    from master.scenario.context import Context
    from master.scenario.problems import NS_SSD, Problems
    from master.scenario.systems import flatten

    problems = Problems()
    top = etree.parse(str(path)).getroot().find(f"{{{NS_SSD}}}System")
    ctx = Context(problems, str(path), path.parent, None)
    values = system_values(ctx, flatten(ctx, top), {})
    assert problems.items == []
    return {key: float(entry.value.get("value")) for key, entry in values.items()}


def test_omsimulator_linear_transformation_in_a_parameter_mapping(tmp_path):
    """LinearTransformation3: mappedParameter1.ssv binds mapped_Gain_u = mapped_Gain_k = 2 on the
    system, mappedEntry1.ssm (SSP 2.0) maps them to Gain1.u (2 v + 10) and Gain1.k (4 v + 5);
    OMSimulator prints Gain1.k 13, Gain1.u 14, Gain1.y 182 and Add1.u1 182."""
    path = mapped_scene(tmp_path)
    params = {c.name: c.parameters for c in load(path).components}
    assert params == {"Gain1": {"u": 2.0 * 2.0 + 10.0, "k": 4.0 * 2.0 + 5.0}, "Add1": {}}
    d = api.run(path).data
    assert np.all(d["Gain1.y"] == 13.0 * 14.0) and np.all(d["Add1.y"] == 182.0)  # Add1: u1 + 0


def test_omsimulator_mapped_scene_runs_from_the_command_line(tmp_path):
    out = tmp_path / "out.csv"
    path = mapped_scene(tmp_path)
    r = subprocess.run(
        [sys.executable, "-m", "master", "run", str(path), "-o", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == 'time,"Add1.y","Gain1.y"' and lines[-1] == "1,182,182"


# The .ssv of both importParameterMapping scenes also holds Input_3 (50) and parameter_2 (-40), which
# the mapping does not name: SSP says "All parameters of the parameter source which are not referenced
# in a mapping entry will not be applied" (SSP 1.0.1 and 2.0, SSM chapter), so they bind nothing here;
# OMSimulator applies them under their own names and prints co_sim.Input_3 50.0, parameter_2 -40.0.
UNMAPPED = {"Input_3", "parameter_2"}


def test_omsimulator_mapping_from_an_ssm_file_on_system_connectors(caplog):
    """importParameterMapping: one source mapped to several connectors of the system and of its
    sub-systems, as OMSimulator prints them (System1/2.parameter_2 print 0.0: nothing binds them);
    the values the mapping does not name are not applied (above), a warning naming them."""
    values = connector_values(OMS / "importParameterMapping" / "SystemStructure.ssd")
    expected = {"Input_1": 20.0, "Input_2": 20.0, "parameter_1": -30.0}
    for sub in ("System1", "System2"):
        expected |= {f"{sub}.Input_1": 20.0, f"{sub}.Input_2": 20.0, f"{sub}.parameter_1": -30.0}
    assert values == expected and not UNMAPPED & set(values)
    assert '"Input_3", "parameter_2" not applied: the binding\'s parameter mapping does not name them' in (
        caplog.text
    )


def test_omsimulator_inline_mappings_on_each_level():
    """importParameterMappingInline: an inline ssm:ParameterMapping on the top system and on each
    sub-system, as OMSimulator prints them, but for the unmapped values of the top (above)."""
    values = connector_values(OMS / "importParameterMappingInline" / "SystemStructure.ssd")
    expected = {"Input_1": 20.0, "Input_2": 20.0, "parameter_1": -30.0}  # not Input_3, parameter_2: above
    expected |= {f"System1.{n}": -100.0 for n in ("Input_1", "Input_2")}
    expected |= {f"System1.{n}": -50.0 for n in ("parameter_1", "parameter_2")}
    expected |= {f"System2.{n}": 70.0 for n in ("Input_1", "Input_2", "parameter_1", "parameter_2")}
    assert values == expected


def test_omsimulator_mapping_on_a_sub_system():
    """import_hierarchical_ssv_sources: System3's .ssv value -70 reaches Input_1 and parameter_1
    through its .ssm; the other systems' bindings are plain. As OMSimulator prints."""
    values = connector_values(OMS / "import_hierarchical_ssv_sources" / "SystemStructure.ssd")
    assert values == {
        "System3.Input_1": -70.0, "System3.parameter_1": -70.0,
        "System2.Input_1": -30.0, "System2.Input_2": -100.0, "System2.parameter_1": -40.0,
        "System1.Input_1": -10.0, "System1.parameter_1": -20.0,
    }  # fmt: skip


def test_omsimulator_invalid_ssm_is_named_by_file_line_and_element():
    """invalidSSM: an ssm:MappingEntry with destination= for target= (OMSimulator warns at line 12)."""
    problems = validate(OMS / "invalidSSM" / "SystemStructure.ssd")
    assert {(Path(p.file).name, p.line, p.element) for p in problems} == {
        ("import_parameter_mapping.ssm", 12, "ssm:MappingEntry")
    }
    assert any("destination" in p.message for p in problems)
    assert any("'target' is required" in p.message for p in problems)


# -- files written here: the discrete FMU (rate in 1/s, quantum, threshold, n_in Integer, on_in
# -- Boolean, solver Enumeration) ----------------------------------------------------------------

NS = """xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
    xmlns:mm="urn:org.multirate-master:settings:1\""""
SSM_NS = 'xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"'
VALUES = """<ssv:Parameter name="per_minute"><ssv:Real value="120" unit="1/min"/></ssv:Parameter>
<ssv:Parameter name="q"><ssv:Real value="1"/></ssv:Parameter>
<ssv:Parameter name="count"><ssv:Integer value="3"/></ssv:Parameter>
<ssv:Parameter name="flag"><ssv:Boolean value="true"/></ssv:Parameter>
<ssv:Parameter name="method"><ssv:Enumeration value="fast"/></ssv:Parameter>
<ssv:Parameter name="threshold"><ssv:Real value="0.75"/></ssv:Parameter>"""
ENTRIES = """<ssm:MappingEntry source="per_minute" target="rate"/>
<ssm:MappingEntry source="q" target="quantum"><ssc:LinearTransformation factor="0.5" offset="0.125"/>
</ssm:MappingEntry>
<ssm:MappingEntry source="count" target="n_in"><ssc:IntegerMappingTransformation>
<ssc:MapEntry source="3" target="7"/></ssc:IntegerMappingTransformation></ssm:MappingEntry>
<ssm:MappingEntry source="flag" target="on_in"><ssc:BooleanMappingTransformation>
<ssc:MapEntry source="true" target="false"/></ssc:BooleanMappingTransformation></ssm:MappingEntry>
<ssm:MappingEntry source="method" target="solver"><ssc:EnumerationMappingTransformation>
<ssc:MapEntry source="fast" target="rk4"/></ssc:EnumerationMappingTransformation></ssm:MappingEntry>
<ssm:MappingEntry source="absent" target="x"/>"""
UNITS = """<ssd:Units><ssc:Unit name="1/s"><ssc:BaseUnit s="-1"/></ssc:Unit>
<ssc:Unit name="1/min"><ssc:BaseUnit s="-1" factor="0.016666666666666666"/></ssc:Unit></ssd:Units>"""


def only(*names: str) -> str:
    """The lines of VALUES for the parameters `names`."""
    return "\n".join(line for line in VALUES.splitlines() if any(f'"{n}"' in line for n in names))


def scene(tmp_path: Path, mapping: str, values: str = VALUES, units: str = UNITS) -> Path:
    """The discrete FMU as component d, its values inline, `mapping` inside ssd:ParameterMapping."""
    p = tmp_path / "mapped.ssd"
    p.write_text(f"""<ssd:SystemStructureDescription version="1.0" name="mapped" {NS}>
<ssd:System name="top"><ssd:Elements><ssd:Component name="d" source="project:discrete">
<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
<ssv:ParameterSet version="1.0" name="p"><ssv:Parameters>{values}</ssv:Parameters></ssv:ParameterSet>
</ssd:ParameterValues><ssd:ParameterMapping{mapping}</ssd:ParameterMapping>
</ssd:ParameterBinding></ssd:ParameterBindings></ssd:Component></ssd:Elements></ssd:System>{units}
<ssd:DefaultExperiment stopTime="1"><ssd:Annotations>
<ssc:Annotation type="org.multirate-master.settings"><mm:Settings macroStep="0.1"/>
</ssc:Annotation></ssd:Annotations></ssd:DefaultExperiment></ssd:SystemStructureDescription>""")
    return p


def inline(entries: str) -> str:
    """An inline ssm:ParameterMapping of `entries`, as `scene` takes it."""
    return f'><ssm:ParameterMapping version="1.0">{entries}</ssm:ParameterMapping>'


def ssm(tmp_path: Path, entries: str, version: str = "1.0") -> str:
    (tmp_path / "m.ssm").write_text(
        f'<ssm:ParameterMapping version="{version}" {SSM_NS} '
        f'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">{entries}</ssm:ParameterMapping>'
    )
    return ' source="m.ssm">'


@pytest.mark.parametrize("where", ["inline", "file"])
def test_values_are_renamed_transformed_and_converted(tmp_path, where):
    path = scene(tmp_path, inline(ENTRIES) if where == "inline" else ssm(tmp_path, ENTRIES))
    assert load(path).component("d").parameters == {
        "rate": pytest.approx(2.0, rel=1e-15),  # 120 per minute, in 1/s
        "quantum": 0.5 * 1.0 + 0.125,
        "n_in": 7,
        "on_in": False,
        "solver": 4,  # rk4
    }  # not threshold: a mapping applies only the values it names


@pytest.mark.parametrize(
    "entry, expected",
    [
        # the linear transformation after the conversion: 2 (120 per minute) * 3 + 1
        ('<ssm:MappingEntry source="per_minute" target="rate"><ssc:LinearTransformation factor="3" '
         'offset="1"/></ssm:MappingEntry>', 7.0),
        # suppressUnitConversion: the linear transformation instead of the conversion
        ('<ssm:MappingEntry source="per_minute" target="rate" suppressUnitConversion="true">'
         '<ssc:LinearTransformation factor="3" offset="1"/></ssm:MappingEntry>', 361.0),
        ('<ssm:MappingEntry source="per_minute" target="rate" suppressUnitConversion="true"/>', 120.0),
    ],
)  # fmt: skip
def test_unit_conversion_comes_before_the_transformation_unless_suppressed(tmp_path, entry, expected):
    path = scene(tmp_path, inline(entry), only("per_minute"))
    assert load(path).component("d").parameters["rate"] == pytest.approx(expected, rel=1e-15)


def test_one_source_binds_several_targets(tmp_path):
    entries = '<ssm:MappingEntry source="q" target="quantum"/>' * 2
    entries = entries.replace("quantum", "threshold", 1)
    values = '<ssv:Parameter name="q"><ssv:Real value="0.625"/></ssv:Parameter>'
    path = scene(tmp_path, inline(entries), values)
    assert load(path).component("d").parameters == {"quantum": 0.625, "threshold": 0.625}


@pytest.mark.parametrize(
    "mapping, file, element, message",
    [
        ('><ssm:ParameterMapping version="1.0"><ssm:MappingEntry source="q" target="nope"/>'
         "</ssm:ParameterMapping>", "mapped.ssd", "ssm:MappingEntry",
         'the FMU of d (discrete.fmu) has no "nope"'),
        ('><ssm:ParameterMapping version="1.0"><ssm:MappingEntry source="count" target="n_in">'
         '<ssc:LinearTransformation factor="2"/></ssm:MappingEntry></ssm:ParameterMapping>',
         "mapped.ssd", "ssc:LinearTransformation", "transforms Real values only"),
        ('><ssm:ParameterMapping version="1.0"><ssm:MappingEntry source="method" target="solver">'
         '<ssc:EnumerationMappingTransformation><ssc:MapEntry source="fast" target="warp"/>'
         "</ssc:EnumerationMappingTransformation></ssm:MappingEntry></ssm:ParameterMapping>",
         "mapped.ssd", "ssc:MapEntry", 'target "warp" is not an item of d.solver'),
        (' source="missing.ssm">', "mapped.ssd", "ssd:ParameterMapping",
         'parameter mapping "missing.ssm" not found'),
    ],
)  # fmt: skip
def test_problems_are_one_line_naming_file_and_element(tmp_path, mapping, file, element, message):
    values = only(*re.findall(r'MappingEntry source="(\w+)"', mapping)) or only("q")
    problems = validate(scene(tmp_path, mapping, values))
    assert [(Path(p.file).name, p.element) for p in problems] == [(file, element)], problems
    assert message in problems[0].message
    with pytest.raises(ScenarioError):
        load(scene(tmp_path, mapping, values))


@pytest.mark.parametrize(
    "text, message",
    [
        ('<ssm:ParameterMapping version="1.0" {ns}><ssm:MappingEntry source="q" target="nope"/>'
         "</ssm:ParameterMapping>", 'unknown variable: the FMU of d (discrete.fmu) has no "nope"'),
        ('<ssm:ParameterMapping version="1.0" {ns}><ssm:MappingEntry source="q"', "not well-formed XML"),
        ('<ssm:ParameterMapping version="3.0" {ns}/>', "schema violation: attribute version"),
        ('<ssv:ParameterSet version="1.0" name="p" '
         'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"/>', "schema violation"),
    ],
)  # fmt: skip
def test_problems_of_an_ssm_file_name_that_file(tmp_path, text, message):
    (tmp_path / "m.ssm").write_text(text.format(ns=SSM_NS))
    problems = validate(scene(tmp_path, ' source="m.ssm">', only("q")))
    assert [Path(p.file).name for p in problems] == ["m.ssm"], problems
    assert message in problems[0].message


def test_an_ssp2_mapping_file_is_checked_with_the_ssp2_schema(tmp_path):
    """SSP 2.0's schema takes version 2.0 (and 1.0); SSP 1.0's takes 1.x only."""
    entries = '<ssm:MappingEntry source="q" target="quantum"/>'
    values = '<ssv:Parameter name="q"><ssv:Real value="0.5"/></ssv:Parameter>'
    assert load(scene(tmp_path, ssm(tmp_path, entries, "2.0"), values)).component("d").parameters == {
        "quantum": 0.5
    }
    (problem,) = validate(scene(tmp_path, ssm(tmp_path, entries, "2.1"), values))
    assert problem.file.endswith("m.ssm") and "attribute version" in problem.message


def test_a_mapped_system_connector_value_reaches_its_components_transformed(tmp_path):
    """A value mapped to a parameter connector of the system, with a linear transformation, sets
    the gain K of both components connected to it; a transformation that does not fit the value
    is one line, though the connector reaches two components; a target the system lacks is one
    line at the mapping entry."""
    p = tmp_path / "connector.ssd"
    value = '<ssv:Real value="3"/>'
    p.write_text(f"""<ssd:SystemStructureDescription version="1.0" name="s" {NS}>
<ssd:System name="top"><ssd:Connectors><ssd:Connector name="k" kind="parameter"/></ssd:Connectors>
<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
<ssv:ParameterSet version="1.0" name="p"><ssv:Parameters><ssv:Parameter name="gain">{value}</ssv:Parameter>
</ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues><ssd:ParameterMapping>
<ssm:ParameterMapping version="1.0"><ssm:MappingEntry source="gain" target="k">
<ssc:LinearTransformation factor="2" offset="0.5"/></ssm:MappingEntry></ssm:ParameterMapping>
</ssd:ParameterMapping></ssd:ParameterBinding></ssd:ParameterBindings><ssd:Elements>
<ssd:Component name="a" source="project:gain"><ssd:Connectors><ssd:Connector name="K" kind="parameter"/>
</ssd:Connectors></ssd:Component>
<ssd:Component name="b" source="project:gain"><ssd:Connectors><ssd:Connector name="K" kind="parameter"/>
</ssd:Connectors></ssd:Component></ssd:Elements><ssd:Connections>
<ssd:Connection startConnector="k" endElement="a" endConnector="K"/>
<ssd:Connection startConnector="k" endElement="b" endConnector="K"/></ssd:Connections></ssd:System>
<ssd:DefaultExperiment stopTime="1"><ssd:Annotations>
<ssc:Annotation type="org.multirate-master.settings"><mm:Settings macroStep="0.1"/>
</ssc:Annotation></ssd:Annotations></ssd:DefaultExperiment></ssd:SystemStructureDescription>""")
    assert {c.name: c.parameters for c in load(p).components} == {"a": {"K": 6.5}, "b": {"K": 6.5}}
    p.write_text(p.read_text().replace(value, '<ssv:Integer value="3"/>'))
    (problem,) = validate(p)
    assert problem.element == "ssc:LinearTransformation"
    assert 'transforms Real values only: parameter "gain" is Integer' in problem.message
    p.write_text(p.read_text().replace('target="k"', 'target="kk"'))
    (problem,) = validate(p)
    assert problem.element == "ssm:MappingEntry"
    assert '"kk" names neither a connector of system "top" nor a component of it' in problem.message


def test_a_mapping_inside_an_ssp_archive(tmp_path):
    import zipfile

    folder = mapped_scene(tmp_path / "scene").parent
    archive = tmp_path / "LinearTransformation3.ssp"
    with zipfile.ZipFile(archive, "w") as z:
        for f in folder.rglob("*"):
            if f.is_file() and f.name != "ORIGIN.md":
                z.write(f, f.relative_to(folder).as_posix())
    assert load(archive).component("Gain1").parameters == {"u": 14.0, "k": 13.0}


def test_an_enumeration_value_no_map_entry_names_passes_unchanged(tmp_path):
    entry = (
        '<ssm:MappingEntry source="method" target="solver"><ssc:EnumerationMappingTransformation>'
        '<ssc:MapEntry source="slow" target="euler"/></ssc:EnumerationMappingTransformation>'
        "</ssm:MappingEntry>"
    )
    values = '<ssv:Parameter name="method"><ssv:Enumeration value="ab3"/></ssv:Parameter>'
    assert load(scene(tmp_path, inline(entry), values)).component("d").parameters == {"solver": 3}


def test_two_sources_mapped_to_one_target_are_refused(tmp_path):
    """SSP: "Implementations MUST NOT map multiple parameters to the same name"."""
    entries = '<ssm:MappingEntry source="q" target="quantum"/>'
    entries += '<ssm:MappingEntry source="count" target="quantum"/>'
    (problem,) = validate(scene(tmp_path, ssm(tmp_path, entries), only("q", "count")))
    assert (Path(problem.file).name, problem.element) == ("m.ssm", "ssm:MappingEntry")
    assert 'maps "count" to "quantum", to which "q" is mapped already' in problem.message


def test_settings_written_to_another_folder_keep_the_mapping_file(tmp_path):
    """A copy written elsewhere (master tune) points its .ssv, .ssm and FMU sources back at the
    originals, so the mapped values survive."""
    from master.scenario.writer import write_settings

    sc = load(mapped_scene(tmp_path / "scene"))
    again = load(write_settings(sc, sc, tmp_path / "copy.ssd", "test"))
    assert again.component("Gain1").parameters == {"u": 14.0, "k": 13.0}
