"""FMI 3 intermediate update: the project's FMUs built as FMI 3 declare their continuous Float64
inputs intermediateUpdate="true" (providesIntermediateUpdate) and, given the callback, ask the importer
for them at every new stage time of their solver inside doStep; the master answers from the kernel
with the input polynomials an FMI 2 FMU gets as input derivatives (interpolateInputs).

Same polynomials at the same stage times in the same arithmetic: the FMI 3 builds give the FMI 2
builds' results bit for bit, in every backend. Without the callback (fmpy alone) the inputs are
held over a step, as before.
"""

from __future__ import annotations

import dataclasses
import shutil
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from helpers import run_everywhere
from test_model_exchange import oscillator

import master.api as api
from master.description import intermediate_inputs, parse
from master.description import read as read_description
from master.fmubuild import fmu_path
from master.scenario.model import Scenario

ROOT = Path(__file__).resolve().parent.parent
H = 0.01  # one doStep, s
FORCE = (0.5, -2.0, 30.0)  # F(t) = F0 + F1 t + F2 t^2 / 2 over the step


def force(t: float) -> float:
    """The force polynomial in the arithmetic of fmus/fmi/step.c (and of the kernel's callback)."""
    f0, f1, f2 = FORCE
    return f0 + t * (f1 + t * (f2 / 2.0 + t * 0.0 / 6.0))


def test_fmi3_builds_declare_intermediate_update_for_their_continuous_inputs():
    md = parse(fmu_path("msd", fmi=3))
    assert md.coSimulation.providesIntermediateUpdate
    assert intermediate_inputs(md) == ["F", "x_in", "v_in"]
    assert read_description(fmu_path("msd", fmi=3)).can_interpolate_inputs  # interpolateInputs applies
    assert intermediate_inputs(parse(fmu_path("msd"))) == []  # FMI 2: input derivatives instead
    without = parse(fmu_path("dahlquist", fmi=3))  # no inputs: nothing to ask for
    assert not without.coSimulation.providesIntermediateUpdate and intermediate_inputs(without) == []


class Asking:
    """msd built as FMI 3 in fmpy, instantiated with a Python intermediate-update callback that
    answers F(t) and records what the FMU asks."""

    def __init__(self, tmp: Path, answer: bool = True) -> None:
        path = fmu_path("msd", fmi=3)
        md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.slave = FMU3Slave(
            guid=md.instantiationToken,
            unzipDirectory=extract(str(path), str(tmp / "msd3")),
            modelIdentifier="msd",
            instanceName="msd",
        )
        self.asked: list[tuple[float, bool, bool, bool, bool]] = []
        self.refused: list[str] = []
        self.answer = answer
        self.slave.instantiate(intermediateUpdate=self.callback if answer else None, logMessage=self.log)

    def log(self, env, status, category, message) -> None:
        if status >= 3:
            self.refused.append(message.decode())

    def callback(self, env, time, set_requested, get_allowed, step_finished, can_return_early, early, when):
        self.asked.append((time, set_requested, get_allowed, step_finished, can_return_early))
        self.slave.setFloat64([self.vr["F"]], [force(time)])
        for call in (
            lambda: self.slave.setFloat64([self.vr["c"]], [2.0]),  # a parameter: not in this mode
            lambda: self.slave.getFloat64([self.vr["x"]]),  # nothing to get (getAllowed false)
        ):
            try:
                call()
            except Exception:
                pass  # refused: the FMU logged why

    def step(self, internal_step: float) -> list[float]:
        s = self.slave
        s.setFloat64([self.vr["internal_step"]], [internal_step])
        s.setFloat64([self.vr["x0"]], [1.0])
        s.enterInitializationMode(startTime=0.0)
        s.exitInitializationMode()
        s.setFloat64([self.vr["F"]], [FORCE[0]])
        assert self.asked == []  # only inside doStep
        s.doStep(0.0, H)
        out = s.getFloat64([self.vr["x"], self.vr["v"], self.vr["F"]])
        s.terminate()
        s.freeInstance()
        return out


