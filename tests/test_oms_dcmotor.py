"""A third-party scene of Model Exchange FMUs: OMSimulator's DC motor
(tests/ssp/OpenModelica-OMSimulator/dcmotor, an SSP 2.0 file with nested systems whose three
components say implementation="ModelExchange"), laid out with the project's Model Exchange-only
models of the same interface (fmus/oms_edrive_mass, oms_emachine, oms_stimuli; its ORIGIN.md).

The file carries no settings of ours: the master takes the FMUs' stepSize as the macro step and
integrates each component itself (RK4, one step per communication step). The motor (armature
L i' = U - R i - k w, shaft J w' = k i + M_load - d w, the scene's parameters) settles at the speed
(k U / R + M_load) / (k^2 / R + d); the energy supplied is the energy dissipated and stored; the
run converges to the motor's exact solution at the first order of its held coupling.
"""

from __future__ import annotations

import dataclasses
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from helpers import run_everywhere, ssd, third_party_scene
from scipy.linalg import expm

import master.api as api
from master.fmubuild import fmu_path
from master.scenario import ScenarioError
from master.scenario.model import Component, ModelExchange, Scenario

SCENE = Path(__file__).parent / "ssp" / "OpenModelica-OMSimulator" / "dcmotor"
# the scene's parameter values (its ssv:Parameters)
R, L, K, J, D, U, M_LOAD = 0.5, 0.001, 0.1, 0.002, 0.001, 12.0, -0.5
SPEED = (K * U / R + M_LOAD) / (K**2 / R + D)  # rad/s, about 90.5
MASS, MACHINE, STIMULI = "SuT.edrive_mass", "SuT.emachine_model", "stimuli_model"


def motor(tmp_path: Path, stop: str = "2", macro_step: str | None = None) -> Scenario:
    """The scene laid out under tmp_path, recording every connected variable (inputs included) and
    the outputs the top system's connectors show."""
    path = third_party_scene(SCENE, tmp_path) / "SystemStructure.ssd"
    sc = api.load_scenario(path, stop_time=stop, macro_step=macro_step)
    ends = tuple(dict.fromkeys(end for c in sc.connections for end in links(c)))
    return dataclasses.replace(sc, record=ends + ((MASS, "phiB"), (MASS, "wB"), (MACHINE, "I")))


def links(c) -> tuple[tuple[str, str], tuple[str, str]]:
    """A connection's (component, output) and (component, input)."""
    return (c.start_component, c.start_connector), (c.end_component, c.end_connector)


def exact(t: np.ndarray) -> np.ndarray:
    """The motor's current, speed and angle from rest under the scene's constant U and M_load."""
    a = np.zeros((4, 4))
    a[:3, :3] = [[-R / L, -K / L, 0], [K / J, -D / J, 0], [0, 1, 0]]
    a[:3, 3] = [U / L, M_LOAD / J, 0]
    return np.array([expm(a * ti)[:3, 3] for ti in t])


def test_the_scene_runs_its_model_exchange_components_in_every_backend(tmp_path):
    sc = motor(tmp_path)
    assert sc.macro_step == Fraction(1, 500)  # the FMUs' stepSize: the file gives no step
    assert {c.name: c.model_exchange for c in sc.components} == dict.fromkeys(
        (MASS, MACHINE, STIMULI), ModelExchange("rk4")
    )
    assert "rk4, one step per communication step" in sc.origins[f"{MACHINE} integration"]
    d = run_everywhere(sc)
    # each input holds its source's output at every row, through SuT's connectors and the top system's
    for (start, output), (end, input_) in map(links, sc.connections):
        assert np.array_equal(d[f"{end}.{input_}"], d[f"{start}.{output}"]), (end, input_)
    assert {sum(links(c), ()) for c in sc.connections} == {
        (MACHINE, "M", MASS, "M_A"),
        (MASS, "wA", MACHINE, "w"),
        (MASS, "phiA", MACHINE, "phi"),
        (STIMULI, "M_load", MASS, "M_B"),
        (STIMULI, "U", MACHINE, "U"),
    }
    assert np.all(d[f"{STIMULI}.U"] == U) and np.all(d[f"{STIMULI}.M_load"] == M_LOAD)  # bound values
    # after 2 s (20 of the slow time constant's 0.093 s) the motor runs at its steady speed, where
    # the held coupling is exact: the current balances the load and the damping
    w, i = d[f"{MASS}.wB"][-1], d[f"{MACHINE}.I"][-1]
    assert w == pytest.approx(SPEED, rel=1e-8)
    assert i == pytest.approx((U - K * w) / R, rel=1e-8)
    assert d[f"{MACHINE}.M"][-1] == pytest.approx(K * i, rel=1e-12)
    assert np.array_equal(d[f"{MASS}.wA"], d[f"{MASS}.wB"])  # one rigid inertia
    assert d[f"{MASS}.phiB"][-1] == pytest.approx(np.trapezoid(d[f"{MASS}.wB"], d["time"]), rel=1e-4)


def test_energy_supplied_is_dissipated_and_stored(tmp_path):
    """Over 2 s: the electrical energy in (U I) is the resistor's and the damper's heat, the
    load's work and the kinetic and magnetic energy at the end, to within 0.5 % (the held
    coupling's error at H = 2 ms and the trapezoidal sums')."""
    d = api.run(motor(tmp_path), backend="in-process").data
    t, i, w = d["time"], d[f"{MACHINE}.I"], d[f"{MASS}.wB"]
    supplied = np.trapezoid(U * i, t)
    out = np.trapezoid(R * i**2 + D * w**2 - M_LOAD * w, t) + J * w[-1] ** 2 / 2 + L * i[-1] ** 2 / 2
    assert supplied > 100.0  # joules
    assert abs(out - supplied) < 5e-3 * supplied


