"""Iterated macro steps (strong coupling): each macro step repeated from saved FMU states until the
coupled signals settle. The linear model of the scheme (master.evidence.linear) against runs of the
msd FMUs: the two-mass oscillator, parameter set B (m1 = 100 kg, cc = 100 N/m), force split, Jacobi,
order 2, inputs as polynomials, RK4 at a tenth of the macro step, is unstable beyond H = 0.69 s when
explicit and stable far beyond when iterated."""

import dataclasses
import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from master.api import run
from master.backends.component import SimulationError
from master.evidence import bench, linear
from master.evidence.oscillator import SET_A, SET_A_Z0, scene, split_scheme
from master.evidence.stability import run_is_stable
from master.scenario.check import check
from master.scenario.model import Component, Connection, Iteration, Scheme

ROOT = Path(__file__).resolve().parents[1]
SET_B = dataclasses.replace(SET_A, m1=100.0, cc=100.0)
SUBSTEPS = 10  # RK4 steps inside each macro step: the solvers are not what limits the macro step
ITERATION = Iteration(tolerance=1e-12, max_iterations=50)


def set_b(h: Fraction, stop: Fraction = Fraction(60), iteration: Iteration | None = ITERATION, **kw):
    """Set B as the runtime runs it (scene) at macro step h (s), iterated or explicit."""
    sc = scene(SET_B, split="force", macro_step=h, stop_time=stop, order=2, interpolate=(True, True),
               substeps=SUBSTEPS, **kw)  # fmt: skip
    return dataclasses.replace(sc, iteration=iteration)


def set_b_model(iterate: int | str = "converged", first: tuple[str, ...] = ()) -> linear.LinearScheme:
    """The same scheme as a linear model."""
    lin = split_scheme(SET_B, order=2, inputs="polynomial", split="force", substeps=(SUBSTEPS, SUBSTEPS))
    return dataclasses.replace(lin, iterate=iterate, first=first)


def test_the_linear_model_predicts_what_iteration_buys_on_set_b():
    explicit = linear.largest_stable_step(set_b_model(0), 0.05, 5.0)
    iterated = linear.largest_stable_step(set_b_model(), 0.05, 5.0)
    assert explicit == pytest.approx(0.6914, rel=2e-3)
    assert iterated > 4 * explicit  # the internal RK4 steps, not the coupling, limit it
    # the sweeps contract well there: a handful of them settle a macro step
    assert linear.sweep_radius(set_b_model(), 2.0) < 0.5
    assert linear.sweeps_needed(set_b_model(), 2.0, 1e-12) < ITERATION.max_iterations


@pytest.mark.parametrize("h", [Fraction(3, 4), Fraction(1), Fraction(2)])
def test_runs_confirm_the_prediction_beyond_the_explicit_limit(h):
    """Above 0.6914 s the explicit scheme diverges, as the model says; the iterated one stays
    bounded, as the model says, and settles every macro step within its sweeps."""
    assert not linear.is_stable(set_b_model(0), float(h))
    assert not run_is_stable(lambda: run(set_b(h, iteration=None), backend="in-process"))
    assert linear.is_stable(set_b_model(), float(h))
    result = run(set_b(h), backend="in-process")
    assert run_is_stable(lambda: result)
    it = result.summary.iterations
    assert it["macro_steps"] == len(result.data) - 1 and it["max"] < ITERATION.max_iterations


def test_beyond_the_iterated_limit_the_model_and_the_runs_agree_again():
    h = Fraction(16, 5)  # 3.2 s: the internal RK4 step H/10 is past its own limit on mass2
    assert not linear.is_stable(set_b_model(), float(h))
    assert not run_is_stable(lambda: run(set_b(h, stop=Fraction(320)), backend="in-process"))


