"""Model Exchange components: the master integrates the FMU's states in the kernel with the shared
solvers of fmus/solvers, its inputs the extrapolation polynomials at every stage time.

The same code and arithmetic as a Co-Simulation FMU of the project that interpolates its inputs
(one doStep per macro step, the input polynomials at its stage times), so msd run as Model Exchange
equals msd run as Co-Simulation with the same method and internal step, bit for bit, in every
backend; the methods keep their orders on FMUs with closed-form solutions.
"""

from __future__ import annotations

import dataclasses
import math
import zipfile
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from helpers import run_everywhere, ssd
from test_parallel import CAUSES, assert_no_children, lags

import master.api as api
from master.backends.component import SimulationError
from master.description import variables_of
from master.evidence.linear import AB3, EULER
from master.evidence.oscillator import scene
from master.evidence.stability import linearize
from master.fmu import read_description
from master.fmubuild import fmu_path
from master.runtime import native
from master.scenario import ScenarioError
from master.scenario.model import Component, Connection, ModelExchange, Scenario, Scheme
from master.scenario.writer import write_settings
from master.solvers import ITEMS, NUMBERS, RK4, SOLVERS

ROOT = Path(__file__).resolve().parent.parent
H = Fraction(1, 100)  # macro step, s
SUBSTEPS = 4  # internal steps per macro step


def oscillator(solver: str, model_exchange: bool) -> Scenario:
    """The two-mass oscillator: mass 1 (msd, inputs F) integrated by `solver` in SUBSTEPS internal
    steps per macro step, either as Model Exchange by the master or as Co-Simulation by the FMU
    with its inputs as polynomials; mass 2 with the coupling (msd, Co-Simulation)."""
    msd = fmu_path("msd")
    me = ModelExchange(solver, H / SUBSTEPS) if model_exchange else None
    mass1 = Component(
        "mass1",
        msd,
        parameters={"solver": NUMBERS[solver], "internal_step": float(H / SUBSTEPS), "x0": 1.0},
        extrapolation_order=2,
        interpolate_inputs=not model_exchange,
        model_exchange=me,
    )
    mass2 = Component("mass2", msd, parameters={"cc": 1.0, "dc": 1.0}, extrapolation_order=2)
    connections = (
        Connection("mass2", "F_c", "mass1", "F"),
        Connection("mass1", "x", "mass2", "x_in"),
        Connection("mass1", "v", "mass2", "v_in"),
    )
    path = Path("oscillator.ssd")
    return Scenario(path, "oscillator", (mass1, mass2), connections, Fraction(0), Fraction(2), H)


@pytest.mark.parametrize("solver", NUMBERS)
def test_model_exchange_equals_the_interpolating_co_simulation_fmu_in_every_backend(solver):
    """Same solver code, same input polynomials at the same stage times, same history across
    communication steps and start-up sweeps (saved with the FMU state): the same bits."""
    cs = run_everywhere(oscillator(solver, False))
    me = run_everywhere(oscillator(solver, True))
    assert np.max(np.abs(cs["mass1.x"])) > 0.5  # it moves
    for name in cs.dtype.names:
        assert np.array_equal(me[name], cs[name]), name


@pytest.mark.parametrize(
    "order", [("mass2", "mass1"), ("mass1", "mass2")], ids=["mass1-second", "mass1-first"]
)
def test_gauss_seidel_alike(order):
    """Gauss-Seidel, the Model Exchange component stepping after its source (interpolated inputs)
    or before it: the interpolating Co-Simulation FMU's bits."""
    cs = dataclasses.replace(oscillator("ab3", False), coupling=Scheme.GAUSS_SEIDEL, order=order)
    me = dataclasses.replace(oscillator("ab3", True), coupling=Scheme.GAUSS_SEIDEL, order=order)
    a, b = run_everywhere(cs), run_everywhere(me)
    for name in a.dtype.names:
        assert np.array_equal(b[name], a[name]), name


