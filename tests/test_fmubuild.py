"""master.fmubuild: XML generation from the C tables, compilation, packaging, rebuild rules."""

from __future__ import annotations

import multiprocessing
import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from master import fmubuild, solvers


@pytest.mark.parametrize("name", fmubuild.project_fmu_names())
def test_checked_in_model_description_equals_generated(name: str) -> None:
    checked_in = fmubuild.FMUS_DIR / name / "modelDescription.xml"
    assert checked_in.is_file(), f"run: python -m master.fmubuild --write-xml {name}"
    assert checked_in.read_text(encoding="utf-8") == fmubuild.model_description_xml(name)


def test_project_fmu_names() -> None:
    names = fmubuild.project_fmu_names()
    assert {"dahlquist", "msd"} <= set(names)
    assert all((fmubuild.FMUS_DIR / n / "model.c").is_file() for n in names)
    assert "fmi" not in names and "solvers" not in names


def test_fmu_contents_and_sources_compile_on_their_own(tmp_path: Path) -> None:
    path = fmubuild.fmu_path("msd")
    assert path == fmubuild.BUILD_DIR / "msd.fmu"
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
        zf.extractall(tmp_path)
    assert {"modelDescription.xml", "binaries/linux64/msd.so"} <= names
    for src in ("model.c", "fmi2.c", "instance.c", "solvers.c", "lu.c", "model.h", "solvers.h", "instance.h"):
        assert f"sources/{src}" in names
    assert "sources/describe.c" not in names
    sources = tmp_path / "sources"
    args = [fmubuild._compiler(), *fmubuild.CFLAGS, "-shared", f"-I{sources}"]
    args += [str(p) for p in sorted(sources.glob("*.c"))] + ["-lm", "-o", str(tmp_path / "again.so")]
    proc = subprocess.run(args, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_base_units() -> None:
    assert fmubuild.base_unit("N.m/rad") == (1.0, {"kg": 1, "m": 2, "s": -2, "rad": -1})
    assert fmubuild.base_unit("1/s") == (1.0, {"s": -1})
    assert fmubuild.base_unit("m3/s") == (1.0, {"m": 3, "s": -1})
    assert fmubuild.base_unit("MPa") == (1e6, {"kg": 1, "m": -1, "s": -2})
    assert fmubuild.base_unit("furlong") is None


# ------------------------------------------------ a sandbox copy of fmus/


@pytest.fixture
def sandbox(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A private fmus/ (layer, solvers, dahlquist) and build folder, so the repo stays untouched."""
    fmus = tmp_path / "fmus"
    for part in ("fmi", "solvers", "dahlquist"):
        shutil.copytree(fmubuild.FMUS_DIR / part, fmus / part)
    monkeypatch.setattr(fmubuild, "FMUS_DIR", fmus)
    monkeypatch.setattr(fmubuild, "FMI_DIR", fmus / "fmi")
    monkeypatch.setattr(fmubuild, "SOLVERS_DIR", fmus / "solvers")
    monkeypatch.setattr(fmubuild, "BUILD_DIR", tmp_path / "build")
    return fmus


def test_compiler_errors_carry_the_compiler_output(sandbox: Path) -> None:
    model = sandbox / "dahlquist" / "model.c"
    model.write_text(model.read_text() + "\nthis is not C;\n")
    with pytest.raises(fmubuild.FmuBuildError) as info:
        fmubuild.build_fmu("dahlquist")
    message = str(info.value)
    assert "compiler failed" in message and "model.c" in message and "error:" in message


def test_inconsistent_table_is_reported_with_file_and_variable(sandbox: Path) -> None:
    model = sandbox / "dahlquist" / "model.c"
    model.write_text(model.read_text().replace('{"y0", T_REAL', '{"lambda", T_REAL'))
    with pytest.raises(fmubuild.FmuBuildError) as info:
        fmubuild.describe("dahlquist")
    assert str(model) in str(info.value)
    assert 'variable 3 "lambda": duplicate name' in str(info.value)


def test_dependency_on_a_parameter_is_reported(sandbox: Path) -> None:
    model = sandbox / "dahlquist" / "model.c"
    model.write_text(
        model.read_text().replace('"derivative of y", VR_Y, "4"', '"derivative of y", VR_Y, "2 4"')
    )
    with pytest.raises(fmubuild.FmuBuildError) as info:
        fmubuild.describe("dahlquist")
    assert 'variable 5 "der(y)": dependency 2 ("lambda") is neither an input nor a continuous state' in str(
        info.value
    )


def test_solver_descriptions_must_match_the_c_solvers(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(solvers, "SOLVERS", solvers.SOLVERS[:-1])
    with pytest.raises(fmubuild.FmuBuildError, match="model.h: SolverKind is .* but master/solvers.py has 5"):
        fmubuild.describe("dahlquist")


def test_the_c_solver_numbers_and_names_are_the_python_table() -> None:
    header = (fmubuild.FMI_DIR / "model.h").read_text()
    assert solvers.c_mismatch(header) is None
    swapped = header.replace("SOLVER_AB2 = 2", "SOLVER_AB2 = 3").replace("SOLVER_AB3 = 3", "SOLVER_AB3 = 2")
    assert "SOLVER_AB2 = 3" in (solvers.c_mismatch(swapped) or "")
    renamed = header.replace("SOLVER_RK4", "SOLVER_RUNGE_KUTTA")
    assert "SOLVER_RUNGE_KUTTA = 4" in (solvers.c_mismatch(renamed) or "")
    assert solvers.c_mismatch("typedef int SolverKind;") == "no enumeration SolverKind"


def test_layer_constants_come_from_c(sandbox: Path) -> None:
    # Leave `initial` out of the table: the C layer's FMI 2.0 default rule fills it in.
    model = sandbox / "dahlquist" / "model.c"
    text = model.read_text()
    text = text.replace(
        "C_PARAMETER, V_FIXED, I_EXACT, R_LAMBDA", "C_PARAMETER, V_FIXED, I_DEFAULT, R_LAMBDA"
    )
    model.write_text(
        text.replace("C_OUTPUT, V_CONTINUOUS, I_CALCULATED", "C_OUTPUT, V_CONTINUOUS, I_DEFAULT")
    )
    desc = fmubuild.describe("dahlquist")
    by_name = {v["name"]: v for v in desc["variables"]}
    assert by_name["lambda"]["initial"] is None and by_name["lambda"]["effective_initial"] == "exact"
    assert by_name["y"]["initial"] is None and by_name["y"]["effective_initial"] == "calculated"
    assert desc["max_input_derivative_order"] == 3
    assert [c["name"] for c in desc["log_categories"]] == ["logError", "logWarning", "logInfo", "logDebug"]


def test_stale_xml_is_refused_until_regenerated(sandbox: Path) -> None:
    xml = sandbox / "dahlquist" / "modelDescription.xml"
    model = sandbox / "dahlquist" / "model.c"
    model.write_text(model.read_text().replace('"initial value y(0)"', '"initial value"'))
    with pytest.raises(fmubuild.FmuBuildError, match="out of date.*--write-xml dahlquist"):
        fmubuild.build_fmu("dahlquist")
    xml.unlink()
    with pytest.raises(fmubuild.FmuBuildError, match="missing"):
        fmubuild.build_fmu("dahlquist")
    assert fmubuild.main(["--write-xml", "dahlquist"]) == 0
    assert 'description="initial value"' in xml.read_text()
    assert (fmubuild.BUILD_DIR / "dahlquist.fmu").is_file()
    assert fmubuild.main(["no_such_model"]) == 1


def test_fmu_path_rebuilds_only_when_a_source_is_newer(sandbox: Path) -> None:
    path = fmubuild.fmu_path("dahlquist")
    built = path.stat().st_mtime_ns
    assert fmubuild.fmu_path("dahlquist") == path and path.stat().st_mtime_ns == built
    source = sandbox / "solvers" / "solvers.c"
    later = path.stat().st_mtime + 5
    os.utime(source, (later, later))
    fmubuild.fmu_path("dahlquist")
    assert path.stat().st_mtime_ns != built


def _build(_: int) -> str:
    return str(fmubuild.build_fmu("dahlquist"))


def test_concurrent_builds_produce_one_valid_fmu(sandbox: Path) -> None:
    with multiprocessing.get_context("fork").Pool(3) as pool:
        paths = pool.map(_build, range(3))
    assert len(set(paths)) == 1
    with zipfile.ZipFile(paths[0]) as zf:
        assert zf.testzip() is None
    leftovers = [p for p in fmubuild.BUILD_DIR.iterdir() if p.name != "dahlquist.fmu"]
    assert leftovers == []


def test_model_exchange_only_tables(tmp_path: Path) -> None:
    """`.me_only = 1` (the models of OMSimulator's Model Exchange scene): descriptions without a
    CoSimulation element in FMI 2.0 and 3.0, and no FMI 1.0 (Co-Simulation) build."""
    assert "oms_emachine" in fmubuild.project_fmu_names()
    assert "oms_emachine" not in fmubuild.project_fmu_names(1)
    for fmi, slave in ((2, FMU2Slave), (3, FMU3Slave)):
        path = str(fmubuild.fmu_path("oms_emachine", fmi=fmi))
        md = read_model_description(path)
        assert md.modelExchange is not None and md.coSimulation is None
        fmu = slave(
            guid=md.guid,
            unzipDirectory=extract(path, str(tmp_path / str(fmi))),
            modelIdentifier="oms_emachine",
            instanceName="m",
        )
        with pytest.raises(Exception, match="instantiate"):  # the binary refuses it too
            fmu.instantiate()
        fmu.freeLibrary()
    with pytest.raises(fmubuild.FmuBuildError) as info:
        fmubuild.build_fmu("oms_emachine", fmi=1)
    assert "\n" not in str(info.value) and "offers Model Exchange only" in str(info.value)
