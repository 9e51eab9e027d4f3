"""Helpers of the tests: scenario files written as SSD, runs in every backend, exact polynomials,
processes started so that nothing outlives a test, third-party scenes laid out with project FMUs."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from fractions import Fraction
from math import prod
from pathlib import Path

import numpy as np

import master.api as api
from master.fmubuild import fmu_path
from master.scenario.model import Scenario

BACKENDS = ("serial", "parallel", "in-process")


def run_everywhere(sc: Scenario) -> np.ndarray:
    """The results of `sc`, the same columns and bits in every backend."""
    rows = {b: api.run(sc, backend=b).data for b in BACKENDS}
    for backend, d in rows.items():
        assert d.dtype.names == rows["serial"].dtype.names
        for name in d.dtype.names:
            assert np.array_equal(d[name], rows["serial"][name]), (backend, name)
    return rows["serial"]


def lagrange(points: list[tuple[Fraction, Fraction]], x: Fraction) -> Fraction:
    """The polynomial through `points` (time, value) at time x, exactly."""
    return sum(
        (y * prod((x - tk) / (tj - tk) for k, (tk, _) in enumerate(points) if k != j)
         for j, (tj, y) in enumerate(points)),
        Fraction(0),
    )  # fmt: skip


def ssd(path: Path, components: dict[str, str], connections: list[tuple[str, str, str, str]],
        settings: str = "", macro_step: str = "0.1", stop: str = "1") -> Path:  # fmt: skip
    """A scenario file: components (name -> source), connections (start, output, end, input) with
    their connectors declared, and the children of mm:Settings."""
    connectors: dict[str, list[tuple[str, str]]] = {name: [] for name in components}
    for s, o, e, i in connections:
        connectors[s].append((o, "output"))
        connectors[e].append((i, "input"))

    def declared(name: str) -> str:  # its connectors (none: no element, which may not be empty)
        items = "".join(f'<ssd:Connector name="{v}" kind="{k}"/>' for v, k in dict(connectors[name]).items())
        return f"<ssd:Connectors>{items}</ssd:Connectors>" if items else ""

    elements = "".join(
        f'<ssd:Component name="{name}" source="{source}">{declared(name)}</ssd:Component>\n'
        for name, source in components.items()
    )
    links = "".join(
        f'<ssd:Connection startElement="{s}" startConnector="{o}" endElement="{e}" endConnector="{i}"/>\n'
        for s, o, e, i in connections
    )
    links = f"    <ssd:Connections>\n{links}    </ssd:Connections>\n" if links else ""
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="{path.stem}"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:mm="urn:org.multirate-master:settings:1">
  <ssd:System name="{path.stem}">
    <ssd:Elements>
{elements}    </ssd:Elements>
{links}    <ssd:Annotations>
      <ssc:Annotation type="org.multirate-master.settings">
        <mm:Settings macroStep="{macro_step}">{settings}</mm:Settings>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:System>
  <ssd:DefaultExperiment stopTime="{stop}"/>
</ssd:SystemStructureDescription>
""")
    return path


# Execs the command with SIGINT at its default: a suite started with & by a non-interactive shell
# inherits SIGINT ignored, and so would every process it starts (Python then raises no
# KeyboardInterrupt); a user's Ctrl-C reaches a foreground job, so the tests start processes as one.
_AS_IN_A_TERMINAL = (
    "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
    "os.execvp(sys.argv[1], sys.argv[1:])"
)