@pytest.mark.parametrize("solver", ["rk4", "semi_implicit_midpoint"])
def test_several_communication_steps_per_macro_step(solver):
    """mass1 at 4 communication steps per macro step of 2 internal steps each, its inputs held
    (order 0): as Model Exchange, the Co-Simulation FMU's bits (which holds its inputs over a step)."""

    def quarter(sc: Scenario) -> Scenario:
        c = sc.components[0]
        me = ModelExchange(solver, H / 8) if c.model_exchange else None
        parameters = {**c.parameters, "internal_step": float(H / 8)}
        c = dataclasses.replace(c, step_ratio=4, extrapolation_order=0, interpolate_inputs=False)
        c = dataclasses.replace(c, parameters=parameters, model_exchange=me)
        return dataclasses.replace(sc, components=(c, sc.components[1]))

    a, b = (
        run_everywhere(quarter(oscillator(solver, False))),
        run_everywhere(quarter(oscillator(solver, True))),
    )
    for name in a.dtype.names:
        assert np.array_equal(b[name], a[name]), name


def test_divergence_is_caught():
    """y' = 30 y by Euler at 0.1 s: the divergence check ends the run as for any component."""
    me = ModelExchange("euler")
    comp = Component("d", fmu_path("dahlquist"), parameters={"lambda": 30.0}, model_exchange=me)
    sc = Scenario(Path("d.ssd"), "d", (comp,), (), Fraction(0), Fraction(10), Fraction(1, 10))
    with pytest.raises(SimulationError, match="unstable: d.y at t=1.0"):
        api.run(sc, backend="in-process")


def test_the_plan_says_who_integrates():
    text = api.plan(oscillator("ab3", True)).describe()
    assert "mass1: k = 1" in text and "Model Exchange integrated by the master with ab3" in text


def test_the_method_matters():
    """The master's method is the one used: another gives other numbers (and the FMU's own solver
    parameter, AB3 here, is not what integrates it)."""
    sc = oscillator("ab3", True)
    euler = dataclasses.replace(sc.components[0], model_exchange=ModelExchange("euler", H / SUBSTEPS))
    a = api.run(sc, backend="in-process").data
    b = api.run(dataclasses.replace(sc, components=(euler, sc.components[1])), backend="in-process").data
    assert np.max(np.abs(a["mass1.x"] - b["mass1.x"])) > 1e-4


# expected orders (/work's numerics facts: Euler 1, AB2 2, AB3 3, RK4 4, semi-implicit Euler 1,
# semi-implicit midpoint 2), with the internal steps in their asymptotic range on these problems
ORDERS = {
    "euler": (1, 1 / 50),
    "ab2": (2, 1 / 50),
    "ab3": (3, 1 / 50),
    "rk4": (4, 1 / 10),
    "semi_implicit_euler": (1, 1 / 50),
    "semi_implicit_midpoint": (2, 1 / 50),
}


def single(name: str, solver: str, h: float, parameters: dict | None = None) -> Scenario:
    """Project FMU `name` alone as a Model Exchange component, one macro step of 1/10 s split into
    internal steps of h, up to t = 1 s."""
    me = ModelExchange(solver, Fraction(h).limit_denominator(10**6))
    comp = Component(name, fmu_path(name), parameters=parameters or {}, model_exchange=me)
    return Scenario(Path(f"{name}.ssd"), name, (comp,), (), Fraction(0), Fraction(1), Fraction(1, 10))


def observed_order(error) -> float:
    """log2 of the error ratio between internal steps h and h/2."""
    return math.log2(error(1) / error(2))


@pytest.mark.parametrize("solver", NUMBERS)
def test_orders_on_the_test_equation(solver):
    """dahlquist, y' = -y, y(1) = exp(-1): the error at t = 1 falls as h^p."""
    p, h = ORDERS[solver]

    def error(refine: int) -> float:
        d = api.run(single("dahlquist", solver, h / refine), backend="in-process").data
        return abs(float(d["dahlquist.y"][-1]) - math.exp(-1.0))

    assert abs(observed_order(error) - p) < 0.2


