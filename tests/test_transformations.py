"""Connection transformations (SSP 1.0 section 5.3.3) applied by the kernel to the coupled value, in
every backend: ssc:LinearTransformation, unit conversion through the file's ssd:Units, and the
Boolean, Integer and Enumeration mapping transformations.

Real third-party scenes: libcosim's linear transformation test and OMSimulator's
LinearTransformation system (tests/ssp/*/ORIGIN.md; laid out with the project's FMUs of its FMUs'
interface), checked against the exact value of the
transformation and against OMSimulator's own printed result. Files written here cover what those
scenes do not (unit conversion, mappings), on the project's FMUs (gain: y = K u; discrete;
alltypes; msd).
"""

from dataclasses import replace
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from helpers import libcosim_last_values, run_everywhere, third_party_scene

import master.api as api
from master.fmubuild import fmu_path
from master.scenario import ScenarioError, validate
from master.scenario.model import Component, Connection, Scenario, Transformation

SSP = Path(__file__).parent / "ssp"
LIBCOSIM = SSP / "open-simulation-platform-libcosim" / "linear_transformation"
OMS = SSP / "OpenModelica-OMSimulator" / "LinearTransformation"


def test_libcosim_linear_transformation_scene_gives_factor_times_source_plus_offset():
    sc = api.load_scenario(LIBCOSIM / "with-project-fmus.ssd")
    sc = replace(sc, record=(("identity1", "y"), ("identity2", "u"), ("identity2", "y")))
    d = run_everywhere(sc)
    assert np.all(d["identity1.y"] == 4.0)  # the later of the two parameter bindings
    # the target = 1.3 source + 50, from the first row (the initial values) on; y = 1 u exactly
    assert np.array_equal(d["identity2.u"], 1.3 * d["identity1.y"] + 50.0)
    assert np.array_equal(d["identity2.y"], d["identity2.u"])
    assert (
        "identity1.y -> identity2.u: order 0, extrapolated, then 1.3 * value + 50.0"
        in api.plan(sc).describe()
    )


def test_the_runnable_copies_keep_the_originals_as_origin_md_says():
    """The copies differ from the third-party files only where ORIGIN.md says."""
    from lxml import etree

    def structure(path: Path) -> list[tuple[str, dict[str, str]]]:
        root = etree.parse(str(path)).getroot()
        wanted = ("System", "Component", "Connection", "LinearTransformation")
        return [
            (etree.QName(e).localname, dict(e.attrib))
            for e in root.iter()
            if etree.QName(e).localname in wanted
        ]

    renamed = {"realIn": "u", "realOut": "y", "../../fmi1/identity.fmu": "project:gain"}
    original = [
        (name, {k: renamed.get(v, v) for k, v in attributes.items()})
        for name, attributes in structure(LIBCOSIM / "SystemStructure.ssd")
    ]
    assert original == structure(LIBCOSIM / "with-project-fmus.ssd")
    copy = (OMS / "with-settings.ssd").read_text()
    annotation = copy[copy.index("    <ssd:Annotations>") : copy.index("  </ssd:System>")]
    copy = copy.replace(annotation, "").replace('xmlns:mm="urn:org.multirate-master:settings:1" ', "")
    assert copy.replace('version="1.0"', 'version="2.0"', 1) == (OMS / "SystemStructure.ssd").read_text()


@pytest.mark.parametrize("u, u1", [(None, 3.0), ("1.5", 6.0), ("-0.25", 2.5)])
def test_omsimulator_linear_transformation_scene(tmp_path, u, u1):
    """Gain1.y (= k u, k = 1) -> Add1.u1 through factor 2, offset 3; Add1.y = k1 u1 + k2 u2 with
    k1 = k2 = 1 and u2 = 0. OMSimulator prints Add1.u1 = 3.0 after its run (Gain1.u = 0)."""
    scene = third_party_scene(OMS, tmp_path) / "with-settings.ssd"
    sc = api.load_scenario(scene, {"Gain1.u": u} if u else None)
    sc = replace(sc, record=(("Gain1", "y"), ("Add1", "u1"), ("Add1", "y")))
    d = run_everywhere(sc)
    assert np.array_equal(d["Add1.u1"], 2.0 * d["Gain1.y"] + 3.0)
    assert np.all(d["Add1.u1"] == u1) and np.all(d["Add1.y"] == u1)


