"""An FMU described once (master.description): the runtime and the scenario layer see the same
variables and capabilities, the interfaces' flags are read per interface, every kernel call has its
FMI function in one table, and the description sits below both master.fmu and master.scenario."""

from __future__ import annotations

import ast
import shutil
import zipfile
from pathlib import Path

import pytest

from master import description
from master.description import CO_SIMULATION, FMI_FUNCTIONS, MODEL_EXCHANGE, SCHEDULED_FUNCTIONS, Variable
from master.fmu import Fmu, read_description
from master.fmubuild import fmu_path
from master.runtime import native
from master.scenario import fmuinfo

MASTER = Path(description.__file__).parent


def test_the_runtime_and_the_scenario_layer_see_one_variable_type():
    path = fmu_path("msd")
    fmu = Fmu(path, "m")
    try:
        seen = fmuinfo.read(path).variables
        assert seen == fmu.variables  # the same values of the same type, read once
        assert all(type(v) is Variable for v in seen.values())
        x = seen["x"]
        assert (x.type, x.fmi_type, x.kind, x.causality) == ("Real", "Real", "Float64", "output")
    finally:
        fmu.close()
    three = fmuinfo.read(fmu_path("msd", fmi=3)).variables["x"]
    assert (three.type, three.fmi_type, three.kind) == ("Real", "Float64", "Float64")


def test_an_fmi3_integer_has_its_own_type_and_the_calls_class():
    variables = description.read(fmu_path("alltypes", fmi=3)).variables
    int8 = next(v for v in variables.values() if v.fmi_type == "Int8")
    assert (int8.type, int8.kind) == ("Integer", "Int8")


def _rewritten(tmp_path: Path, source: Path, *changes: tuple[str, str]) -> Path:
    """A copy of the FMU at `source` whose modelDescription.xml has each (old, new) replaced."""
    target = tmp_path / source.name
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                for old, new in changes:
                    assert old in text
                    text = text.replace(old, new, 1)
                data = text.encode()
            zout.writestr(item, data)
    return target


def test_each_interface_has_its_own_flags(tmp_path):
    path = _rewritten(
        tmp_path,
        fmu_path("msd"),
        ('numberOfEventIndicators="0"', 'numberOfEventIndicators="2"'),
        # the ModelExchange element comes first: only its state flag and its step flag change
        ('completedIntegratorStepNotNeeded="true" canGetAndSetFMUstate="true"',
         'completedIntegratorStepNotNeeded="false" canGetAndSetFMUstate="false"'),
    )  # fmt: skip
    found = description.read(path)
    cs, me = found.co_simulation, found.model_exchange
    assert set(found.interfaces) == {CO_SIMULATION, MODEL_EXCHANGE}
    assert (cs.model_exchange, cs.can_get_set_state, cs.can_interpolate_inputs, cs.event_indicators) == (
        False, True, True, 0
    )  # fmt: skip
    assert (me.model_exchange, me.can_get_set_state, me.can_interpolate_inputs, me.event_indicators) == (
        True, False, False, 2
    )  # fmt: skip
    assert me.completed_integrator_step and not cs.completed_integrator_step
    assert cs.model_identifier == me.model_identifier == "msd"
    assert cs.dependencies == found.feedthrough  # one reading of the model structure


def test_an_fmu_with_only_model_exchange_is_described_as_one_the_master_integrates(tmp_path):
    text = zipfile.ZipFile(fmu_path("msd")).read("modelDescription.xml").decode()
    cs = text[text.index("<CoSimulation") : text.index("</CoSimulation>") + len("</CoSimulation>")]
    path = _rewritten(tmp_path, fmu_path("msd"), (cs, ""))
    found = description.read(path)
    assert found.co_simulation is None and found.model_exchange is not None
    assert found.integrable and not found.can_interpolate_inputs and found.unsupported is None
    assert description.runs_as_model_exchange(read_description(path))


def test_every_kernel_call_has_its_fmi_function_in_one_table():
    slots = {name for name, _ in native.Component._fields_}
    assert set(FMI_FUNCTIONS) <= slots  # each row is a function pointer of the kernel
    # FMI 3's per-type calls (fmi3Get<Type>, fmi3Set<Type>), the master's own solver, and the
    # Model Exchange Jacobian's call of slot get_directional_derivative are named where they fail
    other = {"get_typed", "set_typed", "solver", "directional_derivative"}
    # (a Scheduled Execution component's own calls: in SCHEDULED_FUNCTIONS, slots of mk_scheduled)
    assert set(SCHEDULED_FUNCTIONS) <= {name for name, _ in native.Scheduled._fields_}
    assert set(native.CALLS) - other <= set(FMI_FUNCTIONS) | set(SCHEDULED_FUNCTIONS)
    fmu = Fmu(fmu_path("msd"), "m")
    try:
        for slot in ("do_step", "get_real", "set_real", "get_state"):
            fmu.slave.dll[description.fmi_function(slot, 2)]  # exported: no AttributeError
        assert "fmi2DoStep" in str(fmu.call_error("do_step", 3))
    finally:
        fmu.close()


def _imports(path: Path) -> set[str]:
    """The master modules a file imports, at its top or inside its functions."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            out.add(f"master.scenario.{node.module or ''}" if path.parent.name == "scenario" else "relative")
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {m for m in out if m.startswith("master.")}


@pytest.mark.parametrize("module", ["description.py", "archives.py", "solvers.py", "fmu.py"])
def test_the_description_and_the_fmu_layer_import_no_scenario_module(module):
    assert not {m for m in _imports(MASTER / module) if m.startswith("master.scenario")}


def test_the_scenario_layer_reads_descriptions_only_through_master_description():
    for path in sorted((MASTER / "scenario").glob("*.py")):
        assert not {m for m in _imports(path) if m == "master.fmu" or m.startswith("master.fmu.")}, path.name


def test_a_changed_file_is_read_again(tmp_path):
    path = tmp_path / "msd.fmu"
    shutil.copy(fmu_path("msd"), path)
    first = description.read(path)
    assert description.read(path) is first  # read once while the file is unchanged
    (tmp_path / "new").mkdir()
    changed = _rewritten(tmp_path / "new", path, ('description="Mass-spring-damper', 'description="Changed'))
    shutil.move(changed, path)
    again = description.read(path)
    assert again is not first and again.variables == first.variables
    assert read_description(path).description.startswith("Changed")
