"""No recorded or coupled output lags its time label: after each macro step a component whose
outputs depend on its inputs reads them again with its inputs set to the sources' samples at the
macro step's end (kernel.h: resample), in every backend and coupling."""

import dataclasses
import itertools
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from helpers import run_everywhere

import master.api as api
from master.backends.component import output_names
from master.evidence.oscillator import SET_A, scene
from master.fmubuild import fmu_path
from master.runtime.tables import resampling
from master.scenario.model import Component, Connection, Scenario, Stimulus

BACKENDS = ("serial", "parallel", "in-process")


@pytest.mark.parametrize("ratios", [(1, 1), (2, 3), (3, 1)])
def test_a_pure_gain_fed_by_another_component_records_k_times_its_input_at_every_row(ratios):
    source = dataclasses.replace(scene(split="force").components[0], step_ratio=ratios[0])  # mass1 alone
    gain = Component("gain", fmu_path("gain"), {"K": 3.0}, ratios[1], 2)
    link, record = Connection("mass1", "x", "gain", "u"), (("mass1", "x"), ("gain", "y"))
    span = (Fraction(0), Fraction(3), Fraction(1, 20))
    sc = Scenario(Path("gain.ssd"), "gain", (source, gain), (link,), *span, record=record)
    for backend in BACKENDS:
        d = api.run(sc, backend=backend).data
        assert np.array_equal(d["gain.y"], 3.0 * d["mass1.x"]), backend  # y(t) = K u(t), not K u(t - H)
        assert len(np.unique(d["gain.y"])) > 50


@pytest.mark.parametrize("coupling, first", [("jacobi", ()), ("gauss-seidel", ("mass1", "mass2")),
                                             ("gauss-seidel", ("mass2", "mass1"))])  # fmt: skip
@pytest.mark.parametrize("ratios", [(1, 1), (1, 4), (4, 1)])
def test_the_coupling_force_is_consistent_with_both_masses_at_every_row(coupling, first, ratios):
    sc = scene(split="force", macro_step=Fraction(1, 20), order=2, step_ratios=ratios, stop_time=Fraction(2),
               coupling=coupling)  # fmt: skip
    sc = dataclasses.replace(sc, order=first or sc.order, record=sc.record + (("mass2", "F_c"),))
    rows = {b: api.run(sc, backend=b).data for b in BACKENDS}
    for d in rows.values():
        assert all(np.array_equal(d[n], rows["serial"][n]) for n in d.dtype.names)  # the same bits
    d = rows["serial"]
    force = SET_A.cc * (d["mass2.x"] - d["mass1.x"]) + SET_A.dc * (d["mass2.v"] - d["mass1.v"])
    assert np.max(np.abs(d["mass2.F_c"] - force)) < 1e-15


def test_only_the_outputs_that_depend_on_inputs_are_read_again():
    force = api.plan(scene(split="force"))
    outs = {pc.name: output_names(force, pc.name, _variables(force, pc.name)) for pc in force.components}
    again, order = resampling(force, outs)
    assert again == {"mass2": ["F_c"]} and order == ["mass2"]  # not x, v: they depend on the state
    plain = api.plan(scene(split="displacement"))
    outs = {pc.name: output_names(plain, pc.name, _variables(plain, pc.name)) for pc in plain.components}
    assert resampling(plain, outs) == ({}, [])  # nothing depends on inputs: no extra FMI call


def _variables(plan, name):
    from master.description import variables_of
    from master.fmu import read_description

    return variables_of(read_description(plan.scenario.component(name).fmu_path))


def _held_scene(record: tuple, with_d: bool = False) -> Scenario:
    """The issue's case: alltypes A (ratio 1) drives alltypes C (ratio 5, order 2) with an Int32, an
    Int64, a Float64 and a Binary (A's time stamp) under step stimuli on A; with_d: C's Int32 and
    Binary outputs drive alltypes D (ratio 2) in turn."""
    f = fmu_path("alltypes", fmi=3)
    a = Component("A", f, {}, 1, 0)
    c = Component("C", f, {"p_int32": 10, "p_int64": -3, "p_float64": 0.5}, 5, 2)
    pairs = (
        ("y_int32", "u_int32"),
        ("y_int64", "u_int64"),
        ("y_float64", "u_float64"),
        ("stamp", "u_binary"),
    )
    links = [Connection("A", y, "C", u) for y, u in pairs]
    comps = (a, c)
    if with_d:
        comps += (Component("D", f, {"p_int32": 100}, 2, 1),)
        links += [Connection("C", "y_int32", "D", "u_int32"), Connection("C", "y_binary", "D", "u_binary")]
    stimuli = (Stimulus("A", "u_int32", "step", (0.3, 0.75), (5, -3)),
               Stimulus("A", "u_int64", "step", (0.5,), (2**40,)),
               Stimulus("A", "u_float64", "step", (0.2,), (1.5,)))  # fmt: skip
    span = (Fraction(0), Fraction(3, 2), Fraction(1, 10))
    return Scenario(Path("held.ssd"), "held", comps, tuple(links), *span, stimuli=stimuli, record=record)


C_OUTPUTS = ("y_int32", "y_int64", "y_float64", "y_binary")
A_RECORD = (("A", "y_int32"), ("A", "y_int64"), ("A", "y_float64"), ("A", "stamp"))


def test_a_recorded_output_of_any_type_is_the_same_whatever_else_is_recorded():
    """C's outputs depend on its inputs: each column is read with the inputs of its row's time,
    whichever subset of C's outputs (of whichever types) is recorded."""
    full = api.run(_held_scene(A_RECORD + tuple(("C", o) for o in C_OUTPUTS)), backend="in-process").data
    assert np.all(full["C.y_int32"] == full["A.y_int32"] + 10)  # not A's value one macro step before
    assert np.all(full["C.y_int64"] == full["A.y_int64"] - 3)
    assert np.array_equal(full["C.y_float64"], full["A.y_float64"] + 0.5)
    assert [b[::-1] for b in full["A.stamp"]] == list(full["C.y_binary"])
    assert len(np.unique(full["C.y_int32"])) == 3 and len(set(full["C.y_binary"])) > 2
    for n in range(1, len(C_OUTPUTS) + 1):
        for subset in itertools.combinations(C_OUTPUTS, n):
            sc = _held_scene(A_RECORD + tuple(("C", o) for o in subset))
            backends = BACKENDS if n in (1, len(C_OUTPUTS)) else ("in-process",)
            for backend in backends:
                d = api.run(sc, backend=backend).data
                for o in subset:
                    assert list(d[f"C.{o}"]) == list(full[f"C.{o}"]), (subset, backend, o)


def test_held_and_binary_outputs_read_again_drive_the_next_component_at_their_time():
    """C re-reads its Int32 and Binary outputs with the step-end inputs before D takes them: D sees
    A's values of the same time through two components, in every backend."""
    record = A_RECORD + (("C", "y_int32"), ("D", "y_int32"), ("D", "y_binary"))
    d = run_everywhere(_held_scene(record, with_d=True))
    assert np.all(d["D.y_int32"] == d["A.y_int32"] + 10 + 100)
    assert list(d["D.y_binary"]) == list(d["A.stamp"])  # reversed twice