# -- extrapolated signals: the transformation acts on the polynomial's value and derivatives --------


def coupled(t: Transformation | None, interpolate: bool = False, coupling: str = "jacobi") -> Scenario:
    """An oscillating msd `a` drives the coupling spring of a resting msd `b` (x_in), extrapolated
    with order 2 (interpolated where a steps first: Gauss-Seidel), b stepping 3 times per macro step
    or once with its inputs as polynomials."""
    fmu = fmu_path("msd")
    a = Component("a", fmu, {"x0": 1.0, "c": 4.0, "d": 0.3}, 1, 0)
    b = Component("b", fmu, {"x0": 0.0, "v0": 0.0, "cc": 2.0, "dc": 0.0, "d": 0.5}, 3, 2, interpolate)
    conn = Connection("a", "x", "b", "x_in", transformation=t)
    record = (("a", "x"), ("b", "x"), ("b", "v"), ("b", "x_in"))
    H = Fraction(1, 20)
    return Scenario(
        Path("coupled.ssd"), "coupled", (a, b), (conn,), Fraction(0), Fraction(2), H, coupling, record=record
    )


@pytest.mark.parametrize(
    "interpolate, coupling",
    [(False, "jacobi"), (True, "jacobi"), (False, "gauss-seidel"), (True, "gauss-seidel")],
)
def test_a_factor_scales_the_extrapolated_signal_and_its_derivatives(interpolate, coupling):
    """b is linear and starts at rest, so an input twice as large gives exactly twice its motion
    (doubling is exact in floating point): the factor reaches every extrapolated value the steps
    use, and every input derivative where b takes its inputs as polynomials."""
    plain = run_everywhere(coupled(None, interpolate, coupling))
    doubled = run_everywhere(coupled(Transformation("linear", 2.0), interpolate, coupling))
    assert np.any(plain["b.x"] != 0.0)
    for col in ("b.x", "b.v", "b.x_in"):
        assert np.array_equal(doubled[col], 2.0 * plain[col]), col
    assert np.array_equal(doubled["a.x"], plain["a.x"])


def test_an_offset_shifts_the_coupled_value_and_an_identity_changes_nothing():
    plain = run_everywhere(coupled(None))
    same = run_everywhere(coupled(Transformation("linear", 1.0, 0.0)))
    for name in plain.dtype.names:
        assert np.array_equal(same[name], plain[name]), name
    shifted = run_everywhere(coupled(Transformation("linear", -0.5, 0.25)))
    assert np.array_equal(shifted["b.x_in"], -0.5 * shifted["a.x"] + 0.25)  # at every row (resampled)
    assert not np.array_equal(shifted["b.x"], plain["b.x"])


# -- unit conversion ---------------------------------------------------------------------------

UNITS = """  <ssd:Units>
    <ssc:Unit name="m"><ssc:BaseUnit m="1"/></ssc:Unit>
    <ssc:Unit name="km"><ssc:BaseUnit m="1" factor="1000"/></ssc:Unit>
    <ssc:Unit name="K"><ssc:BaseUnit K="1"/></ssc:Unit>
    <ssc:Unit name="degC"><ssc:BaseUnit K="1" offset="273.15"/></ssc:Unit>
    <ssc:Unit name="degF">
      <ssc:BaseUnit K="1" factor="0.5555555555555556" offset="255.3722222222222"/>
    </ssc:Unit>
    <ssc:Unit name="s"><ssc:BaseUnit s="1"/></ssc:Unit>
  </ssd:Units>
"""


