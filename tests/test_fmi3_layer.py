"""The shared C layer's FMI 3.0 Co-Simulation interface (fmus/fmi/fmi3.c), through fmpy on real FMUs.

alltypes (fmus/alltypes, FMI 3.0 only) has an input, an output and a parameter of every FMI 3.0
type; each output follows a rule the tests compute on their own (saturating integer sums, float32
arithmetic through numpy, negation, a suffix, reversed bytes, the next enumeration item, 2 u for a
vector, the transpose of a 2x2 matrix), a state integrates u_float64, and stop_at ends the
simulation through fmi3DoStep's terminateSimulation.  msd built as FMI 3.0 must simulate exactly
like its FMI 2.0 build.
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from collections.abc import Callable
from ctypes import byref, c_size_t
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave, fmi3Error
from fmpy.validation import validate_fmu
from lxml import etree

from master import fmubuild

# ----------------------------------------------------------------- helpers


class Fmu3:
    """An FMI 3.0 build of a project FMU, extracted once, with a factory for logging instances."""

    def __init__(self, name: str, tmp: Path) -> None:
        self.path = fmubuild.fmu_path(name, fmi=3)
        self.md = read_model_description(str(self.path))
        self.dir = extract(str(self.path), unzipdir=str(tmp / name))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.var = {v.name: v for v in self.md.modelVariables}

    def instance(self, **parameters: object) -> Instance3:
        """An instance in Step Mode at t = 0 with the given parameters set while instantiated."""
        inst = Instance3(self)
        for name, value in parameters.items():
            inst.set(name, value)
        inst.slave.enterInitializationMode(startTime=0.0)
        inst.slave.exitInitializationMode()
        return inst


class Instance3:
    """An fmpy FMU3Slave plus the messages its logger received, as (status, category, text)."""

    def __init__(self, fmu: Fmu3) -> None:
        self.fmu = fmu
        self.messages: list[tuple[int, str, str]] = []
        self.slave = FMU3Slave(
            guid=fmu.md.guid,
            unzipDirectory=fmu.dir,
            modelIdentifier=fmu.md.coSimulation.modelIdentifier,
            instanceName="inst",
        )
        self.slave.instantiate(logMessage=self._log)
        self.time = 0.0

    def _log(self, env, status, category, message) -> None:  # noqa: ANN001
        self.messages.append((status, category.decode(), message.decode()))

    def errors(self) -> str:
        return "\n".join(m for s, c, m in self.messages if c == "logError")

    def _accessor(self, kind: str, name: str) -> Callable:
        t = self.fmu.var[name].type
        return getattr(self.slave, kind + ("Int64" if t == "Enumeration" else t))

    def set(self, name: str, value: object) -> None:
        values = list(np.ravel(value)) if isinstance(value, (list, np.ndarray)) else [value]
        self._accessor("set", name)([self.fmu.vr[name]], values)

    def get(self, name: str) -> object:
        shape = self.fmu.var[name].shape
        n = int(np.prod(shape)) if shape else 1
        values = self._accessor("get", name)([self.fmu.vr[name]], nValues=n)
        return values if shape else values[0]

    def step(self, h: float = 0.25) -> tuple[bool, bool, bool, float]:
        result = self.slave.doStep(self.time, h)
        self.time += h
        return result

    def free(self) -> None:
        self.slave.freeInstance()


@pytest.fixture(scope="module")
def alltypes(tmp_path_factory: pytest.TempPathFactory) -> Fmu3:
    return Fmu3("alltypes", tmp_path_factory.mktemp("fmi3"))


def saturated(lo: int, hi: int) -> Callable[[int, int], int]:
    return lambda u, p: min(max(u + p, lo), hi)


# name: (rule, parameter values, input values); the rule is computed here independently of the C code
INTEGERS = {
    "int8": (saturated(-(2**7), 2**7 - 1), [1, -128, 127], [-128, -1, 0, 126, 127]),
    "uint8": (saturated(0, 2**8 - 1), [1, 255], [0, 1, 254, 255]),
    "int16": (saturated(-(2**15), 2**15 - 1), [1, -(2**15)], [-(2**15), 0, 2**15 - 1]),
    "uint16": (saturated(0, 2**16 - 1), [1, 2**16 - 1], [0, 2**16 - 1]),
    "int32": (saturated(-(2**31), 2**31 - 1), [1, -(2**31)], [-(2**31), -1, 0, 2**31 - 1]),
    "uint32": (saturated(0, 2**32 - 1), [1, 2**32 - 1], [0, 2**32 - 2, 2**32 - 1]),
    "int64": (saturated(-(2**63), 2**63 - 1), [1, -(2**63), 2**63 - 1], [-(2**63), -1, 0, 2**63 - 1]),
    "uint64": (saturated(0, 2**64 - 1), [1, 2**64 - 1], [0, 2**53 + 1, 2**64 - 2, 2**64 - 1]),
}


# ------------------------------------------------------------ description


def test_fmu_is_valid_fmi3_cosimulation(alltypes: Fmu3) -> None:
    assert validate_fmu(str(alltypes.path)) == []
    md = alltypes.md
    assert md.fmiVersion == "3.0" and md.modelExchange is not None and md.coSimulation is not None
    assert md.guid == fmubuild.describe("alltypes")["guid"]  # instantiationToken
    assert md.coSimulation.canHandleVariableCommunicationStepSize
    root = etree.fromstring(zipfile.ZipFile(alltypes.path).read("modelDescription.xml"))
    cs = root.find("CoSimulation")
    assert cs.get("canReturnEarlyAfterIntermediateUpdate") == "false" and cs.get("hasEventMode") == "false"
    # value references: the table positions, time the next one, unique across all types
    vrs = [v.valueReference for v in md.modelVariables]
    assert len(set(vrs)) == len(vrs) == alltypes.vr["time"] + 1
    assert alltypes.var["time"].causality == "independent"
    assert {v.type for v in md.modelVariables} == {
        "Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
        "Boolean", "String", "Binary", "Enumeration",
    }  # fmt: skip
    assert alltypes.var["u_vec"].shape == (3,) and alltypes.var["y_mat"].shape == (2, 2)
    # each output depends on its own input only; y_mat on none (parameters only); x on the state
    dependencies = {u.variable.name: [d.name for d in u.dependencies] for u in md.outputs}
    for name in dependencies:
        if name.startswith("y_") and name != "y_mat":
            assert dependencies[name] == ["u_" + name[2:]], name
    assert dependencies["y_mat"] == [] and dependencies["x"] == ["x"]
    assert [u.variable.name for u in md.derivatives] == ["der(x)"]
    assert alltypes.var["der(x)"].derivative is alltypes.var["x"]


def test_fmu_contents_and_build_description(alltypes: Fmu3, tmp_path: Path) -> None:
    with zipfile.ZipFile(alltypes.path) as zf:
        names = set(zf.namelist())
        zf.extractall(tmp_path)
    assert "binaries/x86_64-linux/alltypes.so" in names
    assert {"sources/fmi3.c", "sources/fmi3Functions.h", "sources/buildDescription.xml"} <= names
    assert "sources/fmi2.c" not in names and "sources/describe.c" not in names
    schema = Path(fmpy.__file__).parent / "schema" / "fmi3"
    xsd = etree.XMLSchema(etree.parse(str(schema / "fmi3BuildDescription.xsd")))
    build = etree.parse(str(tmp_path / "sources" / "buildDescription.xml"))
    assert xsd.validate(build), xsd.error_log
    listed = [f.get("name") for f in build.iter("SourceFile")]
    assert sorted(listed) == sorted(p.name for p in (tmp_path / "sources").glob("*.c"))
    # the sources compile on their own, warnings-clean
    sources = tmp_path / "sources"
    args = [fmubuild._compiler(), *fmubuild.CFLAGS, "-shared", f"-I{sources}"]
    args += [str(sources / f) for f in listed] + ["-lm", "-o", str(tmp_path / "again.so")]
    proc = subprocess.run(args, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    # and the FMI 2.0 FMUs stay without the FMI 3.0 interface
    with zipfile.ZipFile(fmubuild.fmu_path("msd")) as zf:
        assert "sources/fmi2.c" in zf.namelist() and "sources/fmi3.c" not in zf.namelist()


def test_fmi3_only_tables_are_not_fmi2_models() -> None:
    assert "alltypes" not in fmubuild.project_fmu_names()
    assert "alltypes" in fmubuild.project_fmu_names(3)
    assert set(fmubuild.project_fmu_names()) < set(fmubuild.project_fmu_names(3))
    with pytest.raises(fmubuild.FmuBuildError) as info:
        fmubuild.build_fmu("alltypes")
    message = str(info.value)
    assert "\n" not in message and "builds as FMI 3.0 only" in message and "--fmi 3 alltypes" in message
    assert fmubuild.main(["alltypes"]) == 1
    assert fmubuild.fmu_path("alltypes", fmi=3) == fmubuild.BUILD_DIR / "fmi3" / "alltypes.fmu"


def test_fmi3_table_checks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fmus = tmp_path / "fmus"
    for part in ("fmi", "solvers", "alltypes"):
        shutil.copytree(fmubuild.FMUS_DIR / part, fmus / part)
    monkeypatch.setattr(fmubuild, "FMUS_DIR", fmus)
    monkeypatch.setattr(fmubuild, "FMI_DIR", fmus / "fmi")
    monkeypatch.setattr(fmubuild, "SOLVERS_DIR", fmus / "solvers")
    model = fmus / "alltypes" / "model.c"
    text = model.read_text()
    model.write_text(text.replace(".fmi3_only = 1,", ""))
    assert "alltypes" in fmubuild.project_fmu_names()  # undeclared, it would count as an FMI 2.0 model
    with pytest.raises(fmubuild.FmuBuildError, match='"u_float32" is Float32, which FMI 2.0 lacks: declare'):
        fmubuild.describe("alltypes")
    p_int8 = 'NUMBER("int8", T_INT8, V_DISCRETE, 8, W_INT8, W_INT8 + 1, W_INT8 + 2, 1,'
    u_binary = '"u_binary", T_BINARY, V_DISCRETE, X_U, 0.0, "00ff"'
    assert p_int8 in text and u_binary in text
    text = text.replace(p_int8, p_int8.replace("2, 1,", "2, 300,"))
    model.write_text(text.replace(u_binary, u_binary.replace("00ff", "0f0")))
    with pytest.raises(fmubuild.FmuBuildError) as info:
        fmubuild.describe("alltypes")
    assert 'variable 10 "p_int8": start value 300.0 is not a Int8' in str(info.value)
    assert "Binary start '0f0' is not an even number of hex digits" in str(info.value)


# ------------------------------------------------------------- simulation


def test_simulate_fmu_runs_and_stops_where_asked(alltypes: Fmu3) -> None:
    result = simulate_fmu(
        str(alltypes.path),
        stop_time=1.0,
        output_interval=0.125,
        start_values={"u_float64": 2.0, "u_int8": 100, "p_int8": 100, "u_boolean": True},
    )
    assert list(result["time"]) == [k * 0.125 for k in range(9)]
    assert list(result["x"]) == [2.0 * t for t in result["time"]]  # x' = u_float64, exact with Euler
    assert set(result["y_int8"]) == {127} and not any(result["y_boolean"])
    assert result["y_vec"].shape == (9, 3)
    # stop_at: the step that reaches t >= 0.3 (0.25 -> 0.375) is the last one
    stopped = simulate_fmu(
        str(alltypes.path), stop_time=1.0, output_interval=0.125, start_values={"stop_at": 0.3}
    )
    assert stopped["time"][-1] == 0.375


# ------------------------------------------------- every type, round trip


@pytest.mark.parametrize("name", list(INTEGERS))
def test_integer_types_round_trip_saturated(alltypes: Fmu3, name: str) -> None:
    rule, parameters, inputs = INTEGERS[name]
    for p in parameters:
        inst = alltypes.instance(**{f"p_{name}": p})
        assert inst.get(f"p_{name}") == p
        for u in inputs:
            inst.set(f"u_{name}", u)
            assert inst.get(f"u_{name}") == u
            inst.step()
            assert inst.get(f"y_{name}") == rule(u, p), (name, u, p)
        inst.free()


def test_float32_follows_float32_arithmetic(alltypes: Fmu3) -> None:
    for p in (0.25, 1e-8, -3.0e38):
        inst = alltypes.instance(p_float32=p)
        for u in (0.1, 1.0 / 3.0, 16777217.0, 3.0e38, -1.5e-45, 0.0):
            inst.set("u_float32", u)
            inst.step()
            y = np.float32(inst.get("y_float32"))
            assert y == np.float32(u) + np.float32(p), (u, p)  # numpy's float32 sum, IEEE rounded
        inst.free()
    inst = alltypes.instance()
    inst.set("u_float32", 0.1)
    assert inst.get("y_float32") != 0.1 + 0.25  # a float64 sum would differ: float32 is real here
    for bad in (float("nan"), float("inf")):
        with pytest.raises(FMICallException):
            inst.set("u_float32", bad)
    assert "value nan is not finite" in inst.errors() and "value inf is not finite" in inst.errors()
    inst.free()


def test_float64_boolean_string_binary_enumeration(alltypes: Fmu3) -> None:
    inst = alltypes.instance()
    # start values: u_string "abc", u_binary 00 ff, u_enumeration 1
    assert inst.get("y_string") == "abc!" and inst.get("y_binary") == b"\xff\x00"
    assert inst.get("y_enumeration") == 2
    for u in (0.1, 1e308, -1e-320, -1.5):
        inst.set("u_float64", u)
        inst.step()
        assert inst.get("y_float64") == u + 1.5
    for u in (True, False, True):
        inst.set("u_boolean", u)
        inst.step()
        assert inst.get("y_boolean") is (not u)
    for u in ("", "héllo ✓", "y" * 2046, "x" * 2047):  # STRING_CAPACITY 2048 (fmus/fmi/model.h)
        inst.set("u_string", u)
        inst.step()
        assert inst.get("u_string") == u
        assert inst.get("y_string") == (u.encode() + b"!")[:2047].decode(), u[:10]
    for u in (b"", b"\x00", b"\x00\x01\xff", bytes(range(256))):
        inst.set("u_binary", u)
        inst.step()
        assert inst.get("u_binary") == u and inst.get("y_binary") == u[::-1]
    for u in range(1, 7):
        inst.set("u_enumeration", u)
        inst.step()
        assert inst.get("y_enumeration") == u % 6 + 1
    for name, bad in (("u_string", "z" * 2048), ("u_binary", bytes(257)), ("u_enumeration", 7)):
        with pytest.raises(FMICallException):
            inst.set(name, bad)
    assert "longer than 2047 bytes" in inst.errors() and "257 bytes (at most 256" in inst.errors()
    assert "value 7 outside [1, 6]" in inst.errors()
    inst.free()


def test_arrays(alltypes: Fmu3) -> None:
    matrix = np.array([[1.0, 2.0], [3.0, -4.5]])
    inst = alltypes.instance(p_mat=matrix)
    assert inst.get("p_mat") == [1.0, 2.0, 3.0, -4.5]  # row major
    assert inst.get("y_mat") == list(matrix.T.ravel())
    u = [1.5, -2.0, 1e300]
    inst.set("u_vec", u)
    inst.step()
    assert inst.get("y_vec") == [2.0 * x for x in u]
    # one Get/Set for several variables counts the values of all of them
    vr = inst.fmu.vr
    several = inst.slave.getFloat64([vr["u_float64"], vr["y_vec"], vr["x"]], nValues=5)
    assert several == [0.0, 3.0, -4.0, 2e300, 0.0]
    with pytest.raises(FMICallException):
        inst.slave.getFloat64([vr["y_vec"]], nValues=2)
    assert "2 values for variables that have 3" in inst.errors()
    with pytest.raises(FMICallException):
        inst.slave.setFloat64([vr["u_vec"], vr["u_float64"]], [1.0, 2.0, 3.0])
    assert "3 values for variables that have 4" in inst.errors()
    inst.free()


def test_state_integrates_and_stop_request_arrives_at_the_documented_step(alltypes: Fmu3) -> None:
    for stop_at, last in ((0.75, 3), (0.6, 3), (0.25, 1)):
        inst = alltypes.instance(stop_at=stop_at)
        inst.set("u_float64", 0.5)
        for k in range(1, 5):
            event, terminate, early, last_time = inst.step(0.25)
            assert (event, early, last_time) == (False, False, 0.25 * k)
            assert terminate is (k >= last), (stop_at, k)
            assert inst.get("x") == 0.5 * 0.25 * k and inst.get("time") == 0.25 * k
            if terminate:
                break
        assert k == last
        assert inst.slave.terminate() == 0
        inst.free()


# ----------------------------------------------------------------- errors


def test_wrong_type_unknown_reference_and_wrong_state_are_refused(alltypes: Fmu3) -> None:
    inst = Instance3(alltypes)
    vr = alltypes.vr
    assert inst.slave.getVersion() == "3.0"
    with pytest.raises(FMICallException):
        inst.slave.doStep(0.0, 0.1)
    assert "fmi3DoStep: not allowed in state Instantiated" in inst.errors()
    inst.slave.enterInitializationMode()
    inst.slave.exitInitializationMode()
    n = c_size_t()
    slave = inst.slave
    cases = [
        (
            lambda: slave.getFloat64([vr["u_int8"]]),
            "fmi3GetFloat64: variable u_int8 (value reference 8) is of type Int8",
        ),
        (
            lambda: slave.setInt32([vr["u_int64"]], [1]),
            "variable u_int64 (value reference 26) is of type Int64",
        ),
        (lambda: slave.getInt64([vr["u_int32"]]), "is of type Int32"),
        (lambda: slave.getFloat32([vr["u_float64"]]), "is of type Float64"),
        (lambda: slave.getUInt64([vr["u_int64"]]), "is of type Int64"),
        (lambda: slave.getString([vr["u_binary"]]), "is of type Binary"),
        (lambda: slave.getInt32([999]), "value reference 999 out of range"),
        (lambda: slave.setFloat64([vr["p_float64"]], [1.0]), "only inputs and tunable parameters"),
        (lambda: slave.setFloat64([vr["time"]], [1.0]), "it is the independent variable"),
        (lambda: slave.fmi3EnterEventMode(slave.component), "the FMU has no Event Mode"),
        (
            lambda: slave.fmi3GetNumberOfVariableDependencies(slave.component, vr["y_int8"], byref(n)),
            "fmi3GetNumberOfVariableDependencies: not supported",
        ),
    ]
    for call, message in cases:
        with pytest.raises(FMICallException) as info:
            call()
        assert info.value.status == fmi3Error
        assert message in inst.messages[-1][2], (message, inst.messages[-1])
    assert inst.get("time") == 0.0
    assert all(status == fmi3Error for status, _, _ in inst.messages)
    inst.slave.doStep(0.0, 0.5)  # the refusals changed nothing
    assert inst.get("time") == 0.5
    inst.free()


def test_fmu_state_and_serialization(alltypes: Fmu3) -> None:
    inst = alltypes.instance()
    inst.set("u_float64", 1.0)
    inst.set("u_binary", b"\x01\x02")
    inst.step()
    state = inst.slave.getFMUState()
    serialized = inst.slave.serializeFMUState(state)
    inst.set("u_binary", b"\x07")
    inst.step()
    assert inst.get("x") == 0.5 and inst.get("y_binary") == b"\x07"
    inst.slave.setFMUState(inst.slave.deserializeFMUState(serialized))
    assert inst.get("x") == 0.25 and inst.get("time") == 0.25 and inst.get("y_binary") == b"\x02\x01"
    inst.slave.freeFMUState(state)
    inst.free()


# ------------------------------------------ an FMI 2.0 model built as FMI 3.0


def test_msd_as_fmi3_equals_its_fmi2_build() -> None:
    start = {"x0": 1.0, "F": 0.5, "c": 4.0, "cc": 0.5}
    options = dict(stop_time=3.0, output_interval=0.01, start_values=start)
    fmi2 = simulate_fmu(str(fmubuild.fmu_path("msd")), **options)
    fmi3 = simulate_fmu(str(fmubuild.fmu_path("msd", fmi=3)), **options)
    assert validate_fmu(str(fmubuild.fmu_path("msd", fmi=3))) == []
    assert fmi2.dtype.names == fmi3.dtype.names == ("time", "x", "v", "F_c")
    for name in fmi2.dtype.names:
        assert np.max(np.abs(fmi2[name] - fmi3[name])) <= 1e-12, name
    assert np.ptp(fmi3["x"]) > 0.5  # it moved


def test_directional_derivative_of_msd_as_fmi3(tmp_path: Path) -> None:
    msd = Fmu3("msd", tmp_path)
    inst = msd.instance(c=3.0, d=0.5, m=2.0)
    vr = msd.vr
    J = inst.slave.getDirectionalDerivative([vr["der(x)"], vr["der(v)"]], [vr["x"]], [1.0])
    assert J == [0.0, -3.0 / 2.0]
    inst.free()
