"""`master tune`: the configuration it writes is stable and meets the tolerance, checked
independently of the search (the oscillator against its exact solution, the paper's scenes
against the Model Exchange reference), and the scenario writer changes only the settings."""

from __future__ import annotations

import dataclasses
import os
import shutil
import subprocess
import sys
import zipfile
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import master.api as api
from master.evidence import bench
from master.evidence.errors import as_trajectory, compare
from master.evidence.linear import is_stable
from master.evidence.oscillator import SET_A, SET_A_Z0
from master.evidence.reference import reference
from master.evidence.stability import linearize
from master.scenario.writer import write_settings
from master.solvers import AB2, AB3, EULER, ITEMS, RK4, SI_EULER, SI_MIDPOINT
from master.tune import MACRO, CostModel, check_grid, families, ladder, pilot_for, tune, tuned_scenario

REPO = Path(__file__).resolve().parents[1]
OSCILLATOR = REPO / "tests" / "scenarios" / "oscillator"
BIN = Path(sys.executable).parent


def _copy(tmp_path: Path, folder: Path) -> Path:
    shutil.copytree(folder, tmp_path / folder.name)
    return tmp_path / folder.name


def test_ladder_steps_are_round_and_divide_the_record_interval():
    steps = ladder(Fraction(1, 100))
    assert steps == sorted(steps) and Fraction(1, 100) in steps and Fraction(1, 400) in steps
    assert all((Fraction(1, 100) / h).denominator == 1 for h in steps)
    assert Fraction(3, 1000) not in steps  # does not divide 0.01