def gains(
    path: Path, unit_a: str, unit_b: str, inside: str = "", attributes: str = "", units: str = UNITS
) -> Path:
    """Two gain FMUs (K = 1), a.y -> b.u, their connectors in the units given; a.u is 2.5."""
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="units"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:mm="urn:org.multirate-master:settings:1">
  <ssd:System name="units">
    <ssd:Elements>
      <ssd:Component name="a" source="project:gain">
        <ssd:Connectors><ssd:Connector name="y" kind="output"><ssc:Real unit="{unit_a}"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues><ssv:ParameterSet version="1.0"
          name="a"><ssv:Parameters><ssv:Parameter name="K"><ssv:Real value="1"/></ssv:Parameter>
          <ssv:Parameter name="u"><ssv:Real value="2.5"/></ssv:Parameter></ssv:Parameters></ssv:ParameterSet>
        </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="b" source="project:gain">
        <ssd:Connectors><ssd:Connector name="u" kind="input"><ssc:Real unit="{unit_b}"/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="a" startConnector="y" endElement="b" endConnector="u"{attributes}>{inside}
      </ssd:Connection>
    </ssd:Connections>
    <ssd:Annotations><ssc:Annotation type="org.multirate-master.settings">
      <mm:Settings macroStep="0.1"><mm:Record><mm:Variable component="b" name="u"/></mm:Record></mm:Settings>
    </ssc:Annotation></ssd:Annotations>
  </ssd:System>
{units}  <ssd:DefaultExperiment stopTime="0.3"/>
</ssd:SystemStructureDescription>
""")
    return path


@pytest.mark.parametrize(
    "unit_a, unit_b, inside, attributes, expected",
    [
        ("km", "m", "", "", 2500.0),
        ("m", "km", "", "", 0.0025),
        ("degC", "K", "", "", 2.5 + 273.15),
        ("K", "degC", "", "", 2.5 - 273.15),
        # converted first, then transformed (SSP: the source is already in the target unit)
        ("km", "m", '<ssc:LinearTransformation factor="2" offset="1"/>', "", 2.0 * 2500.0 + 1.0),
        # suppressUnitConversion: the linear transformation instead of the conversion
        (
            "km",
            "m",
            '<ssc:LinearTransformation factor="2" offset="1"/>',
            ' suppressUnitConversion="true"',
            6.0,
        ),
        ("m", "m", "", "", 2.5),
    ],
)
def test_compatible_units_convert_through_their_si_base_units(tmp_path, unit_a, unit_b, inside, attributes,
                                                              expected):  # fmt: skip
    sc = api.load_scenario(gains(tmp_path / "units.ssd", unit_a, unit_b, inside, attributes))
    d = run_everywhere(sc)
    assert d["b.u"] == pytest.approx(np.full(len(d), expected), rel=1e-15)


def test_fahrenheit_to_celsius_through_kelvin(tmp_path):
    sc = api.load_scenario(gains(tmp_path / "f.ssd", "degF", "degC"))
    assert run_everywhere(sc)["b.u"] == pytest.approx([(2.5 - 32.0) * 5.0 / 9.0] * 4, rel=1e-13)


@pytest.mark.parametrize(
    "unit_a, unit_b, units, message",
    [
        ("m", "s", UNITS, 'a.y is in "m", b.u in "s": they measure different quantities (m and s), '
         "no conversion exists"),
        ("m", "ft", UNITS, 'a.y is in "m", b.u in "ft"; define "ft" in the ssd:Units of the file'),
        ("m", "km", "", 'a.y is in "m", b.u in "km"; define "m" and "km" in the ssd:Units of the file'),
    ],
)  # fmt: skip
def test_incompatible_or_undefined_units_are_refused_in_one_line(tmp_path, unit_a, unit_b, units, message):
    path = gains(tmp_path / "bad.ssd", unit_a, unit_b, units=units)
    problems = validate(path)
    assert [p.element for p in problems] == ["ssd:Connection a.y -> b.u"], problems
    assert "unit mismatch: " + message in problems[0].message
    with pytest.raises(ScenarioError):
        api.load_scenario(path)


def test_a_scenario_built_in_python_keeps_the_unit_rule():
    """A Python-built scenario between FMU variables in different units is refused unless its
    transformation says it converts between exactly those units."""
    fmu = fmu_path("msd")
    comps = (Component("a", fmu), Component("b", fmu))
    base = Scenario(Path("s.ssd"), "s", comps, (), Fraction(0), Fraction(1), Fraction(1, 10))
    wrong = replace(base, connections=(Connection("a", "x", "b", "F"),))  # m -> N
    with pytest.raises(ScenarioError, match='unit mismatch: a.x is in "m", b.F in "N"'):
        api.plan(wrong)
    said = Transformation("linear", 3.0, units=("m", "N"))
    api.plan(replace(base, connections=(Connection("a", "x", "b", "F", transformation=said),)))
    bad = replace(
        base, connections=(Connection("a", "x", "b", "x_in", transformation=Transformation("map")),)
    )
    discrete = fmu_path("discrete")
    ints = replace(base, components=(Component("a", discrete), Component("b", discrete)))
    huge = Transformation("map", mapping=((1, 2**40),))
    with pytest.raises(
        ScenarioError, match=r"mapped value 1.09951e\+12 is outside \[-2147483648, 2147483647\]"
    ):
        api.plan(replace(ints, connections=(Connection("a", "n", "b", "n_in", transformation=huge),)))
    with pytest.raises(
        ScenarioError,
        match="a map transformation transforms Integer, Enumeration and Boolean values only: a.x is Real",
    ):
        api.plan(bad)


# -- mapping transformations of held signals -----------------------------------------------------


def pair(path: Path, source: str, connectors: str, connections: str, settings: str = "") -> Path:
    """Two instances a and b of one project FMU; `connectors` declared on both."""
    comps = "".join(
        f'<ssd:Component name="{n}" source="project:{source}"><ssd:Connectors>{connectors}'
        "</ssd:Connectors></ssd:Component>\n"
        for n in ("a", "b")
    )
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="mapped"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:mm="urn:org.multirate-master:settings:1">
  <ssd:System name="mapped">
    <ssd:Elements>{comps}</ssd:Elements>
    <ssd:Connections>{connections}</ssd:Connections>
    <ssd:Annotations><ssc:Annotation type="org.multirate-master.settings">
      <mm:Settings macroStep="0.05">{settings}</mm:Settings>
    </ssc:Annotation></ssd:Annotations>
  </ssd:System>
  <ssd:DefaultExperiment stopTime="2"/>
</ssd:SystemStructureDescription>
""")
    return path