@pytest.mark.parametrize("solver", NUMBERS)
def test_orders_on_a_nonlinear_non_autonomous_system(solver):
    """nonlinear: r' = -a r^3, theta' = omega (1 + t) in Cartesian form (a full Jacobian, from the
    FMU's directional derivatives for the semi-implicit methods), closed-form solution."""
    p, h = ORDERS[solver]
    a, omega = 1.0, 1.0
    r = 1.0 / math.sqrt(1.0 + 2.0 * a)
    theta = omega * 1.5
    exact = (r * math.cos(theta), r * math.sin(theta))

    def error(refine: int) -> float:
        d = api.run(single("nonlinear", solver, h / refine), backend="in-process").data
        return math.hypot(float(d["nonlinear.x"][-1]) - exact[0], float(d["nonlinear.y"][-1]) - exact[1])

    assert abs(observed_order(error) - p) < 0.25


def described(source: Path, target: Path, change) -> Path:
    """A copy of a project FMU whose modelDescription.xml is change(its text)."""
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = change(data.decode()).encode()
            zout.writestr(item, data)
    return target


def without(source: Path, target: Path, interface: str, directional: bool = True) -> Path:
    """A copy of a project FMU whose description lacks the element `interface` ("CoSimulation":
    what a tool that exports Model Exchange alone gives) and, with directional=False, the
    directional derivatives."""

    def change(text: str) -> str:
        start, end = text.index(f"<{interface}"), text.index(f"</{interface}>") + len(interface) + 3
        text = text[:start] + text[end:]
        return text if directional else text.replace(' providesDirectionalDerivative="true"', "")

    return described(source, target, change)


def test_event_indicators_are_watched(tmp_path):
    """The kernel reads as many event indicators as the description declares (tests/test_me_events.py):
    a description that declares one its FMU does not have fails at fmi2GetEventIndicators, named."""

    def declare(text: str) -> str:
        return text.replace('numberOfEventIndicators="0"', 'numberOfEventIndicators="1"')

    indicated = described(fmu_path("dahlquist"), tmp_path / "d.fmu", declare)
    comp = Component("d", indicated, model_exchange=ModelExchange())
    sc = Scenario(tmp_path / "d.ssd", "d", (comp,), (), Fraction(0), Fraction(1), Fraction(1, 10))
    with pytest.raises(SimulationError, match=r"fmi2GetEventIndicators.*in the step from t=0\.0"):
        api.run(sc, backend="in-process")


def test_an_fmu_without_co_simulation_runs_as_model_exchange(tmp_path):
    """No setting needed: an FMU with only Model Exchange is integrated by the master (RK4, one step
    per communication step, by default), equal to the same FMU asked to run as Model Exchange."""
    only = without(fmu_path("dahlquist"), tmp_path / "dahlquist.fmu", "CoSimulation")
    comp = Component("d", only, step_ratio=10)
    sc = Scenario(tmp_path / "d.ssd", "d", (comp,), (), Fraction(0), Fraction(1), Fraction(1, 10))
    assert "Model Exchange integrated by the master with rk4 (one step" in api.plan(sc).describe()
    alone = run_everywhere(sc)
    asked = dataclasses.replace(comp, fmu_path=fmu_path("dahlquist"), model_exchange=ModelExchange())
    both = api.run(dataclasses.replace(sc, components=(asked,)), backend="in-process").data
    assert np.array_equal(alone["d.y"], both["d.y"])
    assert abs(float(alone["d.y"][-1]) - math.exp(-1.0)) < 1e-6  # RK4 at h = 0.01


def test_info_describes_an_fmu_without_co_simulation(tmp_path):
    only = without(fmu_path("msd"), tmp_path / "msd.fmu", "CoSimulation")
    assert "Model Exchange only: 2 continuous states, 0 event indicators" in api.fmu_info(only)