def fmi2_with_derivatives(tmp: Path, internal_step: float) -> list[float]:
    """msd built as FMI 2, the same force handed over as input derivatives."""
    path = fmu_path("msd")
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s = FMU2Slave(
        guid=md.guid,
        unzipDirectory=extract(str(path), str(tmp / "msd2")),
        modelIdentifier="msd",
        instanceName="msd",
    )
    s.instantiate()
    s.setReal([vr["internal_step"], vr["x0"]], [internal_step, 1.0])
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    s.setReal([vr["F"]], [FORCE[0]])
    s.setRealInputDerivatives([vr["F"], vr["F"]], [1, 2], [FORCE[1], FORCE[2]])
    s.doStep(0.0, H)
    out = s.getReal([vr["x"], vr["v"], vr["F"]])
    s.terminate()
    s.freeInstance()
    return out


def test_the_fmu_asks_at_each_new_stage_time_and_uses_the_answer(tmp_path: Path):
    """RK4 in two internal steps of h = H/2: stages at 0, h/2, h/2, h, then h, 3h/2, 3h/2, 2h; each
    new time asked once, to set (the stages at one time share the answer), no early return. The
    step equals the FMI 2 build's with the force as input derivatives, to the bit; the input is
    the set value again after the step; the parameter set and the get inside the callback are
    refused (Intermediate Update Mode)."""
    fmu = Asking(tmp_path)
    x, v, f = fmu.step(H / 2)
    assert [t for t, *_ in fmu.asked] == [0.0, H / 4, H / 2, 3 * H / 4, H]
    assert all(tuple(flags) == (True, False, False, False) for _, *flags in fmu.asked)
    assert [x, v, f] == fmi2_with_derivatives(tmp_path, H / 2)
    assert f == FORCE[0]
    assert len(fmu.refused) == 2 * len(fmu.asked)
    assert "Intermediate Update Mode" in fmu.refused[0] and "Intermediate Update Mode" in fmu.refused[1]


def test_without_a_callback_the_inputs_are_held(tmp_path: Path):
    """fmpy's instantiate passes no callback: F stays at its set value over the step (the FMI 2
    build without derivatives, to the bit), different from the polynomial's step."""
    held = Asking(tmp_path, answer=False).step(H / 2)
    asked = Asking(tmp_path / "again").step(H / 2)
    fmi2 = simulate_fmu(
        str(fmu_path("msd")),
        stop_time=H,
        output_interval=H,
        start_values={"x0": 1.0, "internal_step": H / 2, "F": FORCE[0]},
        output=["x", "v"],
    )
    assert held[:2] == [fmi2["x"][-1], fmi2["v"][-1]]
    assert held[:2] != asked[:2]


def test_simulate_fmu_runs_the_fmi3_build_with_inputs(tmp_path: Path):
    """fmpy.simulate_fmu alone (no callback) with an input signal: it runs, as the FMI 2 build."""
    signal = np.array([(0.0, 0.0), (0.5, 1.0), (1.0, 1.0)], dtype=[("time", float), ("F", float)])
    options = dict(stop_time=1.0, output_interval=0.01, input=signal, output=["x", "v"])
    three = simulate_fmu(str(fmu_path("msd", fmi=3)), **options)
    two = simulate_fmu(str(fmu_path("msd")), **options)
    assert np.ptp(three["x"]) > 0.01  # the force moved it
    for name in ("x", "v"):
        assert np.array_equal(three[name], two[name]), name


# ------------------------------------------------------------------------ the master's scenes


def as_fmi3(sc, names: set[str], **changes):
    """`sc` with the components `names` on their FMUs' FMI 3 builds (and `changes`)."""
    comps = tuple(
        dataclasses.replace(c, fmu_path=fmu_path(Path(c.fmu_path).stem, fmi=3), **changes)
        if c.name in names
        else c
        for c in sc.components
    )
    return dataclasses.replace(sc, components=comps)