DISCRETE = """<ssd:Connector name="n" kind="output"/><ssd:Connector name="on" kind="output"/>
<ssd:Connector name="n_in" kind="input"/><ssd:Connector name="on_in" kind="input"/>"""
INTEGER_MAP = """<ssd:Connection startElement="a" startConnector="n" endElement="b" endConnector="n_in">
  <ssc:IntegerMappingTransformation>
    <ssc:MapEntry source="2" target="5"/><ssc:MapEntry source="1" target="-3"/>
  </ssc:IntegerMappingTransformation></ssd:Connection>"""
BOOLEAN_MAP = """<ssd:Connection startElement="a" startConnector="on" endElement="b" endConnector="on_in">
  <ssc:BooleanMappingTransformation>
    <ssc:MapEntry source="true" target="false"/><ssc:MapEntry source="false" target="true"/>
  </ssc:BooleanMappingTransformation></ssd:Connection>"""


def test_integer_and_boolean_mappings_transform_the_held_values(tmp_path):
    """a's state decays from 0.7 through the quanta 0.25 (its Integer n: 2, 1, 0) and below its
    threshold (its Boolean on): b receives n mapped 2 -> 5, 1 -> -3 (0, named by no entry, as it
    is) and on negated, at every row and in the steps (b grows while its on_in is true)."""
    settings = '<mm:Record><mm:Variable component="a" name="n"/><mm:Variable component="a" name="on"/>'
    settings += "".join(f'<mm:Variable component="b" name="{v}"/>' for v in ("n_in", "on_in", "x"))
    settings += "</mm:Record>"
    path = pair(tmp_path / "m.ssd", "discrete", DISCRETE, INTEGER_MAP + BOOLEAN_MAP, settings)
    sc = api.load_scenario(path, {"a.x": "0.7", "a.threshold": "0.5", "b.x": "0", "b.threshold": "100"})
    d = run_everywhere(sc)
    assert set(d["a.n"]) == {0.0, 1.0, 2.0} and set(d["a.on"]) == {0.0, 1.0}
    assert np.array_equal(d["b.n_in"], np.select([d["a.n"] == 2, d["a.n"] == 1], [5.0, -3.0], d["a.n"]))
    assert np.array_equal(d["b.on_in"], 1.0 - d["a.on"])
    grows = np.diff(d["b.x"]) > 0
    assert grows.any() and not grows.all()  # growth (on_in) once a is below its threshold


