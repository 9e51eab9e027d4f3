"""The shared C layer's FMI 1.0 Co-Simulation interface (fmus/fmi/fmi1.c), through fmpy on real FMUs:
models built as FMI 1.0 pass fmpy's validation, simulate exactly as built as FMI 2.0 (one core),
and follow FMI 1.0's calling sequence (values readable before fmiInitializeSlave, reset to the
start values, calls in the wrong state refused)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException, FMU1Slave
from fmpy.validation import validate_fmu

from master import fmubuild


@pytest.mark.parametrize("name", ["identity", "msd", "discrete", "text"])
def test_models_built_as_fmi1_are_valid(name: str) -> None:
    path = fmubuild.fmu_path(name, fmi=1)
    assert path == fmubuild.BUILD_DIR / "fmi1" / f"{name}.fmu"
    assert validate_fmu(str(path)) == []
    md = fmpy.read_model_description(str(path))
    assert (md.fmiVersion, md.coSimulation.modelIdentifier) == ("1.0", name)
    with zipfile.ZipFile(path) as zf:
        assert {f"binaries/linux64/{name}.so", "sources/fmi1.c", "sources/fmi1Functions.h"} <= set(
            zf.namelist()
        )
        assert "sources/fmi2.c" not in zf.namelist()


def test_msd_simulates_exactly_as_its_fmi2_build() -> None:
    """The same core under both interfaces: the same numbers, bit for bit (RK4, an input held)."""
    kwargs = dict(stop_time=2.0, output_interval=0.01, start_values={"x0": 1.0, "d": 0.3, "F": 0.5})
    one = fmpy.simulate_fmu(str(fmubuild.fmu_path("msd", fmi=1)), output=["x", "v"], **kwargs)
    two = fmpy.simulate_fmu(
        str(fmubuild.fmu_path("msd")), output=["x", "v"], fmi_type="CoSimulation", **kwargs
    )
    assert one["x"][0] == 1.0 and abs(one["x"][-1] - 1.0) > 0.1  # it moved
    assert np.array_equal(one["x"], two["x"]) and np.array_equal(one["v"], two["v"])


@pytest.fixture()
def identity(tmp_path: Path):
    path = fmubuild.fmu_path("identity", fmi=1)
    md = fmpy.read_model_description(str(path))
    unzipped = fmpy.extract(str(path), str(tmp_path / "identity"))
    slave = FMU1Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier="identity", instanceName="id")
    slave.instantiate()
    vr = {v.name: v.valueReference for v in md.modelVariables}
    yield slave, vr
    slave.freeInstance()


def test_fmi1_calling_sequence(identity) -> None:
    slave, vr = identity
    assert slave.getVersion() == "1.0"
    assert slave.getReal([vr["realIn"]]) == [0.0]  # before fmiInitializeSlave: start values
    # (fmpy declares fmiDoStep's result a string: a refused fmiDoStep is not tried through it)
    with pytest.raises(FMICallException):
        slave.terminate()  # not initialised
    slave.setReal([vr["realIn"]], [2.5])
    slave.setInteger([vr["integerIn"]], [-3])
    slave.setBoolean([vr["booleanIn"]], [True])
    slave.setString([vr["stringIn"]], ["ab"])
    slave.initialize(0.0, 1.0)
    slave.doStep(0.0, 0.1)
    assert slave.getRealStatus(2).value == 0.1  # fmiLastSuccessfulTime
    assert slave.getReal([vr["realOut"]]) == [2.5]
    assert slave.getInteger([vr["integerOut"]]) == [-3]
    assert slave.getBoolean([vr["booleanOut"]]) == [True]
    assert slave.getString([vr["stringOut"]]) == [b"ab"]
    slave.terminate()
    with pytest.raises(FMICallException):
        slave.setReal([vr["realIn"]], [1.0])  # terminated
    slave.reset()
    assert slave.getReal([vr["realIn"]]) == [0.0]
    slave.initialize(0.0, 1.0)
    slave.doStep(0.0, 0.1)
    assert slave.getReal([vr["realOut"]]) == [0.0]


def test_the_command_line_builds_fmi1(capsys: pytest.CaptureFixture[str]) -> None:
    assert fmubuild.main(["--fmi", "1", "gain"]) == 0
    assert "fmi1/gain.fmu" in capsys.readouterr().out
