"""Algebraic loops solved at communication points (master.schedule.Loop, kernel.h mk_loop).

The ring: add.y = s(t) + g2.y, g1.y = k1 add.y, g2.y = k2 g1.y, every output depending directly on
its input, s a table stimulus. Its exact solution at every point is add.y = s / (1 - k1 k2).
"""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import BACKENDS, run_everywhere, ssd

import master.api as api
from master.fmubuild import fmu_path
from master.scenario.model import LoopSolver
from master.schedule import EDGE_DECLARED

RING = [("add", "y", "g1", "u"), ("g1", "y", "g2", "u"), ("g2", "y", "add", "u2")]
STIMULUS = (
    '<mm:Stimuli><mm:Table component="add" variable="u1">'
    '<mm:Point time="0" value="1"/><mm:Point time="1" value="3"/><mm:Point time="2" value="-2"/>'
    "</mm:Table></mm:Stimuli>"
)


def ring(tmp_path: Path, k1: float = 0.5, k2: float = -1.0, loops: str = "", stop: str = "2"):
    """The ring scene with gains k1, k2 (loop gain k1 k2) and the mm:Loops element `loops`."""
    path = ssd(
        tmp_path / "ring.ssd",
        {"add": "blocks_add", "g1": "blocks_gain", "g2": "blocks_gain"},
        RING,
        settings=STIMULUS + loops,
        stop=stop,
    )
    sc = api.load_scenario(path, {"g1.k": repr(k1), "g2.k": repr(k2)})
    return sc


def stimulus(t: np.ndarray) -> np.ndarray:
    return np.interp(t, [0.0, 1.0, 2.0], [1.0, 3.0, -2.0])


def test_the_ring_is_planned_as_one_loop_of_declared_dependencies(tmp_path):
    p = api.plan(ring(tmp_path))
    (lp,) = p.loops
    assert set(lp.members) == {"add", "g1", "g2"}
    assert set(lp.unknowns) == {("add", "y"), ("g1", "y"), ("g2", "y")}
    assert not lp.assumed  # the blocks declare their dependencies
    assert sum(e == EDGE_DECLARED for row in lp.structure for e in row) == 3  # one per hop
    assert any("algebraic loop" in n and "Newton" in n for n in p.notes)


@pytest.mark.parametrize("method", ["newton", "fixed-point"])
def test_a_linear_ring_reaches_its_exact_fixed_point_at_every_point_in_every_backend(tmp_path, method):
    sc = ring(tmp_path, loops=f'<mm:Loops method="{method}" tolerance="1e-13"/>')
    d = run_everywhere(sc)
    exact = stimulus(d["time"]) / 1.5  # 1 - k1 k2 = 1.5
    assert np.allclose(d["add.y"], exact, rtol=1e-12, atol=1e-12)
    assert np.allclose(d["g1.y"], 0.5 * exact, rtol=1e-12, atol=1e-12)
    # consistent to the tolerance: each output read with inputs within it of the final samples
    assert np.allclose(d["g2.y"], -d["g1.y"], rtol=1e-12, atol=1e-12)


def test_a_ring_of_loop_gain_beyond_one_converges_with_newton_not_with_plain_iteration(tmp_path):
    # loop gain -3: fixed-point iteration x <- F(x) diverges; Newton (a linear loop: one step) and
    # Aitken's secant do not
    for method in ("newton", "fixed-point"):
        sc = ring(tmp_path, k1=3.0, k2=-1.0, loops=f'<mm:Loops method="{method}" tolerance="1e-13"/>')
        d = api.run(sc, backend="in-process").data
        assert np.allclose(d["add.y"], stimulus(d["time"]) / 4.0, rtol=1e-12, atol=1e-12), method


def test_iterations_are_counted_and_the_jacobian_is_reused(tmp_path):
    res = api.run(ring(tmp_path), backend="in-process")
    (stats,) = res.summary.loops.values()
    points = 21  # the start time and 20 macro steps
    assert stats["solves"] >= points
    assert stats["jacobians"] == 1  # a linear loop: the first Jacobian serves every point
    assert stats["most"] <= 3  # Newton on a linear loop: one step, then the check


def test_a_loop_that_does_not_converge_ends_the_run_naming_it_with_the_rows_kept(tmp_path):
    sc = ring(tmp_path, k1=3.0, k2=-1.0, loops='<mm:Loops method="newton" maxIterations="1"/>')
    out = tmp_path / "out.csv"
    with pytest.raises(api.SimulationError) as e:
        api.run(sc, backend="serial", output=out)
    message = str(e.value)
    assert "algebraic loop" in message and "add.y" in message and "not solved at t=0" in message
    assert "after 1 iterations" in message


def test_scenario_settings_of_a_loop_are_checked():
    sc = dataclasses.replace(
        api.load_scenario(Path(__file__).parent / "scenarios" / "loops" / "dcmotor_pair.ssd"),
        loops=LoopSolver(method="bisection", tolerance=2.0, max_iterations=0),
    )
    with pytest.raises(api.ScenarioError) as e:
        api.plan(sc)
    text = str(e.value)
    assert "bisection" in text and "tolerance 2.0" in text and "max_iterations 0" in text


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_dcmotor_pair_runs_with_consistent_outputs_at_every_point(backend):
    """Two dcmotor controllers feeding each other's w_ext1 (an output depending directly on it): at
    every recorded point each input equals the other's output (solved, not lagged)."""
    scene = Path(__file__).parent / "scenarios" / "loops" / "dcmotor_pair.ssd"
    sc = api.load_scenario(scene, stop_time="0.05")
    names = ["left.w1", "right.w1", "left.w_ext1", "right.w_ext1"]
    d = api.run(sc, backend=backend, record=names).data
    assert np.allclose(d["left.w_ext1"], d["right.w1"], rtol=1e-9, atol=1e-12)
    assert np.allclose(d["right.w_ext1"], d["left.w1"], rtol=1e-9, atol=1e-12)