ENUMS = """<ssd:Connector name="y_enumeration" kind="output"/>
<ssd:Connector name="u_enumeration" kind="input"/>"""
ENUM_MAP = """<ssd:Connection startElement="a" startConnector="y_enumeration"
    endElement="b" endConnector="u_enumeration">
  <ssc:EnumerationMappingTransformation>
    <ssc:MapEntry source="ab2" target="semi_implicit_midpoint"/><ssc:MapEntry source="rk4" target="euler"/>
  </ssc:EnumerationMappingTransformation></ssd:Connection>"""


def test_an_enumeration_mapping_maps_item_names(tmp_path):
    """alltypes (FMI 3.0): y_enumeration = u_enumeration mod 6 + 1 over the items euler = 1 ...
    semi_implicit_midpoint = 6 (ab2 = 2, rk4 = 4). a's input steps 1 -> 3 at t = 0.5, so its output
    goes ab2 -> rk4, which b receives as semi_implicit_midpoint (6), then euler (1)."""
    step = '<mm:Stimuli><mm:Step component="a" variable="u_enumeration"><mm:Point time="0" value="1"/>'
    step += '<mm:Point time="0.5" value="3"/></mm:Step></mm:Stimuli>'
    record = "".join(
        f'<mm:Variable component="{c}" name="{v}"/>' for c in "ab" for v in ("y_enumeration", "u_enumeration")
    )
    path = pair(tmp_path / "e.ssd", "alltypes", ENUMS, ENUM_MAP, f"<mm:Record>{record}</mm:Record>" + step)
    d = run_everywhere(api.load_scenario(path))
    assert set(d["a.y_enumeration"]) == {2.0, 4.0}
    assert np.array_equal(d["b.u_enumeration"], np.where(d["a.y_enumeration"] == 2, 6.0, 1.0))
    assert np.array_equal(d["b.y_enumeration"], d["b.u_enumeration"] % 6 + 1)


@pytest.mark.parametrize(
    "connections, message",
    [
        (INTEGER_MAP.replace('source="1"', 'source="2"'),
         "ssc:IntegerMappingTransformation: a source value is mapped twice"),
        (INTEGER_MAP.replace('"n"', '"on"').replace('"n_in"', '"on_in"'),
         "ssc:IntegerMappingTransformation: transforms Integer and Enumeration values only: a.on is Boolean, "
         "b.on_in is Boolean"),
        ('<ssd:Connection startElement="a" startConnector="n" endElement="b" endConnector="n_in">'
         '<ssc:LinearTransformation factor="2"/></ssd:Connection>',
         "ssc:LinearTransformation: transforms Real values only: a.n is Integer, b.n_in is Integer"),
    ],
)  # fmt: skip
def test_a_transformation_of_the_wrong_type_is_refused_in_one_line(tmp_path, connections, message):
    problems = validate(pair(tmp_path / "bad.ssd", "discrete", DISCRETE, connections))
    assert len(problems) == 1 and f"{problems[0].element}: {problems[0].message}".endswith(message), problems


