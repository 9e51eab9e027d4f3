"""FMI 3 Binary parameters and start values: ssv:Binary (an .ssv file or inline) and --set hex
digits reach the FMU through fmi3SetBinary; other pairings are type mismatches at their line.

The FMU is the project's alltypes (fmus/alltypes/model.c): input u_binary (start 00ff, at most
256 bytes), output y_binary = the bytes of u_binary in reverse order."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import master.api as api
from master.backends.component import open_fmu
from master.fmubuild import fmu_path
from master.scenario import load, read, validate
from master.scenario.model import Component, Scenario
from master.scenario.writer import write_settings

SSV = """<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    version="1.0" name="{name}">
  <ssv:Parameters>
{parameters}
  </ssv:Parameters>
</ssv:ParameterSet>
"""

SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="binary"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:mm="urn:org.multirate-master:settings:1">
  <ssd:System name="binary">
    <ssd:Elements>
      <ssd:Component name="a" source="alltypes.fmu">
        <ssd:ParameterBindings>
          <ssd:ParameterBinding source="a.ssv"/>
        </ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="b" source="alltypes.fmu">
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="b-start"><ssv:Parameters>
{inline}
              </ssv:Parameters></ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Annotations>
      <ssc:Annotation type="org.multirate-master.settings">
        <mm:Settings macroStep="0.1"/>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:System>
  <ssd:DefaultExperiment stopTime="0.3"/>
</ssd:SystemStructureDescription>
"""


def parameter(name: str, value: str) -> str:
    return f'    <ssv:Parameter name="{name}">{value}</ssv:Parameter>'


def scene(folder: Path, in_file: list[str], inline: list[str], name: str = "binary") -> Path:
    """`name`.ssd with components a (its parameters from a.ssv: `in_file`) and b (inline ones)."""
    (folder / "a.ssv").write_text(SSV.format(name="a-start", parameters="\n".join(in_file)))
    path = folder / f"{name}.ssd"
    path.write_text(SSD.format(inline="\n".join(inline)))
    return path


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    shutil.copy(fmu_path("alltypes", fmi=3), tmp_path / "alltypes.fmu")
    return tmp_path


@pytest.fixture
def good(folder: Path) -> Path:
    """a.u_binary = 0a 1b 2c from the .ssv file (mixed case hex), b.u_binary empty (inline)."""
    return scene(
        folder,
        [parameter("u_binary", '<ssv:Binary mime-type="application/octet-stream" value="0A1b2C"/>')],
        [parameter("u_binary", '<ssv:Binary value=""/>')],
    )


def sc_times(sc: Scenario) -> tuple:
    """start_time, stop_time, macro_step: the arguments of a Scenario after its connections."""
    return sc.start_time, sc.stop_time, sc.macro_step


def y_binary(sc: Scenario, name: str, steps: int = 0) -> bytes:
    """y_binary of component `name` after initialisation with its parameters and `steps` steps."""
    fmu = open_fmu(sc, sc.component(name))
    try:
        fmu.exit_initialization()
        for n in range(steps):
            fmu.do_step(0.1 * n, 0.1)
        (value,) = fmu.slave.getBinary([fmu.variables["y_binary"].vr])
        return value
    finally:
        fmu.close()


def test_ssv_binary_values_reach_the_fmu_through_fmi3_set_binary(good: Path):
    assert validate(good) == []
    sc = load(good)
    assert sc.component("a").parameters == {"u_binary": b"\x0a\x1b\x2c"}
    assert sc.component("b").parameters == {"u_binary": b""}  # an empty value: no bytes
    assert y_binary(sc, "a") == b"\x2c\x1b\x0a" and y_binary(sc, "a", steps=2) == b"\x2c\x1b\x0a"
    assert y_binary(sc, "b") == b"" and y_binary(sc, "b", steps=1) == b""
    # without a binding the FMU keeps its start value 00ff
    unbound = Scenario(sc.path, sc.name, (Component("c", sc.component("a").fmu_path),), (), *sc_times(sc))
    assert y_binary(unbound, "c") == b"\xff\x00"


@pytest.mark.parametrize("backend", ["serial", "parallel", "in-process"])
def test_every_backend_sets_the_value_the_fmu_checks_its_size(good: Path, backend: str):
    """The run sets the bytes in the worker that holds the FMU: 256 bytes (alltypes' maxSize) run,
    257 are refused by the FMU at the start with its own words."""
    assert api.run(good, backend=backend).data["time"][-1] == pytest.approx(0.3)
    assert api.run(good, backend=backend, set_values={"a.u_binary": bytes(range(256))}).summary
    with pytest.raises(api.FmuError) as failed:
        api.run(good, backend=backend, set_values={"a.u_binary": bytes(257)})
    message = str(failed.value)
    assert message.startswith("a: cannot set u_binary = 257 bytes 0000000000000000...: fmi3SetBinary failed")
    assert message.endswith("(FMU says: fmi3SetBinary: value 0: 257 bytes (at most 256, and not NULL))")