@pytest.mark.parametrize("coupling", [Scheme.JACOBI, Scheme.GAUSS_SEIDEL])
def test_the_linear_model_reproduces_iterated_runs(coupling):
    """Runtime and model iterate to the same settled macro steps (tolerance 1e-12): Jacobi, and
    Gauss-Seidel whose sweeps give mass2 mass1's samples of the same sweep."""
    h = Fraction(1)
    sc = set_b(h, stop=Fraction(30))
    first = ()
    if coupling == Scheme.GAUSS_SEIDEL:
        first = ("mass1", "mass2")
        sc = dataclasses.replace(sc, coupling=coupling, order=first)
    data = run(sc, backend="in-process").data
    x0 = {"mass1": SET_A_Z0[:2], "mass2": SET_A_Z0[2:]}
    z = linear.simulate(set_b_model(first=first), x0, float(h), 30, tolerance=ITERATION.tolerance)
    for i, name in enumerate(("mass1.x", "mass1.v", "mass2.x", "mass2.v")):
        assert np.max(np.abs(data[name] - z[:, i])) < 1e-9


@pytest.mark.parametrize(
    "first, ratios, solvers",
    [((), (2, 5), (4, 2)), (("mass1", "mass2"), (1, 4), (4, 4)), (("mass2", "mass1"), (3, 1), (3, 1))],
)
def test_the_linear_model_reproduces_iterated_multirate_runs(first, ratios, solvers):
    """Set A at step ratios, held inputs, Jacobi and Gauss-Seidel in either order: runtime and
    model agree to round-off, sweep for sweep."""
    h = Fraction(1, 5)
    sc = scene(SET_A, split="force", macro_step=h, stop_time=Fraction(10), order=2, step_ratios=ratios,
               solvers=solvers)  # fmt: skip
    sc = dataclasses.replace(sc, iteration=ITERATION)
    if first:
        sc = dataclasses.replace(sc, coupling=Scheme.GAUSS_SEIDEL, order=first)
    data = run(sc, backend="in-process").data
    lin = split_scheme(SET_A, order=2, split="force", step_ratios=ratios, solvers=solvers)
    lin = dataclasses.replace(lin, iterate="converged", first=first)
    z = linear.simulate(lin, {"mass1": SET_A_Z0[:2], "mass2": SET_A_Z0[2:]}, float(h), 50, tolerance=1e-12)
    for i, name in enumerate(("mass1.x", "mass1.v", "mass2.x", "mass2.v")):
        assert np.max(np.abs(data[name] - z[:, i])) < 1e-12


def test_gauss_seidel_sweeps_settle_sooner_than_jacobi():
    h = Fraction(1)
    jacobi = run(set_b(h, stop=Fraction(20)), backend="in-process").summary.iterations
    gs = set_b(h, stop=Fraction(20), coupling="gauss-seidel")
    seidel = run(dataclasses.replace(gs, order=("mass1", "mass2")), backend="in-process").summary.iterations
    assert seidel["sweeps"] < jacobi["sweeps"]
    assert linear.sweep_radius(set_b_model(first=("mass1", "mass2")), 1.0) < linear.sweep_radius(
        set_b_model(), 1.0
    )


def _chain(coupling: Scheme):
    """mass1 drives mass2, mass2 drives mass3 (positions and velocities), nothing drives mass1: no loop."""
    sc = scene(
        SET_A,
        split="displacement",
        macro_step=Fraction(1, 10),
        stop_time=Fraction(2),
        order=2,
        interpolate=(True, True),
    )  # inputs as polynomials over the step: the sweeps change them
    mass3 = dataclasses.replace(sc.components[1], name="mass3")
    conns = tuple(c for c in sc.connections if c.start_component == "mass1")
    conns += tuple(dataclasses.replace(c, start_component="mass2", end_component="mass3") for c in conns)
    return dataclasses.replace(sc, components=(*sc.components, mass3), connections=conns, coupling=coupling,
                               order=("mass1", "mass2", "mass3"), record=(),
                               iteration=Iteration(tolerance=1e-14, max_iterations=5))  # fmt: skip


