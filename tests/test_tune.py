"""`master tune`: the configuration it writes is stable and meets the tolerance, checked
independently of the search (the oscillator against its exact solution, the paper's scenes
against the Model Exchange reference), and the scenario writer changes only the settings."""

from __future__ import annotations

import dataclasses
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
from master.tune import ladder, tune, tuned_scenario

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
                           "--repeats", "1"], capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "chosen:" in proc.stdout and "Traceback" not in proc.stderr
    assert (folder / "oscillator.ssd").read_bytes() == original
    assert (folder / "oscillator.tuned.txt").read_text().startswith("master tune: two-mass oscillator")

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


@pytest.mark.parametrize(("scene", "tolerance"), [("hydraulic-manipulator", 3e-3), ("dc-motor-arm", 1e-2)])
def test_tune_on_the_paper_scenes_meets_the_tolerance(tmp_path, scene, tolerance):
    """The tuned scenario, written and read back, run over the bench horizon, is within the
    tolerance of the Model Exchange reference on the paper's variables and linearly stable."""
    folder = _copy(tmp_path, REPO / "models" / scene)
    sc = api.load_scenario(folder / "SystemStructure.ssd")
    result = tune(sc, tolerance, repeats=1, rounds=2)
    assert result.best is not None and result.best.trial.error <= tolerance
    out = write_settings(sc, tuned_scenario(result), folder / "tuned.ssd", "test")
    tuned = api.load_scenario(out)
    p = bench.profile_for(sc)
    assert tuned.stop_time == sc.stop_time
    horizon = dataclasses.replace(tuned, stop_time=p.stop_time, record_interval=p.record_interval)
    res = api.run(horizon, backend="serial")
    rep = compare(as_trajectory(res.data), reference(bench.base_scene(sc, p)), list(p.variables))
    assert rep.worst_max <= tolerance
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
                parameters={**mass2.parameters, "solver": 6},
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
                           "--real-time-budget", "1e-9", "--rounds", "1", "--repeats", "1"],
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
    ],
)
def test_tune_refuses_bad_options_in_one_line(tmp_path, args, message):
    folder = _copy(tmp_path, OSCILLATOR)
    src = str(folder / "oscillator.ssd")
    proc = subprocess.run([str(BIN / "master"), "tune", src, *(a.format(src=src) for a in args)],
                          capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
    assert proc.returncode in (1, 2) and message in proc.stderr and "Traceback" not in proc.stderr