def test_libcosim_runs_the_libcosim_scene_with_the_same_transformed_value(tmp_path):
    """libcosim (libcosimpy) runs the runnable copy of its own scene, the project's gain FMU beside
    it: the transformed value agrees with this project's. libcosim reads the two parameter bindings
    as alternative parameter sets and uses the first (identity1.u = 2); SSP applies both in order
    (4): this project's run is given libcosim's value to compare the transformation alone."""
    pytest.importorskip("libcosimpy", reason="the peers extra: pip install libcosimpy")
    import shutil

    text = (LIBCOSIM / "with-project-fmus.ssd").read_text().replace('"project:gain"', '"gain.fmu"')
    (tmp_path / "SystemStructure.ssd").write_text(text)
    for ssv in LIBCOSIM.glob("*.gain.ssv"):
        shutil.copy(ssv, tmp_path)
    shutil.copy(fmu_path("gain"), tmp_path / "gain.fmu")
    peer = libcosim_last_values(tmp_path, {"identity1": ("u", "y"), "identity2": ("u", "y")})
    assert peer["identity1.y"] == 2.0 and peer["identity2.u"] == 1.3 * 2.0 + 50.0
    sc = api.load_scenario(LIBCOSIM / "with-project-fmus.ssd", {"identity1.u": "2"})
    ours = api.run(replace(sc, record=(("identity2", "u"), ("identity2", "y"))), backend="serial").data
    assert ours["identity2.u"][-1] == peer["identity2.u"] and ours["identity2.y"][-1] == peer["identity2.y"]


FLOATS = """<ssd:Connector name="y_float32" kind="output"/><ssd:Connector name="u_float32" kind="input"/>
<ssd:Connector name="y_vec" kind="output"/><ssd:Connector name="u_vec" kind="input"/>"""
LINEAR = """<ssd:Connection startElement="a" startConnector="{o}" endElement="b" endConnector="{i}">
  <ssc:LinearTransformation factor="3" offset="-1"/></ssd:Connection>"""


def test_a_linear_transformation_on_float32_and_array_connections(tmp_path):
    """alltypes (FMI 3.0): a Float32 signal is transformed in double precision, then set as a
    float; an array's elements are each transformed (y_vec = 2 u_vec, a Float64 vector of 3)."""
    connections = LINEAR.format(o="y_float32", i="u_float32") + LINEAR.format(o="y_vec", i="u_vec")
    table = '<mm:Table component="a" variable="u_float32"><mm:Point time="0" value="0.1"/>'
    table += '<mm:Point time="2" value="1.7"/></mm:Table>'
    record = "".join(
        f'<mm:Variable component="{c}" name="{v}"/>'
        for c in "ab"
        for v in ("y_float32", "u_float32", "y_vec")
    )
    record += '<mm:Variable component="b" name="u_vec"/>'
    settings = f"<mm:Record>{record}</mm:Record><mm:Stimuli>{table}</mm:Stimuli>"
    path = pair(tmp_path / "f.ssd", "alltypes", FLOATS, connections, settings)
    sc = api.load_scenario(path, {"a.u_vec[1]": "0.25", "a.u_vec[3]": "-1.5", "a.p_float32": "0.5"})
    d = run_everywhere(sc)
    assert len(np.unique(d["a.y_float32"])) > 10
    assert np.array_equal(d["b.u_float32"], (3.0 * d["a.y_float32"] - 1.0).astype(np.float32))
    for e in (1, 2, 3):
        assert np.array_equal(d[f"b.u_vec[{e}]"], 3.0 * d[f"a.y_vec[{e}]"] - 1.0)
    assert np.array_equal(d["a.y_vec[1]"], np.full(len(d), 0.5))