@pytest.mark.parametrize("coupling, sweeps", [(Scheme.JACOBI, 2), (Scheme.GAUSS_SEIDEL, 1)])
def test_a_chain_without_loop_settles_at_once(coupling, sweeps):
    """Jacobi: the first sweep gives mass2 mass1's samples of the macro step (mass1's own do not
    change), so mass2's change; the second gives mass3 those, and mass2's stay: settled. Gauss-Seidel
    passes them on within the first pass already, so one sweep confirms them. (Only coupled signals
    count: mass3's, which nothing reads, need not settle.)"""
    result = run(_chain(coupling), backend="in-process")
    n = len(result.data) - 1
    assert result.summary.iterations == {"sweeps": sweeps * n, "max": sweeps, "macro_steps": n}
    assert "iterated coupling:" in str(result.summary)


@pytest.mark.parametrize(
    "sc",
    [set_b(Fraction(1), stop=Fraction(10)), set_b(Fraction(1), stop=Fraction(10), coupling="gauss-seidel"),
     _chain(Scheme.JACOBI)],
    ids=["jacobi", "gauss-seidel", "chain"],
)  # fmt: skip
def test_iterated_results_are_identical_in_every_backend(sc):
    results = {be: run(sc, backend=be) for be in ("in-process", "serial", "parallel")}
    reference = results["in-process"]
    assert reference.summary.iterations["sweeps"] > 0
    for be, r in results.items():
        assert r.summary.iterations == reference.summary.iterations, be
        for name in reference.data.dtype.names:
            assert np.array_equal(r.data[name], reference.data[name]), (be, name)


@pytest.mark.parametrize("backend", ["in-process", "parallel"])
def test_sweeps_that_do_not_settle_end_the_run_with_one_line_rows_kept(backend):
    sc = set_b(Fraction(1), stop=Fraction(10), iteration=Iteration(tolerance=1e-12, max_iterations=2))
    with pytest.raises(SimulationError) as err:
        run(sc, backend=backend)
    message = str(err.value)
    assert (
        "iterated coupling did not converge in the macro step from t=0.0 to t=1.0: after 2 sweeps" in message
    )
    assert "mass" in message and "\n" not in message
    assert len(err.value.result.data) == 1  # the row at the start time, before the failing step


def test_validate_names_an_fmu_that_cannot_save_its_state(tmp_path):
    from master.fmubuild import fmu_path

    sc = _chain(Scheme.JACOBI)
    old = sc.components[1]
    fmi1 = Component(old.name, fmu_path("msd", fmi=1), {}, old.step_ratio, old.extrapolation_order)
    sc = dataclasses.replace(sc, components=(sc.components[0], fmi1, sc.components[2]))
    problems = [str(p) for p in check(sc)]
    assert len(problems) == 1 and "component mass2" in problems[0]
    assert "cannot save its state (canGetAndSetFMUstate false)" in problems[0]
    assert not check(dataclasses.replace(sc, iteration=None))