def test_tune_on_the_oscillator_meets_the_tolerance_against_the_exact_solution(tmp_path):
    """Parameter set A: the written scenario, run over its own stop time, stays within the
    tolerance of the matrix-exponential solution on both masses' positions and velocities (each
    relative to its range), and the linear analysis finds it stable; the original is untouched."""
    folder = _copy(tmp_path, OSCILLATOR)
    original = (folder / "oscillator.ssd").read_bytes()
    out = folder / "oscillator.tuned.ssd"
    proc = subprocess.run([str(BIN / "master"), "tune", str(folder / "oscillator.ssd"), "--tolerance", "1e-3",
                           "--repeats", "1", "--rounds", "2"],
                          capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert (folder / "oscillator.ssd").read_bytes() == original
    report = folder / "oscillator.tuned.txt"
    assert report.read_text().startswith("master tune: two-mass oscillator")
    # the console says the choice, its error and speed, and where the report is; the rest is in it
    lines = proc.stdout.splitlines()
    assert len(lines) <= 6 and any(line.startswith("chosen:") for line in lines)
    assert f"report: {report}" in lines and "largest step that meets it" not in proc.stdout
    assert "families within the tolerance" in report.read_text()
    umask = os.umask(0)
    os.umask(umask)
    assert (out.stat().st_mode & 0o777) == (report.stat().st_mode & 0o777) == 0o666 & ~umask

    tuned = api.load_scenario(out)
    res = api.run(tuned, backend="serial", record=["mass1.x", "mass1.v"])
    d = res.data
    exact = SET_A.exact(d["time"], SET_A_Z0)
    for col, i in (("mass1.x", 0), ("mass1.v", 1)):
        scale = float(np.ptp(exact[:, i]))
        assert np.max(np.abs(d[col] - exact[:, i])) / scale <= 1e-3, col
    _assert_linearly_stable(tuned)


def _assert_linearly_stable(sc) -> None:
    """The scene as written (its plan: ratios, orders, input modes, solvers and their steps),
    linearised where its bench profile says, adds no growth at its macro step."""
    lin = linearize(sc, t=bench.profile_for(sc).linearize_at)
    assert is_stable(lin, float(sc.macro_step))


@pytest.mark.parametrize(
    ("scene", "tolerance", "pilot"),
    [("hydraulic-manipulator", 3e-3, Fraction(1, 2)), ("dc-motor-arm", 1e-2, Fraction(1))],
)
def test_tune_on_the_paper_scenes_meets_the_tolerance(tmp_path, scene, tolerance, pilot):
    """The tuned scenario, written and read back, run over the pilot horizon (0.5 s, 1 s here, one
    round of coordinate search: quicker), is within the tolerance of the Model Exchange reference on
    the paper's variables at every point of the tune's check grid, and linearly stable."""
    folder = _copy(tmp_path, REPO / "models" / scene)
    sc = api.load_scenario(folder / "SystemStructure.ssd")
    result = tune(sc, tolerance, pilot_time=pilot, repeats=1, rounds=1)
    assert result.best is not None and result.best.trial.error <= tolerance
    out = write_settings(sc, tuned_scenario(result), folder / "tuned.ssd", "test")
    tuned = api.load_scenario(out)
    p = bench.profile_for(sc)
    assert tuned.stop_time == sc.stop_time
    grid = Fraction(result.grid).limit_denominator(10**9)
    assert grid <= min(sc.macro_step / c.step_ratio for c in sc.components)
    stop = sc.start_time + pilot
    rows = bench.lcm(tuned.macro_step, grid)
    res = api.run(dataclasses.replace(tuned, stop_time=stop, record_interval=rows), backend="serial")
    record = tuple(tuple(v.split(".", 1)) for v in p.variables)
    fine = dataclasses.replace(sc, macro_step=grid, record_interval=grid, stop_time=stop, record=record)
    rep = compare(as_trajectory(res.data), reference(fine), list(p.variables))
    assert rep.worst_max <= tolerance and rep.n_times == len(res.data)
    _assert_linearly_stable(tuned)
    assert result.stable_limit is not None and result.stable_limit >= float(tuned.macro_step)


def test_the_writer_changes_only_the_settings_and_reads_back(tmp_path):
    """Macro step, coupling, ratios, orders and a solver written into a copy are what the copy
    loads as; comments and everything else stay; a copy in another folder still finds its files."""
    folder = _copy(tmp_path, OSCILLATOR)
    sc = api.load_scenario(folder / "oscillator.ssd")
    mass2 = sc.component("mass2")
    changed = dataclasses.replace(
        sc,
        macro_step=Fraction(1, 50),
        coupling="jacobi",
        order=(),
        components=(
            dataclasses.replace(sc.component("mass1"), extrapolation_order=3),
            dataclasses.replace(
                mass2,
                step_ratio=4,
                extrapolation_order=1,
                interpolate_inputs=False,
                parameters={**mass2.parameters, "solver": SI_MIDPOINT},
            ),  # fmt: skip
        ),
        connections=tuple(dataclasses.replace(c, extrapolation_order=None) for c in sc.connections),
    )
    for dest in (folder / "copy.ssd", tmp_path / "elsewhere" / "copy.ssd"):
        write_settings(sc, changed, dest, "a test")
        back = api.load_scenario(dest)
        assert back.macro_step == Fraction(1, 50) and back.coupling == "jacobi"
        assert back.component("mass1").extrapolation_order == 3
        m2 = back.component("mass2")
        assert (m2.step_ratio, m2.extrapolation_order, m2.interpolate_inputs) == (4, 1, False)
        assert m2.parameters["solver"] == 6 and m2.parameters["cc"] == mass2.parameters["cc"]
        assert all(c.extrapolation_order is None for c in back.connections)
        assert back.record == sc.record and back.record_interval == sc.record_interval
        text = dest.read_text()
        assert "Two-mass oscillator, parameter set A" in text and "<!-- a test -->" in text
        assert '<ssv:Enumeration value="semi_implicit_midpoint"/>' in text
    with pytest.raises(ValueError, match="overwrite"):
        write_settings(sc, changed, folder / "oscillator.ssd", "x")


def test_the_writer_keeps_an_archive_an_archive(tmp_path):
    folder = _copy(tmp_path, OSCILLATOR)
    ssp = tmp_path / "osc.ssp"
    with zipfile.ZipFile(ssp, "w") as zf:
        zf.write(folder / "oscillator.ssd", "SystemStructure.ssd")
        for f in folder.glob("*.ssv"):
            zf.write(f, f.name)
    sc = api.load_scenario(ssp)
    out = write_settings(
        sc, dataclasses.replace(sc, macro_step=Fraction(1, 200)), tmp_path / "osc.tuned.ssp", "t"
    )
    with zipfile.ZipFile(out) as zf:
        assert sorted(zf.namelist()) == sorted(zipfile.ZipFile(ssp).namelist())
    assert api.load_scenario(out).macro_step == Fraction(1, 200)


def test_a_real_time_budget_nothing_meets_writes_the_report_and_no_scenario(tmp_path):
    folder = _copy(tmp_path, OSCILLATOR)
    proc = subprocess.run([str(BIN / "master"), "tune", str(folder / "oscillator.ssd"), "--tolerance", "1e-3",
                           "--real-time-budget", "1e-9", "--rounds", "0", "--repeats", "1"],
                          capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines()[-1].startswith("error: the fastest configuration within 0.001")
    assert "real-time budget 1e-09 s per simulated s: OVER" in (folder / "oscillator.tuned.txt").read_text()
    assert not (folder / "oscillator.tuned.ssd").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--tolerance", "0"], "--tolerance"),
        (["--tolerance", "1e-3", "-o", "{src}"], "not the original"),
        (["--tolerance", "1e-3", "-o", "x.csv"], "not the original"),
        (["--tolerance", "1e-3", "-o", "x.csv"], "--out x.csv: a new .ssd file"),  # the folder's scenario
    ],
)
def test_tune_refuses_bad_options_in_one_line(tmp_path, args, message):
    folder = _copy(tmp_path, OSCILLATOR)
    src = str(folder / "oscillator.ssd")
    given = str(folder) if message.endswith(".ssd file") else src
    proc = subprocess.run([str(BIN / "master"), "tune", given, *(a.format(src=src) for a in args)],
                          capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
    assert proc.returncode in (1, 2) and message in proc.stderr and "Traceback" not in proc.stderr


def _oscillator_pilot(tolerance: float, pilot_time: Fraction | None = None):
    return pilot_for(api.load_scenario(OSCILLATOR / "oscillator.ssd"), tolerance, pilot_time)


def test_the_cost_models_ranking_is_the_same_whatever_the_timings_noise():
    """The oscillator's first families at a few steps, run by the pilot: ranked by the model with
    its calibration, and with one from the same runs under load (every time 3x, and a spike of 10x
    on the slower half of each kind's runs) the order is the same; the cost is the counted work,
    so halving the macro step doubles it."""
    pilot, _ = _oscillator_pilot(1.0, Fraction(2))
    configs = [dataclasses.replace(c, macro_step=h) for _, c in families(pilot.p)[:6]
               for h in (Fraction(1, 100), Fraction(1, 20))]  # fmt: skip
    for c in configs:
        pilot(c)
    clean = pilot.model.calibrate()
    loaded = CostModel()
    for kind, times in pilot.model.samples.items():
        median = sorted(times)[(len(times) - 1) // 2]
        loaded.samples[kind] = [3 * t * (10 if t > median else 1) for t in times]
    noisy = loaded.calibrate()
    assert noisy != clean

    def ranking(times):
        return sorted(range(len(configs)), key=lambda i: (CostModel.cost(pilot.scene(configs[i]), times), i))

    assert ranking(clean) == ranking(noisy)
    fine = CostModel.cost(pilot.scene(configs[0]), clean)
    coarse = CostModel.cost(pilot.scene(configs[1]), clean)
    assert fine == pytest.approx(5 * coarse)  # 0.01 s against 0.05 s: five times the work


def test_the_error_is_checked_over_the_whole_stop_time_on_the_finest_grid():
    """The pilot compares over the scene's whole stop time (10 s) on a grid no coarser than the
    smallest component step (mass2's 2.5 ms); a configuration within a tolerance on the bench's
    0.1 s grid over its first second, but not on the fine grid over 10 s, is rejected."""
    sc = api.load_scenario(OSCILLATOR / "oscillator.ssd")
    smallest = min(sc.macro_step / c.step_ratio for c in sc.components)
    pilot, steps = _oscillator_pilot(1.0)
    assert pilot.stop == sc.stop_time and pilot.grid <= smallest
    assert all((h / pilot.grid).denominator == 1 for h in steps if h >= smallest)  # each checked every step
    c = dataclasses.replace(pilot.p.base, macro_step=Fraction(1, 10))
    fine = pilot(c).error
    p = bench.profile_for(sc)
    short = dataclasses.replace(pilot.scene(c), stop_time=Fraction(1), record_interval=Fraction(1, 10))
    coarse_ref = reference(dataclasses.replace(bench.base_scene(sc, p), stop_time=Fraction(1)))
    coarse = compare(as_trajectory(api.run(short, backend="in-process").data), coarse_ref).worst_max
    assert coarse < fine  # the premise: the coarse check misses part of the error
    strict, _ = _oscillator_pilot((coarse + fine) / 2)
    assert not strict(c).ok


def test_the_check_grid_of_the_hydraulic_scene_is_every_candidate_step():
    """Smallest component step 0.2 ms (hydraulics at 1 ms / 5); candidate steps 0.25 ms, 0.4 ms,
    1.25 ms, ...: compared every 0.05 ms, where each of them has its macro steps."""
    sc = api.load_scenario(REPO / "models" / "hydraulic-manipulator" / "SystemStructure.ssd")
    steps = [h for h in ladder(Fraction(1, 100)) if h >= Fraction(1, 100000)]
    assert check_grid(sc, steps, Fraction(3)) == Fraction(5, 100000)


def _as_model_exchange(folder: Path) -> Path:
    """The oscillator's copy with both masses run as Model Exchange components by the master
    (mass1 AB3 at the macro step, mass2 Euler at its communication step)."""
    ssd = folder / "oscillator.ssd"
    text = ssd.read_text()
    text = text.replace(
        '<mm:Component name="mass1" stepRatio="1"',
        '<mm:Component name="mass1" modelExchange="true" solver="ab3" stepRatio="1"',
    )
    text = text.replace('<mm:Component name="mass2" communicationStep="0.0025" interpolateInputs="true"/>',
                        '<mm:Component name="mass2" modelExchange="true" solver="euler" '
                        'communicationStep="0.0025"/>')  # fmt: skip
    ssd.write_text(text)
    return ssd


def test_tune_varies_the_solvers_of_model_exchange_components(tmp_path):
    """Both masses as Model Exchange: the tune tries every one of the six methods on them (the
    FMUs' solver parameter is not theirs) and their internal steps, ranks them by their calls;
    the written scenario runs them as Model Exchange with the chosen methods and steps, within the
    tolerance of the exact solution, linearly stable."""
    folder = _copy(tmp_path, OSCILLATOR)
    sc = api.load_scenario(_as_model_exchange(folder))
    assert all(c.model_exchange is not None for c in sc.components)
    tolerance = 1e-3
    result = tune(sc, tolerance, pilot_time=Fraction(2), repeats=1, rounds=1)
    assert result.best is not None and result.best.trial.error <= tolerance
    tried = {(c.mech_solver, c.ctrl_solver, c.mech_substeps) for c in _pilot_configs(result)}
    assert {m for m, _, _ in tried} >= {AB2, AB3, RK4} and {k for _, k, _ in tried} >= {EULER, RK4}
    assert any(n > 1 for _, _, n in tried)
    # the cost model counts the calls of each method: a kind per (component, method, steps, polynomials)
    assert any(kind[1] == RK4 and kind[3] for kind in result.costs if kind != MACRO)

    out = write_settings(sc, tuned_scenario(result), folder / "tuned.ssd", "test")
    tuned = api.load_scenario(out)
    c = result.best.trial.config
    mass1, mass2 = tuned.component("mass1"), tuned.component("mass2")
    assert mass1.model_exchange.solver == ITEMS[c.mech_solver]
    assert mass2.model_exchange.solver == ITEMS[c.ctrl_solver if not c.single_rate else c.mech_solver]
    assert mass1.model_exchange.substeps(tuned.macro_step) == c.mech_substeps
    assert mass1.parameters == sc.component("mass1").parameters  # no solver parameter set: not theirs
    assert api.plan(tuned).describe().count("Model Exchange integrated by the master") == 2
    over = dataclasses.replace(tuned, stop_time=Fraction(2))  # the pilot's horizon
    d = api.run(over, backend="serial", record=["mass1.x", "mass1.v"]).data
    exact = SET_A.exact(d["time"], SET_A_Z0)
    for col, i in (("mass1.x", 0), ("mass1.v", 1)):
        scale = float(np.ptp(exact[:, i]))
        assert np.max(np.abs(d[col] - exact[:, i])) / scale <= tolerance, col
    _assert_linearly_stable(tuned)


def _pilot_configs(result):
    return [ch.trial.config for ch in result.choices] + [t.config for _, t, _ in result.failed]


VANDERPOL_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="vdp"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:mm="urn:org.multirate-master:settings:1">
  <ssd:System name="vdp">
    <ssd:Elements>
      <ssd:Component name="vdp" source="project:vanderpol">
        <ssd:Connectors>
          <ssd:Connector name="x1" kind="output"/>
          <ssd:Connector name="x2" kind="output"/>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Annotations>
      <ssc:Annotation type="org.multirate-master.settings">
        <mm:Settings macroStep="0.01">
          <mm:Component name="vdp" modelExchange="true" solver="euler" internalStep="0.001"/>
        </mm:Settings>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="4"/>
</ssd:SystemStructureDescription>
"""


def test_tune_chooses_the_method_of_a_model_exchange_fmu_in_any_scene(tmp_path):
    """A scene without a bench profile: vanderpol alone, written for Model Exchange with Euler in
    steps of 1 ms. The tune tries the six methods and other solver steps per communication step;
    Euler needs about a hundred times the steps of AB3 for 1e-4 (first against third order), so a
    higher-order method wins; the written scenario runs it as Model Exchange, within the tolerance
    of scipy's Radau."""
    from scipy.integrate import solve_ivp

    (tmp_path / "vdp.ssd").write_text(VANDERPOL_SSD)
    sc = api.load_scenario(tmp_path / "vdp.ssd")
    tolerance = 1e-4
    result = tune(sc, tolerance, repeats=1, rounds=2)
    assert result.best is not None and result.best.trial.error <= tolerance
    tried = {c.me_solver for c in _pilot_configs(result)}
    assert tried == {EULER, AB2, AB3, RK4, SI_EULER, SI_MIDPOINT}
    chosen = result.best.trial.config
    assert chosen.me_solver != EULER, result.best.family

    tuned = api.load_scenario(write_settings(sc, tuned_scenario(result), tmp_path / "tuned.ssd", "test"))
    me = tuned.component("vdp").model_exchange
    assert me.solver == ITEMS[chosen.me_solver] and me.substeps(tuned.macro_step) == chosen.me_substeps
    d = api.run(tuned, backend="serial").data
    x0 = (2.0, 0.0)  # vanderpol's start values, mu = 1
    ref = solve_ivp(lambda t, x: [x[1], (1 - x[0] ** 2) * x[1] - x[0]], (0, 4), x0, method="Radau",
                    t_eval=d["time"], rtol=1e-11, atol=1e-13).y  # fmt: skip
    for col, exact in (("vdp.x1", ref[0]), ("vdp.x2", ref[1])):
        assert np.max(np.abs(d[col] - exact)) / float(np.ptp(exact)) <= tolerance, col


def test_the_linear_model_of_a_tune_steps_model_exchange_components_as_the_runtime(tmp_path):
    """The stability check of each candidate takes the scene linearised once and sets each
    configuration's methods, steps and input modes on it (bench.linear_scheme): for Model
    Exchange components (inputs polynomials at every stage, their solver steps) it is the scene of
    that configuration linearised as the runtime plans it."""
    from master.evidence.linear import spectral_radius

    sc = api.load_scenario(_as_model_exchange(_copy(tmp_path, OSCILLATOR)))
    p = bench.profile_for(sc)
    assert p.model_exchange == ("mass1", "mass2")
    lin = bench.linearize_scene(sc, p)
    for change in ({}, {"mech_solver": RK4, "mech_substeps": 4}, {"ctrl_solver": SI_MIDPOINT, "ratio": 2},
                   {"order": 3, "mech_solver": AB2, "mech_substeps": 2}):  # fmt: skip
        c = dataclasses.replace(p.base, **change)
        scheme = bench.linear_scheme(lin, p, c)
        assert all(comp.model_exchange and comp.input_mode == "polynomial" for comp in scheme.components)
        direct = linearize(bench.apply(sc, p, c), t=p.linearize_at)
        h = float(c.macro_step)
        assert spectral_radius(scheme, h) == pytest.approx(spectral_radius(direct, h), rel=1e-9), change