@contextmanager
def started(cmd: list[str], **popen) -> Iterator[subprocess.Popen]:
    """`cmd` running (as a terminal's foreground job, in a process group of its own) while the
    block runs; the whole group is killed when it ends, however it ends: a failing test leaves no
    process behind to fail the next ones."""
    proc = subprocess.Popen([sys.executable, "-c", _AS_IN_A_TERMINAL, *map(str, cmd)], start_new_session=True,
                            **popen)  # fmt: skip
    try:
        yield proc
    finally:
        with suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        for stream in (proc.stdin, proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()


def finished(cmd: list[str], timeout: float, **popen) -> subprocess.CompletedProcess:
    """subprocess.run(cmd, capture_output=True, text=True) for a command that starts processes of
    its own (a Dask cluster): past the timeout, those are killed too."""
    with started(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen) as proc:
        out, err = proc.communicate(timeout=timeout)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def libcosim_last_values(
    folder: Path, variables: dict[str, tuple[str, ...]], steps: int = 10, step_ns: int = 10**6
) -> dict[str, float]:
    """The peer master libcosim (libcosimpy, the peers extra: the caller skips without it) runs the
    SSP scene in `folder` (or the .ssd file) for `steps` steps of `step_ns` ns (1 ms); the last value
    of each instance's variables, as "instance.variable"."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_ssp_file(str(folder), step_size=step_ns)
    observer = CosimObserver.create_last_value()
    ex.add_observer(observer)
    assert ex.step(steps)
    values = {}
    for name, names in variables.items():
        idx = ex.slave_index_from_instance_name(name)
        refs = {v.name.decode(): v.reference for v in ex.slave_variables(idx)}
        values.update({f"{name}.{v}": observer.last_real_values(idx, [refs[v]])[0] for v in names})
    del ex
    return values


# The FMUs third-party scenes name (tests/ssp/*/ORIGIN.md), by file name: the project model built
# with the same interface and equations. The files themselves are not kept (nothing built is).
PROJECT_FMUS = {
    "Add.fmu": "blocks_add",  # Modelica.Blocks.Math.Add, as OpenModelica exports it
    "0001_addP.fmu": "blocks_add",
    "Gain.fmu": "blocks_gain",  # Modelica.Blocks.Math.Gain
    "0002_P.fmu": "blocks_gain",
    "0003_addI.fmu": "blocks_add3",  # Modelica.Blocks.Math.Add3
    "0002_ECS_SW.fmu": "ecs_sw",  # embrace's cooling software (Simulink), with its description's defect
    "chassis.fmu": "qt_chassis",  # ecos's quarter truck (20-sim exports: no dependencies declared)
    "wheel.fmu": "qt_wheel",
    "ground.fmu": "qt_ground",
    "edrive_mass.fmu": "oms_edrive_mass",  # OMSimulator's DC motor (OpenModelica, Model Exchange only)
    "emachine_model.fmu": "oms_emachine",
    "stimuli_model.fmu": "oms_stimuli",
}

# The Simulink export declares Input.Aircraft_State an Enumeration without a variability, so
# "continuous", which FMI 2.0 forbids for an Enumeration, and cannot interpolate inputs (a sampled
# model): the copy's description says the same.
_AIRCRAFT_STATE = (
    '<SimpleType name="Aircraft_State_Type"><Enumeration>'
    + "".join(
        f'<Item name="Aircraft_State_Type_{item}" value="{value}"/>'
        for value, item in enumerate(("Stationary", "Rolling", "Rotating", "Touching_Down", "Airborne"))
    )
    + "</Enumeration></SimpleType>"
)


def _with_enumeration_defect(fmu: Path) -> None:
    with zipfile.ZipFile(fmu) as z:
        members = {item.filename: z.read(item) for item in z.infolist()}
    text = members["modelDescription.xml"].decode()
    declared, n = re.subn(
        r'(<ScalarVariable name="Input.Aircraft_State"[^>]*) variability="discrete">\s*<Integer start="0"/>',
        r'\1>\n      <Enumeration declaredType="Aircraft_State_Type" start="0"/>',
        text,
    )
    assert n == 1, "ecs_sw's description no longer declares its Integer input as expected"
    declared = declared.replace("<TypeDefinitions>", "<TypeDefinitions>\n    " + _AIRCRAFT_STATE, 1)
    members["modelDescription.xml"] = declared.replace('canInterpolateInputs="true"', "").encode()
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)


def third_party_scene(folder: Path, tmp_path: Path) -> Path:
    """A copy of a third-party scene folder under tmp_path: its text files, and at each FMU path its
    .ssd files name the project FMU of PROJECT_FMUS. Returns the copy's folder."""
    copy = tmp_path / folder.name
    shutil.copytree(folder, copy, ignore=shutil.ignore_patterns("*.fmu"), dirs_exist_ok=True)
    for ssd in copy.glob("*.ssd"):
        for source in re.findall(r'source="([^"]+\.fmu)"', ssd.read_text()):
            fmu = copy / source
            if not fmu.exists():
                fmu.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy(fmu_path(PROJECT_FMUS[fmu.name]), fmu)
                if fmu.name == "0002_ECS_SW.fmu":
                    _with_enumeration_defect(fmu)
    return copy