def test_the_command_line_runs_a_scene_file_with_mm_iteration(tmp_path):
    text = (ROOT / "models" / "oscillator" / "SystemStructure.ssd").read_text()
    text = text.replace(
        "</mm:Record>", '</mm:Record>\n          <mm:Iteration tolerance="1e-10" maxIterations="10"/>'
    )
    for f in ("mass1.ssv", "mass2.ssv"):
        (tmp_path / f).write_text((ROOT / "models" / "oscillator" / f).read_text())
    ssd = tmp_path / "SystemStructure.ssd"
    ssd.write_text(text)
    out = subprocess.run(
        [sys.executable, "-m", "master", "run", str(ssd), "--stop-time", "1", "-o", str(tmp_path / "r.csv")],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    line = next(s for s in (out.stdout + out.stderr).splitlines() if "iterated coupling:" in s)
    assert "in 100 macro steps" in line
    info = subprocess.run([sys.executable, "-m", "master", "info", str(ssd)], capture_output=True, text=True)
    assert "iterated: every macro step repeated" in info.stdout


def test_fixed_sweeps_approach_the_fixed_point_of_the_model():
    """A fixed number of sweeps is a linear map too; as they grow it tends to the converged one,
    by about the sweep's contraction (rho(M) = 0.063 at H = 1 s) per sweep."""
    h = 1.0
    rho = linear.sweep_radius(set_b_model(), h)
    converged = linear.step_matrix(set_b_model(), h)
    gaps = [np.max(np.abs(linear.step_matrix(set_b_model(k), h) - converged)) for k in (2, 4, 6, 8)]
    assert rho < 0.1 and gaps == sorted(gaps, reverse=True)
    assert gaps[-1] < (2 * rho) ** 6 * gaps[0]


@pytest.mark.parametrize("first", [(), ("mass1", "mass2")])
def test_a_connection_without_feedback_is_iterated_exactly(first):
    """The one-way chain as a model: the converged macro step equals two Jacobi sweeps (one under
    Gauss-Seidel) exactly, as the runtime counts them."""
    lin = split_scheme(SET_A, order=2, inputs="polynomial", split="displacement")
    lin = dataclasses.replace(lin, connections=lin.connections[:2], first=first)
    converged = linear.step_matrix(dataclasses.replace(lin, iterate="converged"), 0.1)
    swept = linear.step_matrix(dataclasses.replace(lin, iterate=1 if first else 2), 0.1)
    assert np.allclose(converged, swept, rtol=0, atol=1e-13)
    assert linear.sweep_radius(dataclasses.replace(lin, iterate="converged"), 0.1) < 1e-12


def test_tune_tries_iterated_coupling_and_counts_its_sweeps():
    """A scene without a bench profile: `master tune` tries iterated Gauss-Seidel families beside the
    explicit ones, runs them, and its cost model charges each macro step 1 + the sweeps it took."""
    from master.tune import MACRO, CostModel, report, tune, work

    sc = dataclasses.replace(set_b(Fraction(1, 20), stop=Fraction(20), iteration=None),
                             record=(("mass1", "x"), ("mass2", "x")))  # fmt: skip
    result = tune(sc, 1e-2, pilot_time=Fraction(5), repeats=1)  # a quarter of the 20 s: quicker
    iterated = [ch for ch in result.choices if ch.trial.config.iterated]
    assert iterated and all(ch.trial.sweeps >= 1 for ch in iterated)
    scene = bench.apply(sc, result.profile, iterated[0].trial.config)
    once = CostModel.cost(scene, result.costs)  # each macro step stepped once
    master = work(scene)[MACRO] * result.costs[MACRO]  # the master's part, once per macro step
    expected = master + (1 + iterated[0].trial.sweeps) * (once - master)
    assert once - master > 0 and iterated[0].cost == pytest.approx(expected, rel=1e-12)
    assert "gauss-seidel, iterated" in report(result)


def test_the_tune_variants_of_a_family_flip_iterated_coupling():
    from master.tune import variants

    p = bench.PROFILES["oscillator"]
    assert any(v.iterated for _, v in variants(p.base, p))
    assert bench.linear_scheme(split_scheme(SET_A), p, dataclasses.replace(p.base, iterated=True)).iterate


def test_the_writer_carries_iterated_coupling_into_the_scene_file(tmp_path):
    from master.api import load_scenario
    from master.scenario.writer import write_settings

    folder = ROOT / "models" / "oscillator"
    for f in folder.iterdir():
        (tmp_path / f.name).write_bytes(f.read_bytes())
    sc = load_scenario(tmp_path / "SystemStructure.ssd")
    on = write_settings(sc, dataclasses.replace(sc, iteration=Iteration(1e-9, 7)), tmp_path / "on.ssd", "on")
    assert load_scenario(on).iteration == Iteration(1e-9, 7)
    off = write_settings(load_scenario(on), sc, tmp_path / "off.ssd", "off")
    assert load_scenario(off).iteration is None


def test_iterating_a_chain_under_jacobi_gives_the_gauss_seidel_run_exactly():
    """Without feedback the iterated windows (every source's samples of the macro step,
    interpolated) are those of Gauss-Seidel in the chain's order: the same numbers, bit for bit."""
    jacobi = run(_chain(Scheme.JACOBI), backend="in-process").data
    seidel = run(dataclasses.replace(_chain(Scheme.GAUSS_SEIDEL), iteration=None), backend="in-process").data
    for name in jacobi.dtype.names:
        assert np.array_equal(jacobi[name], seidel[name]), name


@pytest.mark.parametrize("backend", ["in-process", "parallel"])
def test_string_connections_settle_too(backend):
    """A chain of text FMUs at step ratios 1, 3, 2 (Strings held): the sweeps settle once the held
    Strings stop changing, and the iterated Jacobi run is the Gauss-Seidel one."""
    from test_string_connections import A, scenario, text

    comps = (Component("a", text(), dict(A), 1), Component("b", text(), {"suffix": "é"}, 3),
             Component("c", text(), {}, 2))  # fmt: skip
    conns = (Connection("a", "y_string", "b", "u_string"), Connection("b", "y_string", "c", "u_string"))
    record = [(c, v) for c in "bc" for v in ("y_length", "y_code", "y_string")]
    iterated = dataclasses.replace(scenario(comps, conns, "jacobi", record=record), iteration=ITERATION)
    result = run(iterated, backend=backend)
    seidel = run(scenario(comps, conns, "gauss-seidel", record=record), backend=backend).data
    assert result.summary.iterations["max"] == 2  # c gets b's settled Strings in the second sweep
    for name in seidel.dtype.names:
        assert np.array_equal(result.data[name], seidel[name]), name


def test_master_validate_names_at_mm_iteration_an_fmu_that_cannot_save_its_state(tmp_path):
    """A scene file whose mass2 is an FMI 1.0 FMU (no FMU state) and that asks for iteration."""
    from master.api import validate
    from master.fmubuild import fmu_path

    folder = ROOT / "models" / "oscillator"
    for f in ("mass1.ssv", "mass2.ssv"):
        (tmp_path / f).write_bytes((folder / f).read_bytes())
    shutil.copy(fmu_path("msd", fmi=1), tmp_path / "msd1.fmu")
    text = (folder / "SystemStructure.ssd").read_text()
    text = text.replace('<ssd:Component name="mass2" source="project:msd">',
                        '<ssd:Component name="mass2" source="msd1.fmu">')  # fmt: skip
    rk4 = '<ssv:Enumeration value="rk4"/>'  # FMI 1.0 has no enumerations: mass2's solver is an Integer
    head, tail = text.rsplit(rk4, 1)
    text = head + '<ssv:Integer value="4"/>' + tail
    (tmp_path / "plain.ssd").write_text(text)
    iterated = text.replace("</mm:Record>", '</mm:Record>\n          <mm:Iteration tolerance="1e-10"/>')
    (tmp_path / "iterated.ssd").write_text(iterated)
    assert not validate(tmp_path / "plain.ssd")
    problems = [str(p) for p in validate(tmp_path / "iterated.ssd")]
    assert len(problems) == 1
    assert (
        "iterated.ssd:" in problems[0] and "mm:Iteration" in problems[0] and "component mass2" in problems[0]
    )
    assert "msd1.fmu cannot save its state (canGetAndSetFMUstate false)" in problems[0]


def test_a_plan_built_past_the_checks_still_never_steps_an_fmu_without_state():
    """build_plan keeps no rule of its own; the kernel's tables refuse the FMU before any call."""
    from master.backends.in_process import InProcessBackend
    from master.description import variables_of
    from master.fmu import FmuError, read_description
    from master.fmubuild import fmu_path
    from master.schedule import build_plan

    sc = _chain(Scheme.JACOBI)
    old = sc.components[1]
    fmi1 = Component(old.name, fmu_path("msd", fmi=1), {}, old.step_ratio, old.extrapolation_order)
    sc = dataclasses.replace(sc, components=(sc.components[0], fmi1, sc.components[2]))
    backend = InProcessBackend(
        build_plan(sc, {c.name: variables_of(read_description(c.fmu_path)) for c in sc.components})
    )
    try:
        with pytest.raises(
            FmuError, match="mass2: msd.fmu cannot save its state: iterated macro steps need it"
        ):
            backend.open()
    finally:
        backend.close()