@pytest.mark.parametrize("solver", ["semi_implicit_euler", "semi_implicit_midpoint"])
def test_without_directional_derivatives_the_jacobian_comes_from_finite_differences(tmp_path, solver):
    """nonlinear without directional derivatives: its Jacobian by forward differences, the same
    method up to the differences' error (relative sqrt(eps) in the Jacobian, times h in a step)."""
    sc = single("nonlinear", solver, 1 / 100)
    plain = without(fmu_path("nonlinear"), tmp_path / "nonlinear.fmu", "CoSimulation", directional=False)
    comp = dataclasses.replace(sc.components[0], fmu_path=plain)
    fd = api.run(dataclasses.replace(sc, components=(comp,)), backend="in-process").data
    exact_jacobian = api.run(sc, backend="in-process").data
    assert not np.array_equal(fd["nonlinear.x"], exact_jacobian["nonlinear.x"])  # another Jacobian was used
    assert np.max(np.abs(fd["nonlinear.x"] - exact_jacobian["nonlinear.x"])) < 1e-8


def test_a_failing_derivative_evaluation_names_the_call_and_the_step():
    """crashtest fails its derivative evaluation from t = 0.5 s (mode 4): the run ends with the
    component, the FMI function and the step."""
    me = ModelExchange("rk4")
    comp = Component("lag", fmu_path("crashtest"), parameters={"mode": 4, "at_time": 0.5}, model_exchange=me)
    sc = Scenario(Path("lag.ssd"), "lag", (comp,), (), Fraction(0), Fraction(1), Fraction(1, 10))
    for backend in ("in-process", "serial"):
        with pytest.raises(SimulationError) as err:
            api.run(sc, backend=backend)
        assert "lag" in str(err.value) and "fmi2GetDerivatives" in str(err.value), str(err.value)
        assert "t=0.5" in str(err.value) or "t=0.4" in str(err.value), str(err.value)


def lag(h: Fraction, order: int, model_exchange: bool = True) -> Scenario:
    """crashtest, y' = -y + u, y(0) = 1, driven by dahlquist, u = exp(-t): y = (1 + t) exp(-t).
    The lag as Model Exchange (RK4, 8 internal steps per macro step h) with inputs extrapolated
    with `order`, or as Co-Simulation (its RK4, same steps), which holds its inputs over a step."""
    src = Component("src", fmu_path("dahlquist"), parameters={"internal_step": float(h / 8)})
    me = ModelExchange("rk4", h / 8) if model_exchange else None
    parameters = {} if model_exchange else {"solver": RK4, "internal_step": float(h / 8)}
    m = Component("lag", fmu_path("crashtest"), parameters, extrapolation_order=order, model_exchange=me)
    connections = (Connection("src", "y", "lag", "u"),)
    return Scenario(Path("lag.ssd"), "lag", (src, m), connections, Fraction(0), Fraction(1), h)


@pytest.mark.parametrize("order", [0, 1, 2])
def test_inputs_between_communication_points_are_the_polynomials(order):
    """Jacobi coupling with extrapolation of order k converges as H^(k+1) when the consumer sees
    the polynomial at its stage times; held over the step (a Co-Simulation FMU that does not
    interpolate) it stays first order whatever k."""

    def order_of(model_exchange: bool) -> float:
        runs = [api.run(lag(Fraction(1, r), order, model_exchange), backend="in-process") for r in (20, 40)]
        e = [abs(float(run.data["lag.y"][-1]) - 2 / math.e) for run in runs]
        return math.log2(e[0] / e[1])

    assert abs(order_of(True) - (order + 1)) < 0.15
    assert abs(order_of(False) - 1) < 0.15


SETTINGS = '<mm:Component name="lag" modelExchange="true" extrapolationOrder="2" {}/>'


def scene_with(tmp_path: Path, settings: str) -> Path:
    components = {"src": "project:dahlquist", "lag": "project:crashtest"}
    return ssd(tmp_path / "me.ssd", components, [("src", "y", "lag", "u")], settings)


def test_the_settings_annotation_asks_for_model_exchange(tmp_path):
    settings = SETTINGS.format('stepRatio="2" solver="ab3" internalStep="0.0125"')
    sc = api.load_scenario(scene_with(tmp_path, settings))
    assert sc.component("lag").model_exchange == ModelExchange("ab3", Fraction(1, 80))
    d = run_everywhere(sc)
    assert abs(float(d["lag.y"][-1]) - 2 / math.e) < 1e-3  # order-2 coupling at H = 0.1 s