def without_dependencies(fmu: Path, to: Path) -> Path:
    """A copy of `fmu` whose description declares no output dependencies (as pythonfmu and 20-sim
    write theirs): FMI then takes every output to depend on every input."""
    with zipfile.ZipFile(fmu) as z:
        members = {item.filename: z.read(item) for item in z.infolist()}
    text = members["modelDescription.xml"].decode()
    stripped, n = re.subn(r'\s+dependencies(Kind)?="[^"]*"', "", text)
    assert n, "the built FMU declares no dependencies to strip"
    members["modelDescription.xml"] = stripped.encode()
    with zipfile.ZipFile(to, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return to


def feedback(tmp_path: Path, declared: bool):
    """msd's position fed back as its force through a gain: a loop only if msd declares nothing."""
    msd = fmu_path("msd") if declared else without_dependencies(fmu_path("msd"), tmp_path / "msd_open.fmu")
    path = ssd(
        tmp_path / f"feedback_{declared}.ssd",
        {"body": str(msd), "k": "blocks_gain"},
        [("body", "x", "k", "u"), ("k", "y", "body", "F")],
        settings='<mm:Record><mm:Variable component="body" name="x"/><mm:Variable component="body" name="F"/>'
        '<mm:Variable component="k" name="y"/></mm:Record>',
        macro_step="0.01",
    )
    return api.load_scenario(path, {"k.k": "-4.0", "body.x0": "1.0"})


def test_an_fmu_that_merely_omits_dependencies_costs_one_probe_and_gives_the_same_bits(tmp_path):
    declared, assumed = feedback(tmp_path, True), feedback(tmp_path, False)
    assert not api.plan(declared).loops
    p = api.plan(assumed)
    (lp,) = p.loops
    assert lp.assumed
    (note,) = [n for _, n in p.fmu_notes if "declares no dependencies" in n]
    assert "msd_open.fmu" in note and "x" in note
    reference = api.run(declared, backend="in-process").data
    for backend in BACKENDS:
        res = api.run(assumed, backend=backend)
        for name in reference.dtype.names:
            assert np.array_equal(res.data[name], reference[name]), (backend, name)
        (stats,) = res.summary.loops.values()
        assert stats["sequential"] == 1  # the probe found msd.x independent of F: no iteration
        assert stats["jacobians"] == 1 and stats["most"] == 1


def test_validate_prints_the_notes_on_assumed_dependencies_once_per_fmu(tmp_path):
    scene = feedback(tmp_path, False).path
    out = subprocess.run(
        [sys.executable, "-m", "master", "validate", str(scene)], capture_output=True, text=True, check=True
    ).stdout
    assert f"{scene}: ok" in out
    notes = [line for line in out.splitlines() if "declares no dependencies" in line]
    assert len(notes) == 1 and "msd_open.fmu" in notes[0]
    assert any("algebraic loop" in line for line in out.splitlines())


def cubic_root(s: float, a: float, b: float) -> float:
    """The real y of a y^3 + (1 + b) y = s (one: a, 1 + b > 0)."""
    roots = np.roots([a, 0.0, 1.0 + b, -s])
    return float(roots[np.argmin(abs(roots.imag))].real)


@pytest.mark.parametrize("method", ["newton", "fixed-point"])
def test_a_nonlinear_loop_reaches_the_root_at_every_point(tmp_path, method):
    """add.y = s(t) + c.y, c.y = -(a u^3 + b u) with u = add.y: y solves a y^3 + (1 + b) y = s."""
    path = ssd(
        tmp_path / "cubic.ssd",
        {"add": "blocks_add", "c": "cubic"},
        [("add", "y", "c", "u"), ("c", "y", "add", "u2")],
        settings=STIMULUS + f'<mm:Loops method="{method}" tolerance="1e-12"/>',
        stop="2",
    )
    sc = api.load_scenario(path, {"c.a": "-2.0", "c.b": "-0.5", "add.k2": "1.0"})
    res = api.run(sc, backend="in-process")
    d = res.data
    exact = [cubic_root(s, 2.0, 0.5) for s in stimulus(d["time"])]
    assert np.allclose(d["add.y"], exact, rtol=1e-10, atol=1e-10)
    (stats,) = res.summary.loops.values()
    if method == "newton":  # refreshed where a kept Jacobian slows it: Newton's rate
        assert stats["jacobians"] > 1 and stats["most"] <= 8


@pytest.mark.parametrize(
    "settings",
    [
        '<mm:Component name="g1" stepRatio="4"/>',  # members at different rates: solved at common points
        '<mm:Component name="add" extrapolationOrder="2"/>',  # start-up sweeps, then the loop solved
    ],
)
def test_the_ring_is_exact_at_the_macro_steps_whatever_the_rates_and_orders(tmp_path, settings):
    path = ssd(
        tmp_path / "ring.ssd",
        {"add": "blocks_add", "g1": "blocks_gain", "g2": "blocks_gain"},
        RING,
        settings=settings + STIMULUS + '<mm:Loops tolerance="1e-13"/>',
        stop="2",
    )
    sc = api.load_scenario(path, {"g1.k": "0.5", "g2.k": "-1.0"})
    d = run_everywhere(sc)
    assert np.allclose(d["add.y"], stimulus(d["time"]) / 1.5, rtol=1e-12, atol=1e-12)