def test_set_takes_hex_digits_with_or_without_0x(good: Path):
    for text, value in [("0x0A0b", b"\x0a\x0b"), ("0102", b"\x01\x02"), ("", b""), ("  ff  ", b"\xff")]:
        assert load(good, {"a.u_binary": text}).component("a").parameters == {"u_binary": value}
    # a Scenario built in Python: --set text converted by the variable's type (not the integer 102)
    sc = api.apply_overrides(load(good), set_values=["a.u_binary=0102", "b.u_binary=0x"])
    assert sc.component("a").parameters == {"u_binary": b"\x01\x02"}
    assert sc.component("b").parameters == {"u_binary": b""}
    with pytest.raises(
        api.UsageError, match=r'^--set a\.u_binary=0g: "0g" is not hex digits \(u_binary is Binary'
    ):
        api.apply_overrides(load(good), set_values=["a.u_binary=0g"])
    # values given as text or bytes in a Scenario built in Python
    hexed = Scenario(good, "hexed", (Component("a", good.with_name("alltypes.fmu"), {"u_binary": "0x0102"}),),
                     (), *sc_times(load(good)))  # fmt: skip
    assert y_binary(hexed, "a") == b"\x02\x01"
    wrong = Scenario(good, "wrong", (Component("a", good.with_name("alltypes.fmu"), {"u_binary": 5}),),
                     (), *sc_times(load(good)))  # fmt: skip
    with pytest.raises(api.FmuError, match=r"^a\.u_binary: 5 is not a Binary value \(bytes, or hex digits"):
        y_binary(wrong, "a")


@pytest.mark.parametrize("text", ["0g", "abc", "0x1", "b'1'", "0 1"])
def test_bad_hex_is_one_problem_naming_the_variable(good: Path, text: str):
    _, problems = read(good, {"a.u_binary": text})
    (problem,) = problems
    assert (problem.file, problem.line) == ("--set", None)
    assert (
        problem.message
        == f'"{text}" is not hex digits (u_binary is Binary: two digits a byte, such as 0a1b2c)'
    )


def test_the_command_line_refuses_bad_hex_with_one_line(good: Path):
    command = [sys.executable, "-m", "master", "run", str(good), "-o", str(good.with_name("out.csv"))]
    run = subprocess.run([*command, "--set", "a.u_binary=0xzz"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 1 and "Traceback" not in run.stderr
    assert run.stderr.strip().splitlines() == [
        'error: --set: a.u_binary: "0xzz" is not hex digits (u_binary is Binary: two digits a byte, '
        "such as 0a1b2c)"
    ]
    ok = subprocess.run([*command, "-q", "--set", "a.u_binary=0x0a1b2c"], capture_output=True, text=True,
                        timeout=120)  # fmt: skip
    assert ok.returncode == 0, ok.stderr


def test_type_mismatches_are_refused_at_their_line(folder: Path):
    path = scene(
        folder,
        [
            parameter("u_string", '<ssv:Binary value="00"/>'),
            parameter("u_binary", '<ssv:String value="00ff"/>'),
        ],
        [
            parameter("u_binary", '<ssv:Integer value="12"/>'),
            parameter("u_uint8", '<ssv:Binary value="07"/>'),
        ],
        name="mismatch",
    )
    found = [(Path(p.file).name, p.line, p.message) for p in validate(path)]
    assert found == [
        ("a.ssv", 5, "a.u_string: type mismatch: ssv:Binary value for u_string, which is String"),
        ("a.ssv", 6, "a.u_binary: type mismatch: ssv:String value for u_binary, which is Binary"),
        ("mismatch.ssd", 19, "b.u_binary: type mismatch: ssv:Integer value for u_binary, which is Binary"),
        ("mismatch.ssd", 20, "b.u_uint8: type mismatch: ssv:Binary value for u_uint8, which is UInt8"),
    ]
    bad = scene(folder, [parameter("u_binary", '<ssv:Binary value="0g"/>')], [], name="schema")
    (problem,) = validate(bad)  # not xs:hexBinary: the schema says so, at the line
    assert Path(problem.file).name == "a.ssv" and problem.line == 5 and "hexBinary" in problem.message


def test_tune_writes_a_binary_back_as_ssv_binary(good: Path):
    original = load(good)
    a, b = original.components
    components = (Component("a", a.fmu_path, {"u_binary": b"\xde\xad"}),
                  Component("b", b.fmu_path, {"u_binary": b"\x00\xff"}))  # fmt: skip
    changed = Scenario(original.path, original.name, components, (), *sc_times(original))
    tuned = write_settings(original, changed, good.with_name("tuned.ssd"), "tuned")
    text = tuned.read_text()  # b's value is its start value, but not the value it had: written
    assert '<ssv:Binary value="dead"/>' in text and '<ssv:Binary value="00ff"/>' in text
    assert validate(tuned) == []
    again = load(tuned)
    assert again.component("a").parameters == {"u_binary": b"\xde\xad"}
    assert again.component("b").parameters == {"u_binary": b"\x00\xff"}