@pytest.mark.parametrize(
    "attributes, problem",
    [
        ('solver="ab4"', 'solver "ab4" is not one of euler, ab2'),
        ('stepRatio="2" internalStep="0.03"', "internalStep 0.03 s does not divide the communication step"),
    ],
)
def test_bad_model_exchange_settings_are_one_line_each(tmp_path, attributes, problem):
    with pytest.raises(ScenarioError) as err:
        api.load_scenario(scene_with(tmp_path, SETTINGS.format(attributes)))
    assert len(err.value.problems) == 1
    assert problem in str(err.value) and "me.ssd" in str(err.value)


def test_a_solver_without_model_exchange_is_a_problem(tmp_path):
    path = scene_with(tmp_path, '<mm:Component name="lag" solver="ab3"/>')
    with pytest.raises(ScenarioError, match="solver and internalStep are for Model Exchange components"):
        api.load_scenario(path)


def test_a_scenario_built_in_python_is_checked_alike():
    comp = Component("m", fmu_path("dahlquist"), model_exchange=ModelExchange("ab9", Fraction(3, 100)))
    sc = Scenario(Path("m.ssd"), "m", (comp,), (), Fraction(0), Fraction(1), Fraction(1, 10))
    with pytest.raises(ScenarioError) as err:
        api.plan(sc)
    assert 'solver "ab9"' in str(err.value) and "internalStep 0.03 s" in str(err.value)


def test_a_model_exchange_setting_needs_the_interface(tmp_path):
    """An FMU whose description offers no Model Exchange cannot be run as one."""
    without(fmu_path("crashtest"), tmp_path / "crashtest.fmu", "ModelExchange")
    components = {"src": "project:dahlquist", "lag": "crashtest.fmu"}
    path = ssd(tmp_path / "me.ssd", components, [("src", "y", "lag", "u")], SETTINGS.format(""))
    with pytest.raises(ScenarioError, match="crashtest.fmu has no Model Exchange 2.0 or 3.0 interface"):
        api.load_scenario(path)


def test_written_settings_read_back(tmp_path):
    """A scenario written back (master tune's copies) keeps its Model Exchange settings."""
    original = api.load_scenario(scene_with(tmp_path, SETTINGS.format('solver="ab3"')))
    lag_ = dataclasses.replace(
        original.component("lag"), model_exchange=ModelExchange("rk4", Fraction(1, 400))
    )
    changed = dataclasses.replace(original, components=(original.component("src"), lag_))
    copy = write_settings(original, changed, tmp_path / "tuned.ssd", "tuned")
    assert api.load_scenario(copy).component("lag").model_exchange == ModelExchange("rk4", Fraction(1, 400))
    cs = dataclasses.replace(
        changed, components=(original.component("src"), dataclasses.replace(lag_, model_exchange=None))
    )
    again = api.load_scenario(write_settings(original, cs, tmp_path / "cs.ssd", "cs"))
    assert again.component("lag").model_exchange is None


def as_model_exchange(comp: Component) -> Component:
    """A project FMU's component as Model Exchange with the method and internal step its own
    parameters (or their start values) give its Co-Simulation interface."""
    v = variables_of(read_description(comp.fmu_path))
    solver = int(comp.parameters.get("solver", v["solver"].start))
    h = Fraction(float(comp.parameters.get("internal_step", v["internal_step"].start)))
    return dataclasses.replace(comp, model_exchange=ModelExchange(ITEMS[solver], h if h > 0 else None))


@pytest.mark.parametrize("scene, stop", [("hydraulic-manipulator", "0.3"), ("dc-motor-arm", "2")])
def test_the_papers_scenes_with_model_exchange_components(scene, stop):
    """The hydraulic manipulator (mechanics AB3 at the macro step, hydraulics Euler at a fifth of it)
    and the DC-motor arm (mechanics AB3, motors Euler at a quarter of it), every component
    run as Model Exchange by the master: the scenes' results, bit for bit, in every backend."""
    sc = api.load_scenario(ROOT / "models" / scene / "SystemStructure.ssd", stop_time=stop)
    me = dataclasses.replace(sc, components=tuple(as_model_exchange(c) for c in sc.components))
    assert api.plan(me).describe().count("Model Exchange integrated by the master") == 2
    cs, ours = run_everywhere(sc), run_everywhere(me)
    for name in cs.dtype.names:
        assert np.array_equal(ours[name], cs[name]), name