def assert_same(ours: np.ndarray, theirs: np.ndarray) -> None:
    assert ours.dtype.names == theirs.dtype.names
    for name in theirs.dtype.names:
        assert np.array_equal(ours[name], theirs[name]), name


@pytest.mark.parametrize("solver", ["rk4", "semi_implicit_midpoint"])
def test_oscillator_with_fmi3_msd_equals_fmi2_in_every_backend(solver):
    """The two-mass oscillator, mass 1 taking its force as a polynomial (order 2) at its internal
    stages: msd built as FMI 3 with intermediate update gives the FMI 2 build's bits in every
    backend; held (no interpolation) it does not."""
    sc = oscillator(solver, False)
    two = run_everywhere(sc)
    three = run_everywhere(as_fmi3(sc, {"mass1", "mass2"}))
    assert_same(three, two)
    held = api.run(as_fmi3(sc, {"mass1", "mass2"}, interpolate_inputs=False), backend="serial").data
    assert not np.array_equal(held["mass1.x"], two["mass1.x"])


def hydraulic_scene(tmp: Path, stop: str) -> Scenario:
    """The hydraulic manipulator with the hydraulics taking its strokes and stroke rates as
    polynomials (order 2) in one doStep per macro step (its communication step its internal step)."""
    shutil.copytree(ROOT / "models" / "hydraulic-manipulator", tmp / "scene")
    ssd = tmp / "scene" / "SystemStructure.ssd"
    text = ssd.read_text()
    old = '<mm:Component name="hydraulics" stepRatio="5" extrapolationOrder="2"'
    assert old in text
    ssd.write_text(text.replace(old, old + ' interpolateInputs="true"'))
    return api.load_scenario(ssd, stop_time=stop)


def test_hydraulic_scene_with_fmi3_hydraulics_equals_fmi2_in_every_backend(tmp_path: Path):
    sc = hydraulic_scene(tmp_path, "0.2")
    assert "hydraulics: k = 1" in api.plan(sc).describe()
    two = run_everywhere(sc)
    three = run_everywhere(as_fmi3(sc, {"hydraulics"}))
    assert_same(three, two)
    assert np.ptp(two["mechanics.stroke1"]) > 1e-4  # the pistons moved
    held = api.run(as_fmi3(sc, {"hydraulics"}, interpolate_inputs=False), backend="serial").data
    assert not np.array_equal(held["hydraulics.p_left1"], two["hydraulics.p_left1"])


def test_order_with_intermediate_update_is_the_polynomial_inputs_order():
    """The oscillator's error against a run at a quarter of the macro step: with intermediate update
    it falls as with FMI 2 input derivatives (the same numbers), faster than with held inputs."""

    def error(sc_of) -> list[float]:
        runs = {}
        for h in (Fraction(1, 50), Fraction(1, 100), Fraction(1, 400)):
            sc = oscillator("rk4", False)
            step = {"internal_step": float(h / 4)}
            mass1, mass2 = (
                dataclasses.replace(c, parameters={**c.parameters, **step}, interpolate_inputs=True)
                for c in sc.components
            )
            sc = dataclasses.replace(sc, components=(mass1, mass2), macro_step=h, stop_time=Fraction(1))
            runs[h] = api.run(sc_of(sc), backend="in-process").data
        ref = runs[Fraction(1, 400)]
        return [
            float(abs(runs[h]["mass1.x"][-1] - ref["mass1.x"][-1]))
            for h in (Fraction(1, 50), Fraction(1, 100))
        ]

    fmi2 = error(lambda sc: sc)
    fmi3 = error(lambda sc: as_fmi3(sc, {"mass1", "mass2"}))
    held = error(lambda sc: as_fmi3(sc, {"mass1", "mass2"}, interpolate_inputs=False))
    assert fmi3 == fmi2
    order = np.log2(fmi3[0] / fmi3[1])
    held_order = np.log2(held[0] / held[1])
    print(f"orders: intermediate update {order:.2f}, held {held_order:.2f}; errors {fmi3}, held {held}")
    assert order > held_order + 0.5, (order, held_order)
