"""Integer and Boolean connections: carried by the kernel through the FMUs' own typed calls, held
between communication points (never extrapolated, whatever the consumer's order), in every backend.

Two `discrete` FMUs (fmus/discrete, built from C) in a ring: each one's Integer output n and
Boolean output on drive the other's inputs n_in and on_in, and each integrates
x' = on_in ? (n_in + 1) rate : -rate x with explicit Euler, one step per communication step.
"""

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import master.api as api
from master.fmubuild import fmu_path
from master.scenario.model import Component, Connection, Scenario
from master.solvers import EULER

H = Fraction(1, 50)


def ring(ratio_b: int = 1, coupling: str = "jacobi") -> Scenario:
    fmu = fmu_path("discrete")
    comps = (
        Component("a", fmu, {"x": 0.7, "solver": EULER}, 1, 2),  # order 2: must not reach discrete inputs
        Component("b", fmu, {"x": 0.0, "solver": EULER, "rate": 0.5}, ratio_b, 2),
    )
    conns = tuple(
        Connection(src, out, dst, inp)
        for src, dst in (("a", "b"), ("b", "a"))
        for out, inp in (("n", "n_in"), ("on", "on_in"))
    )
    record = tuple((c, v) for c in ("a", "b") for v in ("x", "n", "on", "n_in", "on_in"))
    return Scenario(Path("ring.ssd"), "discrete ring", comps, conns, Fraction(0), Fraction(2), H,
                    coupling=coupling, order=("a", "b") if coupling == "gauss-seidel" else (),
                    record=record)  # fmt: skip


def euler(x0: float, n_in: int, on_in: bool, rate: float, h: float, steps: int) -> float:
    x = x0
    for _ in range(steps):
        x = x + h * ((n_in + 1) * rate if on_in else -rate * x)
    return x


@pytest.mark.parametrize("ratio_b, coupling", [(1, "jacobi"), (3, "jacobi"), (1, "gauss-seidel")])
def test_integer_and_boolean_signals_are_held_and_drive_the_equations(ratio_b, coupling):
    sc = ring(ratio_b, coupling)
    plan = api.plan(sc)
    assert {(lk.kind, lk.order) for lk in plan.links} == {("Integer", 0), ("Boolean", 0)}
    serial = api.run(sc, backend="serial").data
    for backend in ("parallel", "in-process"):  # the same bits in every backend
        other = api.run(sc, backend=backend).data
        for name in serial.dtype.names:
            assert np.array_equal(serial[name], other[name]), (backend, name)
    d = serial
    assert len(d) == 101
    for col in ("a.n", "b.n"):
        assert np.array_equal(d[col], np.floor(np.where(col == "a.n", d["a.x"], d["b.x"]) / 0.25))
    assert {float(d["a.on"][-1]), float(d["b.on"][-1])} != {float(d["a.on"][0]), float(d["b.on"][0])}
    assert len(np.unique(d["a.n"])) > 1 and len(np.unique(d["b.n"])) > 1  # discrete events happen
    # recorded inputs: the producer's sample at the row's time (resampling), whatever the coupling
    for src, dst in (("a", "b"), ("b", "a")):
        assert np.array_equal(d[f"{dst}.n_in"], d[f"{src}.n"])
        assert np.array_equal(d[f"{dst}.on_in"], d[f"{src}.on"])
    # held: the step ending at row i saw the producer's sample at its start (Jacobi) or at its end
    # (Gauss-Seidel, a before b): Euler steps recomputed here from the recorded inputs
    for comp, rate, k in (("a", 1.0, 1), ("b", 0.5, ratio_b)):
        lag = 0 if coupling == "gauss-seidel" and comp == "b" else 1
        for i in range(1, len(d)):
            n_in, on_in = int(d[f"{comp}.n_in"][i - lag]), bool(d[f"{comp}.on_in"][i - lag])
            x = euler(d[f"{comp}.x"][i - 1], n_in, on_in, rate, float(H) / k, k)
            assert d[f"{comp}.x"][i] == pytest.approx(x, rel=1e-13, abs=1e-15)


def test_a_connection_of_a_type_no_call_carries_is_refused_with_both_ends(tmp_path):
    sc = ring()
    bad = Scenario(sc.path, sc.name, sc.components, (Connection("a", "n", "b", "x"),), sc.start_time,
                   sc.stop_time, H)  # fmt: skip
    with pytest.raises(
        api.ScenarioError, match=r"connection a\.n -> b\.x: end b\.x is an output, not an input"
    ):
        api.plan(bad)
    mixed = Scenario(sc.path, sc.name, sc.components, (Connection("a", "n", "b", "u"),), sc.start_time,
                     sc.stop_time, H)  # fmt: skip
    with pytest.raises(api.ScenarioError, match=r"type mismatch: a\.n is Integer, b\.u is Real"):
        api.plan(mixed)


def test_what_a_connection_carries_per_fmi_type():
    from master.scenario.fmuinfo import coupling_kind

    assert [coupling_kind(t, "2.0") for t in ("Real", "Integer", "Boolean", "Enumeration", "String")] == [
        "Real",
        "Integer",
        "Boolean",
        "Integer",
        "String",
    ]
    fmi3 = ("Float64", "Int32", "Boolean", "Enumeration", "Float32", "Int64", "UInt8", "String", "Binary")
    assert [coupling_kind(t, "3.0") for t in fmi3] == [
        "Real", "Integer", "Boolean", "Int64", "Float32", "Int64", "UInt8", "String", "Binary"
    ]  # fmt: skip
    assert coupling_kind("Clock", "3.0") == "Clock"  # its count of ticks, to a triggered input clock


def test_a_step_stimulus_drives_an_integer_input():
    # b grows at (n_in + 1) rate with on_in held true; n_in steps from 0 to 3 at t = 0.5 s: Euler
    # integrates the piecewise constant slope exactly
    from master.scenario.model import Stimulus

    sc = ring()
    b = Component("b", sc.components[1].fmu_path, {"solver": EULER, "rate": 0.5, "on_in": True}, 2, 2)
    step = Stimulus("b", "n_in", "step", (0.5,), (3.0,))
    record = (("b", "x"), ("b", "n_in"))
    scene = Scenario(sc.path, sc.name, (b,), (), Fraction(0), Fraction(2), H, record=record, stimuli=(step,))
    for backend in ("serial", "in-process"):
        d = api.run(scene, backend=backend).data
        t = d["time"]
        assert np.allclose(d["b.x"], np.where(t <= 0.5, 0.5 * t, 0.25 + 2.0 * (t - 0.5)), rtol=0, atol=1e-13)
        assert set(np.unique(d["b.n_in"])) == {0.0, 3.0}
    table = Stimulus("b", "n_in", "table", (0.0, 1.0), (0.0, 3.0))
    with pytest.raises(api.ScenarioError, match="an Integer input takes a step"):
        api.plan(Scenario(sc.path, sc.name, (b,), (), Fraction(0), Fraction(2), H, stimuli=(table,)))