@pytest.mark.parametrize("solver", ["ab3", "semi_implicit_midpoint"])
def test_fmi3_model_exchange_equals_fmi2(solver):
    """msd built as FMI 3.0 (fmi3SetTime, fmi3SetContinuousStates,
    fmi3GetContinuousStateDerivatives, fmi3CompletedIntegratorStep, fmi3GetDirectionalDerivative)
    integrated by the master: the FMI 2.0 run's bits, in every backend."""
    sc = oscillator(solver, True)
    fmi3 = dataclasses.replace(sc.components[0], fmu_path=fmu_path("msd", fmi=3))
    assert read_description(fmi3.fmu_path).fmiVersion == "3.0"
    two, three = (
        run_everywhere(sc),
        run_everywhere(dataclasses.replace(sc, components=(fmi3, sc.components[1]))),
    )
    for name in two.dtype.names:
        assert np.array_equal(three[name], two[name]), name


def test_one_table_of_solver_names():
    """The methods by name (master.solvers, numbered as model.h's SolverKind, whose count the kernel
    library reports: native checks it) are the items of the project FMUs' Solver enumeration."""
    assert native.library() and native.CONSTANTS["SOLVER_COUNT"] == len(SOLVERS)
    for fmi in (2, 3):
        types = read_description(fmu_path("msd", fmi=fmi)).typeDefinitions
        solver = next(t for t in types if t.name == "Solver")
        assert [(item.name, int(item.value)) for item in solver.items] == list(NUMBERS.items())


@pytest.mark.parametrize("backend", ["serial", "parallel"])
@pytest.mark.parametrize("mode", [1, 2, 4, 5], ids=["segfault", "hang", "error", "fatal"])
def test_a_failing_model_exchange_component_is_isolated_as_a_co_simulation_one(mode, backend):
    """c1 of three crashtest lags, run as Model Exchange, misbehaves in its derivatives from
    t = 0.5 s: the run stops there naming it, the time and the cause, rows kept, no process left.
    (The FMU reports its fatal error in fmi2GetDerivatives as fmi2Error.)"""
    sc = lags(3, params={"c1": {"mode": mode, "at_time": 0.5}})
    me = dataclasses.replace(sc.components[1], model_exchange=ModelExchange("rk4"))
    sc = dataclasses.replace(sc, components=(sc.components[0], me, sc.components[2]))
    with pytest.raises(SimulationError) as info:
        api.run(sc, backend=backend, step_timeout=0.5)
    e = info.value
    cause = CAUSES[mode] if mode in (1, 2, 4) else "crashtest: fatal error requested at t = 0.5"
    assert e.component == "c1" and cause in str(e), str(e)
    assert mode in (1, 2) or "fmi2GetDerivatives failed" in str(e), str(
        e
    )  # a crash or hang: no call returned
    assert e.time == pytest.approx(0.5, abs=0.011) and len(e.result.data) >= 50
    assert_no_children()


def test_the_linear_stability_analysis_models_the_master_s_method():
    """linearize: mass1 as Model Exchange (AB3, 4 steps per macro step, inputs as polynomials) is
    the interpolating Co-Simulation FMU with the same method and steps, and the FMU's own solver
    parameter (Euler here) is not what the analysis takes."""
    cs = scene(order=2, solvers=(AB3, EULER), interpolate=(True, False), substeps=4)
    mass1 = dataclasses.replace(
        cs.components[0], model_exchange=ModelExchange("ab3", H / 4), interpolate_inputs=False
    )
    mass1 = dataclasses.replace(mass1, parameters={**mass1.parameters, "solver": EULER})
    me = dataclasses.replace(cs, components=(mass1, cs.components[1]))
    a, b = linearize(cs, t=0.5).components[0], linearize(me, t=0.5).components[0]
    assert (
        (b.solver, b.substeps, b.input_mode) == (a.solver, a.substeps, a.input_mode) == (AB3, 4, "polynomial")
    )