def test_the_run_converges_to_the_motor_at_first_order(tmp_path):
    """Halving the macro step halves the largest speed and current errors against the exact
    solution: extrapolation order 0 (the default for a file without settings) is first order."""
    errors = []
    for step in ("0.002", "0.001", "0.0005"):
        d = api.run(motor(tmp_path / step, stop="0.5", macro_step=step), backend="in-process").data
        ref = exact(d["time"])
        errors.append(
            [np.max(np.abs(d[f"{MACHINE}.I"] - ref[:, 0])), np.max(np.abs(d[f"{MASS}.wB"] - ref[:, 1]))]
        )
    errors = np.array(errors)
    assert np.all(errors[0] < [1.0, 2.0])  # of 23 A and 90 rad/s
    assert np.all((errors[1:] / errors[:-1] > 0.4) & (errors[1:] / errors[:-1] < 0.6)), errors


def test_the_machine_alone_agrees_with_fmpy(tmp_path):
    """oms_emachine at U = 12 V, w = 50 rad/s: the current rises to (U - k w) / R = 14 A. The
    master's Euler equals fmpy's (one step per output interval) to rounding; its RK4 is the exact
    discrete solution 14 (1 - R4(z)^n), z = -h R / L, within the method's error of fmpy's CVode."""
    inputs = {"U": 12.0, "w": 50.0}
    h = Fraction(1, 2000)
    path = fmu_path("oms_emachine")
    final = (inputs["U"] - K * inputs["w"]) / R

    def master_run(solver: str, fmu: Path = path) -> np.ndarray:
        comp = Component("m", fmu, parameters=dict(inputs), model_exchange=ModelExchange(solver))
        sc = Scenario(tmp_path / "m.ssd", "m", (comp,), (), Fraction(0), Fraction(1, 50), h)
        return api.run(sc, backend="in-process").data["m.I"]

    def fmpy_run(**options) -> np.ndarray:
        result = simulate_fmu(str(path), fmi_type="ModelExchange", stop_time=0.02, output_interval=float(h),
                              start_values=inputs, output=["I"], **options)  # fmt: skip
        return result["I"]

    euler = master_run("euler")
    assert np.max(np.abs(euler - fmpy_run(solver="Euler"))) < 1e-12 * final
    rk4, cvode = master_run("rk4"), fmpy_run(relative_tolerance=1e-10)
    z = -float(h) * R / L
    n = np.arange(len(rk4))
    assert np.allclose(
        rk4, final * (1 - (1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24) ** n), rtol=1e-12, atol=1e-12
    )
    method_error = final * np.max(np.abs((1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24) ** n - np.exp(z * n)))
    assert np.max(np.abs(rk4 - cvode)) < method_error + 1e-6 * final
    assert rk4[-1] > 0.99 * final  # it has risen
    assert np.array_equal(master_run("rk4", fmu_path("oms_emachine", fmi=3)), rk4)  # FMI 3.0 alike


SOURCES = {"src": "project:dahlquist", "lag": "project:crashtest"}


def test_implementation_model_exchange_runs_an_fmu_of_both_interfaces_as_model_exchange(tmp_path):
    """SSP's implementation="ModelExchange" on a component whose FMU has both interfaces: the master
    integrates it, in a file with our settings annotation or without."""
    path = ssd(tmp_path / "me.ssd", SOURCES, [("src", "y", "lag", "u")])
    text = path.read_text().replace(
        '<ssd:Component name="lag"', '<ssd:Component name="lag" implementation="ModelExchange"'
    )
    path.write_text(text)
    assert api.load_scenario(path).component("lag").model_exchange == ModelExchange()
    chosen = text.replace(
        "</mm:Settings>", '<mm:Component name="lag" solver="ab3" internalStep="0.025"/></mm:Settings>'
    )
    path.write_text(chosen)
    assert api.load_scenario(path).component("lag").model_exchange == ModelExchange("ab3", Fraction(1, 40))
    assert api.load_scenario(path).component("src").model_exchange is None
    start, end = text.index("<ssd:Annotations>"), text.index("</ssd:Annotations>") + len("</ssd:Annotations>")
    path.write_text(text[:start] + text[end:])
    assert api.load_scenario(path, macro_step="0.1").component("lag").model_exchange == ModelExchange()


def test_implementation_co_simulation_needs_that_interface(tmp_path):
    """implementation="CoSimulation" on an FMU that offers Model Exchange alone: one line naming it."""
    for model in ("oms_stimuli", "oms_emachine"):
        (tmp_path / f"{model}.fmu").write_bytes(fmu_path(model).read_bytes())
    path = ssd(tmp_path / "cs.ssd", {"s": "oms_stimuli.fmu", "m": "oms_emachine.fmu"}, [("s", "U", "m", "U")])
    path.write_text(path.read_text().replace('name="m" ', 'name="m" implementation="CoSimulation" '))
    with pytest.raises(ScenarioError) as err:
        api.load_scenario(path)
    assert len(err.value.problems) == 1
    assert 'implementation="CoSimulation": oms_emachine.fmu has no Co-Simulation interface' in str(err.value)
