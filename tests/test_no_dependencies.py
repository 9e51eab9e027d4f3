"""FMUs that declare no dependencies: FMI 2.0 then reads every output as depending on every input,
so a feedback loop through them is an algebraic loop to the master, which solves it at each
communication point.  Two plain pythonfmu FMUs (a lag and a PI controller) and ecos's quarter
truck (20-sim exports, here project FMUs of their interface) run unedited, and equal the runs with
their true dependencies declared.  Units: s, m, m/s, N, kg.
"""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import libcosim_last_values, ssd, third_party_scene
from lxml import etree
from test_run import build_pythonfmu

import master.api as api

QUARTER_TRUCK = Path(__file__).parent / "ssp" / "Ecos-platform-ecos" / "quarter_truck"

PLANT = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Plant(Fmi2Slave):
    """A first-order lag y' = (u - y) / tau by explicit Euler over each communication step: y does
    not depend directly on u, but pythonfmu declares no dependencies."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.tau = 0.5
        self.u = 0.0
        self.y = 0.0
        self.register_variable(Real("tau", causality=Fmi2Causality.parameter, variability="fixed"))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.y += step_size * (self.u - self.y) / self.tau
        return True
'''

CONTROLLER = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Controller(Fmi2Slave):
    """A PI controller u = kp e + ki integral(e), e = r - y_m, the integral by explicit Euler over
    each communication step: u depends directly on the input y_m."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.kp = 2.0
        self.ki = 1.5
        self.r = 1.0
        self.y_m = 0.0
        self.integral = 0.0
        self.register_variable(Real("kp", causality=Fmi2Causality.parameter, variability="fixed"))
        self.register_variable(Real("ki", causality=Fmi2Causality.parameter, variability="fixed"))
        self.register_variable(Real("r", causality=Fmi2Causality.parameter, variability="fixed"))
        self.register_variable(Real("y_m", causality=Fmi2Causality.input))
        self.register_variable(Real("u", causality=Fmi2Causality.output, getter=self.output))

    def output(self):
        return self.kp * (self.r - self.y_m) + self.ki * self.integral

    def do_step(self, current_time, step_size):
        self.integral += step_size * (self.r - self.y_m)
        return True
'''

H, STOP = 0.1, 3.0  # s


def declare_dependencies(fmu: Path, dependencies: dict[str, tuple[str, ...]]) -> None:
    """Writes into the FMU's description the dependencies of the outputs named (their inputs, by
    name): what a user would edit by hand."""
    with zipfile.ZipFile(fmu) as z:
        members = {item.filename: z.read(item) for item in z.infolist()}
    root = etree.fromstring(members["modelDescription.xml"])
    index = {v.get("name"): str(i) for i, v in enumerate(root.iter("ScalarVariable"), 1)}
    for unknown in root.find("ModelStructure/Outputs"):
        name = next(n for n, i in index.items() if i == unknown.get("index"))
        if name in dependencies:
            unknown.set("dependencies", " ".join(index[v] for v in dependencies[name]))
    members["modelDescription.xml"] = etree.tostring(root, xml_declaration=True, encoding="UTF-8")
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)


def declares_dependencies(fmu: Path) -> bool:
    with zipfile.ZipFile(fmu) as z:
        root = etree.fromstring(z.read("modelDescription.xml"))
    return any(u.get("dependencies") is not None for u in root.iter("Unknown"))


def validate_cli(scene: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "master", "validate", str(scene), *args],
                          capture_output=True, text=True, timeout=120)  # fmt: skip


def notes_naming(output: str, name: str) -> list[str]:
    return [line for line in output.splitlines() if name in line and "dependencies" in line]


@pytest.fixture(scope="module")
def pi_loop(tmp_path_factory) -> dict[str, Path]:
    """The loop plant.y -> ctrl.y_m, ctrl.u -> plant.u as written (key "plain") and with the lag's
    output declared independent of its input (key "declared")."""
    d = tmp_path_factory.mktemp("pi_loop")
    fmus = {name: build_pythonfmu(name, src, d) for name, src in (("Plant", PLANT), ("Controller", CONTROLLER))}
    assert not any(declares_dependencies(f) for f in fmus.values())  # what makes the loop
    declared = d / "declared"
    declared.mkdir()
    for name, f in fmus.items():
        (declared / f.name).write_bytes(f.read_bytes())
    declare_dependencies(declared / "Plant.fmu", {"y": ()})
    links = [("plant", "y", "ctrl", "y_m"), ("ctrl", "u", "plant", "u")]
    return {
        key: ssd(folder / "loop.ssd", {"plant": "Plant.fmu", "ctrl": "Controller.fmu"}, links,
                 macro_step=str(H), stop=str(STOP))
        for key, folder in (("plain", d), ("declared", declared))
    }  # fmt: skip


def test_pythonfmu_loop_validates_with_a_note_per_fmu(pi_loop):
    """Neither FMU declares dependencies: validate accepts the loop and says once per FMU what it
    assumes (every output depends on every input) instead of refusing the scene."""
    done = validate_cli(pi_loop["plain"])
    out = done.stdout + done.stderr
    assert done.returncode == 0, out
    assert "error" not in out.lower() and "algebraic loop through direct feedthrough" not in out
    for fmu in ("Plant", "Controller"):
        assert len(notes_naming(out, fmu)) == 1, out


def test_pythonfmu_loop_runs_as_with_the_dependencies_declared(pi_loop):
    """The unedited loop runs, bit for bit as the one whose lag declares y independent of u."""
    plain = api.run(pi_loop["plain"]).data
    declared = api.run(pi_loop["declared"]).data
    assert plain.dtype.names == declared.dtype.names
    for name in plain.dtype.names:
        assert np.array_equal(plain[name], declared[name]), name


def test_pythonfmu_loop_is_the_recurrence_of_the_scheme(pi_loop):
    """At t_n the lag's y_n feeds the controller, whose u_n = kp (r - y_n) + ki I_n feeds the lag;
    then both step by Euler: y_{n+1} = y_n + H (u_n - y_n) / tau, I_{n+1} = I_n + H (r - y_n)."""
    tau, kp, ki, r = 0.5, 2.0, 1.5, 1.0
    y, integral, ys, us = 0.0, 0.0, [], []
    for _ in range(round(STOP / H) + 1):
        u = kp * (r - y) + ki * integral
        ys.append(y)
        us.append(u)
        y, integral = y + H * (u - y) / tau, integral + H * (r - y)
    for key in ("declared", "plain"):  # the second needs the loop solver
        d = api.run(pi_loop[key]).data
        np.testing.assert_allclose(d["time"], np.arange(len(ys)) * H, rtol=0, atol=1e-12)
        np.testing.assert_allclose(d["plant.y"], ys, rtol=1e-15, atol=1e-15, err_msg=key)
        np.testing.assert_allclose(d["ctrl.u"], us, rtol=1e-15, atol=1e-15, err_msg=key)
    assert abs(ys[-1] - r) < 0.05  # the integral action brings y to the set point
